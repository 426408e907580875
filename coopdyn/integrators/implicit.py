"""Linearly implicit methods for stiff interconnections: implicit Euler ("implicit springs",
Baraff & Witkin 1998) and the two-stage L-stable Rosenbrock-W method ROS2 (Verwer et al. 1999).

Both use the Jacobian of the stiff part, ``J = [[0, I], [−M⁻¹K̃, −M⁻¹D̃]]`` with K̃, D̃ from
:meth:`System.stiffness`, and never form ``M⁻¹``: a stage solve ``(I − γhJ) k = f`` on
``k = (k_q, k_v)`` is ``S k_v = M f_v − γh K̃ f_q``, ``k_q = f_q + γh k_v`` with the symmetric
positive definite ``S = M + γh D̃ + (γh)² K̃`` — one Cholesky factorisation per step.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .base import AdaptiveIntegrator, Attempt, Integrator, System


class _WSolver:
    """``(I − γhJ)⁻¹`` at one state: ``S = M + γh D̃ + (γh)² K̃`` (symmetric positive definite)
    inverted once. For the small, well-conditioned S of a few arms (nv ≲ 50) an explicit
    inverse and a matrix–vector product per solve cost less than LAPACK's triangular solves
    through scipy's wrappers (measured: ~2 µs vs ~35 µs per solve for nv = 20)."""

    def __init__(self, system: System, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float) -> None:
        self.M, self.K, self.gh = M, K, gh
        self.S_inv = np.linalg.inv(M + gh * D + (gh * gh) * K)
        system.n_factor += 1

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k_q, k_v) for the right-hand side (f_q, f_v), given ``M f_v``."""
        k_v = self.S_inv @ (Mf_v - self.gh * (self.K @ f_q))
        return f_q + self.gh * k_v, k_v


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

    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        if self.jacobian_every == 1:
            v_new = system.implicit_euler_velocity(t, q, v, h)
            return pin.integrate(system.model, q, h * v_new), v_new
        cache = system.cache.get("implicit_euler")
        if cache is None or cache[0] >= self.jacobian_every or cache[1] != h:
            f, M, K, D = system.implicit_terms(t, q, v)
            w = _WSolver(system, M, K, D, h)
            count = 0
        else:
            count, _, w = cache
            f = w.M @ system.acceleration(t, q, v)
        system.cache["implicit_euler"] = (count + 1, h, w)
        _, k_v = w.solve(v, f)
        v_new = v + h * k_v
        return pin.integrate(system.model, q, h * v_new), v_new

    def __repr__(self) -> str:
        return f"LinearlyImplicitEuler(jacobian_every={self.jacobian_every})"

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return 1.0 / (1.0 - np.asarray(z, dtype=complex))


GAMMA = 1.0 + 1.0 / math.sqrt(2.0)


def _ros2(system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, ...]:
    """One ROS2 step; returns (δ, v⁺, error of δ, error of v⁺) with the embedded first-order estimate."""
    f1, M, K, D = system.implicit_terms(t, q, v)
    w = _WSolver(system, M, K, D, GAMMA * h)
    kq1, kv1 = w.solve(v, f1)
    d2, v2 = h * kq1, v + h * kv1
    q2 = pin.integrate(system.model, q, d2)
    a2 = system.acceleration(t + h, q2, v2)
    kq2, kv2 = w.solve(system.chart_velocity(q, d2, v2) - 2.0 * kq1, M @ (a2 - 2.0 * kv1))
    delta = h * (1.5 * kq1 + 0.5 * kq2)
    v_new = v + h * (1.5 * kv1 + 0.5 * kv2)
    return delta, v_new, 0.5 * h * (kq1 + kq2), 0.5 * h * (kv1 + kv2)


def _ros2_stability(z: np.ndarray) -> np.ndarray:
    z = np.asarray(z, dtype=complex)
    hk1 = z / (1.0 - GAMMA * z)
    hk2 = (z * (1.0 + hk1) - 2.0 * hk1) / (1.0 - GAMMA * z)
    return 1.0 + 1.5 * hk1 + 0.5 * hk2


class ROS2(Integrator):
    """Two-stage L-stable Rosenbrock-W method, γ = 1 + 1/√2, fixed step.

    Second order with any Jacobian approximation; 2 RHS, 1 Jacobian, 1 factorisation per step.
    """

    name = "ros2"
    order = 2
    a_stable = True

    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        delta, v_new, _, _ = _ros2(system, t, q, v, h)
        return pin.integrate(system.model, q, delta), v_new

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z)


class AdaptiveROS2(AdaptiveIntegrator):
    """ROS2 with step control from its embedded first-order solution (``rtol``, ``atol``)."""

    name = "ros2_adaptive"
    order = 2
    error_order = 1
    a_stable = True

    def attempt(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> Attempt:
        delta, v_new, e_d, e_v = _ros2(system, t, q, v, h)
        return Attempt(pin.integrate(system.model, q, delta), v_new, self.error_norm(system, e_d, e_v, q, v, v_new))

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z)
