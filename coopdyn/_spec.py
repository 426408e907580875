"""Typed hand-over specs: what a compiled component (an integrator family, a controller) gives its
C++ twin. Each is a frozen dataclass whose fields are the names the twin reads (src/native/
methods/, src/native/controllers/, through settings.hpp's Settings, which refuses a field it
does not read): declared once, here, with their units, and checked both ways by the tests."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np


@dataclass(frozen=True, eq=False, kw_only=True)
class CompiledSpec:
    """Base of the specs: :meth:`fields` is what crosses to C++ (``None`` fields are left out)."""

    #: the key naming the twin in the registry ("method" or "kind") and its registered name
    key: ClassVar[str]
    name: ClassVar[str]

    def fields(self) -> dict[str, Any]:
        return {self.key: self.name, **_fields(self)}


def _fields(spec: Any) -> dict[str, Any]:
    """A spec's fields by name (nested specs as tables; ``None`` fields left out)."""
    out = {}
    for name in _field_names(type(spec)):
        value = getattr(spec, name)
        if value is not None:
            out[name] = _fields(value) if hasattr(type(value), "__dataclass_fields__") else value
    return out


_FIELD_NAMES: dict[type, tuple[str, ...]] = {}


def _field_names(cls: type) -> tuple[str, ...]:
    """A spec class's field names (read once: a run's plan reads them at every run)."""
    names = _FIELD_NAMES.get(cls)
    if names is None:
        names = _FIELD_NAMES[cls] = tuple(f.name for f in dataclasses.fields(cls))
    return names


# -- integrator families (src/native/methods/) ----------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class MethodSpec(CompiledSpec):
    """A method family; ``adaptive`` and ``error_order`` are also the loop's step control."""

    key: ClassVar[str] = "method"
    adaptive: bool = False
    error_order: int = 0  #: the embedded error's order (the step controller's exponent is 1/(p+1))


@dataclass(frozen=True, eq=False, kw_only=True)
class SymplecticEulerSpec(MethodSpec):
    name: ClassVar[str] = "symplectic_euler"


@dataclass(frozen=True, eq=False, kw_only=True)
class RungeKuttaSpec(MethodSpec):
    """An explicit Butcher tableau (rows of A, b, c; b_hat for an embedded error)."""

    name: ClassVar[str] = "rk"
    A: list[list[float]]  #: row i has i entries (explicit)
    b: list[float]
    c: list[float]
    b_hat: list[float] | None = None


@dataclass(frozen=True, eq=False, kw_only=True)
class ImplicitEulerSpec(MethodSpec):
    name: ClassVar[str] = "implicit_euler"
    jacobian_every: int = 1  #: steps between step-matrix factorisations


@dataclass(frozen=True, eq=False, kw_only=True)
class RosenbrockSpec(MethodSpec):
    name: ClassVar[str] = "rosenbrock"
    gamma: float  #: the stages' γ in [½, 2] (ROS2: 1 + 1/√2; the trapezoid: ½ to 1 + 1/√2 by ρ∞)


@dataclass(frozen=True, eq=False, kw_only=True)
class ExponentialSpec(MethodSpec):
    """Filled in by coopdyn.compiled.plan: one discretisation per step size the run takes."""

    name: ClassVar[str] = "exponential"
    #: (h [s], step (2nv, 2nv + n_actuated + 1), predictor (p·2nv, same), inner (2nv, p·n_actuated), p) each
    discretisations: list[tuple[Any, ...]] | None = None
    n_factor: int | None = None  #: factorisations already made in Python (a counter)


@dataclass(frozen=True, eq=False, kw_only=True)
class GeneralizedAlphaSpec(MethodSpec):
    name: ClassVar[str] = "generalized_alpha"
    alpha: tuple[float, float, float, float]  #: (α_m < 1, α_f, γ > 0, β > 0)


# -- controllers (src/native/controllers/) --------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class ControllerSpec(CompiledSpec):
    key: ClassVar[str] = "kind"


@dataclass(frozen=True, eq=False, kw_only=True)
class NoControllerSpec(ControllerSpec):
    """No controller: zero torques."""

    name: ClassVar[str] = "none"


@dataclass(frozen=True, eq=False, kw_only=True)
class PythonControllerSpec(ControllerSpec):
    """A controller without a compiled twin, called back (coopdyn.compiled.PythonCallback)."""

    name: ClassVar[str] = "python"
    callback: Any


@dataclass(frozen=True, eq=False, kw_only=True)
class GravityPDSpec(ControllerSpec):
    name: ClassVar[str] = "gravity_pd"
    kp: np.ndarray  #: (n_actuated,) [N·m/rad or N/m]
    kd: np.ndarray  #: (n_actuated,) [N·m·s/rad or N·s/m]
    q_des: np.ndarray  #: (nq,) the configuration held [rad, m]


@dataclass(frozen=True, eq=False, kw_only=True)
class TorqueSequenceSpec(ControllerSpec):
    name: ClassVar[str] = "torque_sequence"
    torques: np.ndarray  #: (N, n_actuated) [N·m or N], each held for one period
    period: float  #: [s]


@dataclass(frozen=True, eq=False, kw_only=True)
class MotorPDSpec(ControllerSpec):
    name: ClassVar[str] = "motor_pd"
    kp: np.ndarray  #: (n_actuated,) [N·m/rad or N/m]
    kd: np.ndarray  #: (n_actuated,) [N·m·s/rad or N·s/m]
    target: np.ndarray  #: (nq,) the configuration whose drive coordinates are held (θ_d, rigid joints' q_d) [rad, m]
    g_d: np.ndarray  #: (n_actuated,) g(q_d), the arms' gravity at the target [N·m or N]
    online: bool  #: the gravity term at θ̄ = θ − K⁻¹ g(q_d) (else the constant g_d)
    arm_joints: np.ndarray  #: (n_actuated,) int32: each arm joint's v index (link side)
    #: (m, 5) rows of (link q, link v, motor q, continuous, K⁻¹ g(q_d)) of the elastic joints
    elastic: np.ndarray


@dataclass(frozen=True, eq=False, kw_only=True)
class ComputedTorqueSpec(ControllerSpec):
    name: ClassVar[str] = "computed_torque"
    q_index: np.ndarray  #: (n_actuated,) int32: each actuated joint's configuration index
    kp: np.ndarray  #: (n_actuated,) [1/s²]
    kd: np.ndarray  #: (n_actuated,) [1/s]
    q_d: np.ndarray  #: (n_actuated,) the joint positions held [rad or m]


@dataclass(frozen=True, eq=False, kw_only=True)
class DrivesSpec(ControllerSpec):
    name: ClassVar[str] = "drives"
    #: per actuated joint, rows (start [s], constant [N·m or N], ramp [N·m/s or N/s], amplitude [N·m or N],
    #: ω [rad/s], phase [rad])
    segments: list[np.ndarray]


@dataclass(frozen=True, eq=False, kw_only=True)
class HoldTaskSpec:
    """ObjectImpedance's default task: hold the object's initial pose."""

    hold: bool = dataclasses.field(default=True, init=False)
    start: np.ndarray  #: (3,) the object frame's position held [m]
    rotation: np.ndarray  #: (3, 3) its orientation held


@dataclass(frozen=True, eq=False, kw_only=True)
class GripLiftOscillateTaskSpec:
    """coopdyn.cooperative.GripLiftOscillate's timings (its docstring says what each does)."""

    hold: bool = dataclasses.field(default=False, init=False)
    start: np.ndarray  #: (3,) [m]
    rotation: np.ndarray  #: (3, 3)
    axis: np.ndarray  #: (3,) unit, the oscillation's direction
    squeeze: float  #: [N]
    t_grip: float  #: [s]
    lift: float  #: [m]
    t_lift: float  #: [s]
    lift_duration: float  #: [s]
    amplitude: float  #: [m]
    frequency: float  #: [Hz]
    t_osc: float  #: [s]
    cycles: float


@dataclass(frozen=True, eq=False, kw_only=True)
class ObjectImpedanceSpec(ControllerSpec):
    """ObjectImpedance with its task."""

    name: ClassVar[str] = "object_impedance"
    object_frame: int
    grasps: list[tuple[int, int, np.ndarray]]  #: (grasp frame, tip frame, arm velocity indices) each
    task: HoldTaskSpec | GripLiftOscillateTaskSpec
    mass: float  #: [kg]
    com: np.ndarray  #: (3,) [m], object frame
    gravity: np.ndarray  #: (3,) [m/s²]
    Kp: np.ndarray  #: (3,) [N/m]
    Kr: np.ndarray  #: (3,) [N·m/rad]
    Dp: np.ndarray  #: (3,) [N·s/m]
    Dr: np.ndarray  #: (3,) [N·m·s/rad]
    joint_damping: float  #: [N·m·s/rad]
    null_k: float  #: posture stiffness in the null space [N·m/rad]
    null_d: float  #: posture damping in the null space [N·m·s/rad]
    q0: np.ndarray  #: (nq,) the posture
    collocated: bool  #: measure="tips": the object's pose and velocity read at the tool frames
    tip_offsets: np.ndarray  #: (4·n_grasps, 4): each tool frame's pose in the object frame at the start
    Ki: np.ndarray  #: (3,) internal rotational stiffness [N·m/rad] (collocated only)
    Di: np.ndarray  #: (3,) internal rotational damping [N·m·s/rad] (collocated only)
    #: (4m,) the elastic joints' fast damping, four values each: (its entry in τ, link v, motor v,
    #: K_v [N·m·s/rad]): τ += K_v (q̇ − θ̇)
    transmissions: np.ndarray
