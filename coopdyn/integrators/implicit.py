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
from scipy.linalg import cho_factor, cho_solve

from .._spec import GeneralizedAlphaSpec, ImplicitEulerSpec, RosenbrockSpec
from ..errors import SimulationError
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
        self.jacobian_every = jacobian_every

    @property
    def jacobian_every(self) -> int:
        """Steps between two Jacobians (≥ 1)."""
        return self._jacobian_every

    @jacobian_every.setter
    def jacobian_every(self, value: int) -> None:
        from .._validate import count

        self._jacobian_every = count(value, "jacobian_every", SimulationError)

    def compiled_spec(self) -> ImplicitEulerSpec:
        return ImplicitEulerSpec(jacobian_every=self.jacobian_every)

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

    def compiled_spec(self) -> RosenbrockSpec:
        return RosenbrockSpec(gamma=GAMMA)

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z)


class AdaptiveROS2(AdaptiveIntegrator):
    """ROS2 with step control from its embedded first-order solution (``rtol``, ``atol``).

    A second-order method's error estimate shrinks as h², so its steps grow as rtol^½ (dopri5's
    as rtol^⅕): it is meant for loose tolerances, and its defaults are looser than dopri5's
    (rtol 1e-3, atol 1e-6). At dopri5's 1e-6 it took 170–280× dopri5's steps on the bench scenes,
    at these 5–9× with force errors of 0.1–4 % of the force swing; ten times looser (rtol 1e-2)
    it would take 1.7–2.5× but be 1–29 % off (``benchmarks/adaptive_steps.py``). For tight
    accuracy, use dopri5.
    """

    name = "ros2_adaptive"
    order = 2
    error_order = 1
    a_stable = True
    advised = False  # ros2's stability function

    def __init__(self, rtol: float = 1e-3, atol: float = 1e-6, h_min: float = 1e-12) -> None:
        super().__init__(rtol=rtol, atol=atol, h_min=h_min)

    def attempt(self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None) -> Attempt:
        delta, v_new, e_d, e_v = _ros2(system, t, q, v, h)
        return Attempt(system.integrate(q, delta), v_new, self.error_norm(system, e_d, e_v, q, v, v_new))

    def compiled_spec(self) -> RosenbrockSpec:
        return RosenbrockSpec(gamma=GAMMA, adaptive=True, error_order=self.error_order)

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z)


def _check_rho(rho_inf: object) -> float:
    """ρ∞ as a float, or a SimulationError naming the bad value."""
    try:  # float() of a huge int overflows
        rho = float(rho_inf) if isinstance(rho_inf, numbers.Real) and not isinstance(rho_inf, bool | np.timedelta64) else math.nan
    except OverflowError:
        rho = math.nan
    if not 0.0 <= rho <= 1.0:
        raise SimulationError(f"rho_inf must be a number in [0, 1], got {repr(rho_inf)[:40]}")
    return rho


class _RhoInf:
    """ρ∞ in [0, 1], checked whenever it is set; :meth:`_derive` sets what follows from it."""

    @property
    def rho_inf(self) -> float:
        """The high-frequency spectral radius ρ∞ in [0, 1]."""
        return self._rho_inf

    @rho_inf.setter
    def rho_inf(self, value: float) -> None:
        self._rho_inf = _check_rho(value)
        self._derive(self._rho_inf)

    def _derive(self, rho: float) -> None:
        raise NotImplementedError


class Trapezoid(_RhoInf, Integrator):
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
        self.rho_inf = rho_inf

    def _derive(self, rho: float) -> None:
        self._gamma = gamma_for(rho)

    @property
    def gamma(self) -> float:
        """The scheme's γ, from ρ∞ (:func:`gamma_for`)."""
        return self._gamma

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        delta, v_new, _, _ = _ros2(system, t, q, v, h, self.gamma)
        return system.integrate(q, delta), v_new

    def compiled_spec(self) -> RosenbrockSpec:
        return RosenbrockSpec(gamma=self.gamma)

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _ros2_stability(z, self.gamma)

    def __repr__(self) -> str:
        return f"Trapezoid(rho_inf={self.rho_inf:g})"


def alpha_parameters(rho_inf: float) -> tuple[float, float, float, float]:
    """Chung & Hulbert's (α_m, α_f, γ, β) for the high-frequency spectral radius ρ∞ ∈ [0, 1]:
    ``α_m = (2ρ∞ − 1)/(ρ∞ + 1)``, ``α_f = ρ∞/(ρ∞ + 1)``, ``γ = ½ − α_m + α_f``,
    ``β = ¼ (1 − α_m + α_f)²`` — second order, unconditionally stable, least low-frequency
    dissipation for the given high-frequency dissipation. ρ∞ = 1 is Newmark's average
    acceleration (the trapezoidal rule).

    Raises:
        SimulationError: ρ∞ is not a number in [0, 1].
    """
    rho = _check_rho(rho_inf)
    am, af = (2.0 * rho - 1.0) / (rho + 1.0), rho / (rho + 1.0)
    return am, af, 0.5 - am + af, 0.25 * (1.0 - am + af) ** 2


class _AlphaState:
    """Generalized-α's workspace: the algorithmic acceleration aₙ at the state it belongs to."""

    def __init__(self) -> None:
        self.a: np.ndarray | None = None
        self.q: np.ndarray | None = None
        self.v: np.ndarray | None = None


def alpha_coefficients(am: float, gamma: float, beta: float, h: float) -> tuple[float, float, float]:
    """What one step of ``h`` [s] knows at its start, with x̂ = (1 − α_m)a⁺ + α_m a the unknown:
    a⁺ = (x̂ − α_m a)/(1 − α_m), so ``q⁺ = q ⊕ (h v + dq_a·a + βhc x̂)`` and
    ``v⁺ = v + dv_a·a + γc x̂``; returns (c = h/(1 − α_m), dq_a, dv_a)."""
    c = h / (1.0 - am)
    return c, h * h * (0.5 - beta - beta * am / (1.0 - am)), h * (1.0 - gamma - gamma * am / (1.0 - am))


def alpha_amplification(Aq: np.ndarray, Av: np.ndarray, h: float, rho_inf: float) -> np.ndarray:
    """The matrix of one generalized-α step of ``h`` [s] on the linear system
    ``q̈ = Aq q + Av q̇``, acting on ``(q, q̇, a)`` (3n × 3n; a: the algorithmic acceleration).
    For a batch, Aq and Av are (..., n, n)."""
    am, af, gamma, beta = alpha_parameters(rho_inf)
    Aq, Av = np.asarray(Aq), np.asarray(Av)
    n = Aq.shape[-1]
    eye = np.broadcast_to(np.eye(n), Aq.shape)
    c, dq_a, dv_a = alpha_coefficients(am, gamma, beta, h)  # and x̂ = (1 − α_f) q̈(q⁺, v⁺) + α_f q̈(q, v) here
    lhs = eye - (1.0 - af) * (beta * h * c * Aq + gamma * c * Av)
    # x̂ − (1 − α_f)(βhc Aq + γc Av) x̂ = Aq q + ((1 − α_f)h Aq + Av) v + (1 − α_f)(dq_a Aq + dv_a Av) a
    rhs = np.concatenate([Aq, (1.0 - af) * h * Aq + Av, (1.0 - af) * (dq_a * Aq + dv_a * Av)], axis=-1)
    xh = np.linalg.solve(lhs, rhs)
    zero = np.zeros_like(Aq)
    top = np.concatenate([eye, h * eye, dq_a * eye], axis=-1) + beta * h * c * xh
    mid = np.concatenate([zero, eye, dv_a * eye], axis=-1) + gamma * c * xh
    bottom = (xh - np.concatenate([zero, zero, am * eye], axis=-1)) / (1.0 - am)
    return np.concatenate([top, mid, bottom], axis=-2)


class GeneralizedAlpha(_RhoInf, Integrator):
    """Generalized-α on the Lie group (Chung & Hulbert 1993; Arnold & Brüls 2007; Brüls,
    Cardona & Arnold 2012) — the structural-dynamics method of flexible-multibody codes, with
    the high-frequency dissipation ρ∞ as its one parameter:

    ``q⁺ = q ⊕ h(v + h(½ − β)a + hβ a⁺)``, ``v⁺ = v + h((1 − γ)a + γ a⁺)``,
    ``(1 − α_m) a⁺ + α_m a = (1 − α_f) q̈⁺ + α_f q̈``

    where q̈ is the true acceleration (the equations of motion) and a the algorithmic one,
    carried from step to step (the first step starts from a = q̈). Second order in q and v on
    the Lie group, unconditionally stable on linear problems; ρ∞ = 1 damps nothing (Newmark's
    average acceleration: |R(iω)| = 1); smaller ρ∞ damp modes far above 1/h by ρ∞ per step
    (ρ∞ = 0: gone within three steps), and a mode well resolved by the step is damped only at
    third order in ωh. Like every generalized-α, a displaced mode far above 1/h overshoots in
    velocity for a step or two before it decays (by up to ~ωh/4 of its displacement at ρ∞ = 0),
    and stiff overdamped modes (a stiff spring with a stiff damper, as a beam's
    stiffness-proportional damping makes every fast element mode) amplify a start velocity by
    hundreds to 1e5 on a held strip at 1 ms (docs/physics.md): on beam scenes use the trapezoid
    or implicit Euler.

    The implicit equation for ``x̂ = (1 − α_m)a⁺ + α_m a`` is solved by one linearised solve
    about the step's start (with the Jacobian of ``implicit_terms``: ``S = M + γ' D̃ + β' K̃``,
    γ' = (1 − α_f)γh/(1 − α_m), β' = (1 − α_f)βh²/(1 − α_m), controller gains added) and one
    Newton correction with the same factorisation from the true acceleration at the result: the
    correction makes the step second order with the approximate Jacobian, and is zero on
    linear scenes. 2 RHS, 1 Jacobian, 1 factorisation and 2 solves per step, like ROS2.

    Args:
        rho_inf: high-frequency spectral radius ρ∞ in [0, 1] (default 0.9, as in Exudyn).
    """

    name = "generalized_alpha"
    order = 2
    a_stable = True

    def __init__(self, rho_inf: float = 0.9) -> None:
        self.rho_inf = rho_inf

    def _derive(self, rho: float) -> None:
        self._parameters = alpha_parameters(rho)

    @property
    def alpha_m(self) -> float:
        """α_m, from ρ∞ (:func:`alpha_parameters`)."""
        return self._parameters[0]

    @property
    def alpha_f(self) -> float:
        """α_f, from ρ∞."""
        return self._parameters[1]

    @property
    def gamma(self) -> float:
        """Newmark's γ, from ρ∞."""
        return self._parameters[2]

    @property
    def beta(self) -> float:
        """Newmark's β, from ρ∞."""
        return self._parameters[3]

    def workspace(self, system: Problem) -> _AlphaState:
        return _AlphaState()

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        am, af, gamma, beta = self.alpha_m, self.alpha_f, self.gamma, self.beta
        if not h > 0.0:
            raise SimulationError(f"generalized_alpha needs a step h > 0, got {h!r}")
        f, M, K, D = system.implicit_terms(t, q, v)  # f = M q̈ at the step's start
        # v⁺ = v + dv0 + γc x̂ and q⁺ = q ⊕ (dq0 + βhc x̂), dv0 and dq0 the parts known at the start
        c, dq_a, dv_a = alpha_coefficients(am, gamma, beta, h)
        gp, bp = (1.0 - af) * gamma * c, (1.0 - af) * beta * h * c  # γ', β'
        system.factor(M, K, D, gp, bp)  # first: a state that is not finite is a StepMatrixError
        # the loop hands back the arrays this step returned: same objects, same state (as FSAL)
        # (a new held torque at this step's start: a fresh start, the acceleration carried is the old load's)
        carried = ws is not None and ws.a is not None and ws.q is q and ws.v is v and not system.new_sample
        a = ws.a if carried else cho_solve(cho_factor(M), f)  # a fresh start: a = q̈ (Cholesky, as the kernel)
        dv0 = dv_a * a
        dq0 = h * v + dq_a * a
        # the linearised solve, for y = γ' x̂ + (1 − α_f) dv0 (the form solve() takes; the D̃ dv0 terms
        # cancel): S y = (1 − α_f) M dv0 + γ' f − γ' K_g (1 − α_f)(dq0 − (β'/γ') dv0)
        _, y = system.solve((1.0 - af) * (dq0 - (bp / gp) * dv0), (1.0 - af) * (M @ dv0) + gp * f)
        xh = (y - (1.0 - af) * dv0) / gp
        q1, v1 = system.integrate(q, dq0 + (beta * h * c) * xh), v + dv0 + (gamma * c) * xh
        # one Newton correction: the residual M((1 − α_f) q̈(q⁺, v⁺) + α_f q̈ − x̂) with S as its Jacobian
        r = M @ ((1.0 - af) * system.acceleration(t + h, q1, v1) - xh) + af * f
        _, dx = system.solve(np.zeros_like(v), r)
        xh = xh + dx
        q1, v1 = system.integrate(q, dq0 + (beta * h * c) * xh), v + dv0 + (gamma * c) * xh
        if ws is not None:
            ws.a, ws.q, ws.v = (xh - am * a) / (1.0 - am), q1, v1
        return q1, v1

    def compiled_spec(self) -> GeneralizedAlphaSpec:
        return GeneralizedAlphaSpec(alpha=(self.alpha_m, self.alpha_f, self.gamma, self.beta))

    def spectral_radius(self, A: np.ndarray, h: float) -> float:
        n = A.shape[0] // 2
        T = alpha_amplification(A[n:, :n], A[n:, n:], h, self.rho_inf)
        return float(np.max(np.abs(np.linalg.eigvals(T))))

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        """The principal root of one step on the mode whose eigenvalues are z and z̄ (z = hλ):
        the mode ``q̈ = −|z|² q + 2 Re z q̇`` at h = 1 (for a real z, the critically damped
        double root). One step multiplies that mode by a 3 × 3 matrix on (q, q̇, a): its complex
        pair approximates (e^z, e^z̄), and the member on z's side is returned; its third, real
        root belongs to the algorithmic acceleration a (−α_m/(1 − α_m) at z = 0, −ρ∞ at z → ∞;
        :meth:`spectral_radius` counts it). When all three roots are real, the largest."""
        z = np.asarray(z, dtype=complex)
        Aq = (-(np.abs(z) ** 2)).reshape(*z.shape, 1, 1)
        Av = (2.0 * z.real).reshape(*z.shape, 1, 1)
        with np.errstate(all="ignore"):
            T = alpha_amplification(Aq, Av, 1.0, self.rho_inf)
            eig = np.linalg.eigvals(np.where(np.isfinite(T), T, 0.0))
        side = np.where(z.imag < 0, -1.0, 1.0)[..., None]
        on_side = np.where(side * eig.imag > 1e-12 * np.maximum(np.abs(eig), 1e-300), np.abs(eig), -1.0)
        pick = np.where(on_side.max(axis=-1) >= 0, on_side.argmax(axis=-1), np.abs(eig).argmax(axis=-1))
        root = np.take_along_axis(eig, pick[..., None], -1)[..., 0]
        return np.where(np.isfinite(z), root, np.nan)

    def __repr__(self) -> str:
        return f"GeneralizedAlpha(rho_inf={self.rho_inf:g})"
