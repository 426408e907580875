"""Fixed-step integrators on the scene's configuration Lie group.

An integrator is configuration only (its coefficients); :meth:`Integrator.step` takes the
:class:`System` and a state and returns the next state. The system counts right-hand-side
evaluations. A new method implements ``step`` and registers itself in :data:`INTEGRATORS`.

Runge–Kutta stages are built in a local chart ``q = q₀ ⊕ δ`` around the step's start, where the
chart coordinates obey ``δ̇ = dIntegrate(q₀, δ)⁻¹ v`` (DESIGN §2): the method then keeps its
classical order on SE(3) free-flyers, which the naive ``q₀ ⊕ h Σ aᵢⱼ vⱼ`` stages do not.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pinocchio as pin

from .dynamics import Dynamics
from .errors import ControllerError, SimulationError

Controller = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


class System:
    """The closed loop ``q̈ = a(t, q, v)``: dynamics plus controller, with work counters.

    Args:
        dynamics: the scene dynamics.
        controller: ``controller(t, q, v) -> τ`` (n_actuated,) [N·m or N]; ``None`` means τ = 0.
    """

    def __init__(self, dynamics: Dynamics, controller: Controller | None = None) -> None:
        self.dynamics = dynamics
        self.model = dynamics.model
        self.controller = controller
        self.n_actuated = dynamics.scene.n_actuated
        self._zero = np.zeros(self.n_actuated)
        self.n_rhs = 0
        self._chart = _chart_blocks(self.model)

    def torque(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The controller output, checked: (n_actuated,) finite floats."""
        if self.controller is None:
            return self._zero
        tau = np.asarray(self.controller(t, q, v), dtype=float)
        if tau.shape != (self.n_actuated,):
            raise ControllerError(
                f"the controller returned shape {tau.shape} at t = {t:.6g} s; it must return one torque/force per "
                f"arm joint, shape ({self.n_actuated},), in scene order"
            )
        if not np.all(np.isfinite(tau)):
            bad = np.flatnonzero(~np.isfinite(tau)).tolist()
            raise ControllerError(f"the controller returned non-finite torques at t = {t:.6g} s (entries {bad})")
        return tau

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """q̈ (nv,) at (t, q, v); counts one right-hand-side evaluation."""
        self.n_rhs += 1
        return self.dynamics.acceleration(q, v, self.torque(t, q, v))

    def chart_velocity(self, q0: np.ndarray, delta: np.ndarray, v: np.ndarray) -> np.ndarray:
        """δ̇ = dIntegrate(q₀, δ)⁻¹ v: the chart-coordinate rate for the velocity v at q₀ ⊕ δ."""
        if not self._chart:
            return v
        J = pin.dIntegrate(self.model, q0, delta, pin.ArgumentPosition.ARG1)
        out = v.copy()
        for s in self._chart:
            out[s] = np.linalg.solve(J[s, s], v[s])
        return out


def _chart_blocks(model: pin.Model) -> list[slice]:
    """Velocity blocks of joints whose dIntegrate is not the identity (free-flyer, planar, …)."""
    blocks = []
    for j in model.joints[1:]:
        if j.nv > 1:
            blocks.append(slice(j.idx_v, j.idx_v + j.nv))
    return blocks


class Integrator(ABC):
    """A one-step method for (q, v) on the configuration Lie group."""

    name: ClassVar[str]
    order: ClassVar[int]

    @abstractmethod
    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance from (t, q, v) by ``h`` [s]; return the new (q, v)."""


class SymplecticEuler(Integrator):
    """Semi-implicit Euler: ``v⁺ = v + h a(q, v)``, ``q⁺ = q ⊕ h v⁺``. First order, 1 RHS/step."""

    name = "symplectic_euler"
    order = 1

    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        v_new = v + h * system.acceleration(t, q, v)
        return pin.integrate(system.model, q, h * v_new), v_new


@dataclass(frozen=True)
class ButcherTableau:
    """Coefficients of an explicit Runge–Kutta method."""

    A: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]


class ExplicitRungeKutta(Integrator):
    """An explicit Runge–Kutta method applied in the local chart around the step's start."""

    tableau: ClassVar[ButcherTableau]

    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        tab = self.tableau
        kd: list[np.ndarray] = []  # chart rates δ̇
        ka: list[np.ndarray] = []  # accelerations
        for row, c in zip(tab.A, tab.c, strict=True):
            if kd:
                delta = h * _combine(row, kd)
                v_s = v + h * _combine(row, ka)
                q_s = pin.integrate(system.model, q, delta)
                kd.append(system.chart_velocity(q, delta, v_s))
            else:
                q_s, v_s = q, v
                kd.append(v)
            ka.append(system.acceleration(t + c * h, q_s, v_s))
        delta = h * _combine(tab.b, kd)
        v_new = v + h * _combine(tab.b, ka)
        return pin.integrate(system.model, q, delta), v_new


def _combine(coefficients: tuple[float, ...], ks: list[np.ndarray]) -> np.ndarray:
    """Σ cᵢ kᵢ over the non-zero coefficients."""
    out = np.zeros_like(ks[0])
    for c, k in zip(coefficients, ks, strict=False):
        if c:
            out += c * k
    return out


class RK4(ExplicitRungeKutta):
    """The classical fourth-order Runge–Kutta method (Lie-group correct), 4 RHS/step."""

    name = "rk4"
    order = 4
    tableau = ButcherTableau(
        A=((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)),
        b=(1 / 6, 1 / 3, 1 / 3, 1 / 6),
        c=(0.0, 0.5, 0.5, 1.0),
    )


#: Name → integrator class. ``simulate(..., integrator=name)`` looks names up here.
INTEGRATORS: dict[str, type[Integrator]] = {cls.name: cls for cls in (SymplecticEuler, RK4)}


def get_integrator(integrator: str | Integrator) -> Integrator:
    """An integrator instance from a name in :data:`INTEGRATORS` or an instance."""
    if isinstance(integrator, Integrator):
        return integrator
    if isinstance(integrator, str) and integrator in INTEGRATORS:
        return INTEGRATORS[integrator]()
    raise SimulationError(f"unknown integrator {integrator!r}; valid: {sorted(INTEGRATORS)}")
