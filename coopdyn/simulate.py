"""``coopdyn.simulate``: run a scene under a controller and return a :class:`Result`."""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from . import _progress, _validate, compiled
from . import accuracy as screening
from .budget import check_budget, step_count
from .closed_loop import Controller, System
from .dynamics import Dynamics
from .dynamics.constrained import check_integrator, has_constraints
from .errors import (
    AccuracyWarning,
    ControlRateWarning,
    CoopdynError,
    DivergenceError,
    EnergyBalanceError,
    SceneWarning,
    SimulationError,
    SimulationInterrupted,
    StepBudgetError,
    StepMatrixError,
    StepSizeError,
    UnstableLoopWarning,
)
from .integrators import DormandPrince, EmbeddedRungeKutta, Integrator, get_integrator
from .model.scene import Scene, data_bytes
from .monitor import EnergyMonitor
from .result import Result, SampleFiles
from .simulator import Simulator
from .statics import rest_pose
from .stepping import (
    ENERGY_CHECKS,
    _check_samples,
    _checked_choice,
    _checked_duration,
    _checked_steps,
    _control_period,
    _progress_bar,
    _Run,
    execute,
)

LOOPS = ("auto", "compiled", "python")
ACCURACY_CHECKS = ("auto", "screen", "off")
#: a set-up whose two Pinocchio data (the Python dynamics' and the kernel's) and last run's samples
#: would hold more than this [bytes] is not kept between calls (see _reused)
REUSE_MAX_BYTES = 16e6
_kept = threading.local()  #: per thread: the Simulator of the last call without checks, and its key


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
            ``"screen"``: the screen alone (no second run). ``"off"``: no judgement; and such a
            call (without ``object_wrench``, ``stream_to``, ``progress`` or a ``loop`` named) is a
            :class:`coopdyn.Simulator` run whose set-up — the compiled kernel and loop — the
            thread keeps: its next such call on the same scene and controller (the same objects)
            with the same settings — only the start state and the duration may differ —
            restarts that loop instead of building one (``benchmarks/fixed_cost.py``), with the
            same result to the last bit. What the thread keeps (its Pinocchio data and the last
            run's samples, at most :data:`REUSE_MAX_BYTES`, and the scene and controller) is
            released by its next such call with other settings.
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
    if accuracy_check == "off" and object_wrench is None and stream_to is None and not progress and loop == "auto":
        settings = dict(
            dt=dt, save_every=save_every, max_speed=max_speed, energy_check=energy_check, control_dt=control_dt,
            backend=backend, max_steps=max_steps, max_memory=max_memory,
        )  # fmt: skip
        return _reused(scene, controller, method, settings, t_final, q, v, budget)

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
    result = execute(run, config, monitor, bar, cpu0)
    if accuracy_check != "off" and t_final > 0 and _probed(controller, scene):
        _check_the_loop(result, system, q, v)
    if not judged:
        return result
    rerun = dict(
        controller=controller, q0=q, v0=v, object_wrench=object_wrench, backend=backend, progress=progress, control_dt=control_dt
    )
    return _judge_forces(result, system, method, accuracy_check, stream_to is not None, rerun)


def _reused(
    scene: Scene,
    controller: Any,
    method: Integrator,
    settings: dict[str, Any],
    t_final: float,
    q: np.ndarray,
    v: np.ndarray,
    budget: int | None,
) -> Result:
    """The run on the Simulator this thread kept from its last call without checks when that
    call had the same scene, controller and settings (a controller retuned since is run as it is
    now: Simulator.run reads it), else on a new one, kept in turn. It is taken while it runs: a
    controller that calls simulate gets one of its own, and a run that raises keeps none."""
    objects = (scene, controller, type(method))  # (the same objects: compared by identity)
    values = (settings, os.environ.get("COOPDYN_BACKEND"))  # (numbers, text and None: compared by value)
    key = (objects, values, dict(vars(method)))  # (the method's settings: to the bit, arrays too)
    sim: Simulator | None = getattr(_kept, "simulator", None)
    kept: Any = getattr(_kept, "key", None)
    _kept.simulator = _kept.key = None
    if (
        sim is None
        or any(a is not b for a, b in zip(objects, kept[0], strict=True))
        or values != kept[1]
        or not compiled.same(key[2], kept[2])
    ):
        # its own copy of the method: one the user retunes later must not run under these settings' key
        sim = Simulator(scene, controller, copy.deepcopy(method), **settings)
    result = sim._run(t_final, q, v, budget)  # (the arguments checked by simulate, as Simulator.run checks them)
    samples = result.t.size * (1 + scene.nq + scene.nv + scene.n_actuated) * 8.0  # (the loop keeps them)
    if 2.0 * data_bytes(scene.nv) + samples <= REUSE_MAX_BYTES:
        _kept.simulator, _kept.key = sim, key
    return result


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
