"""``coopdyn.simulate``: run a scene under a controller and return a :class:`Result`."""

from __future__ import annotations

import itertools
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .dynamics import Dynamics, Energy
from .errors import DivergenceError, SimulationError, SimulationInterrupted
from .integrators import AdaptiveIntegrator, Controller, Integrator, System, get_integrator
from .monitor import EnergyMonitor
from .scene import Scene


def simulate(
    scene: Scene,
    t_final: float,
    controller: Controller | None = None,
    integrator: str | Integrator = "rk4",
    dt: float = 1e-3,
    save_every: int = 1,
    q0: Any = None,
    v0: Any = None,
    progress: bool = False,
    max_speed: float = 1e4,
    energy_check: str = "warn",
    object_wrench: Callable[[float], np.ndarray] | None = None,
    backend: str | None = None,
) -> Result:
    """Simulate ``scene`` from t = 0 to ``t_final``.

    Args:
        scene: the scene.
        t_final: duration [s], ≥ 0.
        controller: ``controller(t, q, v) -> τ``, one torque/force per arm joint in scene order
            (``scene.n_actuated``) [N·m or N]; ``None`` applies none.
        integrator: a name from ``coopdyn.integrators.INTEGRATORS`` or an instance.
        dt: time step [s], > 0. The last step is shortened to end exactly at ``t_final``.
            Adaptive methods (``dopri5``, ``ros2_adaptive``) choose their own steps and land on
            the output grid ``k·dt·save_every``; ``dt`` is then also their first trial step.
        save_every: keep every k-th step (the initial and final states are always kept).
        q0, v0: initial state (nq,), (nv,); default ``scene.q0`` and ``scene.v0``.
        progress: show a progress bar.
        max_speed: a joint velocity above this [rad/s or m/s] is taken as divergence.
        energy_check: ``"warn"`` (default), ``"raise"`` or ``"off"``: the energy-balance monitor
            (:class:`coopdyn.monitor.EnergyMonitor`), evaluated about every 5 ms (the work is integrated every step); not
            run for ``exponential``, whose exact discretisation cannot go unstable.
        object_wrench: ``object_wrench(t) -> (6,)``: an external wrench on the object [N, N·m],
            world axes, at the object frame origin (disturbances, loads, contacts).
        backend: ``"native"`` (the compiled kernel), ``"python"`` or ``"auto"`` (see
            :mod:`coopdyn.backend`); ``None`` reads ``COOPDYN_BACKEND`` (default ``"auto"``).

    Returns:
        the saved trajectory, with readouts (wrenches, deformations, energies) and work counters.

    Raises:
        DivergenceError: when the state stops being finite or exceeds ``max_speed``; it carries
            the trajectory up to the failure and a stability diagnosis.
        SimulationInterrupted: on Ctrl-C (a ``KeyboardInterrupt``), carrying the trajectory so far.
        SimulationError: on invalid arguments. ControllerError: on a bad controller output.
    """
    if not isinstance(scene, Scene):
        raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
    t_final = _number(t_final, "t_final")
    dt = _number(dt, "dt")
    if t_final < 0.0:
        raise SimulationError(f"t_final must be >= 0 [s], got {t_final}")
    if dt <= 0.0:
        raise SimulationError(f"dt must be > 0 [s], got {dt}")
    if not isinstance(save_every, int | np.integer) or isinstance(save_every, bool) or save_every < 1:
        raise SimulationError(f"save_every must be an integer >= 1, got {save_every!r}")
    if energy_check not in ("warn", "raise", "off"):
        raise SimulationError(f"energy_check must be 'warn', 'raise' or 'off', got {energy_check!r}")
    method = get_integrator(integrator)
    q, v = scene.check_state(scene.q0 if q0 is None else q0, scene.v0 if v0 is None else v0)

    system = System(Dynamics(scene, backend), controller, object_wrench)
    run = _Run(scene, system, method, dt, save_every, t_final, max_speed)
    monitor = None
    if energy_check != "off" and not method.exact_discretisation:
        monitor = EnergyMonitor(system, 0.0, q, v, every=max(1, round(5e-3 / dt)), mode=energy_check)
    bar = _progress_bar(t_final, method.name) if progress else None
    cpu0 = time.process_time()
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # a blow-up is reported as a DivergenceError
            if method.adaptive:
                _adaptive_loop(run, q, v, monitor, bar)
            else:
                _fixed_loop(run, q, v, monitor, bar)
    except KeyboardInterrupt as exc:
        if isinstance(exc, SimulationInterrupted):
            raise
        run.cpu_time = time.process_time() - cpu0
        partial = run.result("interrupted")
        raise SimulationInterrupted(
            f"interrupted at t = {partial.t[-1]:.6g} s of {t_final:g} s; the trajectory so far is in this exception's .result",
            result=partial,
        ) from None
    finally:
        if bar is not None:
            bar.close()
    run.cpu_time = time.process_time() - cpu0
    return run.result()


MAX_STEPS = 10**9  #: a run asking for more steps is refused (it would not finish)


class _Run:
    """Bookkeeping of one simulation: the output grid and what has been saved."""

    def __init__(
        self, scene: Scene, system: System, method: Integrator, dt: float, save_every: int, t_final: float, max_speed: float
    ) -> None:
        self.scene, self.system, self.method, self.dt, self.t_final = scene, system, method, dt, t_final
        self.max_speed = max_speed
        self._max_speed_sq = max_speed * max_speed
        n_steps = max(0, math.ceil(t_final / dt - 1e-9))
        self.n_steps = n_steps
        if n_steps > MAX_STEPS:
            raise SimulationError(
                f"t_final / dt = {t_final:g} / {dt:g} asks for {n_steps:.3g} steps (more than {MAX_STEPS:.0e}); "
                "shorten the run or enlarge dt"
            )
        self.save_every = save_every
        self.t: list[float] = []
        self.q: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.tau: list[np.ndarray | None] = []  # None: pending, see save()
        self.n_accepted = 0
        self.n_rejected = 0
        self.cpu_time = 0.0

    def save(self, t: float, q: np.ndarray, v: np.ndarray, step_follows: bool = True) -> None:
        """Keep a sample. When a step from it follows, its torque is taken from that step's own
        controller call by :meth:`settle_torque` instead of calling the controller twice."""
        self.t.append(t)
        self.q.append(q)
        self.v.append(v)
        self.tau.append(None if step_follows else self.system.torque(t, q, v))

    def settle_torque(self) -> None:
        """Fill the last sample's pending torque: reused from the step just taken from it, or
        computed when that step recorded no evaluation there (``exponential`` evaluates no dynamics)."""
        if self.tau and self.tau[-1] is None:
            tau = self.system.recorded_torque(self.q[-1], self.v[-1])
            self.tau[-1] = self.system.torque(self.t[-1], self.q[-1], self.v[-1]) if tau is None else tau

    def check(self, t: float, q: np.ndarray, v: np.ndarray, h: float) -> None:
        """Raise DivergenceError when (q, v) is not finite or too fast."""
        # Fast path, one dot product each: |v|₂ ≤ max_speed implies max |vᵢ| ≤ max_speed; NaN and
        # overflow fail it and fall through to the exact tests.
        if float(v @ v) <= self._max_speed_sq and math.isfinite(float(q @ q)):
            return
        if (not v.size or np.abs(v).max() <= self.max_speed) and np.all(np.isfinite(q)):
            return
        from .stability import advise

        what = (
            "non-finite"
            if not np.all(np.isfinite(v)) or not np.all(np.isfinite(q))
            else f"faster than max_speed = {self.max_speed:g}"
        )
        try:
            last_q, last_v = self.q[-1], self.v[-1]
            advice = advise(self.scene, last_q, last_v, self.system.controller, dt=h)
            diagnosis = (
                f"ω_max = {advice.omega_max:.4g} rad/s, ω_max·dt = {advice.omega_max * h:.3g}; "
                f"methods predicted stable at dt = {h:g} s: {advice.stable_at(h)}"
            )
        except Exception as exc:  # the diagnosis must never hide the divergence itself
            advice, diagnosis = None, f"(no stability diagnosis: {exc})"
        partial = self.result("diverged")
        raise DivergenceError(
            f"the simulation diverged at t = {t:.6g} s with {self.method.name} at dt = {h:g} s: the state became {what}. "
            f"{diagnosis}. The trajectory up to t = {partial.t[-1]:.6g} s is in this error's .result",
            result=partial,
            advice=advice,
        )

    def result(self, status: str = "completed") -> Result:
        s = self.system
        self.settle_torque()  # a run stopped right after a save
        n = len(self.t)
        return Result(
            scene=self.scene,
            t=np.array(self.t),
            q=np.array(self.q).reshape(n, self.scene.nq),
            v=np.array(self.v).reshape(n, self.scene.nv),
            tau=np.array(self.tau).reshape(n, self.scene.n_actuated),
            integrator=self.method.name,
            dt=self.dt,
            n_rhs=s.n_rhs,
            cpu_time=self.cpu_time,
            n_jac=s.n_jac,
            n_factor=s.n_factor,
            n_steps=self.n_accepted,
            n_rejected=self.n_rejected,
            status=status,
        )


def _fixed_loop(run: _Run, q: np.ndarray, v: np.ndarray, monitor: EnergyMonitor | None, bar: Any) -> None:
    method, system, dt, n_steps = run.method, run.system, run.dt, run.n_steps
    t, every = 0.0, run.save_every
    for k in range(n_steps + 1):
        if k % every == 0 or k == n_steps:
            run.save(t, q, v, step_follows=k < n_steps)
        if k == n_steps:
            break
        h = min(dt, run.t_final - k * dt)
        system.begin_step()
        q_new, v_new = method.step(system, t, q, v, h)
        run.settle_torque()
        t_new = run.t_final if k + 1 == n_steps else (k + 1) * dt
        run.check(t_new, q_new, v_new, h)
        if monitor is not None:
            monitor.after_step(t, q, v, h, t_new, q_new, v_new)
        t, q, v = t_new, q_new, v_new
        run.n_accepted += 1
        if bar is not None and (k & 255) == 0:
            bar.update(t - bar.n)
    if monitor is not None:
        monitor.finish(t, q, v)
    if bar is not None:
        bar.update(run.t_final - bar.n)


def _adaptive_loop(run: _Run, q: np.ndarray, v: np.ndarray, monitor: EnergyMonitor | None, bar: Any) -> None:
    """Error-controlled steps that land exactly on the output times."""
    method, system = run.method, run.system
    assert isinstance(method, AdaptiveIntegrator)
    t, h = 0.0, run.dt
    run.save(t, q, v)
    steps = itertools.chain(range(run.save_every, run.n_steps, run.save_every), [run.n_steps])
    outputs = (min(k * run.dt, run.t_final) for k in steps)
    for t_out in outputs:
        if t_out <= t:
            continue
        while t < t_out:
            h_try = min(h, t_out - t)
            if t + h_try * (1.0 + 1e-9) >= t_out:  # land exactly on the output time
                h_try = t_out - t
            system.begin_step()
            out = method.attempt(system, t, q, v, h_try)
            run.settle_torque()
            h = method.next_step(h_try, out.error)
            if not (out.error <= 1.0):  # also rejects NaN
                run.n_rejected += 1
                if h < method.h_min or not np.isfinite(out.error):
                    run.check(t + h_try, out.q, out.v, h_try)  # non-finite → DivergenceError
                    raise SimulationError(
                        f"{method.name} could not meet rtol = {method.rtol:g}, atol = {method.atol:g} at t = {t:.6g} s: "
                        f"the step fell below h_min = {method.h_min:g} s"
                    )
                continue
            t_new = t_out if h_try == t_out - t else t + h_try
            run.check(t_new, out.q, out.v, h_try)
            if monitor is not None:
                monitor.after_step(t, q, v, h_try, t_new, out.q, out.v)
            t, q, v = t_new, out.q, out.v
            run.n_accepted += 1
        run.save(t, q, v, step_follows=t < run.t_final)
        if bar is not None:
            bar.update(t - bar.n)
    if monitor is not None:
        monitor.finish(t, q, v)


def _number(x: Any, name: str) -> float:
    try:
        value = float(x)
    except (TypeError, ValueError) as exc:
        raise SimulationError(f"{name} must be a number [s], got {x!r}") from exc
    if not math.isfinite(value):
        raise SimulationError(f"{name} must be finite [s], got {value}")
    return value


def _progress_bar(t_final: float, desc: str) -> Any:
    from ._optional import require

    tqdm = require("tqdm", "the progress bar", "tqdm").tqdm
    return tqdm(
        total=t_final, desc=desc, unit="s", leave=False, bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} s [{elapsed}<{remaining}]"
    )


@dataclass(frozen=True, eq=False)
class Result:
    """A saved trajectory and its readouts.

    Attributes:
        scene: the simulated scene.
        t: sample times (n,) [s].
        q, v: configurations (n, nq) and velocities (n, nv).
        tau: controller output at the samples (n, n_actuated) [N·m or N].
        integrator: name of the method; dt: its step (adaptive: output interval) [s].
        n_rhs: right-hand-side evaluations; cpu_time: CPU time of the integration loop [s].
        n_jac, n_factor: Jacobian evaluations and factorisations (implicit methods).
        n_steps, n_rejected: accepted and rejected steps.
    """

    scene: Scene
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    integrator: str
    dt: float
    n_rhs: int
    cpu_time: float
    n_jac: int = 0
    n_factor: int = 0
    n_steps: int = 0
    n_rejected: int = 0
    status: str = "completed"  #: "completed", "interrupted" (Ctrl-C) or "diverged"
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    @cached_property
    def _dynamics(self) -> Dynamics:
        return Dynamics(self.scene)

    def _link(self, i: int) -> int:
        n = len(self.scene.links)
        if not -n <= i < n:
            raise SimulationError(f"interconnection index {i} out of range: the scene has {n}")
        return i % n

    def _springs(self) -> list[list[Any]]:
        if "springs" not in self._cache:
            dyn = self._dynamics
            self._cache["springs"] = [dyn.springs(q, v) for q, v in zip(self.q, self.v, strict=True)]
        return self._cache["springs"]

    def _frame_rotations(self, frame: int) -> np.ndarray:
        model, data = self.scene.model, self._dynamics.data
        out = np.empty((len(self.t), 3, 3))
        for k, q in enumerate(self.q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, frame).rotation
        return out

    def _world(self, frame: int, local: np.ndarray) -> np.ndarray:
        R = self._frame_rotations(frame)
        return np.concatenate([np.einsum("nij,nj->ni", R, local[:, :3]), np.einsum("nij,nj->ni", R, local[:, 3:])], axis=1)

    def wrench(self, i: int) -> np.ndarray:
        """Wrench of interconnection i on the object (n, 6) [N, N·m]: force, then moment about the
        grasp point, in world-aligned axes."""
        i = self._link(i)
        local = np.array([s[i].G_f_G for s in self._springs()])
        return self._world(self.scene.links[i].grasp_frame, local)

    def arm_wrench(self, i: int) -> np.ndarray:
        """Wrench of interconnection i on its arm (n, 6) [N, N·m], about the tip point, world axes."""
        i = self._link(i)
        local = np.array([s[i].T_f_T for s in self._springs()])
        return self._world(self.scene.links[i].tip_frame, local)

    def deformation(self, i: int) -> np.ndarray:
        """Deformation e = log6(T_M_G) of interconnection i (n, 6) [m, rad], in tip-frame axes."""
        i = self._link(i)
        return np.array([s[i].e for s in self._springs()])

    def elastic_energy(self, i: int) -> np.ndarray:
        """½ eᵀ K e of interconnection i (n,) [J]."""
        e = self.deformation(i)
        K = self.scene.links[self._link(i)].K
        return 0.5 * np.einsum("ni,ij,nj->n", e, K, e)

    def energy(self) -> Energy:
        """Kinetic, gravity and elastic energy along the trajectory, each (n,) [J]."""
        dyn = self._dynamics
        parts = np.array([dyn.energy(q, v) for q, v in zip(self.q, self.v, strict=True)])
        return Energy(parts[:, 0], parts[:, 1], parts[:, 2])

    def frame_position(self, frame: str | int) -> np.ndarray:
        """World position of a frame of the scene model (n, 3) [m]."""
        model = self.scene.model
        if isinstance(frame, str):
            if not model.existFrame(frame):
                from .errors import did_you_mean

                raise SimulationError(f"no frame {frame!r} in the scene.{did_you_mean(frame, [f.name for f in model.frames])}")
            frame = int(model.getFrameId(frame))
        data = self._dynamics.data
        out = np.empty((len(self.t), 3))
        for k, q in enumerate(self.q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, frame).translation
        return out

    def grasp_points(self) -> np.ndarray:
        """World positions of the grasp frames (n, N, 3) [m]."""
        return np.stack([self.frame_position(lk.grasp_frame) for lk in self.scene.links], axis=1)

    def wrenches(self) -> np.ndarray:
        """Every interconnection's wrench on the object (n, N, 6) [N, N·m] (see :meth:`wrench`)."""
        return np.stack([self.wrench(i) for i in range(len(self.scene.links))], axis=1)

    def wrench_split(self) -> tuple[np.ndarray, np.ndarray]:
        """The interconnection wrenches on the object split into the part that moves the object
        and the internal part (:func:`coopdyn.grasp.split`), each (n, N, 6) [N, N·m]."""
        from .grasp import grasp_matrix, split

        W, P = self.wrenches(), self.grasp_points()
        parts = [split(grasp_matrix(p), w) for p, w in zip(P, W, strict=True)]
        return np.array([s.moving for s in parts]), np.array([s.internal for s in parts])

    def squeeze(self) -> np.ndarray:
        """Internal (squeeze) force at each grasp (n, N) [N], positive = compression."""
        from .grasp import squeeze_force

        return np.array([squeeze_force(p, w) for p, w in zip(self.grasp_points(), self.wrenches(), strict=True)])

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the trajectory atomically (temporary file, then rename): ``.npz`` (t, q, v, tau
        and the interconnection wrenches) or ``.csv`` (one row per sample). Returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        W = self.wrenches().reshape(len(self.t), -1)
        if path.suffix == ".npz":
            with open(tmp, "wb") as f:
                np.savez(f, t=self.t, q=self.q, v=self.v, tau=self.tau, wrenches=W, integrator=self.integrator, dt=self.dt)
        elif path.suffix == ".csv":
            qn = [f"q[{i}]" for i in range(self.scene.nq)]
            vn = [f"v[{i}]" for i in range(self.scene.nv)]
            joints = [name for a in self.scene.arms for name in a.joint_names]
            taun = [f"tau[{joints[i] if len(joints) == self.scene.n_actuated else i}]" for i in range(self.scene.n_actuated)]
            wn = [f"link{i}_{c}" for i in range(len(self.scene.links)) for c in ("fx", "fy", "fz", "mx", "my", "mz")]
            header = ",".join(["t", *qn, *vn, *taun, *wn])
            np.savetxt(tmp, np.column_stack([self.t, self.q, self.v, self.tau, W]), delimiter=",", header=header, comments="")
        else:
            raise SimulationError(f"unknown result format {path.suffix!r}: use .npz or .csv")
        os.replace(tmp, path)
        return path

    def tracking_error(self, reference: Callable[[float], Any]) -> np.ndarray:
        """Object position error ‖p − p_d‖ (n,) [m] against ``reference(t).position`` (e.g. a
        :class:`coopdyn.cooperative.GripLiftOscillate`) or ``reference(t)`` returning (3,)."""
        desired = []
        for t in self.t:
            ref = reference(float(t))
            desired.append(np.asarray(getattr(ref, "position", ref), dtype=float))
        return np.linalg.norm(self.object_position() - np.array(desired), axis=1)

    def tip_position(self, arm: int | str) -> np.ndarray:
        """World position of an arm's tip frame (n, 3) [m]."""
        return self.frame_position(self.scene.arms[self.scene.arm_index(arm)].tip_frame)

    def object_position(self) -> np.ndarray:
        """World position of the object frame origin (n, 3) [m]."""
        return self.frame_position(self.scene.object_frame)


def save_partial(error: BaseException, folder: str | os.PathLike[str]) -> list[Path]:
    """After a ``DivergenceError`` or ``SimulationInterrupted``: write the trajectory it carries
    (``trajectory.npz``, ``trajectory.csv``) and the message (``diagnosis.txt``) to ``folder``,
    atomically. Returns the paths written."""
    result = getattr(error, "result", None)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    if isinstance(result, Result) and len(result.t):
        written += [result.save(folder / "trajectory.npz"), result.save(folder / "trajectory.csv")]
    note = folder / "diagnosis.txt"
    tmp = note.with_name(".diagnosis.txt.tmp")
    advice = getattr(error, "advice", None)
    tmp.write_text(f"{type(error).__name__}: {error}\n" + (f"\n{advice}\n" if advice is not None else ""))
    os.replace(tmp, note)
    written.append(note)
    return written
