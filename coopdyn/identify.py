"""``coopdyn.identify``: interconnection stiffness and damping (and where the grasps sit on the
object, and the object's mass) fitted to measured joint angles and grasp wrenches.

The fit is output error: the scene is run from the known start — open loop under the measured
torques (each held for one period, as :func:`coopdyn.rollout` plays them), or closed loop under
the controller that ran the experiment, sampled every period as it was — and its arm joint
angles and grasp wrenches are compared with the measured ones, each divided by its noise level.
An arm under constant torques is unstable (it falls away from any pose it does not hold), so an
open-loop replay drifts away exponentially from a record longer than a fraction of a second
whatever the parameters; a record of normal, closed-loop operation is fitted with its controller.
``scipy.optimize.least_squares`` (trust-region reflective; stiffness, damping and mass kept ≥ 0,
grasp positions free) minimises the sum
of squares with the exact Jacobian of every sample with respect to the parameters
(:func:`coopdyn.sensitivity.trajectory_sensitivity`) — or, for comparison, by finite
differences of compiled rollouts (``jacobian="finite-differences"``: one rollout per parameter
and iterate, as a simulator without derivatives offers).

The covariance is the Gauss–Newton one at the estimate, ``s²·(JᵀJ)⁻¹`` with ``s²`` the weighted
residual's variance per degree of freedom (≈ 1 when the noise levels given are the true ones).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from . import _validate
from .closed_loop import Controller
from .dynamics import Dynamics
from .errors import FitWarning, SceneError, SimulationError
from .integrators import get_integrator
from .model.scene import Scene
from .parameters import Parameter, with_parameters
from .parameters import parameters as scene_parameters
from .result import Result
from .rollout import rollout
from .sensitivity import step_of, trajectory_sensitivity
from .simulate import simulate
from .step_derivative import step_method

__all__ = ["Identification", "Measurements", "identify"]


@dataclass(frozen=True)
class Measurements:
    """What the sensors recorded at t = k·period, k = 0 … N.

    Attributes:
        period: the sample and control period [s].
        joints: (N + 1, n_arm_joints) the arm joint angles [rad or m], ``scene.arm_joints`` order.
        wrench: (N + 1, n_links, 6) each interconnection's wrench on the object at its grasp frame
            G, G axes [N, N·m] (what a force–torque sensor at the grasp reads), or None.
        torques: (N, n_actuated) the torques applied, each held for one period [N·m or N]: the
            open-loop model's input; None for a closed-loop fit (the controller computes them).
        joint_noise: the joint angles' noise σ [rad or m]; ``force_noise`` [N], ``torque_noise``
            [N·m]: the wrench's. They weight the residuals.
        q0, v0: the start (nq,), (nv,); default the scene's.
    """

    period: float
    joints: np.ndarray
    wrench: np.ndarray | None = None
    torques: np.ndarray | None = None
    joint_noise: float = 1e-4
    force_noise: float = 0.1
    torque_noise: float = 0.01
    q0: np.ndarray | None = None
    v0: np.ndarray | None = None

    @classmethod
    def from_result(
        cls,
        result: Result,
        *,
        open_loop: bool = False,
        joint_noise: float = 1e-4,
        force_noise: float = 0.1,
        torque_noise: float = 0.01,
    ) -> Measurements:
        """What perfect sensors read during a simulated run, sampled as it was saved: the arm joint
        angles and each grasp's wrench in its grasp frame's axes (not the world axes of
        :meth:`Result.wrenches`), with the run's start; with ``open_loop`` the torques applied too,
        which are the held ones only when the controller was sampled at the save period
        (``simulate(..., control_dt=dt·save_every)``): they are replayed once, and refused when
        the replay leaves the run. For a synthetic study: add your noise to ``joints`` and
        ``wrench`` (``dataclasses.replace``).

        Raises:
            SimulationError: uneven samples, rigid grasps (their wrench is a constraint's, which
                the elastic model's fit cannot read), or torques that are not the held ones."""
        if not isinstance(result, Result):
            raise SimulationError(f"Measurements.from_result: result must be a coopdyn.Result, got {type(result).__name__}")
        open_loop = _validate.flag(open_loop, "open_loop", SimulationError)
        for name, value in (("joint_noise", joint_noise), ("force_noise", force_noise), ("torque_noise", torque_noise)):
            _validate.positive(value, name, "rad, N or N·m", SimulationError)
        t = np.asarray(result.t)
        if len(t) < 2 or not np.allclose(np.diff(t), t[1] - t[0], rtol=1e-9, atol=0.0):
            raise SimulationError("Measurements.from_result: the run's samples must be evenly spaced, two at least")
        scene = result.scene
        if scene.constraints:
            raise SimulationError(
                "Measurements.from_result: the run has rigid grasps, whose wrenches are constraint forces; "
                "simulate the elastic scene to make measurements of it"
            )
        q_idx = _joint_coordinates(scene)
        dynamics = Dynamics(scene, result.backend)
        L = len(scene.links)
        wrench = np.array([[e.G_f_G for e in dynamics.element_states(q, v)[:L]] for q, v in zip(result.q, result.v, strict=True)])
        torques = np.array(result.tau[:-1], dtype=float) if open_loop else None
        if torques is not None:
            period = float(t[1] - t[0])
            replay = rollout(scene, torques[None], period=period, dt=min(result.dt, period), q0=result.q[0], v0=result.v[0],
                             integrator=result.integrator, threads=1)  # fmt: skip
            gap = float(np.max(np.abs(replay.q[0] - result.q)))
            if not gap < 1e-8:
                raise SimulationError(
                    f"Measurements.from_result: the run's saved torques, each held for a period, do not replay it "
                    f"({gap:.3g} apart): its controller was not sampled at the save period (simulate with "
                    f"control_dt = {period:g} s, dt·save_every, for open-loop measurements, or fit the closed loop), "
                    "or the run had an object_wrench, which the replay and the fit do not apply"
                )
        noise = (joint_noise, force_noise, torque_noise)
        return cls(float(t[1] - t[0]), result.q[:, q_idx].copy(), wrench, torques, *noise, result.q[0].copy(), result.v[0].copy())


@dataclass(frozen=True)
class Identification:
    """The estimate of :func:`identify` (see the module docstring).

    Attributes:
        parameters: the fitted :class:`~coopdyn.parameters.Parameter` (their values in the scene);
            start: the values the fit started from (``initial``, else the scene's).
        estimate, std: each parameter's estimate and 1-σ uncertainty, by name [its unit].
        covariance: (n_p, n_p) ``s²·(JᵀJ)⁻¹``; residual_rms: s = √(Σr²/(m − n)), the weighted
            residual's RMS per degree of freedom (≈ 1 when the noise levels given are the true
            ones); joint_rms [rad or m], wrench_rms ([N], [N·m]): the plain residuals' RMS.
        scene: the scene with the estimate. jacobian, exact: how the Jacobian was had, and whether
            it was exact throughout. evaluations, jacobians, cpu_time [s], message: the fit's work.
    """

    parameters: tuple[Parameter, ...]  #: the fitted parameters, their values at the start of the fit
    estimate: dict[str, float]  #: by name [its unit]
    std: dict[str, float]  #: 1-σ uncertainty by name [its unit]
    covariance: np.ndarray  #: (n_p, n_p) [the units' products]
    residual_rms: float  #: √(Σr²/(m − n)) of the weighted residual r (m values, n parameters): ≈ 1 when the noise levels hold
    joint_rms: float  #: RMS joint-angle residual [rad or m]
    wrench_rms: tuple[float, float] | None  #: RMS force [N] and moment [N·m] residuals, or None
    scene: Scene  #: the scene with the estimate
    jacobian: str  #: "exact" (sensitivities) or "finite-differences"
    exact: bool  #: the Jacobian was exact throughout (False: finite differences, or a controller's derivative by them)
    evaluations: int  #: runs of the model (residuals)
    jacobians: int  #: Jacobian evaluations
    cpu_time: float  #: CPU time of the fit [s]
    message: str  #: the optimiser's
    start: dict[str, float] = dataclasses.field(default_factory=dict)  #: the values the fit started from, by name
    #: what came from differences when ``exact`` is False with the exact Jacobian ("the controller's derivative", …)
    differenced: str = ""

    def interval(self, name: str, sigmas: float = 2.0) -> tuple[float, float]:
        """(low, high): the estimate ± ``sigmas``·σ of the parameter ``name``."""
        return self.estimate[name] - sigmas * self.std[name], self.estimate[name] + sigmas * self.std[name]

    def summary(self) -> str:
        """A table: each parameter's start, estimate and σ, with units."""
        lines = [f"{'parameter':<22} {'start':>12} {'estimate':>12} {'σ':>10}  unit"]
        for p in self.parameters:
            scale, unit = (1e3, "mm") if p.position else (1.0, p.unit)  # (a grasp position in mm: readable)
            start, estimate, std = (
                self.start.get(p.name, p.value) * scale,
                self.estimate[p.name] * scale,
                self.std[p.name] * scale,
            )
            lines.append(f"{p.name:<22} {start:>12.6g} {estimate:>12.6g} {std:>10.3g}  {unit}")
        fit = f"weighted residual RMS {self.residual_rms:.3f}; joints {self.joint_rms:.3g} rad"
        if self.wrench_rms is not None:
            fit += f", forces {self.wrench_rms[0]:.3g} N, moments {self.wrench_rms[1]:.3g} N·m"
        lines.append(fit)
        how = self.jacobian if self.exact or self.jacobian != "exact" else f"sensitivities; {self.differenced} by differences"
        lines.append(f"{self.evaluations} runs, {self.jacobians} Jacobians ({how}), {self.cpu_time:.2f} s CPU: {self.message}")
        return "\n".join(lines)


def _checked(
    scene: Scene, m: Measurements, closed_loop: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """(the model's input: torques (N, na) or zeros, joints, wrench, q0, v0) of ``m``, checked."""
    if not isinstance(m, Measurements):
        raise SimulationError(f"identify: measurements must be a coopdyn.identify.Measurements, got {type(m).__name__}")
    na, nj = scene.n_actuated, len(scene.arm_joints)
    joints = _validate.finite_array(m.joints, "measurements.joints [rad or m]", error=SimulationError)
    if joints.ndim != 2 or joints.shape[0] < 2 or joints.shape[1] != nj:
        raise SimulationError(
            f"measurements.joints must be (N + 1, {nj}): one row per sample k = 0 … N, N ≥ 1, got {joints.shape}"
        )
    N = joints.shape[0] - 1
    if closed_loop:
        if m.torques is not None:
            raise SimulationError(
                "identify: a closed-loop fit computes the torques with its controller; give measurements.torques=None"
            )
        U = np.zeros((N, na))
    else:
        if m.torques is None:
            raise SimulationError("identify: an open-loop fit plays measurements.torques; give them, or the controller that ran")
        U = _validate.finite_array(m.torques, "measurements.torques [N·m or N]", error=SimulationError)
        if U.shape != (N, na):
            raise SimulationError(
                f"measurements.torques must be ({N}, {na}): one row per period between the samples, got {U.shape}"
            )
    wrench = None
    if m.wrench is not None:
        wrench = _validate.finite_array(m.wrench, "measurements.wrench [N, N·m]", error=SimulationError)
        if wrench.shape != (N + 1, len(scene.links), 6):
            raise SimulationError(f"measurements.wrench must be ({N + 1}, {len(scene.links)}, 6), got {wrench.shape}")
    for name in ("joint_noise", "force_noise", "torque_noise"):
        _validate.positive(getattr(m, name), f"measurements.{name}", "rad, N or N·m", SimulationError)
    q0, v0 = scene.check_state(scene.q0 if m.q0 is None else m.q0, scene.v0 if m.v0 is None else m.v0)
    return U, joints, wrench, q0, v0


def _joint_coordinates(scene: Scene) -> np.ndarray:
    """The q indices of the arm joints (each must be one coordinate: revolute or prismatic)."""
    out = []
    for i in scene.arm_joints:
        joint = next(j for j in scene.model.joints[1:] if j.idx_v == i)
        if joint.nq != 1:
            raise SceneError(
                f"identify: arm joint {scene.model.names[joint.id]} has {joint.nq} coordinates; only 1-coordinate joints"
            )
        out.append(joint.idx_q)
    return np.array(out, dtype=int)


def identify(
    scene: Scene,
    measurements: Measurements,
    parameters: Sequence[str],
    *,
    initial: Mapping[str, float] | None = None,
    integrator: Any = "rk4",
    dt: float | None = None,
    jacobian: str = "exact",
    max_iterations: int = 30,
    backend: str | None = None,
    controller: Controller | None = None,
) -> Identification:
    """Fit the named ``parameters`` of ``scene`` (:func:`coopdyn.parameters.parameters`: e.g.
    ``["left.k_linear", "right.k_linear"]`` [N/m]) to ``measurements`` (see the module docstring).

    Args:
        initial: start values by name (default: the scene's values).
        integrator: the method the model runs with, a fixed-step one with sensitivities
            (``"rk4"``, ``"symplectic_euler"``, an explicit tableau, or for stiff grasps
            ``"implicit_euler"``, ``"ros2"``, ``"trapezoid"``, ``"generalized_alpha"``) for either
            Jacobian, so that both fit the same model; ``dt`` [s] its step, a divisor of the period
            (default the period).
        jacobian: ``"exact"`` (default) or ``"finite-differences"`` (forward differences of
            compiled rollouts, for comparison).
        max_iterations: the optimiser's budget of runs of the model (residual evaluations, scipy's
            ``max_nfev``); with ``jacobian="finite-differences"`` the runs of the differences
            come on top (one per parameter and Jacobian).
        controller: the controller that ran the experiment (a closed-loop fit; see
            :class:`coopdyn.sensitivity.Sensitivity`): built for the nominal scene, it keeps its
            own model while the fit changes the plant's parameters. Its gain comes from central
            differences; ``jacobian="finite-differences"`` then runs compiled closed-loop simulations.
            A fitted grasp position moves a grasp frame, so the candidate scenes are not twins of
            the nominal one (:func:`coopdyn.compiled.twin_scenes`) and a built-in controller runs
            as a Python callback there (about 3× slower a run).

    Raises:
        SimulationError: bad measurements or arguments, or a model run that diverges at the start.
    """
    if not isinstance(scene, Scene):
        raise SceneError(f"identify: scene must be a coopdyn.Scene, got {type(scene).__name__}")
    if jacobian not in ("exact", "finite-differences"):
        raise SimulationError(f"identify: jacobian must be 'exact' or 'finite-differences', got {jacobian!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or max_iterations < 1:
        raise SimulationError(f"identify: max_iterations must be a positive integer (runs of the model), got {max_iterations!r}")
    if controller is not None and not callable(controller):
        raise SimulationError(
            f"identify: controller must be a callable controller(t, q, v) -> tau, got {type(controller).__name__}"
        )
    if scene.constraints:
        raise SceneError(
            "identify: the scene has rigid grasps (constraints), whose wrenches no elastic law gives; fit the elastic scene "
            "they stand for"
        )
    if initial is not None and not isinstance(initial, Mapping):
        raise SimulationError(f"identify: initial must be a dict of start values by name, got {type(initial).__name__}")
    params = scene_parameters(scene, parameters)
    names = [p.name for p in params]
    start = dict(initial or {})
    unknown = set(start) - set(names)
    if unknown:
        raise SimulationError(f"identify: initial names {sorted(unknown)}, which are not among the parameters {names}")
    positions = np.array([p.position for p in params])  # grasp positions: any sign, no bound
    for p, position in zip(params, positions, strict=True):
        if p.name not in start and p.value == 0.0 and not position:
            raise SimulationError(
                f"identify: {p.name} is 0 {p.unit} in the scene, which cannot start the fit (its scale); give a positive guess: "
                f"initial={{{p.name!r}: ...}}"
            )
    x0 = np.array(
        [
            (_validate.number if position else _validate.positive)(
                start.get(p.name, p.value), f"initial value of {p.name}", p.unit, SimulationError
            )
            for p, position in zip(params, positions, strict=True)
        ]
    )
    U, joints, wrench, q0, v0 = _checked(scene, measurements, controller is not None)
    period = _validate.positive(measurements.period, "measurements.period", "s", SimulationError)
    step_method(integrator)  # (refuses a method without sensitivities, up front)
    if get_integrator(integrator).adaptive:
        raise SimulationError(
            f"identify: {integrator!r} adapts its step in a run, so its sensitivities (of fixed steps) and finite differences "
            "would fit two different models; use a fixed-step method ('rk4', 'symplectic_euler', 'trapezoid') at a dt that "
            "resolves the scene"
        )
    step_of(period, dt)  # (refuses a dt that does not divide the period)
    q_idx = _joint_coordinates(scene)
    L = len(scene.links)
    w_joint = 1.0 / measurements.joint_noise
    w_wrench = np.array(3 * [1.0 / measurements.force_noise] + 3 * [1.0 / measurements.torque_noise])
    cpu0 = time.process_time()
    cache: dict[bytes, tuple[np.ndarray, np.ndarray | None]] = {}
    counts = {"runs": 0, "jacobians": 0, "inexact": 0}

    def model_scene(x: np.ndarray) -> Scene:
        return with_parameters(scene, dict(zip(names, (float(v) for v in x), strict=True)))

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            counts["runs"] += 1
            s = model_scene(x)
            if jacobian == "exact":
                tr = trajectory_sensitivity(
                    s,
                    U,
                    period,
                    dt=dt,
                    q0=q0,
                    v0=v0,
                    integrator=integrator,
                    parameters=names,
                    backend=backend,
                    controller=controller,
                )
                cache[key] = (residual(tr.q, tr.wrench), jac(tr.dx_dp, tr.dwrench_dp))
                counts["inexact"] += not tr.exact
            else:
                cache[key] = (residual(*_run(s, U, period, dt, q0, v0, integrator, backend, controller)), None)
        return cache[key]

    def residual(Q: np.ndarray, W: np.ndarray) -> np.ndarray:
        r = [((Q[1:, q_idx] - joints[1:]) * w_joint).ravel()]
        if wrench is not None:
            r.append(((W[:, :L] - wrench) * w_wrench).ravel())
        return np.concatenate(r)

    def jac(dX: np.ndarray, dW: np.ndarray) -> np.ndarray:
        rows = [dX[1:, scene.arm_joints].reshape(-1, len(names)) * w_joint]
        if wrench is not None:
            rows.append((dW[:, :L] * w_wrench[None, None, :, None]).reshape(-1, len(names)))
        return np.vstack(rows)

    def fun(x: np.ndarray) -> np.ndarray:
        r = evaluate(x)[0]
        if not np.all(np.isfinite(r)):
            raise SimulationError("identify: a model run is not finite at these parameters")
        return r

    def exact_jac(x: np.ndarray) -> np.ndarray:
        counts["jacobians"] += 1
        J = evaluate(x)[1]
        assert J is not None
        return J

    try:
        fit = least_squares(
            fun,
            x0,
            jac=exact_jac if jacobian == "exact" else "2-point",
            bounds=(np.where(positions, -np.inf, 0.0), np.full(len(x0), np.inf)),
            x_scale=np.where(positions, np.maximum(np.abs(x0), POSITION_SCALE), np.abs(x0)),
            max_nfev=max_iterations,
            method="trf",
        )
    except SimulationError as exc:
        if "diverged" not in str(exc):  # (an argument the model refuses, not a divergence: as it is)
            raise
        raise SimulationError(
            f"identify: the model diverged during the fit ({exc}); start nearer, or shorten the record"
        ) from exc
    if jacobian == "finite-differences":
        counts["jacobians"] = int(fit.njev or 0)  # (its runs are counted in `runs`)
    J, r = fit.jac, fit.fun
    dof = max(r.size - len(x0), 1)
    s2 = float(r @ r) / dof
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((len(x0), len(x0)), np.inf)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    _warn_if_untrustworthy(names, fit.x, std, math.sqrt(s2), [p.unit for p in params], fit.active_mask, positions)
    if fit.status == 0:  # (the budget of runs spent before a convergence test passed)
        warnings.warn(
            f"identify: stopped after max_iterations = {max_iterations} runs of the model (residuals, not counting finite "
            f"differences) before converging; the estimate "
            "may not be the best fit: raise max_iterations",
            FitWarning,
            stacklevel=2,
        )
    best = model_scene(fit.x)
    n_joint = (U.shape[0]) * len(q_idx)
    joint_rms = math.sqrt(float(np.mean((r[:n_joint] / w_joint) ** 2)))
    wrench_rms = None
    if wrench is not None:
        rw = r[n_joint:].reshape(-1, 6) / w_wrench
        wrench_rms = (math.sqrt(float(np.mean(rw[:, :3] ** 2))), math.sqrt(float(np.mean(rw[:, 3:] ** 2))))
    return Identification(
        params,
        dict(zip(names, map(float, fit.x), strict=True)),
        dict(zip(names, map(float, std), strict=True)),
        cov,
        math.sqrt(s2),
        joint_rms,
        wrench_rms,
        best,
        jacobian,
        jacobian == "exact" and counts["inexact"] == 0,
        counts["runs"],
        counts["jacobians"],
        time.process_time() - cpu0,
        str(fit.message),
        dict(zip(names, map(float, x0), strict=True)),
        "the controller's derivative" if controller is not None else "an element's tangent",
    )


#: a weighted residual RMS above this says the model does not explain the data (≈ 1 when it does)
MISFIT = 3.0
#: [m] a grasp position's scale: the fit's step scale for one near 0, and the uncertainty above
#: which it counts as not determined by the data
POSITION_SCALE = 0.01


def _warn_if_untrustworthy(
    names: list[str], x: np.ndarray, std: np.ndarray, rms: float, units: list[str], active: np.ndarray, positions: np.ndarray
) -> None:
    """FitWarning: the model does not explain the data, or a parameter is not determined by them
    (its uncertainty as large as its value — a grasp position's: above :data:`POSITION_SCALE` —, or
    the fit stopped at its bound 0)."""
    bound = [n for n, a in zip(names, active, strict=True) if a]
    if bound:
        warnings.warn(
            f"identify: stopped at the bound 0: {', '.join(bound)} (the uncertainty reported ignores the bound); the data "
            "want a negative value: check the model (frames, noise, start) or leave it out",
            FitWarning,
            stacklevel=3,
        )
    if rms > MISFIT:
        warnings.warn(
            f"identify: the weighted residual RMS is {rms:.3g} (≈ 1 when the model explains the data within the noise given): "
            "check the wrench's frame (the grasp frame's axes, not the world's), the noise levels, the start state, the "
            "parameters fitted and the controller; the uncertainty reported assumes the model is right",
            FitWarning,
            stacklevel=3,
        )
    loose = [
        f"{n} = {v:.3g} ± {e:.3g} {u}"
        for n, v, e, u, a, position in zip(names, x, std, units, active, positions, strict=True)
        if not a and not e < (POSITION_SCALE if position else abs(v))
    ]
    if loose:
        warnings.warn(
            f"identify: not determined by these data (the uncertainty is as large as the value, or above "
            f"{POSITION_SCALE * 100:g} cm for a grasp position): {', '.join(loose)}; a record "
            "that excites it (motion across that axis, a load on it) or fewer parameters",
            FitWarning,
            stacklevel=3,
        )


def _run(
    scene: Scene,
    U: np.ndarray,
    period: float,
    dt: float | None,
    q0: np.ndarray,
    v0: np.ndarray,
    integrator: Any,
    backend: str | None,
    controller: Controller | None,
) -> tuple[np.ndarray, np.ndarray]:
    """(Q, W): a compiled run's samples (a rollout, or with a controller a closed-loop simulation
    sampled as the controller) and every link's wrench at them (G axes)."""
    if controller is None:
        run = rollout(scene, U[None], period=period, dt=dt, q0=q0, v0=v0, integrator=integrator, threads=1)
        if run.status[0] != "done":
            raise SimulationError(run.status[0])
        Q, V = run.q[0], run.v[0]
    else:
        h = period if dt is None else dt
        res = simulate(
            scene, len(U) * period, controller, integrator, dt=h, control_dt=period, save_every=round(period / h),
            q0=q0, v0=v0, backend=backend, accuracy_check="off", energy_check="off",
        )  # fmt: skip
        Q, V = res.q, res.v
    dyn = Dynamics(scene, backend)
    W = np.array([[e.G_f_G for e in dyn.element_states(q, v)] for q, v in zip(Q, V, strict=True)])
    return Q, W
