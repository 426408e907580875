"""Linearly implicit methods for stiff interconnections: implicit Euler ("implicit springs",
Baraff & Witkin 1998), the two-stage L-stable Rosenbrock-W method ROS2 (Verwer et al. 1999), and
the same two-stage scheme at γ = ½: the linearly implicit trapezoidal rule, which does not damp
the interconnections' oscillations (|R(iω)| = 1) — with a high-frequency damping ρ∞ between the two.

Both use the Jacobian of the stiff part, ``J = [[0, I], [−M⁻¹K̃, −M⁻¹D̃]]`` with K̃, D̃ from
the problem's ``implicit_terms``, and never form ``M⁻¹``: a stage solve ``(I − γhJ) k = f`` on
``k = (k_q, k_v)`` is ``S k_v = M f_v − γh K̃ f_q``, ``k_q = f_q + γh k_v`` with the symmetric
positive definite ``S = M + γh D̃ + (γh)² K̃`` — one Cholesky factorisation per step. There is
one implementation of that solve, in the dynamics (``factor`` / ``solve``; the compiled kernel or
its Python reference); a step matrix that is not positive definite raises
:class:`coopdyn.errors.StepMatrixError`.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from .base import AdaptiveIntegrator, Attempt, Integrator, Problem


class _Reuse:
    """The W-method's workspace: the mass matrix of the last refresh, the step it was factored
    for and the steps taken since (the factorisation itself stays in the dynamics)."""

    def __init__(self) -> None:
        self.count = 0
        self.h = 0.0
        self.M: np.ndarray | None = None


class LinearlyImplicitEuler(Integrator):
    """``(M + hD̃ + h²K̃) Δv = h M a − h² K̃ v``, ``v⁺ = v + Δv``, ``q⁺ = q ⊕ h v⁺``.

    First order; stable for any stiffness (backward Euler on the linearised system); the same
    metric as MuJoCo's implicit solvers. By default 1 RHS, 1 Jacobian and 1 solve per step.

    Args:
        jacobian_every: re-evaluate M, K̃, D̃ and refactorise every this many steps (≥ 1); in
            between, steps reuse them with the current acceleration (a W-method: still first
            order, stable while the configuration moves little between refreshes), costing one
            RHS and two triangular solves.
    """

    name = "implicit_euler"
    order = 1
    a_stable = True

    def __init__(self, jacobian_every: int = 1) -> None:
        if isinstance(jacobian_every, bool) or not isinstance(jacobian_every, int) or jacobian_every < 1:
            from ..errors import SimulationError

            raise SimulationError(f"jacobian_every must be an integer >= 1, got {jacobian_every!r}")
        self.jacobian_every = jacobian_every

    def compiled_spec(self) -> dict[str, Any]:
        return {"method": "implicit_euler", "jacobian_every": self.jacobian_every}

    def workspace(self, system: Problem) -> _Reuse | None:
        return _Reuse() if self.jacobian_every > 1 else None

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        if self.jacobian_every == 1:
            v_new = system.implicit_euler_velocity(t, q, v, h)
            return system.integrate(q, h * v_new), v_new
        if ws is None or ws.M is None or ws.count >= self.jacobian_every or ws.h != h:
            f, M, K, D = system.implicit_terms(t, q, v)
            system.factor(M, K, D, h)
            if ws is not None:
                ws.count, ws.h, ws.M = 0, h, M
        else:
            f = ws.M @ system.acceleration(t, q, v)
        if ws is not None:
            ws.count += 1
        _, k_v = system.solve(v, f)
        v_new = v + h * k_v
        return system.integrate(q, h * v_new), v_new

    def __repr__(self) -> str:
        return f"LinearlyImplicitEuler(jacobian_every={self.jacobian_every})"

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return 1.0 / (1.0 - np.asarray(z, dtype=complex))


GAMMA = 1.0 + 1.0 / math.sqrt(2.0)  #: ROS2's γ (L-stable: R(∞) = 0)


def gamma_for(rho_inf: float) -> float:
    """The γ of the two-stage Rosenbrock-W scheme whose stability function has |R(∞)| = ρ∞.

    The scheme ``(I − γhJ)k₁ = f(y)``, ``(I − γhJ)k₂ = f(y + hk₁) − 2k₁``,
    ``y⁺ = y + h(3k₁ + k₂)/2`` is second order for any γ and any Jacobian approximation J, and
    A-stable for γ ≥ ¼, with ``R(z) = (1 + (1 − 2γ)z + (γ² − 2γ + ½)z²) / (1 − γz)²``;
    ``R(∞) = (γ² − 2γ + ½)/γ²`` runs from −1 (γ = ½: the trapezoidal rule's Cayley map
    ``(1 + z/2)/(1 − z/2)``, no damping at any frequency) to 0 (γ = 1 + 1/√2: ROS2).
    """
    rho = float(rho_inf)
    return (1.0 + math.sqrt((1.0 - rho) / 2.0)) / (1.0 + rho)


def _ros2(system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, gamma: float = GAMMA) -> tuple[np.ndarray, ...]:
    """One two-stage Rosenbrock-W step; returns (δ, v⁺, error of δ, error of v⁺) with the embedded
    first-order estimate."""
    f1, M, K, D = system.implicit_terms(t, q, v)
    system.factor(M, K, D, gamma * h)
    kq1, kv1 = system.solve(v, f1)
    d2, v2 = h * kq1, v + h * kv1
    q2 = system.integrate(q, d2)
    a2 = system.acceleration(t + h, q2, v2)
    kq2, kv2 = system.solve(system.chart_velocity(q, d2, v2) - 2.0 * kq1, M @ (a2 - 2.0 * kv1))
    delta = h * (1.5 * kq1 + 0.5 * kq2)
    v_new = v + h * (1.5 * kv1 + 0.5 * kv2)
    return delta, v_new, 0.5 * h * (kq1 + kq2), 0.5 * h * (kv1 + kv2)


def _ros2_stability(z: np.ndarray, gamma: float = GAMMA) -> np.ndarray:
    z = np.asarray(z, dtype=complex)
    hk1 = z / (1.0 - gamma * z)
    hk2 = (z * (1.0 + hk1) - 2.0 * hk1) / (1.0 - gamma * z)
    return 1.0 + 1.5 * hk1 + 0.5 * hk2


class ROS2(Integrator):
    """Two-stage L-stable Rosenbrock-W method, γ = 1 + 1/√2, fixed step.

    Second order with any Jacobian approximation; 2 RHS, 1 Jacobian, 1 factorisation per step.
    """

    name = "ros2"
    order = 2
    a_stable = True

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        delta, v_new, _, _ = _ros2(system, t, q, v, h)
        return system.integrate(q, delta), v_new

    def compiled_spec(self) -> dict[str, Any]:
        return {"method": "rosenbrock", "gamma": GAMMA}

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z)


class AdaptiveROS2(AdaptiveIntegrator):
    """ROS2 with step control from its embedded first-order solution (``rtol``, ``atol``)."""

    name = "ros2_adaptive"
    order = 2
    error_order = 1
    a_stable = True

    def attempt(self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None) -> Attempt:
        delta, v_new, e_d, e_v = _ros2(system, t, q, v, h)
        return Attempt(system.integrate(q, delta), v_new, self.error_norm(system, e_d, e_v, q, v, v_new))

    def compiled_spec(self) -> dict[str, Any]:
        return {"method": "rosenbrock", "gamma": GAMMA, "adaptive": True, "error_order": self.error_order}

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z)


class Trapezoid(Integrator):
    """The linearly implicit trapezoidal rule on the Lie group: ROS2's two stages at γ = ½.

    Second order with any Jacobian approximation, A-stable, and **non-dissipative**: its
    stability function is the Cayley map ``(1 + z/2)/(1 − z/2)``, so an undamped oscillation of
    any frequency keeps its amplitude (|R(iω)| = 1) — where implicit Euler and ROS2 damp the
    interconnections' spring modes away and misreport their forces at large steps. An
    under-resolved mode is kept but its phase is wrong (frequency warped by ``2·atan(ωh/2)/h``).
    2 RHS, 1 Jacobian and 1 factorisation per step, like ROS2.

    Args:
        rho_inf: high-frequency spectral radius ρ∞ = |R(∞)| in [0, 1] (as in generalized-α):
            1 (default) damps nothing; smaller values damp modes far above 1/h, down to 0 =
            ROS2 (L-stable). In between the method stays second order and A-stable.
    """

    name = "trapezoid"
    order = 2
    a_stable = True

    def __init__(self, rho_inf: float = 1.0) -> None:
        rho = float(rho_inf) if isinstance(rho_inf, numbers.Real) and not isinstance(rho_inf, bool) else math.nan
        if not 0.0 <= rho <= 1.0:
            from ..errors import SimulationError

            raise SimulationError(f"rho_inf must be a number in [0, 1], got {rho_inf!r}")
        self.rho_inf = rho
        self.gamma = gamma_for(rho)

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        delta, v_new, _, _ = _ros2(system, t, q, v, h, self.gamma)
        return system.integrate(q, delta), v_new

    def compiled_spec(self) -> dict[str, Any]:
        return {"method": "rosenbrock", "gamma": self.gamma}

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z, self.gamma)

    def __repr__(self) -> str:
        return f"Trapezoid(rho_inf={self.rho_inf:g})"
