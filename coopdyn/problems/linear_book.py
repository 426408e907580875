"""The book's linear cooperative system (eq. 45/46): parameters, drives, exact solution, scene.

Three nodes on the vertical axis, gravity g on all: tip 1 (Y1, m1, drive τ1), object (Y2, m),
tip 2 (Y3, m2, drive τ2); spring–damper p (c_p, d_p, rest length s1) between tip 1 and the
object, k (c_k, d_k, s3) between the object and tip 2::

    m1 Ÿ1 + m1 g = τ1 − Fc1,   Fc1 = d_p (Ẏ1 − Ẏ2) + c_p (Y1 − Y2 + s1)
    m2 Ÿ3 + m2 g = τ2 − Fc2,   Fc2 = d_k (Ẏ3 − Ẏ2) + c_k (Y3 − Y2 − s3)
    m  Ÿ2 + m  g = Fc1 + Fc2

The system is linear time-invariant. For drives that are piecewise *constant + ramp + sinusoid*
(:class:`Drive`), it is solved exactly on each piece by the matrix exponential of the state
matrix augmented with a constant, a clock and a harmonic exosystem per drive.
"""

from __future__ import annotations

import bisect
import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import scipy.linalg

from .. import _validate
from .._spec import DrivesSpec
from ..errors import SceneError
from ..model.arm import Arm
from ..model.body import RigidObject
from ..model.interconnection import Interconnection, axial
from ..model.scene import Scene
from ..resources import urdf_path


@dataclass(frozen=True)
class BookParameters:
    """Parameters of the linear system; defaults are the book's values.

    Masses [kg], stiffnesses [N/m], dampings [N·s/m], lengths and positions [m], g [m/s²].
    """

    m: float = 25.0
    m1: float = 12.5
    m2: float = 12.5
    c_p: float = 20e3
    c_k: float = 10e3
    d_p: float = 500.0
    d_k: float = 1000.0
    s1: float = 0.05
    s3: float = 0.05
    Y10: float = 0.150
    Y20: float = 0.200
    Y30: float = 0.250
    g: float = 9.81

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            _validate.finite_array(value, f"linear book parameter {f.name}", ())
            object.__setattr__(self, f.name, float(value))
        for name in ("m", "m1", "m2"):
            _validate.positive(getattr(self, name), f"linear book parameter {name}", "kg")
        for name, unit in (("c_p", "N/m"), ("c_k", "N/m"), ("d_p", "N·s/m"), ("d_k", "N·s/m")):
            _validate.non_negative(getattr(self, name), f"linear book parameter {name}", unit)

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> BookParameters:
        """Parameters from keyword arguments, naming the valid ones on a typo."""
        valid = [f.name for f in fields(cls)]
        unknown = [k for k in kwargs if k not in valid]
        if unknown:
            raise SceneError(f"unknown linear book parameter(s) {unknown}; valid: {valid}")
        return cls(**kwargs)

    def preloaded(self) -> BookParameters:
        """A copy whose tips start where the springs already carry half the object's weight each
        (Y10, Y30 moved; Y20 kept): the static equilibrium under the drives of
        :func:`coopdyn.scenes.book_task` at t = 0, so the start excites no transient."""
        if self.c_p <= 0.0 or self.c_k <= 0.0:
            raise SceneError("a preloaded start needs c_p > 0 and c_k > 0")
        half = 0.5 * self.m * self.g
        return dataclasses.replace(self, Y10=self.Y20 - self.s1 + half / self.c_p, Y30=self.Y20 + self.s3 + half / self.c_k)

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, c) of ẋ = A x + B τ + c for x = [Y1, Y2, Y3, Ẏ1, Ẏ2, Ẏ3], τ = [τ1, τ2]."""
        p = self
        # Fc1 = kp1 · x + c_p s1,  Fc2 = kp2 · x − c_k s3
        f1 = np.array([p.c_p, -p.c_p, 0.0, p.d_p, -p.d_p, 0.0])
        f2 = np.array([0.0, -p.c_k, p.c_k, 0.0, -p.d_k, p.d_k])
        A = np.zeros((6, 6))
        A[:3, 3:] = np.eye(3)
        A[3] = -f1 / p.m1
        A[5] = -f2 / p.m2
        A[4] = (f1 + f2) / p.m
        B = np.zeros((6, 2))
        B[3, 0] = 1.0 / p.m1
        B[5, 1] = 1.0 / p.m2
        c = np.zeros(6)
        c[3] = -p.g - p.c_p * p.s1 / p.m1
        c[5] = -p.g + p.c_k * p.s3 / p.m2
        c[4] = -p.g + (p.c_p * p.s1 - p.c_k * p.s3) / p.m
        return A, B, c

    def contact_forces(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Fc1, Fc2) [N] for states x (..., 6): the force each spring exerts on the object."""
        Y1, Y2, Y3, V1, V2, V3 = np.moveaxis(x, -1, 0)
        Fc1 = self.d_p * (V1 - V2) + self.c_p * (Y1 - Y2 + self.s1)
        Fc2 = self.d_k * (V3 - V2) + self.c_k * (Y3 - Y2 - self.s3)
        return Fc1, Fc2


@dataclass(frozen=True)
class Segment:
    """One piece of a drive, valid from ``start`` [s] until the next piece starts:
    ``τ(t) = constant + ramp·s + amplitude·sin(omega·s + phase)`` with ``s = t − start``.

    Units: constant and amplitude [N], ramp [N/s], omega [rad/s], phase [rad].
    """

    start: float = 0.0
    constant: float = 0.0
    ramp: float = 0.0
    amplitude: float = 0.0
    omega: float = 0.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, float(_validate.finite_array(getattr(self, f.name), f"segment {f.name}", ())))


class Drive:
    """A piecewise constant + ramp + sinusoid force [N] (see :class:`Segment`).

    Args:
        segments: pieces in increasing ``start`` order; the first starts at t = 0.
    """

    def __init__(self, segments: Sequence[Segment]) -> None:
        if isinstance(segments, str | bytes) or not isinstance(segments, Sequence):
            raise SceneError(f"a drive takes a list of Segment, got {type(segments).__name__}")
        segs = tuple(segments)
        bad = [type(s).__name__ for s in segs if not isinstance(s, Segment)]
        if bad:
            raise SceneError(f"a drive takes a list of Segment, got elements of type {bad}")
        if not segs or segs[0].start != 0.0:
            raise SceneError("a drive needs at least one segment, the first starting at t = 0")
        if any(b.start <= a.start for a, b in itertools.pairwise(segs)):
            raise SceneError(f"drive segments must start at strictly increasing times, got {[s.start for s in segs]}")
        self.segments = segs
        self._starts = np.array([s.start for s in segs])
        self._start_list = [s.start for s in segs]

    @classmethod
    def constant(cls, value: float) -> Drive:
        """A constant force [N]."""
        return cls([Segment(constant=value)])

    def segment_at(self, t: float) -> Segment:
        """The piece that holds at time t [s]."""
        return self.segments[max(0, bisect.bisect_right(self._start_list, t) - 1)]

    def __call__(self, t: Any) -> Any:
        """The force at time(s) t [s]."""
        if isinstance(t, float | int) and not isinstance(t, bool) and math.isfinite(t):
            seg = self.segment_at(t)
            s = t - seg.start
            return seg.constant + seg.ramp * s + seg.amplitude * math.sin(seg.omega * s + seg.phase)
        t = _validate.finite_array(t, "a drive's time t [s]")
        idx = np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, None)
        out = np.empty_like(t)
        for i, seg in enumerate(self.segments):
            sel = idx == i
            s = t[sel] - seg.start
            out[sel] = seg.constant + seg.ramp * s + seg.amplitude * np.sin(seg.omega * s + seg.phase)
        return out if out.ndim else float(out)


@dataclass(frozen=True)
class BookSolution:
    """The exact trajectory at the requested times."""

    t: np.ndarray  #: (n,) [s]
    Y: np.ndarray  #: positions Y1, Y2, Y3 (n, 3) [m]
    Ydot: np.ndarray  #: velocities (n, 3) [m/s]
    Fc1: np.ndarray  #: force of spring p on the object (n,) [N]
    Fc2: np.ndarray  #: force of spring k on the object (n,) [N]
    tau1: np.ndarray  #: drive 1 (n,) [N]
    tau2: np.ndarray  #: drive 2 (n,) [N]


def _augmented(params: BookParameters, seg1: Segment, seg2: Segment) -> np.ndarray:
    """State matrix of z = [x (6), 1, s, sin₁, cos₁, sin₂, cos₂] on one piece."""
    A, B, c = params.state_matrices()
    Z = np.zeros((12, 12))
    Z[:6, :6] = A
    Z[:6, 6] = c
    for col, seg in ((0, seg1), (1, seg2)):
        b = B[:, col]
        Z[:6, 6] += b * seg.constant
        Z[:6, 7] += b * seg.ramp
        i = 8 + 2 * col  # sin(ω s + φ) at i, cos at i + 1
        Z[:6, i] += b * seg.amplitude
        Z[i, i + 1] = seg.omega
        Z[i + 1, i] = -seg.omega
    Z[7, 6] = 1.0  # ds/dt = 1
    return Z


def linear_book_exact(
    t: Any, drive1: Drive, drive2: Drive, params: BookParameters | None = None, *, x0: Any = None
) -> BookSolution:
    """The exact solution at times ``t`` (n,) [s], t ≥ 0, for the given drives.

    Args:
        t: sample times [s], non-negative (any order).
        drive1, drive2: the forces τ1 on tip 1 and τ2 on tip 2 [N].
        params: system parameters (default: the book's).
        x0: initial state [Y1, Y2, Y3, Ẏ1, Ẏ2, Ẏ3]; default: at rest at (Y10, Y20, Y30).
    """
    p = params or BookParameters()
    if not isinstance(drive1, Drive) or not isinstance(drive2, Drive):
        raise SceneError("linear_book_exact: drive1 and drive2 must be Drives (e.g. from book_task())")
    t = np.atleast_1d(_validate.finite_array(t, "t [s]"))
    if t.ndim != 1 or np.any(t < 0.0) or not np.all(np.isfinite(t)):
        raise SceneError("t must be a 1-D array of finite, non-negative times [s]")
    x = np.array([p.Y10, p.Y20, p.Y30, 0.0, 0.0, 0.0]) if x0 is None else _validate.finite_array(x0, "x0", (6,))
    starts = np.union1d(drive1._starts, drive2._starts)
    X = np.empty((t.size, 6))
    for k, t0 in enumerate(starts):
        t1 = starts[k + 1] if k + 1 < starts.size else np.inf
        s1, s2 = _restart(drive1.segment_at(t0), t0), _restart(drive2.segment_at(t0), t0)
        Z = _augmented(p, s1, s2)
        z0 = np.concatenate([x, [1.0, 0.0], _harmonic(s1), _harmonic(s2)])
        sel = (t >= t0) & (t < t1)
        if np.any(sel):
            X[sel] = (scipy.linalg.expm(Z[None] * (t[sel] - t0)[:, None, None]) @ z0)[:, :6]
        if np.isfinite(t1):
            x = (scipy.linalg.expm(Z * (t1 - t0)) @ z0)[:6]
    Fc1, Fc2 = p.contact_forces(X)
    if not np.all(np.isfinite(X)):
        raise SceneError(
            f"the exact solution overflows by t = {t.max():.3g} s (the drives grow without bound); ask for shorter times"
        )
    return BookSolution(t=t, Y=X[:, :3], Ydot=X[:, 3:], Fc1=Fc1, Fc2=Fc2, tau1=np.asarray(drive1(t)), tau2=np.asarray(drive2(t)))


def _restart(seg: Segment, t0: float) -> Segment:
    """The same force law re-expressed with its clock starting at t0 ≥ seg.start."""
    s0 = t0 - seg.start
    return Segment(t0, seg.constant + seg.ramp * s0, seg.ramp, seg.amplitude, seg.omega, seg.phase + seg.omega * s0)


def _harmonic(seg: Segment) -> list[float]:
    return [np.sin(seg.phase), np.cos(seg.phase)]


def linear_book(**params: Any) -> Scene:
    """The book's linear cooperative system (eq. 45/46) built from URDF sliders.

    Keyword arguments: any of ``m, m1, m2`` [kg], ``c_p, c_k`` [N/m], ``d_p, d_k`` [N·s/m],
    ``s1, s3, Y10, Y20, Y30`` [m], ``g`` [m/s²]; the book's values by default
    (:class:`coopdyn.reference.BookParameters`).

    Arms ``tip1`` and ``tip2`` are 1-DOF prismatic sliders along world z (``urdf/slider_z.urdf``)
    whose joint coordinate is the tip height (Y1, Y3). The object slides along z from height Y20
    (its joint coordinate is Y2 − Y20). Interconnection 0 is the book's p (tip 1 – object),
    1 is k (object – tip 2); both are 1-D springs along z. Read Y1, Y2, Y3 with
    :func:`book_positions`; the book's Fc1, Fc2 are ``result.wrench(0)[:, 2]``, ``result.wrench(1)[:, 2]``.
    """
    p = BookParameters.from_kwargs(**params)
    slider = urdf_path("slider_z.urdf")
    arms = [
        Arm("tip1", slider, tip_frame="tip", q0=[p.Y10], mass_overrides={"slide": p.m1}),
        Arm("tip2", slider, tip_frame="tip", q0=[p.Y30], mass_overrides={"slide": p.m2}),
    ]
    obj = RigidObject(
        mass=p.m,
        inertia=np.eye(3) * 0.1,
        pose=[0.0, 0.0, p.Y20],
        joint="prismatic",
        axis="z",
        name="object",
        size=(0.08, 0.08, 0.04),
    )
    links = [
        Interconnection("tip1", stiffness=axial(p.c_p), damping=axial(p.d_p), grasp=[0.0, 0.0, -p.s1]),
        Interconnection("tip2", stiffness=axial(p.c_k), damping=axial(p.d_k), grasp=[0.0, 0.0, p.s3]),
    ]
    return Scene(arms, obj, links, gravity=[0.0, 0.0, -p.g])


def book_positions(q: np.ndarray, scene: Scene) -> np.ndarray:
    """Heights Y1, Y2, Y3 (n, 3) [m] of the linear book scene's configurations q (n, nq)."""
    q = np.atleast_2d(_validate.finite_array(q, "q"))
    if q.ndim != 2 or q.shape[1] != scene.nq:
        raise SceneError(f"q must be configurations of shape (n, {scene.nq}), got shape {q.shape}")
    Y20 = float(_validate.se3(scene.object.pose, "object pose").translation[2])
    return np.stack([q[:, scene.arms[0].q_index[0]], Y20 + q[:, scene.object_q[0]], q[:, scene.arms[1].q_index[0]]], axis=1)


def book_task(
    params: BookParameters | None = None,
    *,
    squeeze: float = 100.0,
    t_grip: float = 0.5,
    lift: float = 0.1,
    t_lift: float = 1.0,
    lift_duration: float = 1.0,
    amplitude: float = 0.02,
    frequency: float = 2.0,
    t_oscillate: float = 2.0,
) -> tuple[Drive, Drive]:
    """Open-loop drives τ1, τ2 [N] that grip, lift and oscillate the object (book Fig. 11).

    * from 0: both tips carry their own weight and half the object's; the squeeze (internal
      force) ramps to ``squeeze`` [N] over ``t_grip`` [s] (τ1 up, τ2 down);
    * from ``t_lift`` [s]: an acceleration ``a(s) = A sin(2π s / T)`` over ``T = lift_duration``
      [s] raises the object by ``lift`` [m] and stops it;
    * from ``t_oscillate`` [s]: half a period of ``a(s) = ½ X ω² sin(ω s)`` brings the object to
      the velocity X ω, then ``a(s) = −X ω² sin(ω s)`` makes it oscillate with amplitude
      ``X = amplitude`` [m] at ``frequency`` [Hz] (ω = 2π·frequency).

    Each tip carries the inertial force of its own mass and half the object's. Every drive is
    continuous in time (no force jumps), so fixed-step methods keep their order.
    """
    if params is not None and not isinstance(params, BookParameters):
        raise SceneError(f"book_task: params must be a BookParameters or None, got {type(params).__name__}")
    p = params or BookParameters()
    squeeze, lift, amplitude = (
        _validate.number(x, f"book_task: {n}", "N" if n == "squeeze" else "m")
        for n, x in (("squeeze", squeeze), ("lift", lift), ("amplitude", amplitude))
    )
    t_grip, lift_duration, frequency = (
        _validate.positive(x, f"book_task: {n}", "Hz" if n == "frequency" else "s")
        for n, x in (("t_grip", t_grip), ("lift_duration", lift_duration), ("frequency", frequency))
    )
    if min(t_grip, lift_duration) < 1e-6 or frequency > 1e6:
        raise SceneError(
            "book_task: t_grip and lift_duration must be >= 1 µs and frequency <= 1 MHz (the drives' slopes overflow)"
        )
    t_lift, t_oscillate = (
        _validate.number(x, f"book_task: {n}", "s") for n, x in (("t_lift", t_lift), ("t_oscillate", t_oscillate))
    )
    if not (t_grip <= t_lift and t_lift + lift_duration <= t_oscillate):
        raise SceneError(
            f"book_task needs 0 < t_grip <= t_lift and t_lift + lift_duration <= t_oscillate [s]; got t_grip = {t_grip:g}, "
            f"t_lift = {t_lift:g}, lift_duration = {lift_duration:g}, t_oscillate = {t_oscillate:g}"
        )
    A_lift = 2.0 * np.pi * lift / lift_duration**2
    w_lift = 2.0 * np.pi / lift_duration
    w_osc = 2.0 * np.pi * frequency
    A_osc = amplitude * w_osc**2

    def drive(mass_share: float, weight: float, sign: float) -> Drive:
        hold = weight + sign * squeeze
        segments = [
            Segment(0.0, weight, sign * squeeze / t_grip),
            Segment(t_grip, hold),
            Segment(t_lift, hold, 0.0, mass_share * A_lift, w_lift, 0.0),
            Segment(t_oscillate, hold, 0.0, 0.5 * mass_share * A_osc, w_osc, 0.0),
            Segment(t_oscillate + np.pi / w_osc, hold, 0.0, mass_share * A_osc, w_osc, np.pi),
        ]
        if t_grip == t_lift:
            del segments[1]
        if t_lift + lift_duration < t_oscillate:
            segments.insert(-2, Segment(t_lift + lift_duration, hold))
        return Drive(segments)

    share1, share2 = p.m1 + p.m / 2, p.m2 + p.m / 2
    return drive(share1, share1 * p.g, 1.0), drive(share2, share2 * p.g, -1.0)


class DrivesController:
    """Open-loop drives, one per arm joint: ``τ_i = drive_i(t)`` [N]."""

    def __init__(self, drives: Sequence[Drive]) -> None:
        self.drives = tuple(drives)

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.array([d(t) for d in self.drives])

    def compiled_spec(self, scene: Scene) -> DrivesSpec | None:
        """The drives' segments for the compiled step loop: rows (start, constant, ramp,
        amplitude, omega, phase)."""
        if len(self.drives) != scene.n_actuated or any(type(d) is not Drive for d in self.drives):
            return None  # another callable (or a Drive subclass) runs in Python
        fields = ("start", "constant", "ramp", "amplitude", "omega", "phase")
        return DrivesSpec(segments=[np.array([[float(getattr(s, f)) for f in fields] for s in d.segments]) for d in self.drives])


def drives_controller(*drives: Drive) -> DrivesController:
    """A controller applying open-loop drives, one per arm joint: ``τ_i = drive_i(t)``."""
    for k, drive in enumerate(drives):
        if not callable(drive):
            raise SceneError(f"drives_controller: drive {k} must be a Drive or a callable drive(t) -> τ [N], got {drive!r}")
    return DrivesController(drives)
