"""coopdyn.Simulator: set up once, run many times — each run the same result as simulate's, to
the last bit, with its own counters, and simulate's errors."""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.control import GravityCompensationPD
from coopdyn.errors import ControllerError, DivergenceError, SimulationError
from coopdyn.integrators import AdaptiveROS2, DormandPrince, LinearlyImplicitEuler

#: no judgement, no monitor; with a loop named, a simulate call is set up from nothing (it does not
#: take the thread's kept Simulator: simulate's docstring)
OFF: dict[str, Any] = {"accuracy_check": "off", "energy_check": "off"}


def _warned(run: Callable[[], cd.Result]) -> tuple[cd.Result, list[str]]:
    """``run()``'s result and the messages of the warnings it gave, every one, each attributed
    to the call in this file (not to a line of coopdyn's, however deep it arose)."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = run()
    assert [w.filename for w in said] == [__file__] * len(said)
    return result, [str(w.message) for w in said]


def _same(a: cd.Result, b: cd.Result) -> None:
    for name in ("t", "q", "v", "tau"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("n_rhs", "n_jac", "n_factor", "n_steps", "n_rejected", "status", "loop", "integrator", "dt"):
        assert getattr(a, name) == getattr(b, name), name


@pytest.mark.parametrize(
    ("integrator", "control_dt"),
    [
        ("rk4", None),
        ("trapezoid", None),
        (DormandPrince(rtol=1e-6), None),
        ("implicit_euler", 2e-3),
        ("rk4", 1e-3),
        (LinearlyImplicitEuler(jacobian_every=4), None),
        ("generalized_alpha", None),
        (AdaptiveROS2(rtol=1e-4), None),
        ("exponential", None),
    ],
    ids=str,
)
def test_every_run_is_simulates_run(pandas: cd.Scene, integrator: object, control_dt: float | None) -> None:
    """Runs of one Simulator from different states, one after the other (the later ones restart
    the first's compiled loop), with the energy monitor on: each equals simulate's with the same
    settings bit for bit — counters, a kept step matrix, the monitor's warnings: nothing carries
    over."""
    pd = GravityCompensationPD(pandas)
    scene = pandas
    if integrator == "exponential":  # (a linear scene: the book system)
        scene, pd = cd.problems.linear_book(), None  # type: ignore[assignment]
    sim = cd.Simulator(scene, pd, integrator, 5e-4, save_every=2, control_dt=control_dt, energy_check="warn")
    rng = np.random.default_rng(7)
    for kick in (0.3, 3.0, 0.0, 0.3):  # (3 rad/s: an unresolved run the monitor warns about)
        v0 = rng.normal(size=scene.nv) * kick
        mine, mine_said = _warned(lambda: sim.run(0.03, v0=v0))
        theirs, their_said = _warned(
            lambda: cd.simulate(
                scene, 0.03, controller=pd, integrator=integrator, dt=5e-4, save_every=2, v0=v0,
                control_dt=control_dt, accuracy_check="off", energy_check="warn", loop="compiled",
            )
        )  # fmt: skip
        assert mine.loop == "compiled"
        _same(mine, theirs)
        assert mine_said == their_said


def test_the_energy_monitor_starts_again() -> None:
    """The monitor of a restarted loop judges its own run: grasps of 1e5 N/m kicked, at rest,
    kicked again, under symplectic Euler 5 % beyond its stability limit (the kicked runs break
    the energy balance at once; at rest the unstable mode, grown from round-off, stays below it
    for 50 ms) — the same warnings as simulate's, and none for the run at rest."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e5)
    pd = GravityCompensationPD(scene, 50.0, 5.0)
    dt = 1.05 * cd.advise(scene, controller=pd).max_stable_dt("symplectic_euler")
    sim = cd.Simulator(scene, pd, "symplectic_euler", dt, energy_check="warn")
    rng = np.random.default_rng(0)
    messages = []
    for kick in (0.05, 0.0, 0.05):
        v0 = rng.normal(size=scene.nv) * kick
        mine, mine_said = _warned(lambda: sim.run(0.05, v0=v0))
        theirs, their_said = _warned(
            lambda: cd.simulate(
                scene, 0.05, controller=pd, integrator="symplectic_euler", dt=dt, v0=v0,
                accuracy_check="off", energy_check="warn", loop="compiled",
            )
        )  # fmt: skip
        _same(mine, theirs)
        messages.append(mine_said)
        assert mine_said == their_said
    assert [len(m) for m in messages] == [1, 0, 1] and "energy balance broken" in messages[2][0]


def test_a_python_controller_is_called_once_per_sample_even_when_the_run_warns() -> None:
    """A Python controller with state of its own (an integral term, a call count), on a run that
    warns (grasps kicked, symplectic Euler 5 % beyond its stability limit): Simulator.run calls
    it as often as simulate and gives the same trajectory — the warned run is reported from its
    one pass."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e5)
    pd = GravityCompensationPD(scene, 50.0, 5.0)
    dt = 1.05 * cd.advise(scene, controller=pd).max_stable_dt("symplectic_euler")

    class WithIntegral:
        def __init__(self) -> None:
            self.calls, self.integral = 0, np.zeros(scene.n_actuated)

        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            self.calls += 1
            self.integral += 1e-3 * v[scene.actuated]
            return pd(t, q, v) - 5.0 * self.integral

    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.05
    runs = []
    for make in ("simulator", "simulate"):
        law = WithIntegral()
        with pytest.warns(cd.EnergyBalanceWarning):
            if make == "simulator":
                res = cd.Simulator(scene, law, "symplectic_euler", dt, energy_check="warn").run(0.05, v0=v0)
            else:
                res = cd.simulate(
                    scene,
                    0.05,
                    controller=law,
                    integrator="symplectic_euler",
                    dt=dt,
                    v0=v0,
                    accuracy_check="off",
                    energy_check="warn",
                    loop="compiled",
                )
        runs.append((res, law.calls))
    (mine, my_calls), (theirs, their_calls) = runs
    assert my_calls == their_calls
    _same(mine, theirs)


def test_a_run_after_a_failed_one_and_after_a_retuning(pandas: cd.Scene) -> None:
    """The loop a diverged run leaves behind is not reused half-way; a controller retuned between
    runs, or another duration, gets a loop of its own: each run equals simulate's."""
    pd = GravityCompensationPD(pandas)
    sim = cd.Simulator(pandas, pd, "rk4", 1e-3, max_speed=5.0)
    with pytest.raises(DivergenceError):
        sim.run(0.2, v0=np.full(pandas.nv, 4.9))
    _same(sim.run(0.02), cd.simulate(pandas, 0.02, controller=pd, max_speed=5.0, loop="compiled", **OFF))
    pd.kp = pd.kp * 2.0
    for t_final in (0.02, 0.013):
        _same(
            sim.run(t_final),
            cd.simulate(pandas, t_final, controller=pd, max_speed=5.0, loop="compiled", **OFF),
        )
    pd.kd = 8.0  # a scalar, as the constructor takes it: one value per joint (it once broke the compiled spec)
    assert pd.kd.shape == (pandas.n_actuated,)
    _same(sim.run(0.02), cd.simulate(pandas, 0.02, controller=pd, max_speed=5.0, loop="compiled", **OFF))
    with pytest.raises(cd.SceneError, match=r"GravityCompensationPD: kp must be a scalar or one value per actuated joint"):
        pd.kp = [1.0, 2.0]


def test_a_python_controller_and_the_python_backend(pandas: cd.Scene) -> None:
    """A user's Python controller is called back as in simulate; on the Python backend a run goes
    through the Python loop, as simulate's."""

    def law(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return -5.0 * v[pandas.actuated]

    for backend in ("native", "python"):
        sim = cd.Simulator(pandas, law, "rk4", 1e-3, backend=backend)
        mine = sim.run(0.02)
        loop = "compiled" if backend == "native" else "python"
        theirs = cd.simulate(pandas, 0.02, controller=law, dt=1e-3, backend=backend, loop=loop, **OFF)
        _same(mine, theirs)
        assert mine.loop == ("compiled" if backend == "native" else "python")


def test_simulates_errors(pandas: cd.Scene) -> None:
    """A divergence carries the partial run; a failing controller, a bad state and bad settings
    are refused as simulate refuses them."""
    pd = GravityCompensationPD(pandas)
    with pytest.raises(DivergenceError) as info:
        cd.Simulator(pandas, pd, "rk4", 1e-3, max_speed=1.0).run(0.2, v0=np.full(pandas.nv, 0.9))
    assert len(info.value.result.t) > 1

    def bad(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        raise RuntimeError("sensor lost")

    with pytest.raises(ControllerError, match="sensor lost"):
        cd.Simulator(pandas, bad).run(0.01)
    sim = cd.Simulator(pandas, pd)
    with pytest.raises(cd.SceneError, match="q"):
        sim.run(0.01, q0=np.full(pandas.nq, np.nan))
    with pytest.raises(SimulationError, match="t_final must be >= 0"):
        sim.run(-1.0)
    with pytest.raises(SimulationError, match="whole multiple of dt"):
        cd.Simulator(pandas, pd, "rk4", 3e-4, control_dt=1e-3)
    with pytest.raises(SimulationError, match="energy_check"):
        cd.Simulator(pandas, pd, energy_check="loud")
    assert sim.run(0.01).status == "completed"  # (still usable after a refused run)


def test_after_a_failed_run_and_a_retuning_the_next_run_is_still_simulates(pandas: cd.Scene) -> None:
    """A run that diverges, then the controller retuned (its gains enter the implicit matrix):
    the next run equals simulate's with the controller as it is now."""
    pd = GravityCompensationPD(pandas)
    sim = cd.Simulator(pandas, pd, "implicit_euler", 1e-3, max_speed=5.0)
    with pytest.raises(DivergenceError):
        sim.run(0.3, v0=np.full(pandas.nv, 4.9))
    pd.kp, pd.kd = pd.kp * 3.0, pd.kd * 2.0
    v0 = np.random.default_rng(3).normal(size=pandas.nv) * 0.3
    mine = sim.run(0.05, v0=v0)
    theirs = cd.simulate(
        pandas, 0.05, controller=pd, integrator="implicit_euler", dt=1e-3, v0=v0, max_speed=5.0, loop="compiled", **OFF
    )  # fmt: skip
    _same(mine, theirs)


_SETTINGS = {"kind": "gravity_pd", "kp": np.ones(3), "rtol": 1e-6, "steps": (1, 2.0, "x")}


@pytest.mark.parametrize(
    ("other", "same"),
    [
        ({"kind": "gravity_pd", "kp": np.ones(3), "rtol": 1e-6, "steps": (1, 2.0, "x")}, True),
        ({**_SETTINGS, "kp": np.r_[1.0, 1.0, np.nextafter(1.0, 2.0)]}, False),
        ({**_SETTINGS, "kp": np.ones(3, dtype=np.float32)}, False),
        ({**_SETTINGS, "kp": np.ones((3, 1))}, False),
        ({**_SETTINGS, "rtol": 1e-7}, False),
        ({**_SETTINGS, "steps": (1, 2.0)}, False),
        ({**_SETTINGS, "steps": [1, 2.0, "x"]}, False),
        ({**_SETTINGS, "steps": (1.0, 2.0, "x")}, False),
        ({k: v for k, v in _SETTINGS.items() if k != "rtol"}, False),
    ],
)
def test_a_loop_is_restarted_only_under_settings_equal_to_the_bit(other: dict[str, object], same: bool) -> None:
    from coopdyn import compiled

    assert compiled.same(_SETTINGS, other) is same
    assert compiled.same(other, _SETTINGS) is same


def _kept() -> tuple[Any, Any]:
    """The thread's kept (Simulator, key) of simulate's calls without checks."""
    kept = sys.modules["coopdyn.simulate"]._kept
    return getattr(kept, "simulator", None), getattr(kept, "key", None)


@pytest.mark.parametrize("integrator", ["rk4", "trapezoid", DormandPrince(rtol=1e-6), "implicit_euler"], ids=str)
def test_simulate_without_checks_restarts_the_set_up_it_kept(pandas: cd.Scene, integrator: object) -> None:
    """simulate with accuracy_check="off" (the energy monitor on), called again on the same scene
    and controller from other states: the later calls run on the first call's Simulator, and
    each equals simulate's set up from nothing bit for bit, warnings too."""
    pd = GravityCompensationPD(pandas)
    rng = np.random.default_rng(11)
    kept = []
    for kick in (0.3, 3.0, 0.0):
        v0 = rng.normal(size=pandas.nv) * kick
        args: dict[str, Any] = dict(controller=pd, integrator=integrator, dt=5e-4, v0=v0, accuracy_check="off")
        mine, mine_said = _warned(lambda: cd.simulate(pandas, 0.03, **args))
        kept.append(_kept()[0])
        theirs, their_said = _warned(lambda: cd.simulate(pandas, 0.03, loop="compiled", **args))
        _same(mine, theirs)
        assert mine_said == their_said
    assert kept[0] is not None and kept[1] is kept[0] and kept[2] is kept[0]


def test_simulate_keeps_one_set_up_per_thread_for_equal_settings(pandas: cd.Scene) -> None:
    """A controller retuned in place is run as it is now, on the kept set-up; another dt, another
    controller object or another scene is set up anew and replaces it: one per thread."""
    pd = GravityCompensationPD(pandas)
    cd.simulate(pandas, 0.01, controller=pd, **OFF)
    first = _kept()[0]
    pd.kp = pd.kp * 2.0
    _same(cd.simulate(pandas, 0.01, controller=pd, **OFF), cd.simulate(pandas, 0.01, controller=pd, loop="compiled", **OFF))
    assert _kept()[0] is first
    cd.simulate(pandas, 0.01, controller=pd, dt=5e-4, **OFF)
    assert _kept()[0] is not first and _kept()[0].dt == 5e-4
    cd.simulate(pandas, 0.01, controller=GravityCompensationPD(pandas), dt=5e-4, **OFF)
    assert _kept()[0].controller is not pd
    book = cd.problems.linear_book()
    cd.simulate(book, 0.01, **OFF)
    assert _kept()[0].scene is book


def test_threads_keep_their_own_set_up(pandas: cd.Scene) -> None:
    """Two threads calling simulate without checks, each from its own states: every result equals
    that of a call set up from nothing."""
    pd = GravityCompensationPD(pandas)
    v0s = np.random.default_rng(5).normal(size=(2, 4, pandas.nv)) * 0.3

    def calls(starts: np.ndarray) -> list[cd.Result]:
        return [cd.simulate(pandas, 0.02, controller=pd, v0=v0, **OFF) for v0 in starts]

    with ThreadPoolExecutor(2) as pool:
        mine = [r for results in pool.map(calls, v0s) for r in results]
    theirs = [cd.simulate(pandas, 0.02, controller=pd, v0=v0, loop="compiled", **OFF) for v0 in v0s.reshape(-1, pandas.nv)]
    for a, b in zip(mine, theirs, strict=True):
        _same(a, b)


@pytest.mark.parametrize("integrator", ["rk4", LinearlyImplicitEuler(jacobian_every=4)], ids=str)
def test_a_controller_that_calls_simulate_gets_a_set_up_of_its_own(pandas: cd.Scene, integrator: object) -> None:
    """A planner-like Python controller that, at each of its samples, simulates the scene ahead
    under itself (without checks, as a planner would): the inner calls have the outer call's
    settings but cannot take its set-up while it runs — the second outer call, on the set-up the
    first kept, equals one set up from nothing, and so do all the inner runs. (Sharing it would
    break a method that keeps its step matrix's factor across steps: the inner runs would
    factor their own into the kernel in between.)"""
    pd = GravityCompensationPD(pandas)

    class Planner:
        def __init__(self, loop: str) -> None:
            self.loop, self.inner, self.planning = loop, [], False

        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            if not self.planning:
                self.planning = True
                try:
                    self.inner.append(self.run(0.005, q, v))
                finally:
                    self.planning = False
            return pd(t, q, v)

        def run(self, t_final: float, q: np.ndarray, v: np.ndarray) -> cd.Result:
            return cd.simulate(
                pandas, t_final, controller=self, integrator=integrator, q0=q, v0=v, control_dt=5e-3, loop=self.loop, **OFF
            )

    kept, fresh = Planner("auto"), Planner("compiled")
    v0 = np.random.default_rng(2).normal(size=pandas.nv) * 0.3
    for planner in (kept, fresh):
        planner.run(0.02, pandas.q0, -v0)
    assert _kept()[0].controller is kept  # (the first outer call's, kept last)
    _same(kept.run(0.02, pandas.q0, v0), fresh.run(0.02, pandas.q0, v0))
    assert len(kept.inner) == len(fresh.inner) >= 8
    for a, b in zip(kept.inner, fresh.inner, strict=True):
        _same(a, b)


class _StopAfter:
    """A controller that lets go after ``t_stop`` [s] the way Ctrl-C does: KeyboardInterrupt."""

    def __init__(self, n_actuated: int, t_stop: float = 5e-3) -> None:
        self.zero, self.t_stop = np.zeros(n_actuated), t_stop

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        if t > self.t_stop:
            raise KeyboardInterrupt
        return self.zero


@pytest.mark.parametrize("t_final", [0.01, 0.2], ids=["within the first chunk", "past it"])
@pytest.mark.parametrize("how", ["simulate", "Simulator"])
def test_a_ctrl_c_gives_the_partial_run_as_simulate_set_up_from_nothing(pandas: cd.Scene, how: str, t_final: float) -> None:
    """A Ctrl-C 5 ms into a run without checks — on simulate's kept set-up or a Simulator's run, in
    the compiled loop's first chunk or past it: a SimulationInterrupted carrying the samples so
    far, the same as a simulate call set up from nothing raises (it once escaped as a bare
    KeyboardInterrupt, the run lost)."""
    with pytest.raises(cd.SimulationInterrupted) as theirs:
        cd.simulate(pandas, t_final, controller=_StopAfter(pandas.n_actuated), loop="compiled", **OFF)
    with pytest.raises(cd.SimulationInterrupted) as mine:
        if how == "simulate":
            cd.simulate(pandas, t_final, controller=_StopAfter(pandas.n_actuated), **OFF)
        else:
            cd.Simulator(pandas, _StopAfter(pandas.n_actuated)).run(t_final)
    assert str(mine.value) == str(theirs.value) and mine.value.result.status == "interrupted"
    _same(mine.value.result, theirs.value.result)


def test_an_integrator_retuned_after_a_call_does_not_run_under_its_old_settings(pandas: cd.Scene) -> None:
    """The kept set-up runs its own copy of the integrator: one the user retunes after the call
    that built it (rtol 1e-6 → 1e-2) neither changes what a later call with the old settings
    runs nor is run under the old settings' key."""
    pd = GravityCompensationPD(pandas)
    v0 = np.random.default_rng(4).normal(size=pandas.nv) * 0.3
    method = DormandPrince()
    cd.simulate(pandas, 0.05, controller=pd, integrator=method, v0=v0, **OFF)
    method.rtol = 1e-2
    for integrator in ("dopri5", method):
        _same(
            cd.simulate(pandas, 0.05, controller=pd, integrator=integrator, v0=v0, **OFF),
            cd.simulate(pandas, 0.05, controller=pd, integrator=integrator, v0=v0, loop="compiled", **OFF),
        )


def test_a_large_set_up_or_a_long_run_is_not_kept(pandas: cd.Scene) -> None:
    """What a thread keeps stays under REUSE_MAX_BYTES (16 MB): not after a run of 40 001 samples
    (18 MB in the loop), nor a 16-element beam's two Pinocchio data (2 × 55 MB)."""
    pd = GravityCompensationPD(pandas)
    cd.simulate(pandas, 0.01, controller=pd, **OFF)
    assert _kept()[0] is not None
    cd.simulate(pandas, 4.0, controller=pd, dt=1e-4, **OFF)
    assert _kept()[0] is None
    cd.simulate(pandas, 0.01, controller=pd, **OFF)
    cd.simulate(cd.scenes.held_beam(n_elements=16, damping=0.002), 1e-3, integrator="implicit_euler", **OFF)
    assert _kept()[0] is None


def test_gains_are_read_once_a_call(pandas: cd.Scene) -> None:
    """A controller's gains() (which may have side effects: logging, adaptation) is read once per
    simulate call without checks, as by a call set up from nothing."""

    class Counting:
        def __init__(self) -> None:
            self.reads = 0

        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            return -2.0 * v[pandas.actuated]

        def gains(self) -> tuple[np.ndarray, np.ndarray]:
            self.reads += 1
            return np.zeros(pandas.n_actuated), np.full(pandas.n_actuated, 2.0)

    kept, fresh = Counting(), Counting()
    for _ in range(3):
        cd.simulate(pandas, 0.01, kept, integrator="implicit_euler", **OFF)
        cd.simulate(pandas, 0.01, fresh, integrator="implicit_euler", loop="compiled", **OFF)
    assert kept.reads == fresh.reads == 3
