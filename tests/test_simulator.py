"""coopdyn.Simulator: set up once, run many times — each run the same result as simulate's, to
the last bit, with its own counters, and simulate's errors."""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.control import GravityCompensationPD
from coopdyn.errors import ControllerError, DivergenceError, SimulationError
from coopdyn.integrators import AdaptiveROS2, DormandPrince, LinearlyImplicitEuler


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
                control_dt=control_dt, accuracy_check="off", energy_check="warn",
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
                accuracy_check="off", energy_check="warn",
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
    _same(sim.run(0.02), cd.simulate(pandas, 0.02, controller=pd, max_speed=5.0, accuracy_check="off", energy_check="off"))
    pd.kp = pd.kp * 2.0
    for t_final in (0.02, 0.013):
        _same(
            sim.run(t_final),
            cd.simulate(pandas, t_final, controller=pd, max_speed=5.0, accuracy_check="off", energy_check="off"),
        )
    pd.kd = 8.0  # a scalar, as the constructor takes it: one value per joint (it once broke the compiled spec)
    assert pd.kd.shape == (pandas.n_actuated,)
    _same(sim.run(0.02), cd.simulate(pandas, 0.02, controller=pd, max_speed=5.0, accuracy_check="off", energy_check="off"))
    with pytest.raises(cd.SceneError, match=r"GravityCompensationPD: kp must be a scalar or one value per actuated joint"):
        pd.kp = [1.0, 2.0]


def test_a_python_controller_and_the_python_backend(pandas: cd.Scene) -> None:
    """A user's Python controller is called back as in simulate; on the Python backend a run is an
    ordinary simulate call."""

    def law(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return -5.0 * v[pandas.actuated]

    for backend in ("native", "python"):
        sim = cd.Simulator(pandas, law, "rk4", 1e-3, backend=backend)
        mine = sim.run(0.02)
        theirs = cd.simulate(pandas, 0.02, controller=law, dt=1e-3, backend=backend, accuracy_check="off", energy_check="off")
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
        pandas, 0.05, controller=pd, integrator="implicit_euler", dt=1e-3, v0=v0, max_speed=5.0, accuracy_check="off",
        energy_check="off",
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
