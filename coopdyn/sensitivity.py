"""Exact sensitivities of a step and of a whole trajectory, open loop or closed under a sampled
controller: ∂x⁺/∂(x, u, p).

The state is ``x = (δq, v)`` as in :func:`coopdyn.linearize` (δq Pinocchio's tangent coordinates:
``q ⊕ δq = pin.integrate(model, q, δq)``; after a step, about the new configuration); the input
``u`` is the actuated joints' torque, held over the step [N·m or N]; ``p`` are named physical
parameters of the scene (:func:`coopdyn.parameters.parameters`).

The derivative is that of the discrete map the method computes, not of the continuous flow; one
step's is :class:`coopdyn.step_derivative.StepDerivative` (how each method's stages are
differentiated), and a trajectory chains the steps' (forward sensitivities), in Python or in the
kernel's twin (``src/native/sensitivity.hpp``: every method but the exponential one).

``tests/test_sensitivity.py`` checks every sensitivity against central finite differences of
the step and of the compiled loop's rollout.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from . import _validate
from .accuracy import HoldInstability, sampled_instability
from .budget import MAX_MEMORY, MAX_STEPS
from .closed_loop import Controller, System
from .compiled import controller_settings, start_loop
from .dynamics.backend import kernel_module
from .errors import KernelError, SceneError, SimulationError, StepMatrixError
from .linearize import controller_gain
from .model.elements import lookup
from .model.scene import Scene
from .parameters import Parameter
from .parameters import parameters as scene_parameters
from .step_derivative import Carry, StepDerivative

__all__ = [
    "LossGradient",
    "Sensitivity",
    "StepSensitivity",
    "TrajectorySensitivity",
    "Transitions",
    "step_sensitivity",
    "trajectory_sensitivity",
]

#: a speed [rad/s or m/s] above which a differentiated run counts as diverged (coopdyn.rollout's default)
MAX_SPEED = 1e4
_DIVERGED_HINT = "; a smaller step or a method that resolves the scene's modes"
#: why a closed loop's derivative refuses a controller that answered the same call differently
_STATEFUL = (
    "it keeps state between calls (an integral term, a filter, a counter). A closed loop's derivative calls it "
    "more times per sample (central differences), which would change that state and with it the trajectory: "
    'give a controller that is a function of (t, q, v) alone, or fit with identify(..., jacobian="finite-differences"), '
    "whose runs call it once per sample"
)


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
class LossGradient:
    """A scalar loss's gradient along a trajectory (:meth:`Transitions.gradient`).

    Attributes:
        torques: (N, n_actuated) ∂L/∂u_k [per N·m or N of the torque held over period k].
        parameters: (n_parameters,) ∂L/∂p [per the parameter's unit].
        start: (2nv,) ∂L/∂x₀ (δq about q₀, then v).
    """

    torques: np.ndarray
    parameters: np.ndarray
    start: np.ndarray


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

    def gradient(self, dloss_dx: Any) -> LossGradient:
        """The gradient of a scalar loss ``L(x₀, …, x_N)`` of the samples with respect to the
        torques, the parameters and the start, by one backward (adjoint) pass over the periods'
        exact linearisation — no more runs: ``λ_N = ∂L/∂x_N``, ``λ_k = ∂L/∂x_k + A_kᵀ λ_{k+1}``;
        ``∂L/∂u_k = B_kᵀ λ_{k+1}``, ``∂L/∂p = Σ P_kᵀ λ_{k+1}``, ``∂L/∂x₀ = λ₀``.

        Args:
            dloss_dx: (N + 1, 2nv) ∂L/∂x_k at every sample, in the tangent coordinates about it
                (δq about q_k, then v; not ∂L/∂q, which has nq entries). For a loss of a frame's
                world position p (the box's, say), ``∂L/∂δq = Jᵀ ∂L/∂p`` with J the first three rows
                of Pinocchio's frame Jacobian in ``LOCAL_WORLD_ALIGNED`` at q_k (after
                ``computeJointJacobians``; its columns are the same δq) — a free-flyer's δq is in
                body axes, so ∂L/∂p cannot be put at its index as it is.

        Raises:
            SimulationError: dloss_dx of another shape, or not finite.
        """
        N, n = self.A.shape[0], self.A.shape[1]
        if np.shape(dloss_dx) != (N + 1, n):
            raise SimulationError(
                f"dloss_dx must be (N + 1, 2nv) = ({N + 1}, {n}): one row per sample, δq (nv) then v (nv) in tangent "
                f"coordinates, got shape {np.shape(dloss_dx)}"
            )
        g = _validate.finite_array(dloss_dx, "dloss_dx", (N + 1, n), SimulationError)
        lam = g[N].copy()
        du, dp = np.empty((N, self.B.shape[2])), np.zeros(self.P.shape[2])
        for k in reversed(range(N)):
            du[k] = self.B[k].T @ lam
            dp += self.P[k].T @ lam
            lam = g[k] + self.A[k].T @ lam
        return LossGradient(du, dp, lam)


class Sensitivity:
    """A scene's differentiated steps — open loop, or closed under a sampled controller — set up
    once (the dynamics, the kernel's twin, the parameters' unit laws) for many calls: an MPC's
    knots, an identification's iterations.

    Args:
        scene: an elastic scene (rigid grasps are refused).
        integrator: ``"rk4"`` (default), ``"symplectic_euler"``, ``"dopri5"`` or ``"dop853"`` (a
            step of its solution at the h given — a fixed step: rollout and simulate adapt
            theirs), an explicit :class:`~coopdyn.integrators.ExplicitRungeKutta`, or for stiff
            grasps a linearly implicit method: ``"implicit_euler"``, ``"ros2"``, ``"trapezoid"``,
            ``"generalized_alpha"`` (any ρ∞) — stable at steps where the explicit ones diverge —
            or on a linear scene ``"exponential"`` (in Python: it has no compiled twin).
        parameters: names as :func:`coopdyn.parameters.parameters` takes them (e.g. ``["left.k_linear"]``).
        backend: the dynamics' backend, as for :class:`coopdyn.Dynamics`: ``"native"`` runs the
            whole recursion in the compiled kernel (the exponential method: in Python),
            ``"python"`` the reference; they agree to round-off open loop, to ~1e-9 closed (the
            controller's derivative is differences of it).
        controller: a closed loop's controller ``controller(t, q, v) -> τ``, sampled at every
            period's start and held over it (a digital controller; :meth:`trajectory` only). A
            built-in one built for a twin of the scene (the nominal one: same arms and frames,
            other interconnection or object parameters; :func:`coopdyn.compiled.twin_scenes`)
            runs compiled and keeps its own model of the object, as on a real robot. Its
            derivative along the sensitivities' columns comes from central differences (2 calls
            per column and period; 4·nv when there are 2·nv columns or more), so the result's
            ``exact`` is then False. It must be a function of (t, q, v): one that keeps state
            between calls (an integral term) would be changed by those calls, and is refused
            (SimulationError) when it answers the same call twice differently.
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
        self.stepper = StepDerivative(scene, integrator, params, backend)
        self.scene, self.params, self.method = scene, params, self.stepper.method
        self.dynamics, self.nv = self.stepper.dynamics, scene.nv
        self.native = None  # the kernel's twin (src/native/sensitivity.hpp), on the native backend
        kernel = getattr(self.dynamics, "_kernel", None)
        if kernel is not None and self.method.exponential is None:
            A, b = self.method.tableau if self.method.tableau is not None else ((), ())
            method = self.method
            implicit = (method.gamma, float(method.stages)) if method.gamma is not None else (method.alpha or ())
            specs = [self._native_parameter(k, p, law) for k, (p, law) in enumerate(zip(params, self.stepper.units, strict=True))]
            rows = [list(map(float, row)) for row in A]
            symplectic = method.explicit and method.tableau is None
            self.native = kernel_module().Sensitivity(
                kernel, rows, list(map(float, b)), symplectic, tuple(map(float, implicit)), self.stepper.charts, specs
            )
        self.controller = controller
        self.system: System | None = None
        self._callback: Any = None
        if controller is not None:
            self.system = System(self.dynamics, controller)
            if self.native is not None:
                settings = controller_settings(scene, self.system)
                self._callback = settings.get("callback")
                self.native.set_controller(kernel, settings)

    @property
    def exact(self) -> bool:
        """Whether the last run's derivatives are exact (no tangent or controller by differences)."""
        return self.stepper.exact

    @exact.setter
    def exact(self, value: bool) -> None:
        self.stepper.exact = value

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
        nv, na, n_p = scene.nv, scene.n_actuated, len(self.params)
        u = np.zeros(na) if tau is None else _validate.finite_array(tau, "tau [N·m or N]", (na,), SimulationError)
        h = _validate.positive(dt, "dt", "s", SimulationError)
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
        initial_state = _validate.flag(initial_state, "initial_state", SimulationError)
        h, per = step_of(period, dt)
        na, nv, n_p = scene.n_actuated, scene.nv, len(self.params)
        m = n_p + (2 * nv if initial_state else 0)
        if self.controller is not None and isinstance(torques, int | np.integer) and not isinstance(torques, bool):
            torques = int(torques)
            if torques < 1:
                raise SimulationError(f"trajectory: the number of periods must be >= 1, got {torques}")
            _check_budget(scene, torques, per, h, m)  # (before its zeros are made)
            torques = np.zeros((torques, na))
        U = _torques(scene, torques, closed=self.controller is not None)
        N = len(U)
        _check_budget(scene, N, per, h, m)
        dq, dv, du, dp = np.zeros((nv, m)), np.zeros((nv, m)), np.zeros((na, m)), np.zeros((n_p, m))
        dp[:, :n_p] = np.eye(n_p)
        if initial_state:
            dq[:, n_p : n_p + nv] = np.eye(nv)
            dv[:, n_p + nv :] = np.eye(nv)
        try:
            Q, V, W, dX, dW, applied = self._run(q, v, U, per, h, (dq, dv, du, dp))
        except SimulationError as exc:  # a closed loop's divergence: is its hold too slow for its gains?
            hold = self._hold(q, v, period) if self.system is not None and "diverged" in str(exc) else None
            if hold is None:
                raise
            when = _diverged_at(str(exc))
            if when is None or hold.explains(when):
                raise SimulationError(f"{exc}. The {hold.sentence.removeprefix('the ')}") from exc
            slowly = f" — slowly: alone it takes {hold.seconds():.3g} s to grow ×1000"
            raise SimulationError(f"{exc}. Besides, {hold.sentence}{slowly}") from exc
        dx0 = dX[:, :, n_p:] if initial_state else None
        return TrajectorySensitivity(
            np.arange(N + 1) * period, Q, V, W, applied, dX[:, :, :n_p], dW[..., :n_p], dx0, self.params, self.exact
        )

    def _native_parameter(self, k: int, p: Parameter, law: Any) -> tuple[Any, ...]:
        """Parameter k as the kernel's twin takes it (src/native/sensitivity.hpp: its constructor)."""
        if p.position:
            return ("offset", p.link, list(map(float, self.stepper.offsets[k])))
        if law is None:  # the object's mass
            return ("mass", self.scene.object_joint, float(self.scene.object.mass_and_com()[0]))
        return ("element", p.link, lookup(type(law)).native, law.native_parameters())

    def _hold(self, q: np.ndarray, v: np.ndarray, period: float) -> HoldInstability | None:
        """The closed loop's controller, sampled every period and held, when that alone makes the
        loop linearised at (q, v) unstable (:func:`coopdyn.accuracy.sampled_instability`)."""
        assert self.system is not None
        loop = start_loop(self.system, q, v)  # (its compiled twin's gain, if any)
        try:
            return None if loop is None else sampled_instability(loop, period, knob="period")
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):  # (never hiding the divergence itself)
            return None

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
        _check_budget(scene, N, per, h, 2 * nv + na + n_p)
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
                if str(exc).startswith("diverged"):  # (the twin's divergences: the Python loop's messages)
                    raise SimulationError(f"sensitivities: {exc}{_DIVERGED_HINT}") from exc
                if str(exc).startswith("stateful controller"):
                    when = str(exc).removeprefix("stateful controller ").split(":")[0]
                    raise _stateful(when) from None
                raise SimulationError(f"sensitivities: the kernel stopped the run: {exc}") from exc
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
                tau_k = self.system.torque(t_k, q, v)
                applied[k] = U[k] + tau_k
                du_k = du + _controller_derivative(self.system, t_k, q, v, dq, dv)
                again = self.system.torque(t_k, q, v)  # (a controller with a state has been changed by the probes)
                if not np.max(np.abs(again - tau_k), initial=0.0) <= 1e-9 * max(1.0, float(np.max(np.abs(tau_k), initial=0.0))):
                    raise _stateful(f"at t = {t_k:.6g} s")
                self.exact = False
            carry: Carry = None  # (a new held torque: generalized-α starts afresh, as the integrators do)
            for s in range(per):
                try:
                    q1, v1, dq1, dv1, d, dW_dp, carry = self.stepper.step(
                        q, v, applied[k], h, (dq, dv, du_k, dp), carry, sampled=s == 0
                    )
                except (KernelError, StepMatrixError) as exc:  # (a stage's state, or its step matrix, is no longer finite)
                    raise SimulationError(
                        f"sensitivities: diverged in the step from t = {t0 + (k * per + s) * h:.6g} s ({exc}){_DIVERGED_HINT}"
                    ) from exc
                if s == 0:
                    sample(k, d, dW_dp)
                if not all(np.all(np.isfinite(x)) for x in (q1, v1, dq1, dv1)):
                    t1 = t0 + (k * per + s + 1) * h
                    raise SimulationError(f"sensitivities: diverged: the state is not finite at t = {t1:.6g} s{_DIVERGED_HINT}")
                if np.max(np.abs(v1)) > MAX_SPEED:
                    raise SimulationError(
                        f"sensitivities: diverged: a speed of {np.max(np.abs(v1)):.3g} rad/s or m/s (above {MAX_SPEED:.6g}) "
                        f"after the step from t = {t0 + (k * per + s) * h:.6g} s{_DIVERGED_HINT}"
                    )
                q, v, dq, dv = q1, v1, dq1, dv1
        if end_wrench:
            d, _, dW_dp = self.stepper.stage(q, v, U[-1])
            sample(N, d, dW_dp)
        else:  # (the end's wrench would cost one more evaluation of the derivatives)
            Q[N], V[N], dX[N, :nv], dX[N, nv:], W[N], dW[N] = q, v, dq, dv, np.nan, np.nan
        return Q, V, W, dX, dW, applied


def _stateful(when: str) -> SimulationError:
    """The refusal of a controller that answered the same call ``when`` ("at t = … s") differently."""
    return SimulationError(f"sensitivities: the controller answered the same call {when} differently: {_STATEFUL}")


def _check_budget(scene: Scene, N: int, per: int, h: float, m: int) -> None:
    """Refuse a run of N periods of ``per`` steps of h [s] with m derivative columns beyond
    :data:`coopdyn.budget.MAX_STEPS` steps or :data:`coopdyn.budget.MAX_MEMORY` bytes of records
    (simulate's defaults): before it starts, not after an hour or with a MemoryError."""
    if N * per > MAX_STEPS:
        raise SimulationError(
            f"sensitivities: {N} periods of {per} steps of {h:g} s are {N * per:,} steps, more than {MAX_STEPS:,}: take a "
            "larger dt, or split the trajectory (a piece's end state is the next one's start)"
        )
    size = 8.0 * (N + 1) * (2 * scene.nv + 6 * len(scene.elements)) * max(m, 1)
    if size > MAX_MEMORY:
        raise SimulationError(
            f"sensitivities: {N} periods with {m} derivative columns would take {size / 1e9:.3g} GB, more than "
            f"{MAX_MEMORY / 1e9:.3g} GB: split the trajectory or differentiate fewer columns"
        )


def _diverged_at(message: str) -> float | None:
    """The time [s] a divergence message of :meth:`Sensitivity._run` names (both backends write
    "t = … s"), or None."""
    found = re.search(r"\bt = ([-+0-9.eE]+) s", message)
    return float(found.group(1)) if found else None


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


def _torques(scene: Scene, torques: Any, closed: bool = False) -> np.ndarray:
    """``torques`` (N, n_actuated) checked; ``closed``: a closed loop's (added to its controller's,
    which may also be given as the number of periods N)."""
    U = _validate.finite_array(torques, "torques [N·m or N]", error=SimulationError)
    if U.ndim != 2 or U.shape[0] < 1 or U.shape[1] != scene.n_actuated:
        periods = ", or the number of periods N (an integer) under the controller alone" if closed else ""
        raise SimulationError(f"torques must be (N, {scene.n_actuated}): one row per period{periods}, got shape {U.shape}")
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
