"""``coopdyn.advise_model``: which model of the elastic system a scene needs (docs/physics.md).

The book's bandwidth argument: the drives excite the elastic system only up to the control
bandwidth (parts of a hertz to ~15 Hz), so an elastic mode far above it follows quasi-statically.
:func:`advise_model` computes the lowest modes of the object itself (a beam's internal modes;
none for a rigid object) and of the grasps (the quasi-static system: the object as one rigid
body on its condensed interconnections), compares them with the bandwidth, and measures on the
spot what each of the three models costs:

* ``"rigid"`` — :func:`coopdyn.rigid_limit`: grasps as constraints; the internal force is the
  solver's least-norm choice, not the physical one;
* ``"quasi-static"`` — :func:`coopdyn.quasi_static`: one rigid body on elastic grasps (the
  object's own flexibility condensed into them);
* ``"elastic"`` — the full scene: every node of an elastic object a body.

Arms with elastic joints (:class:`coopdyn.JointElasticity`) get the same test of their own: the
joints' lowest transmission mode (arms and motors with the object released) against the
bandwidth says whether the elastic joints matter or rigid ones carrying the motor inertia as
armature (``stiffness=inf``) give the motion; both are measured (``"rigid joints"``).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg

from . import _validate
from .dynamics import Dynamics
from .errors import SimulationError
from .model.limits import quasi_static, rigid_limit
from .model.scene import Scene
from .simulate import simulate

MODE_SEPARATION = 5.0  #: a mode this many times above the bandwidth is taken as not excited
MODELS = ("rigid", "quasi-static", "elastic")
EXPLICIT_LIMIT = 2.0 * math.sqrt(2.0)  #: rk4's stability limit on |λ|·dt on the imaginary axis (undamped modes)


@dataclass(frozen=True)
class ModelCost:
    """What one model of the scene costs."""

    model: str  #: "rigid", "quasi-static" or "elastic"
    states: int  #: nq + nv
    lowest_mode_hz: float | None  #: its lowest elastic natural frequency [Hz] (None: rigid)
    fastest_mode_hz: float | None  #: its highest [Hz]
    max_dt_rk4: float | None  #: rk4's stability limit 2√2/ω_max [s] (the modes are undamped)
    integrator: str  #: what the measurement ran
    cpu_per_second: float  #: CPU time per simulated second at the chosen dt [s/s], no controller


@dataclass(frozen=True)
class ModelAdvice:
    """The result of :func:`advise_model`."""

    recommendation: str  #: "rigid", "quasi-static" or "elastic"
    bandwidth: float  #: the control bandwidth [Hz]
    dt: float  #: the step the costs were measured at [s]
    object_mode_hz: float | None  #: the object's lowest internal mode [Hz] (None: rigid object)
    grasp_mode_hz: float  #: the grasps' lowest mode in the quasi-static system [Hz]
    reason: str
    costs: tuple[ModelCost, ...]
    joint_mode_hz: float | None = None  #: the elastic joints' lowest transmission mode [Hz] (None: rigid joints)
    joints: str | None = None  #: "elastic" or "rigid" (with the motor inertia as armature); None: rigid joints given

    def __str__(self) -> str:
        rows = [
            f"model advice at a control bandwidth of {self.bandwidth:g} Hz: {self.recommendation}"
            + (f", {self.joints} joints" if self.joints else ""),
            f"  {self.reason}",
            f"  {'model':<13}{'states':>7}{'lowest mode':>14}{'fastest mode':>15}{'rk4 dt limit':>14}"
            f"{'CPU / sim. s':>14}  (measured with, dt = {self.dt:g} s)",
        ]
        for c in self.costs:
            lo = "—" if c.lowest_mode_hz is None else f"{c.lowest_mode_hz:.4g} Hz"
            hi = "—" if c.fastest_mode_hz is None else f"{c.fastest_mode_hz:.4g} Hz"
            lim = "—" if c.max_dt_rk4 is None else f"{c.max_dt_rk4 * 1e3:.3g} ms"
            rows.append(f"  {c.model:<13}{c.states:>7}{lo:>14}{hi:>15}{lim:>14}{c.cpu_per_second:>12.3g} s  ({c.integrator})")
        return "\n".join(rows)


def _frequencies(K: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Natural frequencies [rad/s] of (M, K), the zero (mechanism and rigid-body) modes left out."""
    w = np.sqrt(np.clip(scipy.linalg.eigh(K, M, eigvals_only=True), 0.0, None))
    return w[w > 1e-6 * max(w.max(), 1.0)]


def _modes(scene: Scene) -> np.ndarray:
    """The scene's natural frequencies [rad/s], linearised at q0 (interconnections and object
    elements only, no controller)."""
    M, K, _ = Dynamics(scene).stiffness(scene.q0, scene.v0)
    return _frequencies(K, M)


def _joint_modes(scene: Scene) -> np.ndarray:
    """The elastic joints' transmission modes [rad/s] at q0: the arms and their motors on the
    springs alone (the object released, the arms' other joints free)."""
    springs = scene.joint_springs
    K = np.zeros((scene.nv, scene.nv))
    springs.add_matrices(K)
    M = pin.crba(scene.model, scene.model.createData(), scene.q0)
    M = np.triu(M) + np.triu(M, 1).T
    arm = np.concatenate([scene.arm_joints, springs.motor_v])
    return _frequencies(K[np.ix_(arm, arm)], M[np.ix_(arm, arm)])


def rigid_joints(scene: Scene) -> Scene:
    """The scene with every elastic joint rigid, its motor inertia as armature (K → ∞)."""
    arms = [
        a if a.elasticity is None else a.replace(elasticity=dataclasses.replace(a.elasticity, stiffness=math.inf))
        for a in scene.arm_specs
    ]
    return Scene(arms, scene.object, scene.interconnection_specs, gravity=scene.gravity)


def _cost(name: str, scene: Scene, dt: float, t_measure: float, omega: np.ndarray) -> ModelCost:
    """What one model costs to simulate (measured) and its modes ``omega`` [rad/s] (none for the rigid one)."""
    integrator = "rk4" if name == "rigid" else "implicit_euler"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a measurement, not a run to trust
        res = simulate(
            scene,
            t_measure,
            integrator=integrator,
            dt=dt,
            save_every=max(1, round(t_measure / dt)),
            energy_check="off",
            accuracy_check="off",  # (timed: a check would be counted)
        )
        cpu = res.cpu_time / t_measure  # the run's steps, not the set-up (building a large beam's dynamics)
    return ModelCost(
        name,
        scene.nq + scene.nv,
        float(omega.min() / (2 * np.pi)) if omega.size else None,
        float(omega.max() / (2 * np.pi)) if omega.size else None,
        float(EXPLICIT_LIMIT / omega.max()) if omega.size else None,
        integrator,
        cpu,
    )


MAX_MEASURE = 60.0  #: [s] the longest simulated time advise_model spends timing one model


def advise_model(scene: Scene, bandwidth: float = 15.0, dt: float = 1e-3, measure: float = 0.05) -> ModelAdvice:
    """Which model the scene needs at a control ``bandwidth`` [Hz], and what each one costs.

    The object's lowest internal mode below ``MODE_SEPARATION × bandwidth``: the drives excite
    it — ``"elastic"``. Else the grasps' lowest mode (the quasi-static system) below it: the
    grasp compliance matters — ``"quasi-static"``. Else ``"rigid"`` is enough for the motion.
    The costs are measured by simulating each model for ``measure`` seconds at ``dt`` [s]
    without a controller (rk4 for the rigid limit, implicit Euler for the others).
    """
    if not isinstance(scene, Scene):
        raise SimulationError(f"advise_model takes a coopdyn.Scene, got {type(scene).__name__}")
    if scene.constraints:
        raise SimulationError("advise_model takes an elastic scene and derives the rigid limit itself; this one is rigid already")
    bandwidth = _validate.positive(bandwidth, "bandwidth", "Hz", SimulationError)
    dt = _validate.positive(dt, "dt", "s", SimulationError)
    measure = _validate.positive(measure, "measure", "s", SimulationError)
    if not 1e-12 <= dt <= measure:
        raise SimulationError(f"dt must be from 1e-12 s up to measure = {measure:g} s, got {dt:g} s")
    if measure > MAX_MEASURE:
        raise SimulationError(
            f"measure = {measure:g} s: each model is simulated that long to time it; give at most {MAX_MEASURE:g} s"
        )
    qs = quasi_static(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the preloads it drops are reported by rigid_limit itself elsewhere
        rigid = rigid_limit(qs)
    object_hz = scene.object.lowest_frequency()  # None: a rigid object, no elastic modes of its own
    grasp = _modes(qs)
    grasp_hz = float(grasp.min() / (2 * np.pi)) if grasp.size else float("inf")
    limit = MODE_SEPARATION * bandwidth
    if object_hz is not None and object_hz < limit:
        choice = "elastic"
        reason = f"the object's own lowest mode, {object_hz:.3g} Hz, is within {MODE_SEPARATION:g}× the bandwidth ({limit:g} Hz)"
    elif grasp_hz < limit:
        choice = "quasi-static"
        what = f"the object's modes ({object_hz:.3g} Hz and up) follow quasi-statically; " if object_hz is not None else ""
        reason = f"{what}the grasps' lowest mode, {grasp_hz:.3g} Hz, is within {MODE_SEPARATION:g}× the bandwidth ({limit:g} Hz)"
    else:
        choice = "rigid"
        reason = (
            f"every elastic mode is above {MODE_SEPARATION:g}× the bandwidth ({limit:g} Hz; grasps from {grasp_hz:.3g} Hz): the "
            "rigid model gives the motion, but its internal force is the solver's least-norm choice — use the quasi-static "
            "model when the squeeze matters"
        )
    models = {"rigid": rigid, "quasi-static": qs, "elastic": scene}
    if object_hz is None:
        models.pop("elastic")  # a rigid object's elastic system is its massless grasps: quasi-static already
    # computed above; the elastic model's only if it is run; the rigid limit's: its elastic joints' (it keeps them)
    modes = {"rigid": _joint_modes(rigid) if rigid.joint_springs.size else np.zeros(0), "quasi-static": grasp}
    joint_hz, joints = None, None
    if scene.joint_springs.size:
        w = _joint_modes(scene)
        joint_hz = float(w.min() / (2 * np.pi))
        joints = "elastic" if joint_hz < limit else "rigid"
        reason += (
            f"; the joints' lowest transmission mode, {joint_hz:.3g} Hz, is within {MODE_SEPARATION:g}× the bandwidth: keep "
            "the elastic joints"
            if joints == "elastic"
            else f"; the joints' transmission modes (from {joint_hz:.3g} Hz) are above {MODE_SEPARATION:g}× the bandwidth: rigid "
            "joints carrying the motor inertia (stiffness=inf) give the motion"
        )
        models["rigid joints"] = rigid_joints(scene)
    costs = tuple(_cost(name, s, dt, measure, modes[name] if name in modes else _modes(s)) for name, s in models.items())
    return ModelAdvice(choice, bandwidth, dt, object_hz, grasp_hz, reason, costs, joint_hz, joints)


__all__ = ["MODELS", "MODE_SEPARATION", "ModelAdvice", "ModelCost", "advise_model"]
