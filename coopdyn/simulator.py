"""``coopdyn.Simulator``: many runs of one scene, controller and method, each at a fraction of
:func:`coopdyn.simulate`'s fixed cost — for model-predictive control, identification and
sweeps over initial states, where a run is short and there are thousands of them."""

from __future__ import annotations

import contextlib
import time
from typing import Any

import numpy as np

from . import compiled
from ._spec import PythonControllerSpec
from .budget import check_budget
from .closed_loop import Controller, System
from .dynamics import Dynamics
from .dynamics.constrained import check_integrator
from .errors import SimulationError, SimulationInterrupted
from .integrators import get_integrator
from .model.scene import Scene
from .monitor import EnergyMonitor
from .result import Result
from .stepping import (
    ENERGY_CHECKS,
    _check_samples,
    _checked_choice,
    _checked_duration,
    _checked_steps,
    _compiled_loop,
    _control_period,
    _Run,
    execute,
    interruption,
    take_samples,
)

__all__ = ["Simulator"]


class Simulator:
    """Repeated runs of ``scene`` under ``controller`` with one method and step, set up once.

    ``Simulator(scene, controller, integrator, dt).run(t_final, q0, v0)`` gives the same
    :class:`Result`, to the last bit, as ``coopdyn.simulate(scene, t_final, controller,
    integrator, dt, q0=q0, v0=v0, accuracy_check="off", energy_check=…)`` with the same settings
    (tests/test_simulator.py). What ``simulate`` does before every run — checking the
    arguments, building the dynamics (the compiled kernel) and the closed loop — is done here
    once; a run checks its state, reads the controller's gains and compiled twin (a controller
    retuned between runs is run as it is now), restarts the compiled loop the last run built
    when nothing but the start state changed (a new one otherwise: other gains, another
    ``t_final``, a Python controller) and collects its samples (a short run that completes
    without a warning straight into its Result). ``benchmarks/fixed_cost.py`` measures both.

    What it leaves out, as the price of that: the accuracy judgement and the loop check
    (``accuracy_check``; the ``UnstableLoopWarning`` and ``ControlRateWarning``: judge one
    representative run with :func:`coopdyn.simulate` first), progress bars and
    ``stream_to``, and an ``object_wrench`` (not taken). A run that cannot go to the compiled
    loop (the Python backend, a Python integrator, rigid grasps) runs in the Python loop, on the
    dynamics set up once. ``simulate`` itself runs a call with ``accuracy_check="off"`` on a
    Simulator it keeps for the thread's next such call.

    Args:
        scene: the scene.
        controller: ``controller(t, q, v) -> τ`` (n_actuated,) [N·m or N], or None.
        integrator: a name from ``coopdyn.integrators.INTEGRATORS`` or an instance.
        dt: time step [s]; save_every: keep every k-th step.
        max_speed: [rad/s or m/s]; control_dt: the controller's sample period [s] or None;
            backend, max_steps, max_memory [bytes]: as for :func:`coopdyn.simulate`.
        energy_check: as for ``simulate``, but ``"off"`` by default (a controller design loop
            runs the same scene many times; check it once with ``"warn"``).

    Raises:
        SimulationError, ControllerError: the arguments, as ``simulate`` refuses them.
    """

    def __init__(
        self,
        scene: Scene,
        controller: Controller | None = None,
        integrator: Any = "rk4",
        dt: float = 1e-3,
        *,
        save_every: int = 1,
        max_speed: float = 1e4,
        energy_check: str = "off",
        control_dt: float | None = None,
        backend: str | None = None,
        max_steps: int | None = 2 * 10**6,
        max_memory: float | None = 4e9,
    ) -> None:
        if not isinstance(scene, Scene):
            raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
        self.scene, self.controller = scene, controller
        self.dt, self.save_every, self.max_speed = _checked_steps(dt, save_every, max_speed)
        self.energy_check = _checked_choice("energy_check", energy_check, ENERGY_CHECKS)
        self.method = get_integrator(integrator)
        check_integrator(scene, self.method)
        self.control_dt = _control_period(control_dt, self.dt, self.method)
        self.backend, self.max_steps, self.max_memory = backend, max_steps, max_memory
        self.system = System(Dynamics(scene, backend), controller, None, self.control_dt)
        self.system.max_speed = self.max_speed
        self._energy = "off" if self.method.exact_discretisation else energy_check
        # the last run's compiled loop and its configuration: the next run with the same settings
        # (other q0, v0) restarts it instead of building one (benchmarks/fixed_cost.py)
        self._loop: Any = None
        self._loop_config: dict[str, Any] = {}
        self._loop_key: tuple[Any, ...] = ()
        self._fresh = True  # (the system just built: its first run need not restart it, nor read the gains twice)
        # Python code inside the compiled loop besides a Python controller: an element without a C++ twin
        self._python_elements = any(lk.native is None for lk in scene.elements)

    def run(self, t_final: float, q0: Any = None, v0: Any = None) -> Result:
        """Simulate from (q0 (nq,), v0 (nv,)) (default: the scene's) over ``t_final`` [s]; the result as
        :func:`coopdyn.simulate` returns it (its errors too: a DivergenceError with the partial
        run, a ControllerError …)."""
        t_final = _checked_duration(t_final)
        scene = self.scene
        q, v = scene.check_state(scene.q0 if q0 is None else q0, scene.v0 if v0 is None else v0)
        budget = check_budget(scene, t_final, self.dt, self.save_every, self.max_steps, self.max_memory)
        _check_samples(t_final, self.control_dt, budget)
        return self._run(t_final, q, v, budget)

    def _run(self, t_final: float, q: np.ndarray, v: np.ndarray, budget: int | None) -> Result:
        """:meth:`run` with its arguments checked (``budget``: ``check_budget``'s): simulate's
        calls without checks come here, checked once."""
        cpu0 = time.process_time()  # (a new loop's preparation counts, as in simulate)
        scene, method, system = self.scene, self.method, self.system
        if self._fresh:
            self._fresh = False
        else:
            system.restart()
        run = _Run(scene, system, method, self.dt, self.save_every, t_final, self.max_speed, (q, v))
        run.budget = budget
        native, self._loop = self._loop, None  # (not kept while it runs: a run that raises leaves none)
        settings = None
        if native is not None:  # the last run's loop, restarted when only the start state differs
            settings = compiled.controller_settings(scene, system)
            key = self._key(t_final, settings)
            if compiled.same(key, self._loop_key):
                native.restart(q, v)
                return self._compiled(run, native, self._loop_config, key, cpu0)
        config, _ = compiled.plan(
            scene,
            system,
            method,
            q0=q,
            v0=v,
            dt=self.dt,
            t_final=t_final,
            n_steps=run.n_steps,
            save_every=self.save_every,
            max_speed=self.max_speed,
            energy_check=self._energy,
            controller=settings,
        )
        if config is None:  # the Python loop, on the dynamics set up once
            monitor = None
            if self._energy != "off":
                every = max(1, round(5e-3 / self.dt))
                monitor = EnergyMonitor(system, 0.0, q, v, every=every, mode=self._energy, method=method.name)
            return execute(run, None, monitor, None, cpu0)
        native = system.dynamics.compiled_loop(config)  # type: ignore[attr-defined]
        return self._compiled(run, native, config, self._key(t_final, config["controller"]), cpu0)

    def _key(self, t_final: float, controller: dict[str, Any]) -> tuple[Any, ...]:
        """What a run's compiled loop depends on besides the Simulator's own settings and the
        start state: the duration, the integrator's settings (a user may change its rtol), the
        controller's compiled settings and its gains (retuned between runs)."""
        return (t_final, dict(vars(self.method)), controller, *self.system.matrix_gains)

    def _compiled(self, run: _Run, native: Any, config: dict[str, Any], key: tuple[Any, ...], cpu0: float) -> Result:
        """The run in ``native`` (at its start); the loop kept for the next run. A Ctrl-C is a
        :class:`SimulationInterrupted` with the samples so far, as in simulate."""
        run.loop = "compiled"
        # a blow-up's overflow is a DivergenceError, not a numpy warning; only Python code needs the
        # errstate (1 µs of a one-step run's fixed cost): a controller called back, an element
        # without a C++ twin, the general path
        python = self._python_elements or config["controller"]["kind"] == PythonControllerSpec.name
        try:
            with np.errstate(over="ignore", invalid="ignore") if python else contextlib.nullcontext():
                first = self._first_chunk(run, native)
            result = self._short(run, native, cpu0, first)
            if result is None:
                with np.errstate(over="ignore", invalid="ignore"):
                    _compiled_loop(run, config, None, native, first)
                run.cpu_time = time.process_time() - cpu0
                result = run.result()
        except KeyboardInterrupt as exc:
            if isinstance(exc, SimulationInterrupted):
                raise
            if not run.t:  # (in the first chunk: the general path has not taken the loop's samples)
                take_samples(run, native)
            raise interruption(run, cpu0) from None
        self._loop, self._loop_config, self._loop_key = native, config, key
        return result

    @staticmethod
    def _first_chunk(run: _Run, native: Any) -> tuple[int, list[Any]] | None:
        """(status, events) of a fixed-step run that fits in the loop's first chunk, run whole
        here; None for any other run (the general path advances it)."""
        if run.method.adaptive or run.n_steps >= compiled.FIRST_CHUNK:
            return None
        status = native.advance(compiled.FIRST_CHUNK)
        return status, native.take_events()

    def _short(self, run: _Run, native: Any, cpu0: float, first: tuple[int, list[Any]] | None) -> Result | None:
        """The Result of a run done in its first chunk without a warning, straight from the loop's
        samples (the general path's bookkeeping, 14 µs, is most of a one-step run's fixed cost:
        benchmarks/fixed_cost.py); None when anything is to report — a warning, a failure, a
        torque left pending: the general path takes over from that chunk, nothing run twice."""
        if first is None or first != (compiled.DONE, []):
            return None
        t, Q, V, TAU, pending = native.samples()
        if pending:
            return None
        cpu_time = time.process_time() - cpu0
        n_rhs, n_jac, n_factor, n_steps, n_rejected = native.counters()
        s = self.system
        s.n_rhs, s.n_jac, s.n_factor = n_rhs, n_jac, n_factor
        t, Q, V, TAU = compiled.rows(t, Q, V, TAU, self.scene)
        return Result(
            scene=self.scene, t=t, q=Q, v=V, tau=TAU, integrator=run.method.name, dt=self.dt, n_rhs=n_rhs,
            cpu_time=cpu_time, n_jac=n_jac, n_factor=n_factor, n_steps=n_steps, n_rejected=n_rejected,
            status="completed", backend=s.dynamics.backend, loop="compiled",
        )  # fmt: skip

    def __repr__(self) -> str:
        return f"Simulator({self.scene!r}, {type(self.controller).__name__}, {self.method!r}, dt={self.dt:g})"
