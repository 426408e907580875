"""The exact derivative of one step of a method, with respect to its start, its held torques and
named physical parameters: what :class:`coopdyn.sensitivity.Sensitivity` chains along a
trajectory (see there for the state, the input and the parameters).

The derivative is that of the discrete map the method computes, not of the continuous flow: an
explicit Runge–Kutta step takes its stages in the chart around q (``q_i = q ⊕ δ_i``, the chart
rates ``δ̇_i = dexp⁻¹(δ_i) v_i``), and every stage is differentiated exactly —

* ``∂q̈/∂(q, v, τ)`` from the dynamics' exact derivatives (:meth:`coopdyn.Dynamics.derivatives`:
  Pinocchio's ABA derivatives, the elements' geometric stiffness);
* ``∂(q ⊕ δ)`` by Pinocchio's ``dIntegrate`` with respect to q and δ;
* ``∂(dexp⁻¹(δ) v)/∂δ`` on a free-flyer's or spherical joint's block by complex step of the
  closed-form ``Jlog6(exp6 δ)`` (:func:`coopdyn.model.elements.lie.dexp_inv_rate`): exact to
  round-off, no difference is taken;
* ``∂q̈/∂p`` = M⁻¹ ∂Q/∂p: a stiffness or damping entry enters the element's wrench linearly, so
  ∂Q/∂p is the generalized force of the same law with those entries alone at 1; the object's
  mass scales its whole inertia (uniform density), so ∂(M q̈ + h)/∂m is the object's columns of
  Pinocchio's joint-torque regressor times its inertial parameters / m.

The linearly implicit methods (implicit Euler, ROS2, the trapezoid, generalized-α) solve their
stages with the step matrix ``S = M + γ' D̃ + β' K̃`` of the step's start (γ' = γh, β' = (γh)² but
for generalized-α), K̃ and D̃ the Gauss–Newton matrices. A stage ``S k_v = M y − γ' K̃ f_q`` is
differentiated as it stands: ``S dk_v = M dy − γ' K̃ df_q − dG`` with ``G = M (k_v − y) + γ' D̃ k_v
+ K̃ (β' k_v + γ' f_q)`` — the matrices' own variation with the start and the parameters, exact
(:class:`coopdyn.dynamics.derivatives.MatrixDerivatives`: the elements'
:meth:`~coopdyn.model.elements.Element.matrix_tangent`, Pinocchio's frame-velocity and RNEA
derivatives) — one more solve with the step's own S per stage. Generalized-α's algorithmic
acceleration and its derivative are carried from step to step within a period. The kernel's twin
(``src/native/sensitivity.hpp``) computes the same for every method but the exponential one.

The exponential integrator (linear scenes) steps ``x⁺ = Φ x + Γ u + γ``, Φ, Γ, γ from the matrix
exponential of ``[[hF, hG, hc], 0]``: ∂x⁺/∂x = Φ, ∂x⁺/∂u = Γ, and a parameter's derivative is the
exponential's Fréchet derivative in the direction of that matrix's own derivative. Implicit Euler
with ``jacobian_every > 1`` (a W-method reusing an earlier step's matrices) is not differentiated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
import scipy.linalg
from scipy.linalg import cho_factor, cho_solve

from .closed_loop import System
from .dynamics import Dynamics
from .dynamics.derivatives import MatrixDerivatives, RelativeTwist, motion_cross
from .errors import SceneError, SimulationError
from .integrators import (
    ROS2,
    AdaptiveROS2,
    EmbeddedRungeKutta,
    ExplicitRungeKutta,
    Exponential,
    Integrator,
    LinearlyImplicitEuler,
    SymplecticEuler,
    Trapezoid,
    get_integrator,
)
from .integrators.explicit import combine
from .integrators.exponential import linear_form
from .integrators.implicit import GAMMA, GeneralizedAlpha, alpha_coefficients
from .model.elements.ball_spring import BallSpring
from .model.elements.lie import dexp_inv_rate
from .model.elements.se3_spring import SE3Spring
from .model.scene import Scene
from .parameters import KINDS, Parameter, grasp_pose

__all__ = ["Carry", "StepDerivative", "StepMethod", "step_method"]

LOCAL = pin.ReferenceFrame.LOCAL
#: what a step carries to the next: generalized-α's algorithmic acceleration and its derivative
Carry = tuple[np.ndarray, np.ndarray] | None
#: complex step [m, rad] of the chart-rate derivative (far below round-off: no truncation error)
_COMPLEX_STEP = 1e-30


class StepDerivative:
    """One scene's differentiated steps under one method: the dynamics, the parameters' unit laws
    and, for an implicit method, its matrices' derivatives, set up once.

    Args:
        scene: an elastic scene (no rigid grasps).
        integrator: a method :func:`step_method` accepts.
        params: the :class:`~coopdyn.parameters.Parameter` of each parameter column.
        backend: the dynamics' backend (:class:`coopdyn.Dynamics`).

    Attributes:
        exact: False once an element's tangent came from finite differences (cleared by the caller
            at a run's start).
    """

    def __init__(self, scene: Scene, integrator: Any, params: tuple[Parameter, ...], backend: str | None) -> None:
        self.method = step_method(integrator)
        self.scene, self.params = scene, params
        self.dynamics = Dynamics(scene, backend)
        self.model = scene.model
        self.data = pin.Data(self.model)
        nv = scene.nv
        self.charts: list[tuple[int, int]] = []
        for joint in self.model.joints[1:]:
            kind = joint.shortname().removeprefix("JointModel")
            if kind == "FreeFlyer":
                self.charts.append((joint.idx_v, 6))
            elif kind == "Spherical":
                self.charts.append((joint.idx_v, 3))
            elif joint.nq != joint.nv or joint.nv > 1:
                if kind not in ("RUBX", "RUBY", "RUBZ", "RevoluteUnboundedUnaligned"):
                    raise SceneError(
                        f"sensitivities: joint type {kind} ({self.model.names[joint.id]}) is not differentiated here; supported: "
                        "free-flyer, spherical, continuous and every joint whose configuration is its coordinates"
                    )
        self.nv = nv
        self.units = [self._unit_law(p) for p in params]
        #: a grasp position's direction: the right perturbation of G per metre, (R_OGᵀ e_axis, 0)
        self.offsets = {k: self._offset(p) for k, p in enumerate(params) if p.position}
        self.exact = True
        if any(p.kind == "mass" for p in params):
            j = scene.object_joint
            self.object_columns = slice(10 * (j - 1), 10 * j)
            self.object_pi = self.model.inertias[j].toDynamicParameters() / scene.object.mass_and_com()[0]
        self.matrices: MatrixDerivatives | None = None  # a linearly implicit step's: ∂(M, K̃, D̃)
        if self.method.implicit:
            links = self.dynamics.force_links
            self.matrices = MatrixDerivatives(self.model, links, [element.has_damping for *_, element in links])
        if self.method.exponential is not None:
            self._exponential_setup()

    def _offset(self, p: Parameter) -> np.ndarray:
        """A grasp position's direction in G's body twist: moving G by e along the object frame's
        axis is ``G·exp6((R_OGᵀ e, 0))`` (R_OG: G's orientation in the object frame)."""
        assert p.link is not None
        R = grasp_pose(self.scene, p.link).rotation
        return np.concatenate([R.T @ np.eye(3)[KINDS[p.kind][1][0]], np.zeros(3)])

    def _unit_law(self, p: Parameter) -> Any:
        """The law with only p's entries at 1 (its wrench is ∂G_f_G/∂p), or None for the mass and a
        grasp position."""
        if p.link is None or p.position:
            return None
        element = self.scene.links[p.link].element
        matrix, idx, _, _ = KINDS[p.kind]
        size = 6 if isinstance(element, SE3Spring) else 3
        unit, zero = np.zeros((size, size)), np.zeros((size, size))
        unit[idx, idx] = 1.0
        K, D = (unit, zero) if matrix == "stiffness" else (zero, unit)
        cls = SE3Spring if size == 6 else BallSpring
        return cls(K, D, p.name)

    # -- one stage ----------------------------------------------------------------------------
    def stage(self, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray]:
        """The derivatives at (q, v, u), ∂q̈/∂p (nv, n_p) and ∂W/∂p (L, 6, n_p)."""
        d = self.dynamics.derivatives(q, v, u)
        self.exact = self.exact and d.exact
        n_p = len(self.params)
        da_dp = np.zeros((self.nv, n_p))
        dW_dp = np.zeros((len(d.wrench), 6, n_p))
        if n_p:
            model, data = self.model, self.data
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            M = pin.crba(model, data, q)
            M = np.triu(M) + np.triu(M, 1).T
            dQ = np.zeros((self.nv, n_p))
            mass = [p.kind == "mass" for p in self.params]
            for k, (p, law) in enumerate(zip(self.params, self.units, strict=True)):
                if p.link is None:
                    continue
                link = self.scene.links[p.link]
                X = data.oMf[link.tip_frame].actInv(data.oMf[link.grasp_frame])
                J_G = pin.getFrameJacobian(model, data, link.grasp_frame, LOCAL).reshape(6, self.nv)
                J_T = pin.getFrameJacobian(model, data, link.tip_frame, LOCAL).reshape(6, self.nv)
                Jr = J_G - X.toActionMatrixInverse() @ J_T
                if k in self.offsets:
                    dQ[:, k], dW_dp[p.link, :, k] = self._offset_force(link.element, X, Jr, v, self.offsets[k])
                    continue
                f = law.evaluate(X, Jr @ v).G_f_G  # (the law with p's entries alone at 1: ∂G_f_G/∂p)
                dQ[:, k] = Jr.T @ f
                dW_dp[p.link, :, k] = f
            if any(mass):  # the object's mass: −∂(M q̈ + h)/∂m at q̈
                Y = pin.computeJointTorqueRegressor(model, data, q, v, d.acceleration)
                dQ[:, mass] = -(Y[:, self.object_columns] @ self.object_pi)[:, None]
            da_dp = cho_solve(cho_factor(M), dQ)
        return d, da_dp, dW_dp

    def _offset_force(
        self, element: Any, X: pin.SE3, Jr: np.ndarray, v: np.ndarray, delta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(∂Q/∂p, ∂G_f_G/∂p)`` of a grasp position: G moved as ``G·exp6(δ p)`` turns X into
        ``X·exp6(δ p)``, its relative Jacobian into ``Ad(exp6(−δ p)) Jr`` and so the twist ξ by
        ``−ad(δ) ξ`` per unit: ``∂f = F_d δ − F_x ad(δ) ξ`` (the element's tangent) and
        ``∂Q = Jrᵀ ∂f − (ad(δ) Jr)ᵀ f``."""
        xi = Jr @ v
        f = element.evaluate(X, xi).G_f_G
        F_d, F_x = element.tangent(X, xi)
        self.exact = self.exact and bool(element.exact_tangent)
        ad = motion_cross(delta)
        df = F_d @ delta - F_x @ (ad @ xi)
        return Jr.T @ df - (ad @ Jr).T @ f, df

    def chart(self, delta: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(δ̇ = dexp⁻¹(δ) v, its ∂/∂v, its ∂/∂δ) with exact derivatives (complex step)."""
        rate, C, N = v.copy(), np.eye(self.nv), np.zeros((self.nv, self.nv))
        for i0, n in self.charts:
            s = slice(i0, i0 + n)
            rate[s], C[s, s], N[s, s] = dexp_inv_rate(delta[s], v[s], _COMPLEX_STEP)
        return rate, C, N

    # -- one step -----------------------------------------------------------------------------
    def step(
        self,
        q: np.ndarray,
        v: np.ndarray,
        u: np.ndarray,
        h: float,
        seeds: tuple[np.ndarray, ...],
        carry: Carry = None,
        sampled: bool = True,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, np.ndarray, Carry]:
        """One step from (q, v) under u, with the derivatives of (δq⁺, v⁺) along the seed columns
        ``(dq, dv, du, dp)`` (each (n, m)); also the start's derivatives and ∂W/∂p there, and what
        the method carries to the next step (generalized-α's acceleration; None: a fresh start).
        ``sampled``: whether the start's derivatives are wanted (the exponential method, whose step
        needs none, skips them otherwise: they are most of its cost; the others have them anyway)."""
        dq0, dv0, du, dp = seeds
        if self.method.alpha is not None:
            return self._alpha_step(q, v, u, h, seeds, carry)
        if self.method.gamma is not None:
            return (*self._implicit_step(q, v, u, h, seeds), None)
        if self.method.exponential is not None:
            return (*self._exponential_step(q, v, u, h, seeds, sampled), None)
        if self.method.tableau is None:  # symplectic Euler: v⁺ = v + h a(q, v), q⁺ = q ⊕ h v⁺
            d, da_dp, dW_dp = self.stage(q, v, u)
            v1 = v + h * d.acceleration
            dv1 = dv0 + h * acceleration_derivative(d, da_dp, dq0, dv0, du, dp)
            q1, dq1 = self.integrate(q, h * v1, dq0, h * dv1)
            return q1, v1, dq1, dv1, d, dW_dp, None
        A, b = self.method.tableau
        kd: list[np.ndarray] = []
        ka: list[np.ndarray] = []
        dkd: list[np.ndarray] = []
        dka: list[np.ndarray] = []
        start: tuple[Any, np.ndarray] | None = None
        for i, row in enumerate(A):
            if i == 0:
                q_i, v_i, dq_i, dv_i = q, v, dq0, dv0
                kd.append(v)
                dkd.append(dv0)
            else:
                delta = h * combine(row, kd)
                ddelta = h * combine(row, dkd)
                v_i = v + h * combine(row, ka)
                dv_i = dv0 + h * combine(row, dka)
                q_i, dq_i = self.integrate(q, delta, dq0, ddelta)
                rate, C, N = self.chart(delta, v_i)
                kd.append(rate)
                dkd.append(C @ dv_i + N @ ddelta)
            d, da_dp, dW_dp = self.stage(q_i, v_i, u)
            if i == 0:
                start = (d, dW_dp)
            ka.append(d.acceleration)
            dka.append(acceleration_derivative(d, da_dp, dq_i, dv_i, du, dp))
        Delta = h * combine(b, kd)
        dDelta = h * combine(b, dkd)
        v1 = v + h * combine(b, ka)
        dv1 = dv0 + h * combine(b, dka)
        q1, dq1 = self.integrate(q, Delta, dq0, dDelta)
        assert start is not None
        return q1, v1, dq1, dv1, start[0], start[1], None

    def _exponential_setup(self) -> None:
        """The exponential integrator's system (the torque held in ``self._held``), its linear form
        ``ẋ = F x + G u + c`` and the form's derivatives along each parameter: the acceleration is
        affine in (q, v, u) for every parameter value, so ∂q̈/∂p is too, and its differences at unit
        states (from :meth:`stage`, exact) are its coefficients."""
        self._held = np.zeros(self.scene.n_actuated)
        self.system = System(self.dynamics, lambda t, q, v: self._held)
        try:
            self.form = linear_form(self.system)
        except SimulationError as exc:  # (a scene that is not linear)
            raise SimulationError(
                f"sensitivities: {exc}; a non-linear scene's stiff grasps: 'trapezoid' or 'implicit_euler'"
            ) from exc
        self._workspace = self.method.exponential.workspace(self.system)  # type: ignore[union-attr]
        self._steps: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        nv, na, n_p = self.nv, self.scene.n_actuated, len(self.params)
        q0, zero_v, zero_u = self.system.q0, np.zeros(nv), np.zeros(na)

        def da_dp(q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
            return self.stage(q, v, u)[1]

        base = da_dp(q0, zero_v, zero_u)
        dA_q = np.stack([da_dp(q0 + e, zero_v, zero_u) - base for e in np.eye(nv)], axis=1)  # (nv, nv, n_p)
        dA_v = np.stack([da_dp(q0, e, zero_u) - base for e in np.eye(nv)], axis=1)
        dB = np.stack([da_dp(q0, zero_v, e) - base for e in np.eye(na)], axis=1) if na else np.zeros((nv, 0, n_p))
        self._form_derivatives = []  # (dF, dG, dc) per parameter
        for k in range(n_p):
            dF = np.zeros((2 * nv, 2 * nv))
            dF[nv:, :nv], dF[nv:, nv:] = dA_q[..., k], dA_v[..., k]
            dG = np.vstack([np.zeros((nv, na)), dB[..., k]])
            dc = np.concatenate([np.zeros(nv), base[:, k] - dA_q[..., k] @ q0])
            self._form_derivatives.append((dF, dG, dc))

    def _exponential_step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, h: float, seeds: tuple[np.ndarray, ...], sampled: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, Any]:
        """The exponential integrator's step (the integrator's own, the torque held at u) and its
        derivative: ``x⁺ = Φ x + Γ u + γ`` with Φ, Γ, γ from ``expm`` of ``E = [[hF, hG, hc], 0]``,
        so ∂x⁺/∂x = Φ, ∂x⁺/∂u = Γ, and along a parameter the Fréchet derivative of ``expm`` at E
        in the direction of E's own derivative (:func:`scipy.linalg.expm_frechet`)."""
        dq, dv, du, dp = seeds
        method = self.method.exponential
        assert method is not None
        nv, na, nx = self.nv, self.scene.n_actuated, 2 * self.nv
        if h not in self._steps:
            step, _, inner, _ = method.discretisation(self.system, h, self._workspace)
            Phi, Gamma = step[:, :nx], step[:, nx : nx + na].copy()
            if inner is not None and na:  # (the inner nodes' torques: the same held u)
                Gamma += inner.reshape(nx, -1, na).sum(axis=1)
            F, G, c = self.form
            E = np.zeros((nx + na + 1, nx + na + 1))
            E[:nx, :nx], E[:nx, nx : nx + na], E[:nx, -1] = h * F, h * G, h * c
            rows = []
            for dF, dG, dc in self._form_derivatives:
                dE = np.zeros_like(E)
                dE[:nx, :nx], dE[:nx, nx : nx + na], dE[:nx, -1] = h * dF, h * dG, h * dc
                rows.append(scipy.linalg.expm_frechet(E, dE, compute_expm=False)[:nx])
            self._steps[h] = (Phi, Gamma, np.array(rows).reshape(len(rows), nx, nx + na + 1))
        Phi, Gamma, frechet = self._steps[h]
        self._held = np.asarray(u, dtype=float)
        q1, v1 = method.step(self.system, 0.0, q, v, h, self._workspace)
        d, _, dW_dp = self.stage(q, v, u) if sampled else (None, None, None)
        z = np.concatenate([q, v, u, [1.0]])
        dx = Phi @ np.vstack([dq, dv]) + Gamma @ du + np.einsum("pij,j->ip", frechet, z) @ dp
        return q1, v1, dx[:nv], dx[nv:], d, dW_dp

    def _implicit_step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, h: float, seeds: tuple[np.ndarray, ...]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, np.ndarray]:
        """A linearly implicit step (:mod:`coopdyn.integrators.implicit`) and its derivative along
        the seed columns, as :meth:`step`. Implicit Euler is the first stage at γ = 1
        (``δ = h k_q``, ``v⁺ = v + h k_v``); the two-stage scheme (ROS2, the trapezoid) adds
        ``(I − γhJ) k₂ = f(q ⊕ hk_q1, v + hk_v1) − 2k₁`` with the same matrices, and
        ``δ = h(3k₁ + k₂)/2``."""
        dq0, dv0, du, dp = seeds
        assert self.method.gamma is not None
        dyn, gh, stages = self.dynamics, self.method.gamma * h, self.method.stages
        d, da_dp, dW_dp = self.stage(q, v, u)
        f, M, K, D = dyn.implicit_terms(q, v, u)
        gains = np.zeros(self.scene.n_actuated)
        dyn.factor(M, K, D, gh, gains, gains)
        start = (q, v, cho_factor(M + gh * D + gh * gh * K), M, K)
        kq1, kv1 = dyn.solve(v, f)
        da1 = acceleration_derivative(d, da_dp, dq0, dv0, du, dp)
        dkv1 = self._solve_derivative(start, (gh, gh * gh), v, kv1, d.acceleration, da1, dv0, seeds)
        dkq1 = dv0 + gh * dkv1
        if stages == 1:
            q1, dq1 = self.integrate(q, h * kq1, dq0, h * dkq1)
            return q1, v + h * kv1, dq1, dv0 + h * dkv1, d, dW_dp
        d2, v2, dd2, dv2 = h * kq1, v + h * kv1, h * dkq1, dv0 + h * dkv1
        q2, dq2 = self.integrate(q, d2, dq0, dd2)
        e, da_dp2, _ = self.stage(q2, v2, u)
        rate, C, N = self.chart(d2, v2)
        y2, dy2 = e.acceleration - 2.0 * kv1, acceleration_derivative(e, da_dp2, dq2, dv2, du, dp) - 2.0 * dkv1
        fq2, dfq2 = rate - 2.0 * kq1, C @ dv2 + N @ dd2 - 2.0 * dkq1
        kq2, kv2 = dyn.solve(fq2, M @ y2)
        dkv2 = self._solve_derivative(start, (gh, gh * gh), fq2, kv2, y2, dy2, dfq2, seeds)
        dkq2 = dfq2 + gh * dkv2
        q1, dq1 = self.integrate(q, h * (1.5 * kq1 + 0.5 * kq2), dq0, h * (1.5 * dkq1 + 0.5 * dkq2))
        return q1, v + h * (1.5 * kv1 + 0.5 * kv2), dq1, dv0 + h * (1.5 * dkv1 + 0.5 * dkv2), d, dW_dp

    def _alpha_step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, h: float, seeds: tuple[np.ndarray, ...], carry: Carry
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, np.ndarray, Carry]:
        """A generalized-α step (:class:`coopdyn.integrators.GeneralizedAlpha`: one linearised solve
        for x̂ = (1 − α_m)a⁺ + α_m a, one Newton correction with the same S) and its derivative, as
        :meth:`step`; ``carry`` is the algorithmic acceleration a and its derivative from the step
        before (None: a fresh start, a = q̈), and the step returns its own."""
        dq, dv, du, dp = seeds
        assert self.method.alpha is not None
        am, af, gamma, beta = self.method.alpha
        c, dq_a, dv_a = alpha_coefficients(am, gamma, beta, h)
        gp, bp = (1.0 - af) * gamma * c, (1.0 - af) * beta * h * c
        dyn = self.dynamics
        d, da_dp, dW_dp = self.stage(q, v, u)
        f, M, K, D = dyn.implicit_terms(q, v, u)
        gains = np.zeros(self.scene.n_actuated)
        dyn.factor(M, K, D, gp, gains, gains, bp)
        start = (q, v, cho_factor(M + gp * D + bp * K), M, K)
        a_true = cho_solve(cho_factor(M), f)  # q̈ at the start (f = M q̈), as the integrator's fresh start takes it
        da_true = acceleration_derivative(d, da_dp, dq, dv, du, dp)
        a, da = carry if carry is not None else (a_true, da_true)
        A0, dA0 = dv_a * a, dv_a * da  # v⁺ = v + A0 + γc x̂
        B0, dB0 = h * v + dq_a * a, h * dv + dq_a * da  # q⁺ = q ⊕ (B0 + βhc x̂)
        f_q, df_q = (1.0 - af) * (B0 - (bp / gp) * A0), (1.0 - af) * (dB0 - (bp / gp) * dA0)
        _, y = dyn.solve(f_q, (1.0 - af) * (M @ A0) + gp * f)
        y_v, dy_v = (1.0 - af) * A0 + gp * a_true, (1.0 - af) * dA0 + gp * da_true  # (M y_v: the solve's right-hand side)
        dy = self._solve_derivative(start, (gp, bp), f_q, y, y_v, dy_v, df_q, seeds)
        xh, dxh = (y - (1.0 - af) * A0) / gp, (dy - (1.0 - af) * dA0) / gp
        q1, dq1 = self.integrate(q, B0 + (beta * h * c) * xh, dq, dB0 + (beta * h * c) * dxh)
        v1, dv1 = v + A0 + (gamma * c) * xh, dv + dA0 + (gamma * c) * dxh
        e, da_dp1, _ = self.stage(q1, v1, u)  # the Newton correction: S dx = M((1 − α_f) q̈(q⁺, v⁺) − x̂) + α_f f
        a1, da1 = e.acceleration, acceleration_derivative(e, da_dp1, dq1, dv1, du, dp)
        _, dx = dyn.solve(np.zeros_like(v), M @ ((1.0 - af) * a1 - xh) + af * f)
        y2, dy2 = (1.0 - af) * a1 - xh + af * a_true, (1.0 - af) * da1 - dxh + af * da_true
        zero = np.zeros_like(dq)
        ddx = self._solve_derivative(start, (gp, bp), np.zeros_like(v), dx, y2, dy2, zero, seeds)
        xh, dxh = xh + dx, dxh + ddx
        q1, dq1 = self.integrate(q, B0 + (beta * h * c) * xh, dq, dB0 + (beta * h * c) * dxh)
        v1, dv1 = v + A0 + (gamma * c) * xh, dv + dA0 + (gamma * c) * dxh
        return q1, v1, dq1, dv1, d, dW_dp, ((xh - am * a) / (1.0 - am), (dxh - am * da) / (1.0 - am))

    def _solve_derivative(
        self,
        start: tuple[np.ndarray, np.ndarray, Any, np.ndarray, np.ndarray],
        coefficients: tuple[float, float],
        f_q: np.ndarray,
        k_v: np.ndarray,
        y: np.ndarray,
        dy: np.ndarray,
        df_q: np.ndarray,
        seeds: tuple[np.ndarray, ...],
    ) -> np.ndarray:
        """dk_v along the seed columns for a stage solve ``S k_v = M y − γ' K̃ f_q`` with M, K̃, D̃
        and ``S = M + γ' D̃ + β' K̃`` at the step's start ``start = (q, v, cho_factor(S), M, K̃)``
        (``coefficients = (γ', β')``; γh and (γh)² but for generalized-α), given dy and df_q:
        ``S dk_v = M dy − γ' K̃ df_q − dG`` with ``G = M (k_v − y) + γ' D̃ k_v + K̃ (β' k_v + γ' f_q)``
        — the matrices' own variation with the start
        (:class:`~coopdyn.dynamics.derivatives.MatrixDerivatives`) and with the parameters."""
        q, v, S, M, K = start
        gp, bp = coefficients
        dq0, dv0, _, dp = seeds
        assert self.matrices is not None
        w_M, w_D, w_K = k_v - y, gp * k_v, bp * k_v + gp * f_q
        dG_dq, dG_dv, twists = self.matrices(q, v, w_M, w_D, w_K)
        self.exact = self.exact and self.matrices.exact
        dG = dG_dq @ dq0 + dG_dv @ dv0
        if len(self.params):
            dG = dG + self._matrix_parameters(q, w_M, *twists) @ dp
        return np.asarray(cho_solve(S, M @ dy - gp * (K @ df_q) - dG))

    def _matrix_parameters(
        self, q: np.ndarray, w_M: np.ndarray, at_v: list[RelativeTwist], at_D: list[RelativeTwist], at_K: list[RelativeTwist]
    ) -> np.ndarray:
        """∂G/∂p (nv, n_p) for :meth:`_solve_derivative`'s G: a stiffness or damping entry's is the
        unit law's ``Jrᵀ (S_K ξ_K + S_D ξ_D)`` (K̃ and D̃ are linear in them; ξ_K = Jr w_K, ξ_D =
        Jr w_D); the object's mass scales its inertia, so ∂(M w_M)/∂m is the object's columns of
        the joint-torque regressor at (q, 0, w_M) without gravity times its inertial parameters / m; a
        grasp position moves X by ``exp6(δ)``, ξ by ``−ad(δ) ξ`` and Jr by ``−ad(δ) Jr`` per unit, so
        ``g = S_K ξ_K + S_D ξ_D`` by ``G_d δ − G_x ad(δ) ξ − S_K ad(δ) ξ_K − S_D ad(δ) ξ_D`` (the law's
        matrix_tangent) and ``Jrᵀ g`` by ``Jrᵀ ∂g − (ad(δ) Jr)ᵀ g``."""
        assert self.matrices is not None
        out = np.zeros((self.nv, len(self.params)))
        for k, (p, law) in enumerate(zip(self.params, self.units, strict=True)):
            if p.link is None:  # the object's mass
                matrices = self.matrices
                Y = pin.computeJointTorqueRegressor(matrices.free, matrices.free_data, q, np.zeros(self.nv), w_M)
                out[:, k] = Y[:, self.object_columns] @ self.object_pi
                continue
            i = [link[0] for link in self.matrices.links].index(p.link)
            if k in self.offsets:
                out[:, k] = self._offset_matrices(i, at_v[i], at_D[i].xi, at_K[i].xi, self.offsets[k])
                continue
            ev = law.evaluate(at_K[i].X, np.zeros(6), True)
            out[:, k] = at_K[i].Jr.T @ (ev.S_K @ at_K[i].xi + ev.S_D @ at_D[i].xi)
        return out

    def _offset_matrices(self, i: int, at_v: RelativeTwist, xi_D: np.ndarray, xi_K: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """∂(Jrᵀ (S_K ξ_K + S_D ξ_D))/∂p of link i's grasp position (see :meth:`_matrix_parameters`)."""
        assert self.matrices is not None
        element, damped = self.matrices.links[i][3], self.matrices.damped[i]
        xi_D = xi_D if damped else np.zeros(6)
        ev = element.evaluate(at_v.X, at_v.xi, True)
        S_K, S_D = np.asarray(ev.S_K), np.asarray(ev.S_D)
        G_d, G_x = element.matrix_tangent(at_v.X, at_v.xi, xi_K, xi_D)
        ad = motion_cross(delta)
        g = S_K @ xi_K + S_D @ xi_D
        dg = G_d @ delta - G_x @ (ad @ at_v.xi) - S_K @ (ad @ xi_K) - S_D @ (ad @ xi_D)
        return np.asarray(at_v.Jr.T @ dg - (ad @ at_v.Jr).T @ g)

    def integrate(self, q: np.ndarray, delta: np.ndarray, dq: np.ndarray, ddelta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """q ⊕ δ and its tangent derivative, from q's (dq) and δ's (ddelta)."""
        out = pin.integrate(self.model, q, delta)
        J0 = pin.dIntegrate(self.model, q, delta, pin.ArgumentPosition.ARG0)
        J1 = pin.dIntegrate(self.model, q, delta, pin.ArgumentPosition.ARG1)
        return out, J0 @ dq + J1 @ ddelta


def _method_name(method: Integrator) -> str:
    return f"{method.name!r}" if isinstance(getattr(method, "name", None), str) else type(method).__name__


@dataclass(frozen=True)
class StepMethod:
    """What :class:`Sensitivity` differentiates of a method (:func:`step_method`).

    Attributes:
        tableau: ``(A, b)`` of an explicit Runge–Kutta method, else None.
        gamma: a linearly implicit method's γ (its step matrix ``M + γh D̃ + (γh)² K̃``), else None;
            neither: symplectic Euler.
        stages: a linearly implicit method's stages: 1 (implicit Euler) or 2 (ROS2, the trapezoid).
        alpha: generalized-α's (α_m, α_f, γ, β), else None.
        exponential: the exponential integrator (linear scenes), else None.
    """

    tableau: tuple[Any, ...] | None
    gamma: float | None = None
    stages: int = 0
    alpha: tuple[float, float, float, float] | None = None
    exponential: Exponential | None = None

    @property
    def implicit(self) -> bool:
        """Whether its stages solve with the Gauss–Newton step matrix."""
        return self.gamma is not None or self.alpha is not None

    @property
    def explicit(self) -> bool:
        """Whether it is an explicit Runge–Kutta method or symplectic Euler (the kernel's twin's)."""
        return not self.implicit and self.exponential is None


def step_method(integrator: Any) -> StepMethod:
    """The differentiated form of a method: an explicit Runge–Kutta method (rk4, dopri5's or dop853's
    step, a user's tableau), symplectic Euler, implicit Euler, ROS2, the trapezoid, generalized-α or the
    exponential integrator.

    Raises:
        SimulationError: any other method, with the reason.
    """
    method = get_integrator(integrator)
    tableau_family = next((base for base in (ExplicitRungeKutta, EmbeddedRungeKutta) if isinstance(method, base)), None)
    if tableau_family is not None and _keeps_step(method, tableau_family):
        A, b = method.tableau.A, method.tableau.b  # type: ignore[attr-defined]
        while len(b) > 1 and b[-1] == 0.0:  # a last stage of no weight (a pair's first-same-as-last one) feeds no
            A, b = A[:-1], b[:-1]  # later stage: its derivative would be wasted
        return StepMethod((A, b))
    if type(method) is SymplecticEuler:
        return StepMethod(None)
    if type(method) is LinearlyImplicitEuler and method.jacobian_every == 1:
        return StepMethod(None, 1.0, 1)
    if type(method) is ROS2:
        return StepMethod(None, GAMMA, 2)
    if type(method) is Trapezoid:
        return StepMethod(None, method.gamma, 2)
    if type(method) is GeneralizedAlpha:
        return StepMethod(None, alpha=(method.alpha_m, method.alpha_f, method.gamma, method.beta))
    if type(method) is Exponential:
        return StepMethod(None, exponential=method)
    name = _method_name(method)
    if type(method) is LinearlyImplicitEuler:
        why = (
            f"with jacobian_every = {method.jacobian_every} a step reuses an earlier step's matrices, so it is not a function "
            "of its own start; use jacobian_every=1"
        )
        name = repr(method)
    elif type(method) is AdaptiveROS2:
        why = "it adapts its step in a run; 'ros2' is the same step at a fixed h"
    elif isinstance(
        method,
        ExplicitRungeKutta
        | EmbeddedRungeKutta
        | LinearlyImplicitEuler
        | ROS2
        | Trapezoid
        | GeneralizedAlpha
        | SymplecticEuler
        | Exponential,
    ):
        why = f"it is a subclass of a built-in method ({type(method).__name__}) whose step may differ from the one differentiated"
    else:
        why = "only the explicit Runge–Kutta methods, symplectic Euler and the linearly implicit methods are"
    raise SimulationError(
        f"sensitivities: {name} is not differentiated: {why}; use 'rk4', 'dopri5', 'dop853', 'symplectic_euler', "
        "'implicit_euler', 'ros2', 'trapezoid', 'generalized_alpha', 'exponential' (linear scenes) or an explicit "
        "tableau (ExplicitRungeKutta)"
    )


def _keeps_step(method: Any, base: type) -> bool:
    """Whether ``method``'s class steps as ``base`` does (a subclass that only sets a tableau) —
    not one that overrides the step or an adaptive attempt, which its tableau would not describe."""
    return all(getattr(type(method), name, None) is getattr(base, name, None) for name in ("step", "attempt"))


def acceleration_derivative(
    d: Any, da_dp: np.ndarray, dq: np.ndarray, dv: np.ndarray, du: np.ndarray, dp: np.ndarray
) -> np.ndarray:
    """dq̈ along the seed columns: ∂q̈/∂q dq + ∂q̈/∂v dv + ∂q̈/∂τ du + ∂q̈/∂p dp (the kernel's twin:
    Sensitivity::acceleration_derivative)."""
    return np.asarray(d.da_dq @ dq + d.da_dv @ dv + d.da_dtau @ du + da_dp @ dp)
