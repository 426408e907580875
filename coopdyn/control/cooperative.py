"""Cooperative object-level control: impedance on the object, non-squeezing load
distribution, commanded internal force, and a grip / lift / oscillate / hold task.

:class:`ObjectImpedance` computes, at every call,

1. the object wrench ``F = m (a_d − g) + K_p e_p + D_p (v_d − v)`` and
   ``M = K_r log(R_d Rᵀ) − D_r ω`` (world axes, at the object frame origin);
2. its non-squeezing distribution over the grasps ``f = G⁺ F`` plus the internal wrenches of
   the commanded squeeze ``s(t)`` (inward forces projected onto the null space of G);
3. ``τ_i = J_iᵀ f_i + h_i(q, q̇) − D_j q̇ + N_i (K_null (q0 − q) − D_null q̇)``: the tool wrench
   through the tip Jacobian (world-aligned, at the tip), the arm's own gravity and Coriolis
   terms, joint damping and a posture task in the null space of the tip Jacobian.

The object's motion is then that of a mass–spring–damper with the designed K and D and the
mass of the object plus the arms' reflected inertia at the grasps
(:meth:`ObjectImpedance.effective_mass`).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin
from scipy.linalg import cho_solve

from .. import _validate
from .._spec import GripLiftOscillateTaskSpec, HoldTaskSpec, ObjectImpedanceSpec
from ..errors import SceneError, SceneWarning
from ..grasp import squeeze_directions
from ..model.scene import Scene
from .joint import ScratchData

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
#: where ObjectImpedance reads the object's pose and velocity (its ``measure``)
MEASURES = ("auto", "object", "tips")


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for 3-vectors (np.cross costs ~10× more on the controller's hot path)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a × b for (N, 3) arrays (or a (3,) b); np.cross costs several times more."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _moment_inverse(r: np.ndarray) -> np.ndarray:
    """(A⁻¹) (3, 3) of the moment block ``A = N·I + Σ (|rᵢ|² I − rᵢ rᵢᵀ)`` of G Gᵀ.

    With moments about the centroid (Σ rᵢ = 0) the grasp matrix has the block-diagonal
    ``G Gᵀ = diag(N·I, A)``, so ``G⁺ = Gᵀ (G Gᵀ)⁻¹`` needs one 3×3 inverse and no SVD (G always
    has full row rank: every grasp transmits moments).
    """
    n = r.shape[0]
    A = (n + float(np.einsum("ij,ij->", r, r))) * np.eye(3) - r.T @ r
    return np.linalg.inv(A)


def _distribute(r: np.ndarray, A_inv: np.ndarray, wrench: np.ndarray) -> np.ndarray:
    """``G⁺ F`` as (N, 6) in closed form: ``y = (G Gᵀ)⁻¹ F``, ``fᵢ = Gᵢᵀ y = [y_f − rᵢ × y_m; y_m]``."""
    y_f = wrench[:3] / r.shape[0]
    y_m = A_inv @ wrench[3:]
    out = np.empty((r.shape[0], 6))
    out[:, :3] = y_f - _cross_rows(r, y_m)
    out[:, 3:] = y_m
    return out


def _null_space_part(J: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(I − J⁺J) x``: the part of the joint vector x that moves no tip (J (6, n)).

    Closed form for a full-rank J: ``x − Jᵀ (J Jᵀ)⁻¹ J x`` for a redundant arm (n > 6), zero
    otherwise (``J⁺J = I``); the SVD pseudo-inverse only at a singular configuration."""
    n = J.shape[1]
    try:
        if n > 6:
            L = np.linalg.cholesky(J @ J.T)
            if np.min(np.diag(L)) < 1e-7 * np.max(np.diag(L)):  # condition ≳ 1e14: near a singularity
                raise np.linalg.LinAlgError
            return x - J.T @ cho_solve((L, True), J @ x, check_finite=False)
        L = np.linalg.cholesky(J.T @ J)  # full column rank: J⁺J = I
        if np.min(np.diag(L)) < 1e-7 * np.max(np.diag(L)):
            raise np.linalg.LinAlgError
        return np.zeros(n)
    except np.linalg.LinAlgError:
        return x - np.linalg.pinv(J) @ (J @ x)


class ObjectReference(NamedTuple):
    """Desired object motion at one instant (world axes)."""

    position: np.ndarray  #: (3,) [m]
    rotation: np.ndarray  #: (3, 3)
    velocity: np.ndarray  #: (3,) [m/s]
    angular_velocity: np.ndarray  #: (3,) [rad/s]
    acceleration: np.ndarray  #: (3,) [m/s²]
    squeeze: float  #: commanded internal force per grasp [N], positive = compression


@dataclass(frozen=True)
class GripLiftOscillate:
    """The book's task: grip, lift, oscillate, hold — a desired object motion and squeeze.

    Attributes (times [s], lengths [m], forces [N], frequency [Hz]):
        start: the object's initial position (3,).
        rotation: the object orientation to hold (3, 3); ``None`` (default): the object's
            orientation at the scene's start, which :class:`ObjectImpedance` fills in (a task
            called on its own, without a scene, then reports the world axes).
        squeeze: internal force to grip with; ramped up over ``t_grip``.
        lift: rise along world z, a smooth (minimum-jerk) motion over ``[t_lift, t_lift + lift_duration]``.
        amplitude, frequency, axis: the oscillation ``amplitude·sin(2π f (t − t_osc))`` along
            ``axis`` over ``cycles`` periods from ``t_osc``, with a smooth (sin²) amplitude
            envelope; then hold.
    """

    start: Any
    rotation: Any = None
    squeeze: float = 20.0
    t_grip: float = 0.5
    lift: float = 0.1
    t_lift: float = 0.75
    lift_duration: float = 1.25
    amplitude: float = 0.03
    frequency: float = 1.0
    cycles: float = 2
    t_osc: float = 2.25
    axis: Any = (0.0, 1.0, 0.0)

    def __post_init__(self) -> None:
        checked = {}  # stored as floats: exact inputs (Fraction, Decimal) do not reach the arithmetic
        for name in ("t_grip", "lift_duration", "frequency"):
            unit = "s" if name != "frequency" else "Hz"
            checked[name] = _validate.positive(getattr(self, name), f"GripLiftOscillate: {name}", unit)
        for name, unit in (("squeeze", "N"), ("lift", "m"), ("t_lift", "s"), ("amplitude", "m"), ("t_osc", "s")):
            checked[name] = _validate.number(getattr(self, name), f"GripLiftOscillate: {name}", unit)
        checked["cycles"] = _validate.non_negative(self.cycles, "GripLiftOscillate: cycles", "periods")
        for name in ("lift", "amplitude"):  # a motion beyond a scene's reach (its squares and derivatives overflow)
            if abs(checked[name]) > _validate.MAX_DISTANCE:
                raise SceneError(
                    f"GripLiftOscillate: |{name}| must be at most {_validate.MAX_DISTANCE:g} m, got {checked[name]:g}"
                )
        for name in ("t_grip", "lift_duration", "t_lift", "t_osc", "cycles"):
            if abs(checked[name]) > 1e9:
                raise SceneError(f"GripLiftOscillate: {name} must be at most 1e9, got {checked[name]:g}")
        if checked["frequency"] > 1e6:
            raise SceneError(f"GripLiftOscillate: frequency must be at most 1e6 Hz, got {checked['frequency']:g}")
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        _validate.finite_array(self.start, "GripLiftOscillate: start", (3,))
        if self.rotation is not None:
            R = _validate.finite_array(self.rotation, "GripLiftOscillate: rotation", (3, 3))
            if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise SceneError("GripLiftOscillate: rotation must be a rotation matrix (orthonormal, det +1)")
        axis = _validate.finite_array(self.axis, "GripLiftOscillate: axis", (3,))
        if not np.linalg.norm(axis) > 0:
            raise SceneError("GripLiftOscillate: axis must not be zero")

    def __call__(self, t: float) -> ObjectReference:
        p0 = np.asarray(self.start, dtype=float)
        R = np.eye(3) if self.rotation is None else np.asarray(self.rotation, dtype=float)
        s = min(max(t / self.t_grip, 0.0), 1.0)
        squeeze = self.squeeze * (3 * s**2 - 2 * s**3)
        pos, vel, acc = p0.copy(), np.zeros(3), np.zeros(3)
        # lift: minimum-jerk profile
        tau = min(max((t - self.t_lift) / self.lift_duration, 0.0), 1.0)
        shape = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        dshape = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / self.lift_duration if 0 < tau < 1 else 0.0
        ddshape = (60 * tau - 180 * tau**2 + 120 * tau**3) / self.lift_duration**2 if 0 < tau < 1 else 0.0
        pos[2] += self.lift * shape
        vel[2] += self.lift * dshape
        acc[2] += self.lift * ddshape
        # oscillation with a sin² envelope over the whole window: x = A sin²(πu) sin(ωs)
        duration = self.cycles / self.frequency
        s_osc = t - self.t_osc
        if 0.0 < s_osc < duration:
            axis = np.asarray(self.axis, dtype=float)
            axis = axis / np.linalg.norm(axis)
            w, W = 2 * math.pi * self.frequency, math.pi / duration
            env, denv, ddenv = math.sin(W * s_osc) ** 2, W * math.sin(2 * W * s_osc), 2 * W**2 * math.cos(2 * W * s_osc)
            osc, dosc, ddosc = math.sin(w * s_osc), w * math.cos(w * s_osc), -(w**2) * math.sin(w * s_osc)
            pos += self.amplitude * env * osc * axis
            vel += self.amplitude * (denv * osc + env * dosc) * axis
            acc += self.amplitude * (ddenv * osc + 2 * denv * dosc + env * ddosc) * axis
        return ObjectReference(pos, R, vel, np.zeros(3), acc, float(squeeze))

    def positions(self, t: Any) -> np.ndarray:
        """The desired object position at many times at once: (n, 3) [m] for t (n,) [s] — what
        ``self(t).position`` gives at each (tested equal), without a call per sample."""
        t = np.asarray(t, dtype=float).reshape(-1)
        pos = np.tile(np.asarray(self.start, dtype=float), (t.size, 1))
        tau = np.clip((t - self.t_lift) / self.lift_duration, 0.0, 1.0)
        pos[:, 2] += self.lift * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
        duration = self.cycles / self.frequency
        s_osc = t - self.t_osc
        inside = (s_osc > 0.0) & (s_osc < duration)
        if np.any(inside):
            axis = np.asarray(self.axis, dtype=float)
            axis = axis / np.linalg.norm(axis)
            s = s_osc[inside]
            w, W = 2 * math.pi * self.frequency, math.pi / duration
            pos[inside] += (self.amplitude * np.sin(W * s) ** 2 * np.sin(w * s))[:, None] * axis
        return pos

    @property
    def duration(self) -> float:
        """End of the oscillation [s]; the task holds after it."""
        return self.t_osc + self.cycles / self.frequency

    def phases(self) -> list[tuple[str, float, float]]:
        """The task's phases as (name, start [s], end [s]): grip, lift, oscillate, then hold (to ∞)."""
        return [
            ("grip", 0.0, self.t_grip),
            ("lift", self.t_lift, self.t_lift + self.lift_duration),
            ("oscillate", self.t_osc, self.duration),
            ("hold", self.duration, math.inf),
        ]


#: [m], [rad] how far a task may start from the object's pose at the scene's start, silently
TASK_START_TOLERANCE = (0.005, 0.05)


def _warn_if_away(reference: Callable[[float], ObjectReference], oMo: pin.SE3, Kp: np.ndarray) -> None:
    """Warn (SceneWarning) when ``reference(0)`` is away from the object's pose ``oMo`` at the
    scene's start: the impedance would drag the object there from the first instant."""
    try:
        start = reference(0.0)
        offset = np.asarray(start.position, dtype=float) - oMo.translation
        turn = float(np.linalg.norm(pin.log3(np.asarray(start.rotation, dtype=float) @ oMo.rotation.T)))
    except Exception:  # (a reference that cannot be evaluated here fails in the run, with its own message)
        return
    distance = float(np.linalg.norm(offset))
    if distance <= TASK_START_TOLERANCE[0] and turn <= TASK_START_TOLERANCE[1]:
        return
    pull = float(np.linalg.norm(Kp * offset))
    warnings.warn(
        f"ObjectImpedance: the task starts {distance:.3g} m and {turn:.3g} rad away from the object's pose at the scene's "
        f"start (task at {np.round(start.position, 4).tolist()} m, object at {np.round(oMo.translation, 4).tolist()} m): "
        f"the impedance drags the object there from t = 0, with ~{pull:.3g} N at first. Start the task at "
        "coopdyn.scenes.object_start(scene) (GripLiftOscillate(start=object_start(scene)))",
        SceneWarning,
        stacklevel=3,
    )


class _Tips(NamedTuple):
    """The tools' reading at one state (ObjectImpedance with ``measure="tips"``)."""

    estimates: list[pin.SE3]  #: each tool's estimate of the object frame's pose
    mean: np.ndarray  #: their mean rotation (3, 3)
    origins: list[np.ndarray]  #: each tool frame's origin, world [m]
    twists: list[pin.Motion]  #: each tool frame's twist, world axes at its origin [m/s, rad/s]


def _mean_rotation(rotations: list[np.ndarray]) -> np.ndarray:
    """The mean of rotations in the tangent space of the first: ``R₀ exp(mean log(R₀ᵀ Rᵢ))``."""
    R0 = rotations[0]
    return R0 @ pin.exp3(np.mean([pin.log3(R0.T @ R) for R in rotations], axis=0))


#: the example each pair's message gives
_EXAMPLES = {"damping": (120.0, 6.0), "internal": (100.0, 6.0)}


def _pair(
    value: Any, name: str, units: tuple[str, str], parts: tuple[str, str] = ("linear", "angular")
) -> tuple[np.ndarray, np.ndarray]:
    """(linear, angular) object gains (or the two ``parts`` named), each a non-negative scalar or
    3-vector, as two (3,) arrays."""
    if (
        isinstance(value, str | bytes)
        or not isinstance(value, Sequence | np.ndarray)
        or getattr(value, "ndim", 1) == 0
        or len(value) != 2
    ):
        raise SceneError(
            f"ObjectImpedance: {name} must be a pair ({parts[0]} [{units[0]}], {parts[1]} [{units[1]}]), each a scalar or "
            f"3-vector, e.g. {name}={_EXAMPLES.get(name, (2000.0, 100.0))}; got {_validate._short(value)}"
        )
    linear, angular = (
        _validate.gain(part, f"ObjectImpedance: {name} ({label})", 3, unit, per="axis x, y, z")
        for part, unit, label in zip(value, units, parts, strict=True)
    )
    return linear, angular


class ObjectImpedance:
    """Cooperative impedance control of the held object with internal-force regulation.

    Args:
        scene: the scene (any number of arms, each with one interconnection).
        reference: ``reference(t) -> ObjectReference`` (e.g. :class:`GripLiftOscillate`);
            default: hold the initial pose with no squeeze.
        stiffness: object translational / rotational stiffness, scalars or (3,)
            [N/m], [N·m/rad].
        damping: object translational / rotational damping [N·s/m], [N·m·s/rad].
        joint_damping: extra joint damping on every arm joint [N·m·s/rad].
        null_stiffness, null_damping: posture task in the tip Jacobians' null space
            [N·m/rad], [N·m·s/rad] (redundant arms).
        measure: where the law reads the object's pose and velocity. ``"object"``: the object
            frame itself (a rigid object's pose as a camera or motion capture gives it).
            ``"tips"``: the arms' own tool frames (their joint encoders), each carried to the
            object frame by its offset at the start and averaged — collocated with the arms'
            actuators, so the loop through an elastic object is passive (stable at every gain
            tried: docs/physics.md). ``"auto"`` (default): ``"tips"`` for an elastic object (one with elements of
            its own, a :class:`~coopdyn.Beam`), ``"object"`` otherwise. Feeding back a flexible
            object's own frame reaches the arms only through its compliance (non-collocated)
            and destabilises its bending modes (docs/physics.md, "Cooperative control").
        internal: with ``measure="tips"``, the rotational stiffness and damping (scalars or (3,),
            world axes) [N·m/rad], [N·m·s/rad] holding each tool's estimate of the object's
            orientation to their mean — pairs of moments with no resultant, which keep an elastic
            object's ends from turning against each other (the strip arching as it is lifted)
            and damp that motion; default: the object's rotational ``stiffness`` and ``damping``.
            ``(0, 0)`` turns it off. Collocated, so the loop stays passive.
        transmission_damping: on arms with elastic joints (:class:`coopdyn.JointElasticity`),
            the law's joint torques go to the motors with Spong's composite fast term
            ``K_v (q̇ − θ̇)``, which damps each transmission's oscillation (it reads the link and
            motor velocities): K_v [N·m·s/rad], a scalar or one per elastic joint of the scene;
            default ``1.4 √(K B)`` (damping ratio 0.7 against the link held still). The links
            then move as rigid ones with the motor inertia added (docs/physics.md).
    """

    _data = ScratchData()

    def __init__(
        self,
        scene: Scene,
        reference: Callable[[float], ObjectReference] | None = None,
        stiffness: tuple[Any, Any] = (2000.0, 100.0),
        damping: tuple[Any, Any] = (120.0, 6.0),
        joint_damping: float = 3.0,
        null_stiffness: float = 20.0,
        null_damping: float = 5.0,
        measure: str = "auto",
        internal: tuple[Any, Any] | None = None,
        transmission_damping: Any = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise SceneError(f"ObjectImpedance: scene must be a coopdyn.Scene, got {type(scene).__name__}")
        if measure not in MEASURES:
            raise SceneError(f"ObjectImpedance: measure must be one of {MEASURES}, got {_validate._short(measure)}")
        #: "object" or "tips": where the law reads the object's pose and velocity
        self.measure = measure if measure != "auto" else ("tips" if len(scene.elements) > len(scene.links) else "object")
        if reference is not None and not callable(reference):
            raise SceneError(
                f"ObjectImpedance: reference must be a callable reference(t) -> ObjectReference (e.g. a "
                f"GripLiftOscillate), got {type(reference).__name__}"
            )
        self.scene = scene
        model = scene.model
        self.Kp, self.Kr = _pair(stiffness, "stiffness", ("N/m", "N·m/rad"))
        self.Dp, self.Dr = _pair(damping, "damping", ("N·s/m", "N·m·s/rad"))
        #: the internal rotational stiffness and damping (3,) [N·m/rad], [N·m·s/rad] (``measure="tips"``)
        if internal is not None and self.measure != "tips":
            raise SceneError(
                "ObjectImpedance: internal holds the tools' estimates of the object's orientation together; it needs "
                f"measure='tips' (this one reads the object frame: measure={measure!r} on a {type(scene.object).__name__})"
            )
        if internal is None:
            self.Ki, self.Di = self.Kr.copy(), self.Dr.copy()
        else:
            self.Ki, self.Di = _pair(internal, "internal", ("N·m/rad", "N·m·s/rad"), ("stiffness", "damping"))
        self.joint_damping = _validate.non_negative(joint_damping, "ObjectImpedance: joint_damping", "N·m·s/rad")
        self.null_stiffness = _validate.non_negative(null_stiffness, "ObjectImpedance: null_stiffness", "N·m/rad")
        self.null_damping = _validate.non_negative(null_damping, "ObjectImpedance: null_damping", "N·m·s/rad")
        data = self._data
        pin.framesForwardKinematics(model, data, scene.q0)
        oMo = data.oMf[scene.object_frame]
        hold = ObjectReference(oMo.translation.copy(), oMo.rotation.copy(), np.zeros(3), np.zeros(3), np.zeros(3), 0.0)
        self._hold = hold if reference is None else None
        if type(reference) is GripLiftOscillate and reference.rotation is None:  # hold the starting orientation
            reference = dataclasses.replace(reference, rotation=oMo.rotation.copy())
        if reference is not None:
            _warn_if_away(reference, oMo, self.Kp)

        def hold_reference(t: float) -> ObjectReference:
            return hold

        self._hold_reference = hold_reference
        self.reference = reference if reference is not None else hold_reference
        mass, com = scene.object.mass_and_com()
        self.mass = mass
        self._com = np.asarray(com, dtype=float)
        fixtures = [lk.name for lk in scene.links if lk.arm is None]
        if fixtures or not scene.links:
            raise SceneError(
                f"ObjectImpedance distributes the object wrench over arms; interconnections {fixtures} hold the "
                "object to the world (fixtures), which it cannot command"
            )
        self._links = [(lk.grasp_frame, lk.tip_frame, scene.arms[lk.arm]) for lk in scene.links if lk.arm is not None]
        rigid = [arm.name for _, _, arm in self._links if arm.v_index.size == 0]
        if rigid:
            raise SceneError(f"ObjectImpedance commands the object through the arms' joints; every joint of {rigid} is locked")
        # each tool frame's pose in the object frame at the start: a tip's pose times its inverse
        # estimates the object frame's (measure="tips")
        self._o_M_T = [oMo.actInv(data.oMf[t_id]) for _, t_id, _ in self._links]
        self._transmissions = self._fast_damping(transmission_damping)

    def _fast_damping(self, value: Any) -> np.ndarray:
        """(m, 4) rows (entry in τ, link v, motor v, K_v) of the scene's elastic joints."""
        springs, arm_joints = self.scene.joint_springs, self.scene.arm_joints
        if value is None:
            inertia = np.diag(pin.crba(self.scene.model, self._data, self.scene.q0))[springs.motor_v]
            kv = 1.4 * np.sqrt(springs.stiffness * inertia)
        elif not springs.size:
            raise SceneError("ObjectImpedance: transmission_damping is for arms with elastic joints; this scene has none")
        else:
            kv = _validate.gain(value, "ObjectImpedance: transmission_damping", springs.size, "N·m·s/rad", per="elastic joint")
        entry = [int(np.flatnonzero(arm_joints == link)[0]) for link in springs.link_v]
        return np.column_stack([entry, springs.link_v, springs.motor_v, kv]).reshape(springs.size, 4)

    def object_state(self, tips: _Tips | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The object frame's world position [m], rotation, linear velocity of its origin [m/s] and
        angular velocity [rad/s] (world axes) as the law reads them (``measure``), at the
        kinematics of the last ``forwardKinematics(q, v)`` on its data (``tips``: the tools'
        reading there, when already taken)."""
        model, data, scene = self.scene.model, self._data, self.scene
        if self.measure == "object":
            oMo = data.oMf[scene.object_frame]
            V = pin.getFrameVelocity(model, data, scene.object_frame, LWA)
            return oMo.translation, oMo.rotation, V.linear, V.angular
        tips = self._tips() if tips is None else tips
        p = np.mean([P.translation for P in tips.estimates], axis=0)
        linear = np.mean([V.linear + _cross(V.angular, p - o) for V, o in zip(tips.twists, tips.origins, strict=True)], axis=0)
        return p, tips.mean, linear, np.mean([V.angular for V in tips.twists], axis=0)

    def _tips(self) -> _Tips:
        """The tools' reading: each tool's estimate of the object frame's pose (its pose times its
        offset at the start), their mean rotation, each tool's origin and twist (world axes)."""
        model, data = self.scene.model, self._data
        estimates = [data.oMf[t_id] * o_M_T.inverse() for (_, t_id, _), o_M_T in zip(self._links, self._o_M_T, strict=True)]
        origins = [data.oMf[t_id].translation for _, t_id, _ in self._links]
        twists = [pin.getFrameVelocity(model, data, t_id, LWA) for _, t_id, _ in self._links]
        return _Tips(estimates, _mean_rotation([P.rotation for P in estimates]), origins, twists)

    def internal_moments(self, tips: _Tips | None = None) -> np.ndarray:
        """(N, 3) [N·m], world axes: with ``measure="tips"``, the moments that hold each tool's
        estimate of the object's orientation to their mean, ``−Ki ⊙ e_i − Di ⊙ (ω_i − ω̄)`` with
        ``e_i = R̄ log3(R̄ᵀ R_i)``; zero otherwise."""
        n = len(self._links)
        if self.measure != "tips" or not (np.any(self.Ki) or np.any(self.Di)):
            return np.zeros((n, 3))
        tips = self._tips() if tips is None else tips
        mean = tips.mean
        omega = np.array([V.angular for V in tips.twists])
        spin = omega - omega.mean(axis=0)
        return np.array(
            [-self.Ki * (mean @ pin.log3(mean.T @ P.rotation)) - self.Di * w for P, w in zip(tips.estimates, spin, strict=True)]
        )

    def object_wrench(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, ObjectReference]:
        """The wrench the grasps must apply to the object (6,) [N, N·m] (world axes, object origin)."""
        return self._wrench(t, self.object_state())

    def _wrench(self, t: float, state: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ObjectReference]:
        scene = self.scene
        ref = self.reference(t)
        p, R, linear, angular = state
        e_p = ref.position - p
        e_r = pin.log3(ref.rotation @ R.T)
        force = self.mass * (ref.acceleration - scene.gravity) + self.Kp * e_p + self.Dp * (ref.velocity - linear)
        moment = self.Kr * e_r + self.Dr * (ref.angular_velocity - angular) + _cross(R @ self._com, -self.mass * scene.gravity)
        return np.concatenate([force, moment]), ref

    def grasp_wrenches(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Commanded wrench of each interconnection on the object (N, 6), about its grasp point
        (about its tool frame's origin with ``measure="tips"``)."""
        model, data = self.scene.model, self._data
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        tips = self._tips() if self.measure == "tips" else None
        state = self.object_state(tips)
        F, ref = self._wrench(t, state)
        at = 1 if self.measure == "tips" else 0  # the tool frames or the grasp frames
        points = np.array([data.oMf[frames[at]].translation for frames in self._links])
        c = points.mean(axis=0)
        r = points - c
        o = state[0]
        F_c = F.copy()
        F_c[3:] += _cross(o - c, F[:3])  # moment about the grasps' centroid
        A_inv = _moment_inverse(r)
        f = _distribute(r, A_inv, F_c)
        if ref.squeeze and len(points) > 1:
            inward = np.zeros((len(points), 6))
            inward[:, :3] = ref.squeeze * squeeze_directions(points)
            resultant = np.concatenate([inward[:, :3].sum(axis=0), _cross_rows(r, inward[:, :3]).sum(axis=0)])
            f += inward - _distribute(r, A_inv, resultant)  # keep only its internal (null-space) part
        f[:, 3:] += self.internal_moments(tips)
        return f

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        model, data, scene = self.scene.model, self._data, self.scene
        f = self.grasp_wrenches(t, q, v)
        pin.computeJointJacobians(model, data, q)
        tau_full = pin.nonLinearEffects(model, data, q, v)
        posture = pin.difference(model, q, scene.q0)  # towards the initial posture, any joint type
        out = []
        for (g_id, t_id, arm), f_i in zip(self._links, f, strict=True):
            J = pin.getFrameJacobian(model, data, t_id, LWA)[:, arm.v_index]
            # the wrench is about the grasp point (the tip sits on it up to the small deformation),
            # or already about the tip (measure="tips")
            w = f_i.copy()
            if self.measure == "object":
                w[3:] += _cross(data.oMf[g_id].translation - data.oMf[t_id].translation, f_i[:3])
            vi = v[arm.v_index]
            tau = J.T @ w + tau_full[arm.v_index] - self.joint_damping * vi
            tau += _null_space_part(J, self.null_stiffness * posture[arm.v_index] - self.null_damping * vi)
            out.append(tau)
        tau = np.concatenate(out)
        if self._transmissions.size:  # Spong's fast term on the elastic joints: K_v (q̇ − θ̇)
            entry, link, motor = (self._transmissions[:, k].astype(int) for k in range(3))
            tau[entry] += self._transmissions[:, 3] * (v[link] - v[motor])
        return tau

    def compiled_spec(self, scene: Scene) -> ObjectImpedanceSpec | None:
        """This law for the compiled step loop: with the default hold or a :class:`GripLiftOscillate`
        reference (None for a Python reference, which runs in Python)."""
        if scene is not self.scene:
            return None
        ref = self.reference
        if self._hold is not None and ref is self._hold_reference:
            task: HoldTaskSpec | GripLiftOscillateTaskSpec = HoldTaskSpec(start=self._hold.position, rotation=self._hold.rotation)
        elif type(ref) is GripLiftOscillate:
            axis = np.asarray(ref.axis, dtype=float)
            task = GripLiftOscillateTaskSpec(
                start=np.asarray(ref.start, dtype=float),
                rotation=np.eye(3) if ref.rotation is None else np.asarray(ref.rotation, dtype=float),
                axis=axis / np.linalg.norm(axis),
                cycles=float(ref.cycles),
                **{k: float(getattr(ref, k)) for k in ("squeeze", "t_grip", "lift", "t_lift", "lift_duration")},
                **{k: float(getattr(ref, k)) for k in ("amplitude", "frequency", "t_osc")},
            )
        else:
            return None
        return ObjectImpedanceSpec(
            object_frame=int(scene.object_frame),
            grasps=[(int(g), int(t), np.asarray(arm.v_index, dtype=np.int32)) for g, t, arm in self._links],
            task=task,
            mass=float(self.mass),
            com=self._com.copy(),
            gravity=np.asarray(scene.gravity, dtype=float),
            Kp=self.Kp.copy(),
            Kr=self.Kr.copy(),
            Dp=self.Dp.copy(),
            Dr=self.Dr.copy(),
            joint_damping=float(self.joint_damping),
            null_k=float(self.null_stiffness),
            null_d=float(self.null_damping),
            q0=scene.q0.copy(),
            collocated=self.measure == "tips",
            Ki=self.Ki.copy(),
            Di=self.Di.copy(),
            tip_offsets=np.concatenate([M.homogeneous for M in self._o_M_T]),
            transmissions=self._transmissions.reshape(-1).copy(),
        )

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint damping added by the controller, for implicit integrators [N·m/rad], [N·m·s/rad];
        on an elastic joint (whose torque acts on its motor) the fast term's −∂τ/∂θ̇ = K_v alone."""
        n = self.scene.n_actuated
        kp, kd = np.full(n, self.null_stiffness), np.full(n, self.joint_damping + self.null_damping)
        entry = self._transmissions[:, 0].astype(int)
        kp[entry], kd[entry] = 0.0, self._transmissions[:, 3]
        return kp, kd

    def effective(self, direction: Any = (0.0, 0.0, 1.0), q: np.ndarray | None = None) -> tuple[float, float, float]:
        """(mass [kg], damping [N·s/m], stiffness [N/m]) of the object's translation along
        ``direction`` (world) as this controller shapes it, with stiff interconnections: the
        object's mass plus each arm's reflected inertia at its tool, the designed damping plus the
        reflected joint damping, the designed stiffness. The designed response is then
        ``ω_n = √(k/m)`` and ``ζ = d / (2√(k m))``.

        Each tool moves with the object (twist ``V = (u, 0)``): the arm adds ``Vᵀ Λ V`` to the
        mass (``Λ = (J M⁻¹ Jᵀ)⁻¹``, its operational-space inertia) and ``b Vᵀ (J Jᵀ)⁻¹ V`` to
        the damping (joint damping b along the least-norm joint motion; the posture task damps
        the rest of the null space)."""
        model, data, scene = self.scene.model, self._data, self.scene
        q = scene.q0 if q is None else scene.check_state(q, scene.v0)[0]
        u = _validate.finite_array(direction, "direction", (3,))
        if not np.linalg.norm(u) > 0.0:
            raise SceneError("direction must not be zero")
        u = u / np.linalg.norm(u)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        M = pin.crba(model, data, q)
        m, d = self.mass, float(u @ (self.Dp * u))
        V = np.concatenate([u, np.zeros(3)])
        for _, t_id, arm in self._links:
            J = pin.getFrameJacobian(model, data, t_id, LWA)[:, arm.v_index]
            M_arm = M[np.ix_(arm.v_index, arm.v_index)]
            m += float(V @ np.linalg.solve(J @ np.linalg.solve(M_arm, J.T), V))
            d += self.joint_damping * float(V @ np.linalg.solve(J @ J.T, V))
        return m, d, float(u @ (self.Kp * u))
