"""One run of a simulation: its arguments checked, its bookkeeping (:class:`_Run`: the output
grid, the samples, the errors a run raises with its partial result) and the loops that step it —
compiled (:mod:`coopdyn.compiled`), fixed-step and adaptive in Python. :func:`coopdyn.simulate`
and :class:`coopdyn.Simulator` both run through :func:`execute`."""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from typing import Any

import numpy as np

from . import _progress, _signals, _validate, compiled
from . import accuracy as screening
from .budget import step_count
from .closed_loop import System
from .errors import (
    ControllerError,
    DivergenceError,
    EnergyBalanceError,
    EnergyBalanceWarning,
    GraspGeometryError,
    KernelError,
    LogMapWarning,
    SimulationError,
    SimulationInterrupted,
    StepBudgetError,
    StepMatrixError,
    StepSizeError,
)
from .integrators import AdaptiveIntegrator, Attempt, Integrator
from .model.scene import Scene
from .monitor import ENERGY_RTOL, EnergyMonitor, violation_message
from .result import Result, SampleFiles
from .stability import ADVISED, advise


def _checked_duration(t_final: Any) -> float:
    """``t_final`` checked: a number ≥ 0 [s]."""
    if type(t_final) is float and 0.0 <= t_final < math.inf:  # the common case, without the general checks
        return t_final
    t_final = _validate.number(t_final, "t_final", "s", SimulationError)
    if t_final < 0.0:
        raise SimulationError(f"t_final must be >= 0 [s], got {t_final}")
    return t_final


def _checked_steps(dt: Any, save_every: Any, max_speed: Any) -> tuple[float, int, float]:
    """(dt [s], save_every, max_speed [rad/s or m/s]) checked, as simulate and Simulator take them."""
    dt = _validate.number(dt, "dt", "s", SimulationError)
    if not dt >= MIN_DT:
        raise SimulationError(
            f"dt must be >= {MIN_DT:g} [s] (a step shorter than this is below the clock's resolution), got {dt}"
        )
    save_every = _validate.count(save_every, "save_every", SimulationError)
    max_speed = _validate.number(max_speed, "max_speed", "rad/s or m/s", SimulationError)
    if max_speed <= 0.0:
        raise SimulationError(f"max_speed must be > 0 [rad/s or m/s], got {max_speed}")
    return dt, save_every, max_speed


def _checked_choice(name: str, value: Any, valid: tuple[str, ...]) -> str:
    """``value`` if it is one of ``valid``, else the SimulationError naming them."""
    if not isinstance(value, str) or value not in valid:
        raise SimulationError(f"{name} must be one of {list(valid)}, got {_validate._short(value)}")
    return value


def _control_period(control_dt: Any, dt: float, method: Integrator) -> float | None:
    """``control_dt`` checked [s]: None, or a period > 0 that a fixed-step method's steps land on."""
    if control_dt is None:
        return None
    period = _validate.number(control_dt, "control_dt", "s", SimulationError)
    if not period >= MIN_DT:
        raise SimulationError(
            f"control_dt must be None (a controller called at every evaluation) or >= {MIN_DT:g} [s], got {period}"
        )
    ratio = period / dt
    if not ratio < 1e15:  # (also inf: a period beyond any run's count of steps)
        raise SimulationError(
            f"control_dt = {period:g} s is {ratio:.3g} steps of dt = {dt:g} s: the controller would be called once; give a "
            "period a run can count, or None"
        )
    if not method.adaptive:
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9 * ratio:
            finer = period / math.ceil(ratio * (1.0 - 1e-9) + 1e-9) if ratio >= 1.0 else period
            raise SimulationError(
                f"control_dt = {_exact(period)} s must be a whole multiple of dt = {_exact(dt)} s: {method.name} takes fixed "
                "steps and "
                f"each sample instant k·control_dt must be the start of a step (the held torque changes there). "
                f"Use dt = {finer:.6g} s (or another divisor of control_dt), "
                "or an adaptive method (dopri5, dop853, ros2_adaptive)"
            )
        return round(ratio) * dt  # the exact multiple: sample k is step k·ratio's start, however large k grows
    return period


def _exact(x: float) -> str:
    """``x`` as ``:g`` prints it when that reads back as ``x``, else all its digits (a float32's
    0.001 is 0.0010000000474974513: printed as 0.001 it would contradict the message it is in)."""
    short = f"{x:g}"
    return short if float(short) == x else repr(float(x))


def _check_samples(t_final: float, control_dt: float | None, max_steps: int | None) -> None:
    """Refuse, before it starts, a run whose control samples alone (each starts a step) exceed
    ``max_steps``."""
    if control_dt is None or max_steps is None:
        return
    samples = t_final / control_dt
    if samples > max_steps:
        raise SimulationError(
            f"control_dt = {control_dt:g} s over t_final = {t_final:g} s is {samples:.3g} controller samples, each the start "
            f"of a step: more than max_steps = {max_steps:,}. Give a longer control_dt (a robot's controller runs at "
            "about 1 kHz: 1e-3 s), or max_steps=None"
        )


STREAM_BATCH = 1024  #: samples kept in memory between writes to ``stream_to``
MIN_DT = 1e-12  #: [s] the shortest step ``simulate`` takes
ENERGY_CHECKS = ("warn", "raise", "off")


class _Run:
    """Bookkeeping of one simulation: the output grid and what has been saved."""

    def __init__(
        self,
        scene: Scene,
        system: System,
        method: Integrator,
        dt: float,
        save_every: int,
        t_final: float,
        max_speed: float,
        start: tuple[np.ndarray, np.ndarray],
    ) -> None:
        self.scene, self.system, self.method, self.dt, self.t_final = scene, system, method, dt, t_final
        self.start = start  #: (q, v) at t = 0 (a streamed run drops its samples as it goes)
        self.max_speed = max_speed
        self._max_speed_sq = max_speed * max_speed
        if method.adaptive and method.h_min > dt:  # type: ignore[attr-defined]
            raise SimulationError(
                f"{method.name}'s h_min = {_exact(method.h_min)} s is above dt = {_exact(dt)} s, the first step it tries: "  # type: ignore[attr-defined]
                "give a smaller h_min (the smallest step it may take) or a larger dt"
            )
        v0 = start[1]
        if not float(v0 @ v0) <= self._max_speed_sq and float(np.abs(v0).max(initial=0.0)) > max_speed:
            i = int(np.argmax(np.abs(v0)))
            raise SimulationError(
                f"v0[{i}] = {_exact(float(v0[i]))} [rad/s or m/s] is faster than max_speed = {_exact(max_speed)}, the speed a "
                "run takes for divergence: give a slower start or a larger max_speed"
            )
        self.n_steps = step_count(t_final, dt)
        self.save_every = save_every
        self.t: list[float] = []
        self.q: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.tau: list[np.ndarray | None] = []  # None: pending, see save()
        self.n_accepted = 0
        self.n_rejected = 0
        self.cpu_time = 0.0
        self.ws = method.workspace(system)  # the method's own per-run scratch
        self._warned_links: set[int] = set()
        self.loop = "python"
        self.budget: int | None = None  # an adaptive method's limit on attempted steps
        self.stream: SampleFiles | None = None  # samples go to files instead of these lists

    def flush(self, keep_last: bool = True) -> None:
        """Move the saved samples (all but the last, whose torque may be pending) to the stream."""
        assert self.stream is not None
        m = len(self.t) - (1 if keep_last else 0)
        if m <= 0:
            return
        with _signals.interrupts_deferred():  # written and dropped together: no sample lost or doubled
            self.stream.append(np.array(self.t[:m]), np.array(self.q[:m]), np.array(self.v[:m]), np.array(self.tau[:m]))
            del self.t[:m], self.q[:m], self.v[:m], self.tau[:m]

    def over_budget(self, t: float) -> StepBudgetError | None:
        """The error to raise when an adaptive run has used up its step budget, else None."""
        attempts = self.n_accepted + self.n_rejected
        if self.budget is None or attempts < self.budget or not self.method.adaptive:
            return None
        partial = self.result("stopped")
        return StepBudgetError(
            f"{self.method.name} took {attempts:,} steps (max_steps = {self.budget:,}) and reached only t = {t:.6g} s of "
            f"{self.t_final:g} s: its steps shrank to follow a fast mode (mean step {t / max(self.n_accepted, 1):.3g} s). "
            "An L-stable method (implicit_euler, ros2) steps over stiff modes; coopdyn.advise(scene) lists what is stable "
            "at which dt. Pass max_steps=None to let it run",
            result=partial,
        )

    def step_too_small(self, t: float) -> StepSizeError:
        """The error to raise when an adaptive method's step fell below its h_min at ``t``."""
        m = self.method
        return StepSizeError(
            f"{m.name} could not meet rtol = {m.rtol:g}, atol = {m.atol:g} at t = {t:.6g} s: the step fell below "  # type: ignore[attr-defined]
            f"h_min = {m.h_min:g} s. A fast mode it cannot step over, or tolerances tighter than round-off: an L-stable "  # type: ignore[attr-defined]
            "method (implicit_euler, ros2) steps over stiff modes; coopdyn.advise(scene) lists what is stable at which dt",
            result=self.result("stopped"),
        )

    def save(self, t: float, q: np.ndarray, v: np.ndarray, step_follows: bool = True) -> None:
        """Keep a sample. When a step from it follows, its torque is taken from that step's own
        controller call by :meth:`settle_torque` instead of calling the controller twice."""
        self.t.append(t)
        self.q.append(q)
        self.v.append(v)
        self.tau.append(None if step_follows else self.system.torque(t, q, v))
        if self.stream is not None and len(self.t) > STREAM_BATCH:
            self.flush()

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
        what = (
            "non-finite"
            if not np.all(np.isfinite(v)) or not np.all(np.isfinite(q))
            else f"faster than max_speed = {self.max_speed:g} rad/s or m/s"
        )
        try:
            last_q, last_v = self.q[-1], self.v[-1]
            names = ADVISED if self.method.name in ADVISED else (*ADVISED, self.method.name)
            rho_inf = getattr(self.method, "rho_inf", None) if self.method.name == "generalized_alpha" else None
            advice = advise(self.scene, last_q, last_v, self.system.controller, names, dt=h, rho_inf=rho_inf)
            diagnosis = advice.diagnosis(self.method.name, h)
        except Exception as exc:  # the diagnosis must never hide the divergence itself
            advice, diagnosis = None, f"(no stability diagnosis: {exc})"
        # the loop at the start (by the blow-up the state is far from any linearisation): one
        # linearisation, its controller probed 4·nv times (its compiled twin, if any), for both diagnoses
        loop = compiled.start_loop(self.system, self.start[0], self.start[1])
        period = self.system.control_dt
        try:
            mode = screening.unstable_mode(self.system, self.start[0], self.start[1], t, loop) if loop is not None else ""
            hold = screening.sampled_instability(loop, period) if loop is not None and period else None
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):  # (never hiding the divergence itself)
            mode, hold = "", None
        if mode:
            diagnosis += f". {screening.UNSTABLE_AT_START}: linearised exactly there, it has {mode}"
        if hold is not None and hold.explains(t):  # (the methods' stability is the continuous loop's: in .advice)
            cause = (
                f"The {hold.sentence.removeprefix('the ')} (this error's .advice has the methods' stability with the "
                "controller applied continuously)"
            )
        else:
            cause = f"At the last saved state, {diagnosis}"
            if hold is not None:
                cause += f". Besides, {hold.sentence} — slowly: alone it takes {hold.seconds():.3g} s to grow ×1000"
        partial = self.result("diverged")
        raise DivergenceError(
            f"the simulation diverged at t = {t:.6g} s with {self.method.name} at dt = {h:g} s: the state became {what}. {cause}",
            result=partial,
            advice=advice,
        )

    def after_step(self, t: float) -> None:
        """Warn (once per interconnection) when a deformation's rotation passed 0.9π [rad] during
        the step that ended at ``t`` [s]: at π the SE(3) logarithm jumps, and with it the elastic
        energy of an anisotropic or coupled K."""
        dynamics = self.system.dynamics
        alarm = dynamics.rotation_alarm()
        if alarm is None:
            return
        dynamics.clear_rotation_alarm()
        link, theta = alarm
        if link not in self._warned_links:
            self._warned_links.add(link)
            self.warn_rotation(link, theta, t)

    def warn_rotation(self, link: int, theta: float, t: float) -> None:
        """The log-map warning of :meth:`after_step`, attributed to the caller of ``simulate``."""
        name = self.scene.elements[link].name
        _progress.warn(
            f"interconnection {name!r} (index {link}): its rotation deformation reached {theta:.3f} rad "
            f"({theta / math.pi:.2f}π) at t ≈ {t:.6g} s. At π the SE(3) logarithm jumps: the wrench flips and, "
            "with an anisotropic or coupled K, the elastic energy jumps too. A real grasp twisted this far has "
            "let go; check the scene (stiffness, controller) or use an isotropic rotational K",
            LogMapWarning,
            stacklevel=None,
        )

    def step_failed(self, exc: StepMatrixError, t: float, h: float) -> StepMatrixError:
        """The step-matrix error with the time, the method and what to change."""
        partial = self.result("diverged")
        return StepMatrixError(
            f"{exc} at t = {t:.6g} s ({self.method.name}, dt = {h:g} s). M is positive definite and the "
            "interconnections' K̃, D̃ are positive semi-definite, so a negative joint gain from the controller's "
            "gains() or a state that is no longer finite made it so: check the controller's gains, or run an "
            "explicit method (rk4, dopri5) to see where the state goes",
            result=partial,
        )

    def result(self, status: str = "completed") -> Result:
        s = self.system
        # A Ctrl-C can land between the appends of one save: keep the samples saved whole.
        n = min(len(self.t), len(self.q), len(self.v), len(self.tau))
        del self.t[n:], self.q[n:], self.v[n:], self.tau[n:]
        try:
            self.settle_torque()  # a run stopped right after a save
        except Exception:
            if status == "completed":  # (e.g. a zero-length run: the controller's one call is its check)
                raise
            if self.tau and self.tau[-1] is None:
                self.tau[-1] = np.full(self.scene.n_actuated, np.nan)
        if self.stream is not None:
            self.flush(keep_last=False)
            t, q, v, tau = self.stream.arrays()
        else:
            t = np.array(self.t)
            q = np.array(self.q).reshape(n, self.scene.nq)
            v = np.array(self.v).reshape(n, self.scene.nv)
            tau = np.array(self.tau).reshape(n, self.scene.n_actuated)
        return Result(
            scene=self.scene,
            t=t,
            q=q,
            v=v,
            tau=tau,
            integrator=self.method.name,
            dt=self.dt,
            n_rhs=s.n_rhs,
            cpu_time=self.cpu_time,
            n_jac=s.n_jac,
            n_factor=s.n_factor,
            n_steps=self.n_accepted,
            n_rejected=self.n_rejected,
            status=status,
            backend=s.dynamics.backend,
            loop=self.loop,
        )


def execute(run: _Run, config: dict[str, Any] | None, monitor: EnergyMonitor | None, bar: Any, cpu0: float) -> Result:
    """Step ``run`` from its start to its end — in the compiled loop built from ``config``, or
    in Python when it is None (``monitor``: the Python loop's energy monitor) — and return its
    :class:`Result`; ``cpu0``: the process time its CPU time counts from. A Ctrl-C is a
    :class:`SimulationInterrupted` with the samples so far; ``bar`` is closed however it ends."""
    q, v = run.start
    try:
        with np.errstate(over="ignore", invalid="ignore"), _progress.showing(bar):  # a blow-up: a DivergenceError
            if config is not None:
                _compiled_loop(run, config, bar)
            elif run.method.adaptive:
                _adaptive_loop(run, q, v, monitor, bar)
            else:
                _fixed_loop(run, q, v, monitor, bar)
        run.cpu_time = time.process_time() - cpu0
        return run.result()
    except KeyboardInterrupt as exc:
        if isinstance(exc, SimulationInterrupted):
            raise
        raise interruption(run, cpu0) from None
    except BaseException:
        if run.stream is not None:  # any other stop: the files are cut to the samples made
            with contextlib.suppress(Exception):
                run.result("stopped")
        raise
    finally:
        if bar is not None:
            bar.close()


def interruption(run: _Run, cpu0: float) -> SimulationInterrupted:
    """What a Ctrl-C during ``run`` raises: a :class:`SimulationInterrupted` carrying the samples
    saved so far (``cpu0``: the process time its CPU time counts from)."""
    with _signals.interrupts_deferred(reraise=False):  # a second Ctrl-C cannot cut the partial result
        run.cpu_time = time.process_time() - cpu0
        done = bool(run.t) and run.t[-1] >= run.t_final and len(run.t) == len(run.q) == len(run.v) == len(run.tau)
        partial = run.result("completed" if done else "interrupted")
    reached = f"at t = {partial.t[-1]:.6g} s" if len(partial.t) else "before the first sample"
    return SimulationInterrupted(f"interrupted {reached} of {run.t_final:g} s", result=partial)


def take_samples(run: _Run, native: Any) -> None:
    """A compiled run's samples so far and its counters, from its loop ``native`` into ``run``."""
    samples = compiled.samples(native, run.scene)
    run.t, run.q, run.v = samples.t.tolist(), list(samples.q), list(samples.v)
    run.tau = list(samples.tau)
    if samples.pending:
        run.tau[-1] = None
    s = run.system
    s.n_rhs, s.n_jac, s.n_factor = samples.n_rhs, samples.n_jac, samples.n_factor
    run.n_accepted, run.n_rejected = samples.n_accepted, samples.n_rejected


def _fixed_loop(run: _Run, q: np.ndarray, v: np.ndarray, monitor: EnergyMonitor | None, bar: Any) -> None:
    method, system, dt, n_steps = run.method, run.system, run.dt, run.n_steps
    t, every = 0.0, run.save_every
    for k in range(n_steps + 1):
        if k % every == 0 or k == n_steps:
            run.save(t, q, v, step_follows=k < n_steps)
        if k == n_steps:
            break
        h = min(dt, run.t_final - k * dt)
        system.begin_step(t, q, v)
        try:
            q_new, v_new = method.step(system, t, q, v, h, run.ws)
        except StepMatrixError as exc:
            raise run.step_failed(exc, t, h) from None
        run.settle_torque()
        t_new = run.t_final if k + 1 == n_steps else (k + 1) * dt
        run.check(t_new, q_new, v_new, h)
        run.after_step(t_new)
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


def _compiled_loop(
    run: _Run, config: dict[str, Any], bar: Any, native: Any = None, first: tuple[int, list[Any]] | None = None
) -> None:
    """The whole run in the compiled loop, chunk by chunk (see :mod:`coopdyn.compiled`), in
    ``native`` (a loop built from ``config``, at its start) or a new one; ``first``: the status
    and events of its first chunk when the caller has advanced it already."""
    if native is None:
        native = run.system.dynamics.compiled_loop(config)  # type: ignore[attr-defined]
    status, chunk = compiled.RUNNING, compiled.FIRST_CHUNK
    try:
        while status == compiled.RUNNING:
            wall = time.perf_counter()
            if run.budget is not None and run.method.adaptive:  # no chunk past the step budget
                chunk = max(1, min(chunk, run.budget - run.n_accepted - run.n_rejected))
            if first is not None:
                (status, events), first = first, None
            else:
                status = native.advance(chunk)
                events = native.take_events()
            chunk = compiled.next_chunk(chunk, time.perf_counter() - wall)
            for kind, a, b, c, d, e in events:
                if kind == compiled.ROTATION_ALARM:  # (link, θ, t)
                    run.warn_rotation(int(a), b, c)
                else:  # energy balance: (t, growth, work, excess, scale)
                    message = violation_message(a, b, c, d, ENERGY_RTOL, e, run.method.name)
                    if status == compiled.ENERGY:
                        raise EnergyBalanceError(message)
                    _progress.warn(message, EnergyBalanceWarning, stacklevel=None)
            if bar is not None:
                bar.update(native.t - bar.n)
            if run.stream is not None:
                _stream_chunk(run, native)
            if status == compiled.RUNNING and run.budget is not None and run.method.adaptive:
                counters = native.counters()
                run.n_accepted, run.n_rejected = int(counters[3]), int(counters[4])
                if run.n_accepted + run.n_rejected >= run.budget:
                    status = compiled.BUDGET
                    break
    finally:  # also on Ctrl-C between chunks: the samples so far make the partial result
        take_samples(run, native)
    if status == compiled.DONE:
        return
    run.system.dynamics.reraise_python_error()  # a Python-only element raised inside the loop (a Ctrl-C too)
    if status == compiled.BUDGET:
        error = run.over_budget(native.t)
        assert error is not None
        raise error
    message, t, h, q, v = native.failure()
    if status == compiled.DIVERGED:
        run.check(t, np.asarray(q, dtype=float), np.asarray(v, dtype=float), h)
    if status == compiled.STEP_MATRIX:
        raise run.step_failed(StepMatrixError(message), t, h)
    if status == compiled.H_MIN:
        raise run.step_too_small(t)
    if status == compiled.CONTROLLER:
        callback = config["controller"].get("callback")
        if callback is not None and callback.error is not None:  # a Python controller raised: its own error
            error, callback.error = callback.error, None  # (kept, it would make a cycle through the C++ loop: a leak)
            raise error
        raise ControllerError(f"the controller returned non-finite torques at t = {t:.6g} s (entries {message})")
    if status == compiled.SCENE:  # (the grasps' geometry: the only error the kernel reports so)
        raise GraspGeometryError(f"{message} (at t = {t:.6g} s)")
    raise KernelError(f"the compiled loop stopped at t = {run.t[-1]:.6g} s: {message}")


def _stream_chunk(run: _Run, native: Any) -> None:
    """Move a compiled run's finished samples (all but the last) to its stream."""
    assert run.stream is not None
    with _signals.interrupts_deferred():  # taken from the loop and written together
        rows = compiled.take_samples(native, run.scene)
        if len(rows[0]):
            run.stream.append(*rows)


def _adaptive_loop(run: _Run, q: np.ndarray, v: np.ndarray, monitor: EnergyMonitor | None, bar: Any) -> None:
    """Error-controlled steps that land exactly on the output times."""
    method, system = run.method, run.system
    assert isinstance(method, AdaptiveIntegrator)
    t, h = 0.0, run.dt
    after_rejection = False
    run.save(t, q, v)
    steps = itertools.chain(range(run.save_every, run.n_steps, run.save_every), [run.n_steps])
    outputs = (min(k * run.dt, run.t_final) for k in steps)
    for t_out in outputs:
        if t_out <= t:
            continue
        while t < t_out:
            system.begin_step(t, q, v)  # (a controller's sample is due: taken here)
            t_sample = system.next_sample_time()  # (one within 1e-9 of the period before t_out is t_out: no ulp-long step)
            t_land = t_sample if system.control_dt is not None and t_sample < t_out - 1e-9 * system.control_dt else t_out
            h_try = min(h, t_land - t)
            if t + h_try * (1.0 + 1e-9) >= t_land:  # land exactly on the output time (or sample instant)
                h_try = t_land - t
            try:
                out = method.attempt(system, t, q, v, h_try, run.ws)
                geometry = None
            except StepMatrixError as exc:
                raise run.step_failed(exc, t, h_try) from None
            except GraspGeometryError as exc:  # a trial stage flung the grasps together (a step far too long for
                out, geometry = Attempt(q, v, math.inf), exc  # the stiffest mode): rejected, as a non-finite error
            run.settle_torque()
            h = method.next_step(h_try, out.error)
            if run.budget is not None and run.n_accepted + run.n_rejected + 1 >= run.budget:
                error = run.over_budget(t)
                if error is not None:
                    raise error
            if bar is not None and (run.n_accepted + run.n_rejected) % 1024 == 1023:
                bar.update(t - bar.n)  # small steps: the bar moves between output times too
            if not (out.error <= 1.0):  # also rejects NaN
                system.dynamics.clear_rotation_alarm()  # a rejected attempt's stages may go anywhere
                run.n_rejected += 1
                after_rejection = True
                if h < method.h_min:  # a non-finite error shrinks the step (next_step: 0.2 h) like a large one
                    if geometry is not None:  # at every step down to h_min: the grasps' own geometry
                        raise GraspGeometryError(f"{geometry} (at t = {t:.6g} s)") from None
                    run.check(t + h_try, out.q, out.v, h_try)  # non-finite → DivergenceError
                    raise run.step_too_small(t)
                continue
            if after_rejection:  # no growth right after a rejection (as Hairer's codes): where stability caps the
                h = min(h, h_try)  # step, growing at once would be rejected again and again
            after_rejection = False
            t_new = t_land if h_try == t_land - t else t + h_try
            run.check(t_new, out.q, out.v, h_try)
            run.after_step(t_new)
            if monitor is not None:
                monitor.after_step(t, q, v, h_try, t_new, out.q, out.v)
            t, q, v = t_new, out.q, out.v
            run.n_accepted += 1
        run.save(t, q, v, step_follows=t < run.t_final)
        if bar is not None:
            bar.update(t - bar.n)
    if monitor is not None:
        monitor.finish(t, q, v)


def _progress_bar(t_final: float, desc: str) -> Any:
    from ._optional import require

    tqdm = require("tqdm", "the progress bar", "tqdm").tqdm
    return tqdm(
        total=t_final, desc=desc, unit="s", leave=False, bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} s [{elapsed}<{remaining}]"
    )
