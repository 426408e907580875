"""Typed hand-over specs: what a compiled component (an integrator family, a controller) gives its
C++ twin. Each is a frozen dataclass whose fields are the names the twin reads (src/native/
methods/, src/native/controllers/, through settings.hpp's Settings, which refuses a field it
does not read): declared once, here, with their units, and checked both ways by the tests."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np


@dataclass(frozen=True)
class CompiledSpec:
    """Base of the specs: :meth:`fields` is what crosses to C++ (``None`` fields are left out)."""

    #: the key naming the twin in the registry ("method" or "kind") and its registered name
    key: ClassVar[str]
    name: ClassVar[str]

    def fields(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}
        return {self.key: self.name, **out}


# -- integrator families (src/native/methods/) ----------------------------------------------------
@dataclass(frozen=True)
class MethodSpec(CompiledSpec):
    """A method family; ``adaptive`` and ``error_order`` are also the loop's step control."""

    key: ClassVar[str] = "method"
    adaptive: bool = False
    error_order: int = 0  #: the embedded error's order (the step controller's exponent is 1/(p+1))


@dataclass(frozen=True)
class SymplecticEulerSpec(MethodSpec):
    name: ClassVar[str] = "symplectic_euler"


@dataclass(frozen=True)
class RungeKuttaSpec(MethodSpec):
    """An explicit Butcher tableau (rows of A, b, c; b_hat for an embedded error)."""

    name: ClassVar[str] = "rk"
    A: list[list[float]] = dataclasses.field(default_factory=list)
    b: list[float] = dataclasses.field(default_factory=list)
    c: list[float] = dataclasses.field(default_factory=list)
    b_hat: list[float] | None = None


@dataclass(frozen=True)
class ImplicitEulerSpec(MethodSpec):
    name: ClassVar[str] = "implicit_euler"
    jacobian_every: int = 1  #: steps between step-matrix factorisations


@dataclass(frozen=True)
class RosenbrockSpec(MethodSpec):
    name: ClassVar[str] = "rosenbrock"
    gamma: float = 0.0  #: the stages' γ (ROS2: 1 + 1/√2; the trapezoid: ½ … )


@dataclass(frozen=True)
class ExponentialSpec(MethodSpec):
    """Filled in by coopdyn.compiled.plan: one discretisation per step size the run takes."""

    name: ClassVar[str] = "exponential"
    discretisations: list[tuple[Any, ...]] | None = None  #: (h, step, predictor, inner, p) each
    n_factor: int | None = None  #: factorisations already made in Python (a counter)


@dataclass(frozen=True)
class GeneralizedAlphaSpec(MethodSpec):
    name: ClassVar[str] = "generalized_alpha"
    alpha: tuple[float, float, float, float] = (0.0, 0.0, 0.5, 0.25)  #: (α_m, α_f, γ, β)


# -- controllers (src/native/controllers/) --------------------------------------------------------
@dataclass(frozen=True)
class ControllerSpec(CompiledSpec):
    key: ClassVar[str] = "kind"


@dataclass(frozen=True)
class GravityPDSpec(ControllerSpec):
    name: ClassVar[str] = "gravity_pd"
    kp: np.ndarray  #: (n_actuated,) [N·m/rad or N/m]
    kd: np.ndarray  #: (n_actuated,) [N·m·s/rad or N·s/m]
    q_des: np.ndarray  #: (nq,) the configuration held


@dataclass(frozen=True)
class ComputedTorqueSpec(ControllerSpec):
    name: ClassVar[str] = "computed_torque"
    q_index: np.ndarray  #: (n_actuated,) int32: each actuated joint's configuration index
    kp: np.ndarray  #: (n_actuated,) [1/s²]
    kd: np.ndarray  #: (n_actuated,) [1/s]
    q_d: np.ndarray  #: (n_actuated,) the joint positions held


@dataclass(frozen=True)
class DrivesSpec(ControllerSpec):
    name: ClassVar[str] = "drives"
    segments: list[np.ndarray]  #: per actuated joint, rows (start [s], constant, ramp, amplitude, ω [rad/s], phase [rad])


@dataclass(frozen=True)
class ObjectImpedanceSpec(ControllerSpec):
    """ObjectImpedance; ``task`` is {hold, start, rotation} or GripLiftOscillate's timings too."""

    name: ClassVar[str] = "object_impedance"
    object_frame: int
    grasps: list[tuple[int, int, np.ndarray]]  #: (grasp frame, tip frame, arm velocity indices) each
    task: dict[str, Any]
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
