"""Exact sensitivities of a step and of a whole trajectory, open loop or closed under a sampled
controller: ∂x⁺/∂(x, u, p).

The state is ``x = (δq, v)`` as in :func:`coopdyn.linearize` (δq Pinocchio's tangent coordinates:
``q ⊕ δq = pin.integrate(model, q, δq)``; after a step, about the new configuration); the input
``u`` is the actuated joints' torque, held over the step [N·m or N]; ``p`` are named physical
parameters of the scene (:func:`coopdyn.parameters.parameters`).

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
acceleration and its derivative are carried from step to step within a period. These run in
Python on either backend (the dynamics' derivatives are the backend's); the exponential method
and implicit Euler with ``jacobian_every > 1`` are not differentiated.

``tests/test_sensitivity.py`` checks every sensitivity against central finite differences of
the step and of the compiled loop's rollout.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.linalg import cho_factor, cho_solve

from . import _validate
from .closed_loop import Controller, System
from .compiled import controller_settings
from .dynamics import Dynamics
from .dynamics.backend import kernel_module
from .dynamics.derivatives import MatrixDerivatives, RelativeTwist
from .errors import KernelError, SceneError, SimulationError, StepMatrixError
from .integrators import (
    ROS2,
    AdaptiveROS2,
    DormandPrince,
    ExplicitRungeKutta,
    Exponential,
    Integrator,
    LinearlyImplicitEuler,
    SymplecticEuler,
    Trapezoid,
    get_integrator,
)
from .integrators.explicit import combine
from .integrators.implicit import GAMMA, GeneralizedAlpha, alpha_coefficients
from .linearize import controller_gain
from .model.elements import lookup
from .model.elements.ball_spring import BallSpring
from .model.elements.lie import dexp_inv_rate
from .model.elements.se3_spring import SE3Spring
from .model.scene import Scene
from .parameters import KINDS, Parameter
from .parameters import parameters as scene_parameters

__all__ = ["Sensitivity", "StepSensitivity", "TrajectorySensitivity", "Transitions", "step_sensitivity", "trajectory_sensitivity"]

LOCAL = pin.ReferenceFrame.LOCAL
#: what a step carries to the next: generalized-α's algorithmic acceleration and its derivative
Carry = tuple[np.ndarray, np.ndarray] | None
#: a speed [rad/s or m/s] above which a differentiated run counts as diverged (coopdyn.rollout's default)
MAX_SPEED = 1e4
#: complex step [m, rad] of the chart-rate derivative (far below round-off: no truncation error)
_COMPLEX_STEP = 1e-30


@dataclass(frozen=True)
class StepSensitivity:
    """One open-loop step and its exact derivatives (see the module docstring for the state).

    Attributes:
        q, v: the state after the step, (nq,) and (nv,).
        dx_dx: ∂x⁺/∂x (2nv, 2nv): rows (δq⁺ about the new q, v⁺), columns (δq about the start, v).
        dx_du: ∂x⁺/∂u (2nv, n_actuated), per N·m or N of each actuated joint's torque.
        dx_dp: ∂x⁺/∂p (2nv, n_parameters), one column per entry of ``parameters``, per its unit.
        parameters: the :class:`~coopdyn.parameters.Parameter` of each column of dx_dp.
        exact: False when an element's tangent came from finite differences (a user's law).
    """

    q: np.ndarray  #: the configuration after the step (nq,)
    v: np.ndarray  #: the velocities after the step (nv,) [m/s, rad/s]
    dx_dx: np.ndarray  #: ∂x⁺/∂x (2nv, 2nv), x⁺'s δq about the new q, x's about the start
    dx_du: np.ndarray  #: ∂x⁺/∂u (2nv, n_actuated) [per N·m or N]
    dx_dp: np.ndarray  #: ∂x⁺/∂p (2nv, n_parameters) [per the parameter's unit]
    parameters: tuple[Parameter, ...]  #: the parameters of dx_dp's columns
    exact: bool  #: False when an element's tangent is finite differences (a user's law)


@dataclass(frozen=True)
class TrajectorySensitivity:
    """A trajectory sampled at every period and the derivatives of its samples.

    Attributes:
        t: (N + 1,) the sample times [s]; q (N + 1, nq), v (N + 1, nv): the states there.
        wrench: (N + 1, L, 6) each element's wrench on its grasp frame G, G's axes [N, N·m].
        tau: (N, n_actuated) the torques applied over each period [N·m or N].
        dx_dp: (N + 1, 2nv, n_parameters) ∂x_k/∂p (δq about q_k); dwrench_dp (N + 1, L, 6, n_parameters).
        dx_dx0: (N + 1, 2nv, 2nv) ∂x_k/∂x₀ with ``initial_state=True``, else None.
        parameters: the :class:`~coopdyn.parameters.Parameter` of each column; exact: False when a controller's
            derivative or an element's tangent came from finite differences.
    """

    t: np.ndarray  #: (N + 1,) [s]
    q: np.ndarray  #: (N + 1, nq)
    v: np.ndarray  #: (N + 1, nv) [m/s, rad/s]
    wrench: np.ndarray  #: (N + 1, L, 6) each interconnection's wrench on G at G, G axes [N, N·m]
    tau: np.ndarray  #: (N, n_actuated) the torques applied over each period [N·m or N]
    dx_dp: np.ndarray  #: (N + 1, 2nv, n_parameters): ∂x_k/∂p, δq about q_k
    dwrench_dp: np.ndarray  #: (N + 1, L, 6, n_parameters)
    dx_dx0: np.ndarray | None  #: (N + 1, 2nv, 2nv): ∂x_k/∂x₀, when asked for
    parameters: tuple[Parameter, ...]
    exact: bool


@dataclass(frozen=True)
class Transitions:
    """A trajectory and its linearisation period by period (:meth:`Sensitivity.transitions`).

    Attributes:
        t: (N + 1,) [s]; q (N + 1, nq), v (N + 1, nv): the states at every period's start and the end.
        A: (N, 2nv, 2nv) ∂x_{k+1}/∂x_k (δq about q_k, then about q_{k+1}).
        B: (N, 2nv, n_actuated) ∂x_{k+1}/∂u_k, per N·m or N of the torque held over period k.
        P: (N, 2nv, n_parameters) ∂x_{k+1}/∂p at a fixed x_k.
        parameters: the :class:`~coopdyn.parameters.Parameter` of P's columns; exact: as
            :class:`StepSensitivity`.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    A: np.ndarray
    B: np.ndarray
    P: np.ndarray
    parameters: tuple[Parameter, ...]
    exact: bool


class Sensitivity:
    """A scene's differentiated steps — open loop, or closed under a sampled controller — set up
    once (the dynamics, the kernel's twin, the parameters' unit laws) for many calls: an MPC's
    knots, an identification's iterations.

    Args:
        scene: an elastic scene (rigid grasps are refused).
        integrator: ``"rk4"`` (default), ``"symplectic_euler"``, ``"dopri5"`` (a step of its
            fifth-order solution at the h given — a fixed step: rollout and simulate adapt
            theirs), an explicit :class:`~coopdyn.integrators.ExplicitRungeKutta`, or for stiff
            grasps a linearly implicit method: ``"implicit_euler"``, ``"ros2"``, ``"trapezoid"``,
            ``"generalized_alpha"`` (any ρ∞) — stable at steps where the explicit ones diverge;
            their derivative runs in Python (no compiled twin yet).
        parameters: names as :func:`coopdyn.parameters.parameters` takes them (e.g. ``["left.k_linear"]``).
        backend: the dynamics' backend, as for :class:`coopdyn.Dynamics`: ``"native"`` runs the
            whole recursion in the compiled kernel, ``"python"`` the reference; they agree to
            round-off.
        controller: a closed loop's controller ``controller(t, q, v) -> τ``, sampled at every
            period's start and held over it (a digital controller; :meth:`trajectory` only). A
            built-in one built for a twin of the scene (the nominal one: same arms and frames,
            other interconnection or object parameters; :func:`coopdyn.compiled.twin_scenes`)
            runs compiled and keeps its own model of the object, as on a real robot. Its
            derivative along the sensitivities' columns comes from central differences (2 calls
            per column and period; 4·nv when there are 2·nv columns or more), so the result's
            ``exact`` is then False.
    """

    def __init__(
        self,
        scene: Scene,
        integrator: Any = "rk4",
        parameters: Sequence[str] = (),
        backend: str | None = None,
        controller: Controller | None = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise SceneError(f"sensitivities: scene must be a coopdyn.Scene, got {type(scene).__name__}")
        if controller is not None and not callable(controller):
            raise SceneError(
                f"sensitivities: controller must be a callable controller(t, q, v) -> tau, got {type(controller).__name__}"
            )
        none = isinstance(parameters, list | tuple) and len(parameters) == 0
        params = () if none else scene_parameters(scene, parameters)  # (which refuses a bad one)
        if scene.constraints:
            raise SceneError(
                "sensitivities: the scene has rigid grasps (constraints); differentiate the elastic scene they stand for"
            )
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
        self.exact = True
        if any(p.kind == "mass" for p in params):
            j = scene.object_joint
            self.object_columns = slice(10 * (j - 1), 10 * j)
            self.object_pi = self.model.inertias[j].toDynamicParameters() / scene.object.mass_and_com()[0]
        self.native = None  # the kernel's twin (src/native/sensitivity.hpp), on the native backend
        self.matrices: MatrixDerivatives | None = None  # a linearly implicit step's: ∂(M, K̃, D̃)
        if self.method.implicit:
            links = self.dynamics.force_links
            self.matrices = MatrixDerivatives(self.model, links, [element.has_damping for *_, element in links])
        kernel = getattr(self.dynamics, "_kernel", None)
        if kernel is not None and not self.method.implicit:
            A, b = self.method.tableau if self.method.tableau is not None else ((), ())
            specs = [
                ("mass", scene.object_joint, float(scene.object.mass_and_com()[0]))
                if law is None
                else ("element", p.link, lookup(type(law)).native, law.native_parameters())
                for p, law in zip(params, self.units, strict=True)
            ]
            rows = [list(map(float, row)) for row in A]
            symplectic = self.method.tableau is None
            self.native = kernel_module().Sensitivity(kernel, rows, list(map(float, b)), symplectic, self.charts, specs)
        self.controller = controller
        self.system: System | None = None
        self._callback: Any = None
        if controller is not None:
            self.system = System(self.dynamics, controller)
            if self.native is not None:
                settings = controller_settings(scene, self.system)
                self._callback = settings.get("callback")
                self.native.set_controller(kernel, settings)

    def step(self, q: Any = None, v: Any = None, tau: Any = None, dt: float = 1e-3) -> StepSensitivity:
        """One open-loop step of ``dt`` [s] from (q, v) (default the scene's start) under the torques
        ``tau`` (n_actuated,) [N·m or N] (default zero) held over it, and its exact derivatives with
        respect to the state, the torques and the parameters. Its q, v are what
        :func:`coopdyn.rollout` computes for one step with the same integrator (to round-off).

        Raises:
            SimulationError: a bad argument, a closed loop (its steps are :meth:`trajectory`'s), or a
                step that diverges (a speed above 1e4 rad/s or m/s, as a rollout's default).
        """
        if self.controller is not None:
            raise SimulationError("Sensitivity.step differentiates an open-loop step; a closed loop's: Sensitivity.trajectory")
        scene = self.scene
        q, v = _state(scene, q, v)
        u = np.zeros(scene.n_actuated) if tau is None else _validate.finite_array(tau, "tau [N·m or N]", (scene.n_actuated,))
        h = _validate.positive(dt, "dt", "s", SimulationError)
        nv, na, n_p = scene.nv, scene.n_actuated, len(self.params)
        seeds = _identity_seeds(nv, na, n_p)
        Q, V, _, dX, _, _ = self._run(q, v, u[None], 1, h, seeds, end_wrench=False)
        D = dX[1]
        return StepSensitivity(
            Q[1], V[1], D[:, : 2 * nv], D[:, 2 * nv : 2 * nv + na], D[:, 2 * nv + na :], self.params, self.exact
        )

    def trajectory(
        self,
        torques: Any,
        period: float,
        *,
        dt: float | None = None,
        q0: Any = None,
        v0: Any = None,
        initial_state: bool = False,
    ) -> TrajectorySensitivity:
        """A trajectory — open loop: ``torques[k]`` (N, n_actuated) [N·m or N] held from k·period
        [s], as :func:`coopdyn.rollout` plays it; closed loop (a :class:`Sensitivity` with a
        controller): ``torques`` the number of periods N, or (N, n_actuated) torques added to the
        controller's — in steps of ``dt`` [s] (a divisor of the period, default the period) from
        (q0, v0) (default the scene's start), and the forward sensitivities ∂x_k/∂p at every sample
        — with ``initial_state``, ∂x_k/∂x₀ too — chained from the steps' exact derivatives.

        Raises:
            SimulationError: a bad argument, or a run that diverges (the state is no longer finite).
        """
        scene = self.scene
        q, v = _state(scene, q0, v0)
        if self.controller is not None and isinstance(torques, int) and not isinstance(torques, bool):
            if torques < 1:
                raise SimulationError(f"trajectory: the number of periods must be >= 1, got {torques}")
            torques = np.zeros((torques, scene.n_actuated))
        U = _torques(scene, torques)
        h, per = step_of(period, dt)
        na, nv, n_p, N = scene.n_actuated, scene.nv, len(self.params), len(U)
        m = n_p + (2 * nv if initial_state else 0)
        dq, dv, du, dp = np.zeros((nv, m)), np.zeros((nv, m)), np.zeros((na, m)), np.zeros((n_p, m))
        dp[:, :n_p] = np.eye(n_p)
        if initial_state:
            dq[:, n_p : n_p + nv] = np.eye(nv)
            dv[:, n_p + nv :] = np.eye(nv)
        Q, V, W, dX, dW, applied = self._run(q, v, U, per, h, (dq, dv, du, dp))
        dx0 = dX[:, :, n_p:] if initial_state else None
        return TrajectorySensitivity(
            np.arange(N + 1) * period, Q, V, W, applied, dX[:, :, :n_p], dW[..., :n_p], dx0, self.params, self.exact
        )

    def transitions(self, torques: Any, period: float, *, dt: float | None = None, q0: Any = None, v0: Any = None) -> Transitions:
        """An open-loop trajectory (``torques[k]`` held over period k, as :meth:`trajectory`) and its
        linearisation period by period: ``δx_{k+1} = A_k δx_k + B_k δu_k + P_k δp`` in the tangent
        coordinates about the trajectory — what a model-predictive controller, iLQR or a
        trajectory optimiser works with, and what a scalar loss's gradient is chained backwards
        through (examples/gauss_newton_lift.py). Each period's matrices are one run of its steps
        with the identity as seeds: exact, as :meth:`step`.

        Raises:
            SimulationError: a bad argument, a closed loop (its input is the controller's), or a
                run that diverges.
        """
        if self.controller is not None:
            raise SimulationError("Sensitivity.transitions linearises an open loop; a closed loop's: Sensitivity.trajectory")
        scene = self.scene
        q, v = _state(scene, q0, v0)
        U = _torques(scene, torques)
        h, per = step_of(period, dt)
        nv, na, n_p, N = scene.nv, scene.n_actuated, len(self.params), len(U)
        seeds = _identity_seeds(nv, na, n_p)
        Q, V = np.empty((N + 1, scene.nq)), np.empty((N + 1, nv))
        A, B, P = np.empty((N, 2 * nv, 2 * nv)), np.empty((N, 2 * nv, na)), np.empty((N, 2 * nv, n_p))
        Q[0], V[0] = q, v
        exact = True
        for k in range(N):
            out = self._run(Q[k], V[k], U[k : k + 1], per, h, seeds, end_wrench=False, t0=k * period)
            exact = exact and self.exact
            Q[k + 1], V[k + 1], D = out[0][1], out[1][1], out[3][1]
            A[k], B[k], P[k] = D[:, : 2 * nv], D[:, 2 * nv : 2 * nv + na], D[:, 2 * nv + na :]
        return Transitions(np.arange(N + 1) * period, Q, V, A, B, P, self.params, exact)

    def _unit_law(self, p: Parameter) -> Any:
        """The law with only p's entries at 1 (its wrench is ∂G_f_G/∂p), or None for the mass."""
        if p.link is None:
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
    def _stage(self, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray]:
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
            for k, (p, law) in enumerate(zip(self.params, self.units, strict=True)):
                if law is None:
                    continue
                link = self.scene.links[p.link]  # type: ignore[index]
                X = data.oMf[link.tip_frame].actInv(data.oMf[link.grasp_frame])
                J_G = pin.getFrameJacobian(model, data, link.grasp_frame, LOCAL).reshape(6, self.nv)
                J_T = pin.getFrameJacobian(model, data, link.tip_frame, LOCAL).reshape(6, self.nv)
                Jr = J_G - X.toActionMatrixInverse() @ J_T
                f = law.evaluate(X, Jr @ v).G_f_G  # (the law with p's entries alone at 1: ∂G_f_G/∂p)
                dQ[:, k] = Jr.T @ f
                dW_dp[p.link, :, k] = f
            if any(law is None for law in self.units):  # the object's mass: −∂(M q̈ + h)/∂m at q̈
                Y = pin.computeJointTorqueRegressor(model, data, q, v, d.acceleration)
                dQ[:, [law is None for law in self.units]] = -(Y[:, self.object_columns] @ self.object_pi)[:, None]
            da_dp = cho_solve(cho_factor(M), dQ)
        return d, da_dp, dW_dp

    def _chart(self, delta: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(δ̇ = dexp⁻¹(δ) v, its ∂/∂v, its ∂/∂δ) with exact derivatives (complex step)."""
        rate, C, N = v.copy(), np.eye(self.nv), np.zeros((self.nv, self.nv))
        for i0, n in self.charts:
            s = slice(i0, i0 + n)
            rate[s], C[s, s], N[s, s] = dexp_inv_rate(delta[s], v[s], _COMPLEX_STEP)
        return rate, C, N

    # -- one step -----------------------------------------------------------------------------
    def _step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, h: float, seeds: tuple[np.ndarray, ...], carry: Carry = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, np.ndarray, Carry]:
        """One step from (q, v) under u, with the derivatives of (δq⁺, v⁺) along the seed columns
        ``(dq, dv, du, dp)`` (each (n, m)); also the start's derivatives and ∂W/∂p there, and what
        the method carries to the next step (generalized-α's acceleration; None: a fresh start)."""
        dq0, dv0, du, dp = seeds
        if self.method.alpha is not None:
            return self._alpha_step(q, v, u, h, seeds, carry)
        if self.method.gamma is not None:
            return (*self._implicit_step(q, v, u, h, seeds), None)
        if self.method.tableau is None:  # symplectic Euler: v⁺ = v + h a(q, v), q⁺ = q ⊕ h v⁺
            d, da_dp, dW_dp = self._stage(q, v, u)
            v1 = v + h * d.acceleration
            dv1 = dv0 + h * _acceleration_derivative(d, da_dp, dq0, dv0, du, dp)
            q1, dq1 = self._integrate(q, h * v1, dq0, h * dv1)
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
                q_i, dq_i = self._integrate(q, delta, dq0, ddelta)
                rate, C, N = self._chart(delta, v_i)
                kd.append(rate)
                dkd.append(C @ dv_i + N @ ddelta)
            d, da_dp, dW_dp = self._stage(q_i, v_i, u)
            if i == 0:
                start = (d, dW_dp)
            ka.append(d.acceleration)
            dka.append(_acceleration_derivative(d, da_dp, dq_i, dv_i, du, dp))
        Delta = h * combine(b, kd)
        dDelta = h * combine(b, dkd)
        v1 = v + h * combine(b, ka)
        dv1 = dv0 + h * combine(b, dka)
        q1, dq1 = self._integrate(q, Delta, dq0, dDelta)
        assert start is not None
        return q1, v1, dq1, dv1, start[0], start[1], None

    def _implicit_step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, h: float, seeds: tuple[np.ndarray, ...]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, np.ndarray]:
        """A linearly implicit step (:mod:`coopdyn.integrators.implicit`) and its derivative along
        the seed columns, as :meth:`_step`. Implicit Euler is the first stage at γ = 1
        (``δ = h k_q``, ``v⁺ = v + h k_v``); the two-stage scheme (ROS2, the trapezoid) adds
        ``(I − γhJ) k₂ = f(q ⊕ hk_q1, v + hk_v1) − 2k₁`` with the same matrices, and
        ``δ = h(3k₁ + k₂)/2``."""
        dq0, dv0, du, dp = seeds
        assert self.method.gamma is not None
        dyn, gh, stages = self.dynamics, self.method.gamma * h, self.method.stages
        d, da_dp, dW_dp = self._stage(q, v, u)
        f, M, K, D = dyn.implicit_terms(q, v, u)
        gains = np.zeros(self.scene.n_actuated)
        dyn.factor(M, K, D, gh, gains, gains)
        start = (q, v, cho_factor(M + gh * D + gh * gh * K), M, K)
        kq1, kv1 = dyn.solve(v, f)
        da1 = _acceleration_derivative(d, da_dp, dq0, dv0, du, dp)
        dkv1 = self._solve_derivative(start, (gh, gh * gh), v, kv1, d.acceleration, da1, dv0, seeds)
        dkq1 = dv0 + gh * dkv1
        if stages == 1:
            q1, dq1 = self._integrate(q, h * kq1, dq0, h * dkq1)
            return q1, v + h * kv1, dq1, dv0 + h * dkv1, d, dW_dp
        d2, v2, dd2, dv2 = h * kq1, v + h * kv1, h * dkq1, dv0 + h * dkv1
        q2, dq2 = self._integrate(q, d2, dq0, dd2)
        e, da_dp2, _ = self._stage(q2, v2, u)
        rate, C, N = self._chart(d2, v2)
        y2, dy2 = e.acceleration - 2.0 * kv1, _acceleration_derivative(e, da_dp2, dq2, dv2, du, dp) - 2.0 * dkv1
        fq2, dfq2 = rate - 2.0 * kq1, C @ dv2 + N @ dd2 - 2.0 * dkq1
        kq2, kv2 = dyn.solve(fq2, M @ y2)
        dkv2 = self._solve_derivative(start, (gh, gh * gh), fq2, kv2, y2, dy2, dfq2, seeds)
        dkq2 = dfq2 + gh * dkv2
        q1, dq1 = self._integrate(q, h * (1.5 * kq1 + 0.5 * kq2), dq0, h * (1.5 * dkq1 + 0.5 * dkq2))
        return q1, v + h * (1.5 * kv1 + 0.5 * kv2), dq1, dv0 + h * (1.5 * dkv1 + 0.5 * dkv2), d, dW_dp

    def _alpha_step(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, h: float, seeds: tuple[np.ndarray, ...], carry: Carry
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, np.ndarray, Carry]:
        """A generalized-α step (:class:`coopdyn.integrators.GeneralizedAlpha`: one linearised solve
        for x̂ = (1 − α_m)a⁺ + α_m a, one Newton correction with the same S) and its derivative, as
        :meth:`_step`; ``carry`` is the algorithmic acceleration a and its derivative from the step
        before (None: a fresh start, a = q̈), and the step returns its own."""
        dq, dv, du, dp = seeds
        assert self.method.alpha is not None
        am, af, gamma, beta = self.method.alpha
        c, dq_a, dv_a = alpha_coefficients(am, gamma, beta, h)
        gp, bp = (1.0 - af) * gamma * c, (1.0 - af) * beta * h * c
        dyn = self.dynamics
        d, da_dp, dW_dp = self._stage(q, v, u)
        f, M, K, D = dyn.implicit_terms(q, v, u)
        gains = np.zeros(self.scene.n_actuated)
        dyn.factor(M, K, D, gp, gains, gains, bp)
        start = (q, v, cho_factor(M + gp * D + bp * K), M, K)
        a_true = cho_solve(cho_factor(M), f)  # q̈ at the start (f = M q̈), as the integrator's fresh start takes it
        da_true = _acceleration_derivative(d, da_dp, dq, dv, du, dp)
        a, da = carry if carry is not None else (a_true, da_true)
        A0, dA0 = dv_a * a, dv_a * da  # v⁺ = v + A0 + γc x̂
        B0, dB0 = h * v + dq_a * a, h * dv + dq_a * da  # q⁺ = q ⊕ (B0 + βhc x̂)
        f_q, df_q = (1.0 - af) * (B0 - (bp / gp) * A0), (1.0 - af) * (dB0 - (bp / gp) * dA0)
        _, y = dyn.solve(f_q, (1.0 - af) * (M @ A0) + gp * f)
        y_v, dy_v = (1.0 - af) * A0 + gp * a_true, (1.0 - af) * dA0 + gp * da_true  # (M y_v: the solve's right-hand side)
        dy = self._solve_derivative(start, (gp, bp), f_q, y, y_v, dy_v, df_q, seeds)
        xh, dxh = (y - (1.0 - af) * A0) / gp, (dy - (1.0 - af) * dA0) / gp
        q1, dq1 = self._integrate(q, B0 + (beta * h * c) * xh, dq, dB0 + (beta * h * c) * dxh)
        v1, dv1 = v + A0 + (gamma * c) * xh, dv + dA0 + (gamma * c) * dxh
        e, da_dp1, _ = self._stage(q1, v1, u)  # the Newton correction: S dx = M((1 − α_f) q̈(q⁺, v⁺) − x̂) + α_f f
        a1, da1 = e.acceleration, _acceleration_derivative(e, da_dp1, dq1, dv1, du, dp)
        _, dx = dyn.solve(np.zeros_like(v), M @ ((1.0 - af) * a1 - xh) + af * f)
        y2, dy2 = (1.0 - af) * a1 - xh + af * a_true, (1.0 - af) * da1 - dxh + af * da_true
        zero = np.zeros_like(dq)
        ddx = self._solve_derivative(start, (gp, bp), np.zeros_like(v), dx, y2, dy2, zero, seeds)
        xh, dxh = xh + dx, dxh + ddx
        q1, dq1 = self._integrate(q, B0 + (beta * h * c) * xh, dq, dB0 + (beta * h * c) * dxh)
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
        dG_dq, dG_dv, at_D, at_K = self.matrices(q, v, w_M, w_D, w_K)
        self.exact = self.exact and self.matrices.exact
        dG = dG_dq @ dq0 + dG_dv @ dv0
        if len(self.params):
            dG = dG + self._matrix_parameters(q, w_M, at_D, at_K) @ dp
        return np.asarray(cho_solve(S, M @ dy - gp * (K @ df_q) - dG))

    def _matrix_parameters(
        self, q: np.ndarray, w_M: np.ndarray, at_D: list[RelativeTwist], at_K: list[RelativeTwist]
    ) -> np.ndarray:
        """∂G/∂p (nv, n_p) for :meth:`_solve_derivative`'s G: a stiffness or damping entry's is the
        unit law's ``Jrᵀ (S_K ξ_K + S_D ξ_D)`` (K̃ and D̃ are linear in them; ξ_K = Jr w_K, ξ_D =
        Jr w_D); the object's mass scales its inertia, so ∂(M w_M)/∂m is the object's columns of
        the joint-torque regressor at (q, 0, w_M) without gravity times its inertial parameters / m."""
        assert self.matrices is not None
        out = np.zeros((self.nv, len(self.params)))
        for k, (p, law) in enumerate(zip(self.params, self.units, strict=True)):
            if p.link is None:  # the object's mass
                matrices = self.matrices
                Y = pin.computeJointTorqueRegressor(matrices.free, matrices.free_data, q, np.zeros(self.nv), w_M)
                out[:, k] = Y[:, self.object_columns] @ self.object_pi
                continue
            i = [link[0] for link in self.matrices.links].index(p.link)
            ev = law.evaluate(at_K[i].X, np.zeros(6), True)
            out[:, k] = at_K[i].Jr.T @ (ev.S_K @ at_K[i].xi + ev.S_D @ at_D[i].xi)
        return out

    def _run(
        self,
        q: np.ndarray,
        v: np.ndarray,
        U: np.ndarray,
        per: int,
        h: float,
        seeds: tuple[np.ndarray, ...],
        end_wrench: bool = True,
        t0: float = 0.0,
    ) -> tuple[np.ndarray, ...]:
        """N = len(U) periods of ``per`` steps of h from (q, v), U[k] held over period k, the
        derivatives carried along the seed columns ``(dq, dv, du, dp)`` (du, dp the same at every
        step). Returns Q (N+1, nq), V (N+1, nv), W (N+1, L, 6), dX (N+1, 2nv, m), dW (N+1, L, 6, m)
        and the torques applied: every period's start and the end. A step whose speed passes
        :data:`MAX_SPEED` stops it as diverged (``t0`` [s]: the run's start, for the message)."""
        self.exact = True  # (this run's: a tangent or a controller by differences clears it)
        if self.native is not None:
            try:
                raw = self.native.run(q, v, U, per, h, *seeds, end_wrench, MAX_SPEED, t0)
            except RuntimeError as exc:
                error = getattr(self._callback, "error", None)
                if error is not None:  # a Python controller's own failure
                    self._callback.error = None
                    raise error from None
                self.dynamics.reraise_python_error()  # a Python element's own failure (or Ctrl-C in it)
                diverged = "not finite" in str(exc) or "a speed of" in str(exc)
                what = "diverged" if diverged else "the kernel stopped the run"
                hint = "; a smaller step, or a method that resolves the scene's modes" if diverged else ""
                raise SimulationError(f"sensitivities: {what}: {exc}{hint}") from exc
            Q, V, W, dX, dW, exact, applied = raw
            N, L, m = len(U), len(self.scene.elements), seeds[0].shape[1]
            self.exact = self.exact and bool(exact)
            return (
                Q.reshape(N + 1, -1),
                V.reshape(N + 1, -1),
                W.reshape(N + 1, L, 6),
                dX.reshape(N + 1, 2 * self.nv, m),
                dW.reshape(N + 1, L, 6, m),
                applied.reshape(N, -1),
            )
        dq, dv, du, dp = seeds
        N, nv, m, L = len(U), self.nv, dq.shape[1], len(self.scene.elements)
        applied = np.array(U, dtype=float)
        Q, V = np.empty((N + 1, self.scene.nq)), np.empty((N + 1, nv))
        W, dX, dW = np.empty((N + 1, L, 6)), np.empty((N + 1, 2 * nv, m)), np.empty((N + 1, L, 6, m))

        def sample(k: int, d: Any, dW_dp: np.ndarray) -> None:
            Q[k], V[k], W[k] = q, v, d.wrench
            dX[k, :nv], dX[k, nv:] = dq, dv
            dW[k] = np.einsum("lij,jm->lim", d.dwrench_dq, dq) + np.einsum("lij,jm->lim", d.dwrench_dv, dv)
            dW[k] += np.einsum("lip,pm->lim", dW_dp, dp)

        for k in range(N):
            du_k = du
            if self.system is not None:  # the controller's sample, held over the period
                t_k = k * per * h
                applied[k] = U[k] + self.system.torque(t_k, q, v)
                du_k = du + _controller_derivative(self.system, t_k, q, v, dq, dv)
                self.exact = False
            carry: Carry = None  # (a new held torque: generalized-α starts afresh, as the integrators do)
            for s in range(per):
                try:
                    q1, v1, dq1, dv1, d, dW_dp, carry = self._step(q, v, applied[k], h, (dq, dv, du_k, dp), carry)
                except (KernelError, StepMatrixError) as exc:  # (a stage's state, or its step matrix, is no longer finite)
                    raise SimulationError(
                        f"sensitivities: diverged in the step from t = {t0 + (k * per + s) * h:.6g} s ({exc})"
                    ) from exc
                if s == 0:
                    sample(k, d, dW_dp)
                if not all(np.all(np.isfinite(x)) for x in (q1, v1, dq1, dv1)):
                    raise SimulationError(
                        f"sensitivities: diverged: the state is not finite at t = {t0 + (k * per + s + 1) * h:.6g} s"
                    )
                if np.max(np.abs(v1)) > MAX_SPEED:
                    raise SimulationError(
                        f"sensitivities: diverged: a speed of {np.max(np.abs(v1)):.3g} rad/s or m/s (above {MAX_SPEED:.6g}) "
                        f"after the step from t = {t0 + (k * per + s) * h:.6g} s; a smaller step, or a method that resolves "
                        "the scene's modes"
                    )
                q, v, dq, dv = q1, v1, dq1, dv1
        if end_wrench:
            d, _, dW_dp = self._stage(q, v, U[-1])
            sample(N, d, dW_dp)
        else:  # (the end's wrench would cost one more evaluation of the derivatives)
            Q[N], V[N], dX[N, :nv], dX[N, nv:], W[N], dW[N] = q, v, dq, dv, np.nan, np.nan
        return Q, V, W, dX, dW, applied

    def _integrate(self, q: np.ndarray, delta: np.ndarray, dq: np.ndarray, ddelta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    """

    tableau: tuple[Any, ...] | None
    gamma: float | None = None
    stages: int = 0
    alpha: tuple[float, float, float, float] | None = None

    @property
    def implicit(self) -> bool:
        """Whether its stages solve with the Gauss–Newton step matrix."""
        return self.gamma is not None or self.alpha is not None


def step_method(integrator: Any) -> StepMethod:
    """The differentiated form of a method: an explicit Runge–Kutta method (rk4, dopri5's step, a
    user's tableau), symplectic Euler, implicit Euler, ROS2, the trapezoid or generalized-α.

    Raises:
        SimulationError: any other method, with the reason.
    """
    method = get_integrator(integrator)
    if isinstance(method, ExplicitRungeKutta | DormandPrince):
        return StepMethod((method.tableau.A, method.tableau.b))
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
    name = _method_name(method)
    if type(method) is LinearlyImplicitEuler:
        why = (
            f"with jacobian_every = {method.jacobian_every} a step reuses an earlier step's matrices, so it is not a function "
            "of its own start; use jacobian_every=1"
        )
        name = repr(method)
    elif type(method) is AdaptiveROS2:
        why = "it adapts its step in a run; 'ros2' is the same step at a fixed h"
    elif isinstance(method, Exponential):
        why = "its step exponentiates the Gauss–Newton Jacobian, and the matrix exponential's derivative is not taken here"
    elif isinstance(method, LinearlyImplicitEuler | ROS2 | Trapezoid | GeneralizedAlpha | SymplecticEuler):
        why = f"it is a subclass of a built-in method ({type(method).__name__}) whose step may differ from the one differentiated"
    else:
        why = "only the explicit Runge–Kutta methods, symplectic Euler and the linearly implicit methods are"
    raise SimulationError(
        f"sensitivities: {name} is not differentiated: {why}; use 'rk4', 'dopri5', 'symplectic_euler', "
        "'implicit_euler', 'ros2', 'trapezoid', 'generalized_alpha' or an explicit tableau (ExplicitRungeKutta)"
    )


def _acceleration_derivative(
    d: Any, da_dp: np.ndarray, dq: np.ndarray, dv: np.ndarray, du: np.ndarray, dp: np.ndarray
) -> np.ndarray:
    """dq̈ along the seed columns: ∂q̈/∂q dq + ∂q̈/∂v dv + ∂q̈/∂τ du + ∂q̈/∂p dp (the kernel's twin:
    Sensitivity::acceleration_derivative)."""
    return np.asarray(d.da_dq @ dq + d.da_dv @ dv + d.da_dtau @ du + da_dp @ dp)


def _identity_seeds(nv: int, na: int, n_p: int) -> tuple[np.ndarray, ...]:
    """The seed columns (dq, dv, du, dp) of a derivative with respect to all of (x, u, p)."""
    eye = np.eye(2 * nv + na + n_p)
    return eye[:nv], eye[nv : 2 * nv], eye[2 * nv : 2 * nv + na], eye[2 * nv + na :]


def _controller_derivative(system: System, t: float, q: np.ndarray, v: np.ndarray, dq: np.ndarray, dv: np.ndarray) -> np.ndarray:
    """∂τ/∂(δq, v)·[dq; dv] (n_actuated, m) by central differences of the controller: along each
    column (2m calls; a step of 1e-6 on its largest entry) when m < 2nv, else through its whole
    gain (:func:`coopdyn.linearize.controller_gain`) — as the kernel's twin does."""
    nv, m = len(v), dq.shape[1]
    if m >= 2 * nv:
        G = controller_gain(system, t, q, v)
        return np.asarray(G[:, :nv] @ dq + G[:, nv:] @ dv)
    model = system.dynamics.scene.model
    out = np.zeros((system.n_actuated, m))
    for j in range(m):
        size = max(float(np.max(np.abs(dq[:, j]))), float(np.max(np.abs(dv[:, j]))))
        if size == 0.0:
            continue
        eps = 1e-6 / size
        plus = system.torque(t, pin.integrate(model, q, eps * dq[:, j]), v + eps * dv[:, j])
        minus = system.torque(t, pin.integrate(model, q, -eps * dq[:, j]), v - eps * dv[:, j])
        out[:, j] = (plus - minus) / (2.0 * eps)
    return out


def _state(scene: Scene, q: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
    return scene.check_state(scene.q0 if q is None else q, scene.v0 if v is None else v)


def _torques(scene: Scene, torques: Any) -> np.ndarray:
    U = _validate.finite_array(torques, "torques [N·m or N]", error=SimulationError)
    if U.ndim != 2 or U.shape[0] < 1 or U.shape[1] != scene.n_actuated:
        raise SimulationError(f"torques must be (N, {scene.n_actuated}): one row per period, got shape {U.shape}")
    return U


def step_of(period: float, dt: float | None) -> tuple[float, int]:
    """(h, steps per period), checked."""
    period = _validate.positive(period, "period", "s", SimulationError)
    h = period if dt is None else _validate.positive(dt, "dt", "s", SimulationError)
    per = round(period / h)
    if per < 1 or abs(per * h - period) > 1e-9 * period:
        raise SimulationError(f"dt = {h:g} s must divide the period {period:g} s")
    return h, per


def step_sensitivity(
    scene: Scene,
    q: Any = None,
    v: Any = None,
    tau: Any = None,
    dt: float = 1e-3,
    *,
    integrator: Any = "rk4",
    parameters: Sequence[str] = (),
    backend: str | None = None,
) -> StepSensitivity:
    """``Sensitivity(scene, integrator, parameters, backend).step(q, v, tau, dt)``: one step and its
    exact derivatives (see :class:`Sensitivity`; set one up to differentiate many steps)."""
    return Sensitivity(scene, integrator, parameters, backend).step(q, v, tau, dt)


def trajectory_sensitivity(
    scene: Scene,
    torques: Any,
    period: float,
    *,
    dt: float | None = None,
    q0: Any = None,
    v0: Any = None,
    integrator: Any = "rk4",
    parameters: Sequence[str] = (),
    initial_state: bool = False,
    backend: str | None = None,
    controller: Controller | None = None,
) -> TrajectorySensitivity:
    """``Sensitivity(scene, integrator, parameters, backend, controller).trajectory(torques, period,
    ...)``: a trajectory and its forward sensitivities (see :class:`Sensitivity`)."""
    return Sensitivity(scene, integrator, parameters, backend, controller).trajectory(
        torques, period, dt=dt, q0=q0, v0=v0, initial_state=initial_state
    )
