"""``coopdyn.simulate``: run a scene under a controller and return a :class:`Result`."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import itertools
import math
import os
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from . import _progress, _signals, _validate, compiled
from . import accuracy as screening
from .budget import check_budget, step_count
from .closed_loop import Controller, System
from .dynamics import Dynamics
from .dynamics.constrained import check_integrator, has_constraints
from .errors import (
    AccuracyWarning,
    ControllerError,
    ControlRateWarning,
    CoopdynError,
    DivergenceError,
    EnergyBalanceError,
    EnergyBalanceWarning,
    GraspGeometryError,
    KernelError,
    LogMapWarning,
    SceneWarning,
    SimulationError,
    SimulationInterrupted,
    StepBudgetError,
    StepMatrixError,
    StepSizeError,
    UnstableLoopWarning,
)
from .integrators import AdaptiveIntegrator, Attempt, DormandPrince, EmbeddedRungeKutta, Integrator, get_integrator
from .model.scene import Scene
from .monitor import ENERGY_RTOL, EnergyMonitor, violation_message
from .result import Result, SampleFiles
from .stability import ADVISED, advise
from .statics import rest_pose


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
    loop: str = "auto",
    max_steps: int | None = 2 * 10**6,
    max_memory: float | None = 4e9,
    stream_to: str | os.PathLike[str] | None = None,
    accuracy_check: str = "auto",
    control_dt: float | None = None,
    accuracy: float | None = None,
) -> Result:
    """Simulate ``scene`` from t = 0 to ``t_final``.

    Args:
        scene: the scene.
        t_final: duration [s], ≥ 0.
        controller: ``controller(t, q, v) -> τ``, one torque/force per arm joint in scene order
            (``scene.n_actuated``) [N·m or N]; ``None`` applies none.
        integrator: a name from ``coopdyn.integrators.INTEGRATORS`` or an instance; or, with
            ``accuracy``, ``"auto"``: the method is chosen too (see ``accuracy``).
        dt: time step [s], > 0. The last step is shortened to end exactly at ``t_final``.
            Adaptive methods (``dopri5``, ``dop853``, ``ros2_adaptive``) choose their own steps and land on
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
        loop: ``"auto"`` (default) runs the steps in the compiled loop when it can — native
            backend, an integrator from ``INTEGRATORS`` (all but ``scipy``), no ``object_wrench``
            — and in Python otherwise. A built-in controller (``GravityCompensationPD``,
            ``ComputedTorque`` holding q0, ``ObjectImpedance`` holding or with
            ``GripLiftOscillate``, ``drives_controller``) runs compiled too; any other callable is
            called from the compiled loop at each evaluation, or once per sample with
            ``control_dt`` (Python code, with the GIL taken for the call). ``"compiled"``
            requires the compiled loop (SimulationError saying which piece keeps it in Python);
            ``"python"`` forces the Python loop. Both give the same result to round-off; ``Result.loop`` says which ran.
        max_steps: refuse a run whose ``t_final / dt`` exceeds this many steps, before it starts
            (the message estimates its CPU time); for adaptive methods, also the most steps
            (accepted and rejected) they may take (:class:`StepBudgetError` past it). ``None``:
            no limit.
        max_memory: refuse a run whose saved trajectory would take more than this many bytes
            (the message proposes a ``save_every``); ``None``: no limit.
        stream_to: a new or empty folder: the samples go to ``t.npy``, ``q.npy``, ``v.npy`` and
            ``tau.npy`` there as the run goes (sized up front, checked against the free disk
            space) instead of memory, and the result's arrays are read-only memory maps of them.
        accuracy_check: whether the interconnection forces of a run with a fixed-step method
            (or ``ros2_adaptive``) are judged (:mod:`coopdyn.accuracy`). ``"auto"`` (default):
            a screen of the linearised closed loop's modes at the initial state; a run it cannot
            clear is compared, after it completes, with a reference run of the same scene,
            controller and start (the controller is called again from t = 0): dopri5 where its
            stability limit allows, else ros2_adaptive at rtol 1e-4 (stiff scenes), within
            max(30× the run's steps, 20 000) steps. An ``AccuracyWarning`` gives the force
            error found (``Result.force_error_estimate`` [N]); a reference that runs out of that
            budget or diverges is compared as far as it got (and one that diverges or grows to
            dwarf the run's forces is reported as an unstable loop the run's step hides).
            ``"screen"``: the screen alone (no second run). ``"off"``: no judgement.
            Not for ``dopri5`` or ``dop853`` (error-controlled), ``exponential`` (exact) or rigid
            grasps.
            Whatever the method, a built-in controller's loop is also linearised exactly at the
            start (its gain by central differences of its compiled twin): an oscillating mode that grows by
            more than e over the run gives an ``UnstableLoopWarning`` (saying whether the run's
            grasp forces show it: its figures are then an instability's, and depend on the step),
            and a ``control_dt`` too long for its gains a ``ControlRateWarning``. ``"off"``
            skips that too.
        control_dt: the controller's sample period [s], or ``None`` (default) to call it at every
            evaluation (a continuous-time controller: every stage of every step). With a period
            the controller runs as a digital one does: it is called at t = 0, k·control_dt, …
            and its output is held in between (zero-order hold) — one call per sample instead
            of one per stage, whatever the method. Fixed-step methods need ``control_dt`` a
            whole multiple of ``dt``; adaptive ones land a step on every sample instant. A
            hold is part of the physics: the accuracy check's reference run holds too. A
            built-in controller whose hold makes the loop unstable (linearised exactly at the
            start, discretised exactly over a period) gets a ``ControlRateWarning`` when the run
            completes (a slow growth need not diverge), unless ``accuracy_check="off"``.
        accuracy: the interconnection-force error [N] the run may have, or ``None``. Given, the
            step is chosen for it: the method runs at ``dt``, dt/2, dt/4, … (at most
            :data:`ACCURACY_HALVINGS` halvings, the saved grid kept) until its forces agree with
            a reference run within ``accuracy`` — dopri5 at rtol 1e-9, run once on the same
            grid (the controller is called again from t = 0 for each run) — and that run is
            returned, its ``dt`` the step taken, ``force_error_estimate`` the error found and
            ``cpu_time`` the whole search's (reference and tries). For fixed-step methods
            (dopri5 controls its error with ``rtol``; ``exponential`` is exact), not with
            ``stream_to``; ``progress`` prints each try; a try that diverges or breaks the
            energy balance counts as a miss, and none takes more than ``max_steps``. The
            reference's own error (about 1e-10 of the peak force) bounds what can be asked:
            below 1e-8 of it is refused. With ``integrator="auto"`` each method of
            :data:`AUTO_METHODS` is searched that way from ``dt``, and dopri5 at rtol 1e-3,
            1e-4, … 1e-8 (:data:`AUTO_RTOLS`), and the run that meets ``accuracy`` at the least
            CPU time is returned (``integrator`` names it; dopri5's with its rtol).

    Returns:
        the saved trajectory, with readouts (wrenches, deformations, energies) and work counters.

    Raises:
        DivergenceError: when the state stops being finite or exceeds ``max_speed``; it carries
            the trajectory up to the failure and a stability diagnosis — of the method at the last
            saved state, and of the loop at the start (its controller called 4·nv more times there,
            at t = 0, for its gain: a stateful controller sees those calls): an unstable mode, or a
            ``control_dt`` too long for the controller's gains.
        SimulationInterrupted: on Ctrl-C (a ``KeyboardInterrupt``), carrying the trajectory so far.
        StepMatrixError: an implicit method's step matrix is not positive definite (with .result).
        EnergyBalanceError: with ``energy_check="raise"``, when the energy balance breaks.
        StepBudgetError: an adaptive method used up ``max_steps`` (with .result); its subclass
            StepSizeError: the step fell below the method's ``h_min`` (with .result).
        SimulationError: on invalid arguments and runs refused as too long or too large.
        ControllerError: a controller that is not callable or returns a bad output.
        KernelError: what the compiled kernel refuses.
    """
    if not isinstance(scene, Scene):
        raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
    if accuracy is not None:
        return _to_accuracy(
            accuracy, scene, t_final, controller=controller, integrator=integrator, dt=dt, save_every=save_every, q0=q0,
            v0=v0, progress=progress, max_speed=max_speed, energy_check=energy_check, object_wrench=object_wrench,
            backend=backend, loop=loop, max_steps=max_steps, max_memory=max_memory, stream_to=stream_to,
            control_dt=control_dt, accuracy_check=accuracy_check,
        )  # fmt: skip
    t_final = _checked_duration(t_final)
    dt, save_every, max_speed = _checked_steps(dt, save_every, max_speed)
    for name, value, valid in (
        ("energy_check", energy_check, ENERGY_CHECKS),
        ("loop", loop, LOOPS),
        ("accuracy_check", accuracy_check, ACCURACY_CHECKS),
    ):
        _checked_choice(name, value, valid)
    progress = _validate.flag(progress, "progress", SimulationError)
    if isinstance(integrator, str) and integrator == "auto":
        raise SimulationError('integrator="auto" chooses the method for a force accuracy: give accuracy= [N] too (e.g. 0.1)')
    method = get_integrator(integrator)
    check_integrator(scene, method)
    control_dt = _control_period(control_dt, dt, method)
    if object_wrench is not None and has_constraints(scene):
        raise SimulationError(
            "object_wrench cannot be combined with rigid grasps yet: their constraint wrenches are read out after the run "
            "from (q, v, tau), without the external wrench; model the load as a fixture or a controller term"
        )
    q, v = scene.check_state(scene.q0 if q0 is None else q0, scene.v0 if v0 is None else v0)
    budget = check_budget(scene, t_final, dt, save_every, max_steps, None if stream_to is not None else max_memory)
    _check_samples(t_final, control_dt, budget)

    system = System(Dynamics(scene, backend), controller, object_wrench, control_dt)
    system.max_speed = max_speed
    if accuracy_check != "off" and not has_constraints(scene):
        _warn_if_soft(system.dynamics, q)
    run = _Run(scene, system, method, dt, save_every, t_final, max_speed, (q, v))
    run.budget = budget
    if stream_to is not None:
        n_samples = 1 + len(range(save_every, run.n_steps, save_every)) + (run.n_steps > 0)
        run.stream = SampleFiles(stream_to, n_samples, scene.nq, scene.nv, scene.n_actuated)
    judged = (
        accuracy_check != "off"
        and not isinstance(method, EmbeddedRungeKutta)
        and not method.exact_discretisation
        and not has_constraints(scene)
        and t_final > 0
    )
    cpu0 = time.process_time()  # the compiled loop's preparation (e.g. the exponential's expm) counts too
    config, why = None, "loop='python'"
    if loop != "python":
        config, why = compiled.plan(
            scene,
            system,
            method,
            q0=q,
            v0=v,
            dt=dt,
            t_final=t_final,
            n_steps=run.n_steps,
            save_every=save_every,
            max_speed=max_speed,
            energy_check="off" if method.exact_discretisation else energy_check,
        )
        if config is None and loop == "compiled":
            raise SimulationError(f"loop='compiled' cannot run this simulation: {why}; use loop='auto' or 'python'")
    run.loop = "python" if config is None else "compiled"
    monitor = None
    if config is None and energy_check != "off" and not method.exact_discretisation:
        monitor = EnergyMonitor(system, 0.0, q, v, every=max(1, round(5e-3 / dt)), mode=energy_check, method=method.name)
    bar = _progress_bar(t_final, method.name) if progress else None
    try:
        with np.errstate(over="ignore", invalid="ignore"), _progress.showing(bar):  # a blow-up: a DivergenceError
            if config is not None:
                _compiled_loop(run, config, bar)
            elif method.adaptive:
                _adaptive_loop(run, q, v, monitor, bar)
            else:
                _fixed_loop(run, q, v, monitor, bar)
        run.cpu_time = time.process_time() - cpu0
        result = run.result()
    except KeyboardInterrupt as exc:
        if isinstance(exc, SimulationInterrupted):
            raise
        with _signals.interrupts_deferred(reraise=False):  # a second Ctrl-C cannot cut the partial result
            run.cpu_time = time.process_time() - cpu0
            done = bool(run.t) and run.t[-1] >= t_final and len(run.t) == len(run.q) == len(run.v) == len(run.tau)
            partial = run.result("completed" if done else "interrupted")
        reached = f"at t = {partial.t[-1]:.6g} s" if len(partial.t) else "before the first sample"
        raise SimulationInterrupted(
            f"interrupted {reached} of {t_final:g} s",
            result=partial,
        ) from None
    except BaseException:
        if run.stream is not None:  # any other stop: the files are cut to the samples made
            with contextlib.suppress(Exception):
                run.result("stopped")
        raise
    finally:
        if bar is not None:
            bar.close()
    if accuracy_check != "off" and t_final > 0 and _probed(controller, scene):
        _check_the_loop(result, system, q, v)
    if not judged:
        return result
    rerun = dict(
        controller=controller, q0=q, v0=v, object_wrench=object_wrench, backend=backend, progress=progress, control_dt=control_dt
    )
    return _judge_forces(result, system, method, accuracy_check, stream_to is not None, rerun)


def _check_the_loop(result: Result, system: System, q: np.ndarray, v: np.ndarray, stacklevel: int = 3) -> None:
    """Warn when the run's built-in controller makes its loop — linearised exactly at the start
    (q, v) — unstable: an oscillating mode that grows by more than e over the run
    (UnstableLoopWarning, :func:`coopdyn.accuracy.unstable_mode`), saying whether the run shows
    it (:func:`_shown`); or, the continuous loop stable, a control_dt too long for its gains, the
    hold growing by more than e over the run (ControlRateWarning,
    :func:`coopdyn.accuracy.sampled_instability`). Nothing else says so: the accuracy check's
    reference is just as unstable. Only a controller that runs as its own compiled twin
    (:func:`_probed`) is checked: it keeps no state, so the 4·nv + 1 calls that give its gain
    change nothing (its compiled twin's on the native backend: :func:`coopdyn.compiled.start_loop`);
    a user's own code is not called."""
    t_final = float(result.t[-1])
    period = system.control_dt
    try:
        loop = compiled.start_loop(system, q, v)
        if loop is None:
            return
        mode = screening.unstable_mode(system, q, v, t_final, loop)
        hold = screening.sampled_instability(loop, period) if period is not None and not mode else None
    except (ArithmeticError, ValueError, np.linalg.LinAlgError):  # (a diagnosis never turns a run into an error)
        return
    skip = "(accuracy_check='off' skips this check)"
    if mode:
        _progress.warn(
            f"The closed loop under this controller is unstable: linearised exactly at the start (coopdyn.linearize with "
            f"the controller), it has {mode}, and {_shown(result)}. No method makes it stable: change the controller or its "
            f"gains {skip}",
            UnstableLoopWarning,
            stacklevel=stacklevel,
        )
    grown = t_final / hold.period * math.log(hold.growth) if hold is not None else 0.0  # (over the run, a logarithm)
    if hold is not None and hold.continuous <= 1e-6 and grown > 1.0:
        total = screening.growth_factor(grown)
        _progress.warn(
            f"{hold.sentence[0].upper()}{hold.sentence[1:]}. Over this {t_final:g} s run the linearised loop grows {total}, "
            f"and {_shown(result)} {skip}",
            ControlRateWarning,
            stacklevel=stacklevel,
        )


def _probed(controller: Any, scene: Scene) -> bool:
    """Whether :func:`_check_the_loop` may call ``controller`` for its gain: it runs as its own
    compiled twin (its class defines ``compiled_spec`` and gives one for this scene — not a
    subclass, not a built-in law given a Python reference), so it keeps no state."""
    try:
        return compiled._own_spec(controller, scene) is not None
    except CoopdynError:
        return False


#: samples a run needs, a third of them at least three, before its growth is told (:func:`_shown`)
GROWTH_SAMPLES = 9


def _shown(result: Result) -> str:
    """Whether a run shows its loop's instability, as the warning's clause: its grasp forces (its
    joint speeds without interconnections) grow ×2 from its first third to its last — its figures
    are then the instability's — or not yet; or too few samples to tell."""
    t_final, n = float(result.t[-1]), len(result.t)
    what = "grasp forces" if result.scene.links else "joint speeds"
    if n < GROWTH_SAMPLES:
        return f"this {t_final:g} s run saved too few samples ({n}) to tell whether it shows it"
    grown = _growth(result.wrenches()[..., :3] if result.scene.links else result.v[:, None, :])
    if grown > screening.UNSTABLE_GROWTH:
        return (
            f"this {t_final:g} s run's {what} grow ×{grown:.3g} from its first third to its last: its motion is that "
            "instability's, so its figures (forces, tracking) depend on the step and the start"
        )
    return (
        f"within this {t_final:g} s run it has not grown visibly (its {what} ×{grown:.3g} from its first third to its last), "
        "so its figures hold for this duration, but a longer run, or a larger disturbance, would show it"
    )


def _judge_forces(result: Result, system: System, method: Integrator, mode: str, streamed: bool, rerun: dict[str, Any]) -> Result:
    """Screen the run's modes (:mod:`coopdyn.accuracy`) and, when the screen cannot clear it and
    ``mode`` is ``"auto"``, compare its interconnection forces with a reference run's
    (:func:`coopdyn.accuracy.reference_for`); warn when they are wrong. Returns the result with
    its ``force_error_estimate`` when the check ran."""
    t_final = float(result.t[-1])
    q, v = rerun["q0"], rerun["v0"]
    step = result.dt if not method.adaptive else t_final / max(result.n_steps, 1)  # adaptive: its mean step
    try:
        judged = screening.screen(system, q, v, method, step, t_final)  # (system.dynamics: the run's counters stay)
    except (ArithmeticError, ValueError, NotImplementedError, np.linalg.LinAlgError):  # e.g. a destabilising gain
        return result
    if not judged.suspect:
        return result
    reference, budget = screening.reference_for(judged, result.n_steps)
    name = screening.described(reference)
    unchecked = "accuracy_check='screen'" if mode == "screen" else "a streamed run is not run twice" if streamed else ""
    checked = None
    stopped: tuple[str, float, bool] | None = None  # (why, when [s], diverged) a reference stopped early
    if not unchecked:
        interval = float(result.t[1] - result.t[0]) if len(result.t) > 1 else t_final
        if rerun.pop("progress"):
            print(f"checking the forces against {name} (the accuracy screen could not clear this run) …", file=sys.stderr)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                checked = simulate(
                    result.scene,
                    t_final,
                    integrator=reference,
                    dt=interval,
                    max_steps=budget,
                    energy_check="off",
                    accuracy_check="off",
                    **rerun,
                )
        except SimulationInterrupted:
            raise SimulationInterrupted(f"interrupted while checking the run's forces against {name}", result=result) from None
        except (StepBudgetError, DivergenceError) as exc:  # compared as far as the reference got
            diverged = isinstance(exc, DivergenceError)
            if diverged:
                stop = f"{name} diverged"
            elif isinstance(exc, StepSizeError):
                stop = f"{name}'s step fell below its h_min"
            else:
                stop = f"{name} needed more than {budget} steps"
            partial = exc.result
            if isinstance(partial, Result) and len(partial.t) > 1 and partial.t[-1] > 0:
                checked = partial
                stopped = (stop, float(partial.t[-1]), diverged)
            else:
                unchecked = stop
        except CoopdynError as exc:
            unchecked = f"{name} stopped: {str(exc).splitlines()[0][:200]}"
    if checked is None:
        message = screening.screen_message(judged, unchecked)
    else:
        n = min(len(checked.t), len(result.t))  # (a reference that stopped early: its part of the run)
        mine = result.wrenches()[:n][..., :3]
        theirs = checked.wrenches()[..., :3]
        if len(checked.t) != n or not np.allclose(checked.t, result.t[:n], rtol=0.0, atol=1e-9):
            from scipy.interpolate import interp1d  # (both land on the same output grid; this is a guard)

            theirs = interp1d(checked.t, theirs, axis=0)(result.t[:n])
        error = float(np.max(np.linalg.norm(mine - theirs, axis=-1), initial=0.0))
        peak = float(np.max(np.linalg.norm(theirs, axis=-1), initial=0.0))
        own_peak = float(np.max(np.linalg.norm(mine, axis=-1), initial=0.0))
        growth = _growth(theirs) if len(theirs) >= 3 else 1.0
        result = _estimated(result, error)
        message = screening.checked_message(judged, error, peak, reference, stopped=stopped, own_peak=own_peak, growth=growth)
    if message is not None:
        message += screening.growth_text(system, q, v, t_final)
        warnings.warn(message, AccuracyWarning, stacklevel=3)
    return result


def _growth(forces: np.ndarray) -> float:
    """How many times a reference's largest grasp force (n, links, 3) [N] grows over its run: its
    last third's peak over its first third's."""
    size = np.linalg.norm(forces, axis=-1).reshape(len(forces), -1).max(axis=1)
    third = max(len(size) // 3, 1)
    return float(size[-third:].max() / max(size[:third].max(), screening.FORCE_FLOOR))


def _estimated(result: Result, error: float, **changes: Any) -> Result:
    """``result`` with its ``force_error_estimate`` (and ``changes``), its readouts kept (the
    forces were just computed)."""
    readouts = result.readouts
    result = dataclasses.replace(result, force_error_estimate=error, **changes)
    result.__dict__["readouts"] = readouts
    return result


#: how many times ``simulate(..., accuracy=)`` halves the step before it gives up
ACCURACY_HALVINGS = 8
#: the reference of ``simulate(..., accuracy=)``: dopri5's (rtol, atol), and its step budget
ACCURACY_REFERENCE = (1e-9, 1e-12)
ACCURACY_REFERENCE_STEPS = 2 * 10**6
#: the smallest accuracy asked, relative to the reference's peak force: its own error is ~1e-10 of it
ACCURACY_FLOOR = 1e-8
#: a reference whose forces grow this many times (last third of the run over its first) hints at instability
ACCURACY_GROWTH = 100.0


#: the methods ``integrator="auto"`` tries for an ``accuracy`` (each from dt, halving), then dopri5
AUTO_METHODS = ("trapezoid", "rk4", "implicit_euler")
#: dopri5's tolerances ``integrator="auto"`` tries, loosest first (rtol; atol = rtol·1e-3)
AUTO_RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)


class _Miss(Exception):
    """A method that did not reach the accuracy asked: why, in words; ``budget``: for want of steps
    (max_steps)."""

    def __init__(self, why: str, budget: bool = False) -> None:
        super().__init__(why)
        self.budget = budget


def _to_accuracy(accuracy: Any, scene: Scene, t_final: float, **settings: Any) -> Result:
    """:func:`simulate` with its step — and with ``integrator="auto"`` its method — chosen for a
    force error of ``accuracy`` [N] (see its ``accuracy``): each method at dt, dt/2, … (dopri5 at
    tighter and tighter rtol) against one dopri5 reference on the same grid."""
    tolerance = _validate.positive(accuracy, "accuracy (the force error the run may have)", "N", SimulationError)
    auto = isinstance(settings["integrator"], str) and settings["integrator"] == "auto"
    also = ', or "auto" (the method chosen for the accuracy too)'  # (with an accuracy, "auto" is a choice too)
    chosen = settings["integrator"]
    methods = [get_integrator(name) for name in AUTO_METHODS] if auto else [get_integrator(chosen, also, ("auto",))]
    del settings["integrator"]
    if auto:  # the methods the scene takes (rigid grasps: the explicit ones)
        methods = [m for m in methods if _takes(scene, m)]
    for method in methods:
        check_integrator(scene, method)
    checks = settings.pop("accuracy_check")  # (the search checks the forces; "off" skips the loop's check)
    _checked_choice("accuracy_check", checks, ACCURACY_CHECKS)
    method = methods[0]
    if not auto and (method.adaptive or method.exact_discretisation):
        raise SimulationError(
            f"accuracy= chooses a fixed-step method's step; {method.name} "
            + ("controls its error itself (give its rtol)" if method.adaptive else "is exact: give its dt")
            + ', or integrator="auto" chooses the method too'
        )
    if settings["stream_to"] is not None:
        raise SimulationError("accuracy= runs the scene several times: it cannot stream to files; drop stream_to")
    t_final = _checked_duration(t_final)
    dt, every, _ = _checked_steps(settings.pop("dt"), settings.pop("save_every"), settings["max_speed"])
    for name, valid in (("energy_check", ENERGY_CHECKS), ("loop", LOOPS)):  # (checked before the reference runs)
        _checked_choice(name, settings[name], valid)
    settings["progress"] = _validate.flag(settings["progress"], "progress", SimulationError)
    if settings["max_steps"] is not None:
        settings["max_steps"] = _validate.count(settings["max_steps"], "max_steps", SimulationError, none="no limit")
    _control_period(settings["control_dt"], dt, method if not auto else DormandPrince())  # (auto: each try checks its own)
    q, v = scene.check_state(
        scene.q0 if settings["q0"] is None else settings["q0"], scene.v0 if settings["v0"] is None else settings["v0"]
    )
    if not has_constraints(scene):
        _warn_if_soft(Dynamics(scene, settings["backend"]), q)  # (the tries run without the checks)
    cpu0 = time.process_time()
    reference = _accuracy_reference(scene, t_final, tolerance, dt * every, settings)
    tries = [(m, functools.partial(_halving, m, dt, every)) for m in methods]
    if auto:
        tries.append((DormandPrince(), functools.partial(_tightening, dt * every)))
    found: list[_Found] = []
    misses = []
    for method, search in tries:
        cheapest = min((r.cpu_time for r, _, _ in found), default=math.inf)  # (a try that costs more cannot win)
        try:
            found.append(search(scene, t_final, tolerance, reference, {**settings, "cheapest": cheapest}))
        except _Miss as miss:
            misses.append((method.name, str(miss), miss.budget))
    if not found:
        growth = _growth(reference.wrenches()[..., :3])
        if growth > ACCURACY_GROWTH:
            hint = (
                f"; the reference's forces grow {growth:.3g}× over the run: the closed loop itself may be unstable "
                "(coopdyn.linearize with the controller shows its modes)"
            )
        elif all(budget for _, _, budget in misses):
            hint = ": give a larger max_steps, or a looser accuracy"
        else:
            hint = ": give a smaller dt to start from, another method, or a looser accuracy"
        if not auto:
            raise SimulationError(f"{misses[0][0]} did not reach a force error of {tolerance:g} N {misses[0][1]}{hint}")
        tried = "; ".join(f"{name} {miss}" for name, miss, _ in misses)
        raise SimulationError(f"no method reached a force error of {tolerance:g} N ({tried}){hint}")
    run, error, said = min(found, key=lambda f: f[0].cpu_time)  # the cheapest run that meets it
    if auto and settings["progress"]:
        costs = ", ".join(f"{_setting(r)}: {r.cpu_time * 1e3:.3g} ms" for r, _, _ in found)
        print(f"accuracy {tolerance:g} N: chose {_setting(run)}, the cheapest run that meets it ({costs})", file=sys.stderr)
    for w in said:
        warnings.warn(w.message, w.category, stacklevel=3)
    controller, period = settings["controller"], settings["control_dt"]
    if checks != "off" and t_final > 0 and _probed(controller, scene):  # (the tries run without the checks)
        held = None if period is None else float(period)
        loop = System(Dynamics(scene, settings["backend"]), controller, settings["object_wrench"], held)
        _check_the_loop(run, loop, q, v, stacklevel=4)
    return _estimated(run, error, cpu_time=time.process_time() - cpu0)


def _takes(scene: Scene, method: Integrator) -> bool:
    """Whether ``scene`` can run under ``method`` (:func:`check_integrator`)."""
    try:
        check_integrator(scene, method)
    except SimulationError:
        return False
    return True


def _setting(run: Result) -> str:
    """A run as the messages and `coopdyn simulate`'s summary name it: its method and step (a
    dopri5 run an ``accuracy=`` search chose is named with its tolerance)."""
    return run.integrator if run.integrator.startswith("dopri5 (") else f"{run.integrator} at dt = {run.dt:g} s"


def _accuracy_reference(scene: Scene, t_final: float, tolerance: float, spacing: float, settings: dict[str, Any]) -> Result:
    """The reference run of ``accuracy=``: dopri5 at :data:`ACCURACY_REFERENCE`, sampled every
    ``spacing`` seconds; refuses a tolerance below what it resolves."""
    rtol, atol = ACCURACY_REFERENCE
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reference = simulate(
                scene, t_final, integrator=DormandPrince(rtol=rtol, atol=atol), dt=spacing, accuracy_check="off",
                **{**_tries(settings), "energy_check": "off", "max_steps": ACCURACY_REFERENCE_STEPS},
            )  # fmt: skip
    except SimulationInterrupted:
        raise SimulationInterrupted("interrupted while running the reference of accuracy=") from None
    except DivergenceError as exc:
        when = f" at t = {exc.result.t[-1]:.6g} s" if isinstance(exc.result, Result) and len(exc.result.t) else ""
        raise SimulationError(
            f"the reference of accuracy= (dopri5 at rtol {rtol:g}) diverged{when}: the closed loop itself is unstable "
            "(coopdyn.linearize with the controller shows its modes); no step fixes that"
        ) from None
    except StepBudgetError as exc:
        why = (
            "its step fell below h_min"
            if isinstance(exc, StepSizeError)
            else f"needed more than {ACCURACY_REFERENCE_STEPS} steps"
        )
        raise SimulationError(
            f"the reference of accuracy= (dopri5 at rtol {rtol:g}) {why}: the "
            "scene is too stiff for it; choose the step yourself (coopdyn.advise) or use an implicit method at a small dt"
        ) from None
    forces = reference.wrenches()[..., :3]
    peak = float(np.max(np.linalg.norm(forces, axis=-1), initial=0.0))
    if tolerance < ACCURACY_FLOOR * peak:
        raise SimulationError(
            f"accuracy = {tolerance:g} N is below what the reference resolves: about {ACCURACY_FLOOR:g} of the peak force "
            f"({peak:.3g} N), {ACCURACY_FLOOR * peak:.2g} N"
        )
    return reference


def _tries(settings: dict[str, Any]) -> dict[str, Any]:
    """``settings`` as each run of an ``accuracy=`` search takes them (no progress bar of its own)."""
    return {k: v for k, v in settings.items() if k not in ("progress", "cheapest")} | {"progress": False}


def _force_error(run: Result, reference: Result) -> float:
    """[N] the largest difference between a run's interconnection forces and the reference's,
    sample by sample (the same instants)."""
    mine, forces = run.wrenches()[..., :3], reference.wrenches()[..., :3]
    if mine.shape != forces.shape or not np.allclose(run.t, reference.t, rtol=0.0, atol=1e-9):
        raise SimulationError(f"accuracy=: the run's samples ({len(run.t)}) are not the reference's ({len(reference.t)})")
    return float(np.max(np.linalg.norm(mine - forces, axis=-1), initial=0.0))


_Found = tuple[Result, float, list[warnings.WarningMessage]]  #: a search's run, its force error [N] and its warnings


def _attempt(
    scene: Scene, t_final: float, settings: dict[str, Any], **run: Any
) -> tuple[Result | None, list[warnings.WarningMessage], str]:
    """One run of an ``accuracy=`` search, its warnings kept (shown for the run returned only),
    and what became of it: the run and "completed", or None and "diverged" (it diverged or broke
    the energy balance: past the method's stability limit), "out of steps" (max_steps) or, for an
    adaptive method, "could not keep its step above h_min"."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        try:
            return simulate(scene, t_final, accuracy_check="off", **_tries(settings), **run), said, "completed"
        except SimulationInterrupted:
            raise SimulationInterrupted(f"interrupted while trying {run['integrator']} for accuracy=") from None
        except StepSizeError:
            return None, said, "could not keep its step above h_min"
        except StepBudgetError:
            return None, said, "out of steps"
        except (DivergenceError, StepMatrixError, EnergyBalanceError):
            return None, said, "diverged"


def _halving(
    method: Integrator,
    dt: float,
    every: int,
    scene: Scene,
    t_final: float,
    tolerance: float,
    reference: Result,
    settings: dict[str, Any],
) -> _Found:
    """A fixed-step ``method`` at dt, dt/2, … (at most :data:`ACCURACY_HALVINGS` halvings, the
    saved grid kept) until its forces are within ``tolerance`` of the reference's: (run, error,
    its warnings); :class:`_Miss` if none is."""
    error, why, max_steps, budget = math.inf, "every try diverged", settings["max_steps"], False
    try:  # (a controller's sample period must be whole steps of a fixed-step method: dt/2 … keep that)
        _control_period(settings["control_dt"], dt, method)
    except SimulationError as exc:
        raise _Miss(str(exc)) from None
    if max_steps is not None and step_count(t_final, dt) > max_steps:
        raise _Miss(f"at dt = {dt:g} s already takes more than max_steps = {max_steps} steps", budget=True)
    for _ in range(ACCURACY_HALVINGS + 1):
        if max_steps is not None and step_count(t_final, dt) > max_steps:
            why, budget = f"a smaller step would take more than max_steps = {max_steps} steps", True
            break
        run, said, _ = _attempt(scene, t_final, settings, integrator=method, dt=dt, save_every=every)
        if run is not None:
            error = _force_error(run, reference)
            why = f"off by {error:.3g} N against dopri5 at rtol {ACCURACY_REFERENCE[0]:g}"
        if settings["progress"]:
            outcome = f"is off by {error:.3g} N" if run is not None else "diverges"
            print(f"accuracy {tolerance:g} N: {method.name} at dt = {dt:g} s {outcome}", file=sys.stderr)
        if run is not None and error <= tolerance:
            return run, error, said
        if run is not None and run.cpu_time > settings["cheapest"]:  # the next try, at half the step, costs more still
            raise _Miss(f"at dt = {dt:g} s was off by {error:.3g} N and cost more than a run that meets it")
        dt, every = dt / 2, every * 2
    raise _Miss(f"down to dt = {2 * dt:g} s ({why})", budget=budget)


def _tightening(
    spacing: float, scene: Scene, t_final: float, tolerance: float, reference: Result, settings: dict[str, Any]
) -> _Found:
    """dopri5 at each rtol of :data:`AUTO_RTOLS` until its forces (sampled every ``spacing``
    seconds) are within ``tolerance`` of the reference's: (run, error, its warnings); :class:`_Miss`
    if none is."""
    why, budget = "every try failed", False
    max_steps = settings["max_steps"]
    if max_steps is not None and step_count(t_final, spacing) > max_steps:  # (it lands a step on every sample)
        raise _Miss(f"at its samples, {spacing:g} s apart, already takes more than max_steps = {max_steps} steps", budget=True)
    for rtol in AUTO_RTOLS:
        run, said, became = _attempt(scene, t_final, settings, integrator=DormandPrince(rtol=rtol, atol=rtol * 1e-3), dt=spacing)
        if run is None:
            budget = became == "out of steps"
            what = f"ran out of its step budget (max_steps = {max_steps})" if budget else became
            why = f"at rtol {rtol:g} it {what}"
            if settings["progress"]:
                print(f"accuracy {tolerance:g} N: dopri5 at rtol {rtol:g} {what}", file=sys.stderr)
            if budget:  # (a tighter rtol takes more steps still)
                break
        else:
            error = _force_error(run, reference)
            why = f"off by {error:.3g} N at rtol {rtol:g}"
            if settings["progress"]:
                print(f"accuracy {tolerance:g} N: dopri5 at rtol {rtol:g} is off by {error:.3g} N", file=sys.stderr)
            if error <= tolerance:  # (named with its tolerance: its dt is the samples' spacing)
                return _estimated(run, error, integrator=f"dopri5 (rtol {rtol:g})"), error, said
            if run.cpu_time > settings["cheapest"]:  # a tighter rtol costs more still
                raise _Miss(f"at rtol {rtol:g} was off by {error:.3g} N and cost more than a run that meets it")
    raise _Miss(f"down to rtol {AUTO_RTOLS[-1]:g} ({why})", budget=budget)


#: the fraction of the object's size beyond which its sag on its grasps under gravity warns
SAG_LIMIT = 0.25


def _warn_if_soft(dynamics: Dynamics, q: np.ndarray) -> None:
    """Warn (SceneWarning) when the object, its grasps held still at q, would rest farther from
    its pose at q than :data:`SAG_LIMIT` of its size (twice its grasps' largest distance from the
    object frame, at least 5 cm): interconnections far too soft for its weight — e.g. a stiffness
    thought in N/mm. Nothing is said when the rest pose cannot be found (a free direction). Runs
    on the run's own dynamics and its scratch data."""
    scene, model, data = dynamics.scene, dynamics.model, dynamics.data
    pin.framesForwardKinematics(model, data, q)
    start = data.oMf[scene.object_frame].translation.copy()
    reach = [np.linalg.norm(data.oMf[lk.grasp_frame].translation - start) for lk in scene.links]
    size = max(0.05, 2.0 * max(reach, default=0.0))
    try:
        rest = rest_pose(dynamics, q, 1e-6, 50).q
    except (CoopdynError, ArithmeticError, ValueError, np.linalg.LinAlgError):
        return
    finally:
        dynamics.clear_rotation_alarm()  # (a Newton step's rotation is not the run's)
    pin.framesForwardKinematics(model, data, rest)
    sag = float(np.linalg.norm(data.oMf[scene.object_frame].translation - start))
    if sag > SAG_LIMIT * size:
        warnings.warn(
            f"with its grasps held still, the object would come to rest {sag * 1e3:.4g} mm from where it starts, "
            f"{sag / size:.0%} of its size ({size * 1e3:.4g} mm): its interconnections are far too soft for its weight. "
            "Stiffnesses are in N/m and N·m/rad (not N/mm); coopdyn.statics.equilibrium(scene) gives the rest pose",
            SceneWarning,
            stacklevel=3,
        )


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
LOOPS = ("auto", "compiled", "python")
ACCURACY_CHECKS = ("auto", "screen", "off")


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
            advice = advise(self.scene, last_q, last_v, self.system.controller, names, dt=h)
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
        samples = compiled.samples(native, run.scene)
        run.t, run.q, run.v = samples.t.tolist(), list(samples.q), list(samples.v)
        run.tau = list(samples.tau)
        if samples.pending:
            run.tau[-1] = None
        s = run.system
        s.n_rhs, s.n_jac, s.n_factor = samples.n_rhs, samples.n_jac, samples.n_factor
        run.n_accepted, run.n_rejected = samples.n_accepted, samples.n_rejected
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
