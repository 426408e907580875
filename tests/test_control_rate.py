"""A controller sampled at a fixed rate with a zero-order hold (``simulate(control_dt=…)``): called
once per sample instant, its output held in between, the same in both loops for every method, the
exact discretisation of a sampled-data linear loop, the integrators' own orders kept, and the
energy balance and accuracy check right across the torque's jumps."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.linalg import expm
from test_linearize import ball_pandas

import coopdyn as cd
from coopdyn.closed_loop import System
from coopdyn.control import GravityCompensationPD
from coopdyn.dynamics import Dynamics
from coopdyn.errors import SceneFileError, SimulationError
from coopdyn.integrators import INTEGRATORS, DormandPrince
from coopdyn.integrators.exponential import linear_form
from coopdyn.io import scenefile

COMPILED = [name for name, cls in INTEGRATORS.items() if "compiled_spec" in cls.__dict__ and name != "exponential"]


class Counting:
    """A user's own Python controller: a PD with gravity compensation that records its calls."""

    def __init__(self, scene: cd.Scene) -> None:
        self.inner = GravityCompensationPD(scene)
        self.times: list[float] = []

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        self.times.append(t)
        return self.inner(t, q, v)


@pytest.fixture(scope="module")
def start(pandas: cd.Scene) -> np.ndarray:
    return np.random.default_rng(1).normal(size=pandas.nv) * 0.3


@pytest.mark.parametrize("method", COMPILED)
def test_a_held_controller_is_called_once_per_sample_and_both_loops_agree(
    pandas: cd.Scene, start: np.ndarray, method: str
) -> None:
    """Four steps per 1 ms sample: the controller is called at t = 0, 1, …, 49 ms only (not at
    the final state, which keeps the held torque), the saved torque is constant over each
    sample period, and the Python and compiled loops take the same steps to round-off — with a
    Python controller called back and with the built-in one compiled."""
    runs = {}
    for loop in ("python", "compiled"):
        controller = Counting(pandas)
        runs[loop] = cd.simulate(
            pandas, 0.05, controller=controller, integrator=method, dt=2.5e-4, v0=start, control_dt=1e-3, loop=loop,
            accuracy_check="off",
        )  # fmt: skip
        assert np.allclose(controller.times, np.arange(50) * 1e-3, rtol=0, atol=1e-12), loop
    py, co = runs["python"], runs["compiled"]
    built_in = cd.simulate(
        pandas, 0.05, controller=GravityCompensationPD(pandas), integrator=method, dt=2.5e-4, v0=start, control_dt=1e-3,
        loop="compiled", accuracy_check="off",
    )  # fmt: skip
    assert co.loop == built_in.loop == "compiled"
    for other in (co, built_in):
        assert np.allclose(other.t, py.t, rtol=0, atol=1e-12)
        assert np.max(np.abs(other.q - py.q)) < 1e-12 and np.max(np.abs(other.tau - py.tau)) < 1e-9
        assert (other.n_rhs, other.n_steps, other.n_rejected) == (py.n_rhs, py.n_steps, py.n_rejected)
    sample = np.floor(py.t / 1e-3 + 1e-9)
    for k in np.unique(sample):
        assert np.ptp(py.tau[sample == k], axis=0).max() == 0.0
    assert np.ptp(py.tau, axis=0).max() > 1.0  # (and it does change between samples)


def test_adaptive_methods_land_on_every_sample_instant(pandas: cd.Scene, start: np.ndarray) -> None:
    """dopri5 with an output grid coarser than the sample period still steps to every sample
    instant (a 0.7 ms period against 5 ms outputs), and its first-same-as-last stage is not
    reused across a sample: it converges to the same trajectory as rk4 at fine steps."""
    for loop in ("python", "compiled"):
        controller = Counting(pandas)
        res = cd.simulate(
            pandas, 0.021, controller=controller, integrator=DormandPrince(rtol=1e-10, atol=1e-12), dt=5e-3, v0=start,
            control_dt=7e-4, accuracy_check="off", loop=loop,
        )  # fmt: skip
        assert np.allclose(controller.times, np.arange(30) * 7e-4, rtol=0, atol=1e-12)
        # a stage carried across a sample would be the old torque's: the step would be rejected
        # and retried at every sample (30 rejections, not a handful)
        assert res.n_rejected <= 3, (loop, res.n_rejected)
    fine = cd.simulate(
        pandas, 0.021, controller=GravityCompensationPD(pandas), integrator="rk4", dt=7e-5, v0=start, control_dt=7e-4,
        accuracy_check="off",
    )  # fmt: skip
    assert np.max(np.abs(fine.q[-1] - res.q[-1])) < 1e-9


def test_a_sampled_linear_loop_is_its_zero_order_hold_discretisation(book: cd.Scene) -> None:
    """The book's linear system under a sampled state feedback τ = −K x at 2 ms: every method
    with a hold reproduces x_{k+1} = Φ x_k + Γ τ_k + c_k, Φ and Γ from the matrix exponential of
    the continuous model (the closed form of a sampled-data loop), the exponential integrator
    to round-off and rk4 to its order."""
    rng = np.random.default_rng(3)
    K = rng.normal(size=(book.n_actuated, 2 * book.nv)) * 50.0

    def feedback(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return -K @ np.concatenate([q - book.q0, v])

    form = linear_form(System(Dynamics(book)))
    n, m, period = 2 * book.nv, book.n_actuated, 2e-3
    big = np.zeros((n + m + 1, n + m + 1))
    big[:n, :n], big[:n, n : n + m], big[:n, -1] = form.F, form.G, form.c
    E = expm(big * period)
    Phi, Gamma, drift = E[:n, :n], E[:n, n : n + m], E[:n, -1]
    x = np.concatenate([book.q0, book.v0 + 0.1])
    states = [x]
    for _ in range(50):
        tau = -K @ np.concatenate([x[: book.nv] - book.q0, x[book.nv :]])
        x = Phi @ x + Gamma @ tau + drift
        states.append(x)
    exact = np.array(states)
    for method, dt, tol in (("exponential", 2e-3, 1e-12), ("exponential", 5e-4, 1e-12), ("rk4", 1e-4, 1e-8)):
        res = cd.simulate(
            book, 0.1, controller=feedback, integrator=method, dt=dt, v0=book.v0 + 0.1, control_dt=period,
            save_every=round(period / dt), accuracy_check="off",
        )  # fmt: skip
        got = np.hstack([res.q, res.v])
        assert np.max(np.abs(got - exact)) <= tol * max(1.0, np.max(np.abs(exact))), (method, dt)


class HeldGainsPD:
    """A stiff joint PD on the book system that declares its gains (``gains()``): under a hold the
    implicit methods must leave them out of their matrix, or they lose their order."""

    def __init__(self, scene: cd.Scene) -> None:
        self.q0, self.act = scene.q0.copy(), scene.actuated
        self.kp, self.kd = 4e4, 40.0

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return -self.kp * (q[self.act] - self.q0[self.act]) - self.kd * v[self.act]

    def gains(self) -> tuple[float, float]:
        return self.kp, self.kd


@pytest.mark.parametrize(("method", "order"), [("trapezoid", 2), ("generalized_alpha", 2), ("implicit_euler", 1)])
def test_the_implicit_methods_keep_their_order_under_a_hold(book: cd.Scene, method: str, order: int) -> None:
    """The book system under a stiff PD held at 2 ms: the implicit methods converge to the exact
    sampled-data solution at their orders (a matrix still carrying the held PD's gains would be
    a wrong Jacobian for the held loop, and cost the second-order methods their order)."""
    ctrl = HeldGainsPD(book)
    kw = dict(controller=ctrl, v0=book.v0 + 0.1, control_dt=2e-3, accuracy_check="off", energy_check="off")
    exact = cd.simulate(book, 0.1, integrator="exponential", dt=2e-3, **kw)  # type: ignore[arg-type]
    errors = [
        np.max(np.abs(cd.simulate(book, 0.1, integrator=method, dt=dt, save_every=round(2e-3 / dt), **kw).q - exact.q))  # type: ignore[arg-type]
        for dt in (2.5e-4, 1.25e-4, 6.25e-5)
    ]
    rates = [np.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(abs(r - order) < 0.25 for r in rates), (errors, rates)


def test_the_hold_keeps_rk4_fourth_order(pandas: cd.Scene, start: np.ndarray) -> None:
    """The torque jumps only at step boundaries, so rk4's error against a tight dopri5 of the
    same sampled loop falls 16-fold per halving of dt (a hold inside a step would cost orders)."""
    kw = dict(controller=GravityCompensationPD(pandas), v0=start, control_dt=2e-3, accuracy_check="off")
    ref = cd.simulate(pandas, 0.06, integrator=DormandPrince(rtol=1e-12, atol=1e-14), dt=2e-3, **kw)  # type: ignore[arg-type]
    errors = [
        np.max(np.abs(cd.simulate(pandas, 0.06, integrator="rk4", dt=dt, save_every=round(2e-3 / dt), **kw).q - ref.q))  # type: ignore[arg-type]
        for dt in (1e-3, 5e-4, 2.5e-4)
    ]
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    assert all(12.0 < r < 20.0 for r in ratios), (errors, ratios)


def test_the_energy_balance_holds_across_the_torques_jumps(pandas: cd.Scene, start: np.ndarray) -> None:
    """A held PD does work in jumps; the monitor integrates each hold up to the power before the
    next sample's jump, so a well-resolved run breaks no balance (before, a 2 ms hold tripped it
    by 0.19 J on 2.4 J), in both loops."""
    for loop in ("python", "compiled"):
        res = cd.simulate(
            pandas, 0.2, controller=GravityCompensationPD(pandas), integrator="rk4", dt=2.5e-4, v0=start, control_dt=2e-3,
            energy_check="raise", accuracy_check="off", loop=loop,
        )  # fmt: skip
        assert res.status == "completed"


def test_the_accuracy_check_compares_with_a_reference_that_holds_too(pandas: cd.Scene, start: np.ndarray) -> None:
    """implicit_euler at 1 ms under a 2 ms hold is 24 % off in the forces: the check warns, and
    its estimate is the error against a tight dopri5 of the same sampled loop. (That hold makes
    the loop on undamped grasps unstable, ×1.044 a period: a ControlRateWarning says so too.)"""
    kw = dict(controller=GravityCompensationPD(pandas), v0=start, control_dt=2e-3)
    tight = cd.simulate(pandas, 0.2, integrator=DormandPrince(rtol=1e-11, atol=1e-13), accuracy_check="off", **kw)  # type: ignore[arg-type]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = cd.simulate(pandas, 0.2, integrator="implicit_euler", dt=1e-3, **kw)  # type: ignore[arg-type]
    said = {w.category: str(w.message) for w in caught}
    assert set(said) == {cd.AccuracyWarning, cd.ControlRateWarning}
    assert "wrong by up to" in said[cd.AccuracyWarning] and "grows ×1.044 a period" in said[cd.ControlRateWarning]
    error = np.max(np.linalg.norm(res.wrenches()[..., :3] - tight.wrenches()[..., :3], axis=-1))
    peak = np.max(np.linalg.norm(tight.wrenches()[..., :3], axis=-1))
    assert error > 0.1 * peak
    assert res.force_error_estimate == pytest.approx(error, rel=1e-3)


def test_a_divergence_caused_by_too_slow_a_controller_says_so_and_its_bound_holds() -> None:
    """A PD whose damping is too large for its 1 kHz hold (kd = 20 on a Panda's light wrist)
    diverges under every method; the error blames the sampled loop, not the method, and the
    longest stable period it gives (from the loop linearised and discretised exactly at the
    start: 0.491 ms) is the threshold a run finds: stable at 0.45 ms, growing at 0.5 ms."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    pd = GravityCompensationPD(scene, kp=100.0, kd=20.0)
    for method in ("rk4", "trapezoid"):
        with warnings.catch_warnings(), pytest.raises(cd.errors.DivergenceError) as info:
            warnings.simplefilter("ignore")
            cd.simulate(scene, 0.5, pd, method, dt=1e-3, control_dt=1e-3)
        message = str(info.value)
        assert "The controller, sampled every control_dt = 1 ms and held, makes the loop unstable" in message
        assert "grows ×3.055 a period (applied continuously it decays)" in message
        assert "sample every 0.491 ms or faster, or lower the gains (this error's .advice has the methods'" in message
        assert "stable at dt = 1 ms" not in message  # (the continuous loop's methods, which diverge here too)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calm = cd.simulate(scene, 1.0, pd, "trapezoid", dt=1.125e-4, control_dt=4.5e-4, accuracy_check="off")
        growing = cd.simulate(scene, 1.0, pd, "trapezoid", dt=1.25e-4, control_dt=5e-4, accuracy_check="off")
    assert np.max(np.abs(calm.v[-100:])) < 1e-2 < 10.0 < np.max(np.abs(growing.v[-100:]))
    # the same controller closing the loop of a sensitivity run, sampled every 1 ms: the hold is named there too
    with pytest.raises(cd.errors.SimulationError, match=r"sensitivities: diverged.*The controller, sampled every period = 1 ms"):
        cd.Sensitivity(scene, "trapezoid", controller=pd).trajectory(200, 1e-3)
    # rk4 beyond its limit on stiff grasps under a hold that is stable: the method is blamed, not the hold
    stiff = cd.scenes.facing_arms("panda", stiffness=1e6, damping=0.002)
    with warnings.catch_warnings(), pytest.raises(cd.errors.DivergenceError) as info:
        warnings.simplefilter("ignore")
        cd.simulate(stiff, 0.5, GravityCompensationPD(stiff, kp=100.0, kd=2.0), "rk4", dt=2e-3, control_dt=2e-3)
    assert "sampled every" not in str(info.value) and "rk4 is stable while" in str(info.value)
    # a hold that is unstable but slowly (×1.022 a period) while rk4 blows up in 5 ms: the method first
    with warnings.catch_warnings(), pytest.raises(cd.errors.DivergenceError) as info:
        warnings.simplefilter("ignore")
        cd.simulate(stiff, 0.5, GravityCompensationPD(stiff, kp=100.0, kd=13.25), "rk4", dt=1e-3, control_dt=1e-3)
    message = str(info.value)
    assert message.index("rk4 is stable while") < message.index("Besides, the controller, sampled every control_dt = 1 ms")
    assert "grows ×1.022 a period" in message and "slowly: alone it takes 0.323 s to grow ×1000" in message
    # the same loop closing a sensitivity run: the method first there too, and the knob is its period
    with pytest.raises(cd.errors.SimulationError) as info:
        cd.Sensitivity(stiff, "rk4", controller=GravityCompensationPD(stiff, kp=100.0, kd=13.25)).trajectory(500, 1e-3)
    message = str(info.value)
    assert "Besides, the controller, sampled every period = 1 ms and held" in message
    assert "slowly: alone it takes 0.323 s to grow ×1000" in message and "control_dt" not in message
    # ball grasps leave the object a free spin (a neutral mode): the bound is still the hold's
    ball = ball_pandas((1e4, 1e4, 1e4))
    with warnings.catch_warnings(), pytest.raises(cd.errors.DivergenceError) as info:
        warnings.simplefilter("ignore")
        cd.simulate(ball, 0.5, GravityCompensationPD(ball, kp=100.0, kd=20.0), "trapezoid", dt=1e-3, control_dt=1e-3)
    assert "sample every 0.491 ms or faster" in str(info.value)


def test_a_run_that_completes_under_too_slow_a_built_in_controller_warns() -> None:
    """The same PD sampled every 0.5 ms (beyond its 0.491 ms bound) does not diverge within 0.3 s,
    yet its joints end at hundreds of rad/s: a ControlRateWarning says why, with the growth per
    period and over the run and the bound. At 0.45 ms, with accuracy_check='off', or under a
    user's own controller (not probed: called once per sample only) nothing is said."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    pd = GravityCompensationPD(scene, kp=100.0, kd=20.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = cd.simulate(scene, 0.3, pd, "trapezoid", dt=1.25e-4, control_dt=5e-4)
    assert np.max(np.abs(res.v[-20:])) > 100.0  # (what the warning explains)
    (message,) = [str(w.message) for w in caught if w.category is cd.ControlRateWarning]
    assert message.startswith("The controller, sampled every control_dt = 0.5 ms and held, makes the loop unstable")
    assert "grows ×1.036 a period (applied continuously it decays)" in message
    assert "sample every 0.491 ms or faster" in message
    assert "Over this 0.3 s run the linearised loop grows ×1.646e+09, and this 0.3 s run's grasp forces grow ×6.31" in message
    assert caught[0].filename == __file__  # (attributed to the caller of simulate)
    with warnings.catch_warnings(record=True) as caught:  # the step chosen for an accuracy: the same warning
        warnings.simplefilter("always")
        cd.simulate(scene, 0.1, pd, "trapezoid", dt=1.25e-4, control_dt=5e-4, accuracy=1.0)
    assert [w.filename for w in caught if w.category is cd.ControlRateWarning] == [__file__]

    def rate_warnings(controller: object, control_dt: float, **options: object) -> list[warnings.WarningMessage]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            dt = control_dt / 4
            cd.simulate(scene, 0.3, controller, "trapezoid", dt=dt, control_dt=control_dt, **options)  # type: ignore[arg-type]
        return [w for w in caught if w.category is cd.ControlRateWarning]

    assert not rate_warnings(pd, 4.5e-4)
    assert not rate_warnings(pd, 5e-4, accuracy_check="off")
    user = Counting(scene)
    user.inner = pd
    assert not rate_warnings(user, 5e-4)
    assert len(user.times) == 600  # one call per sample: not probed


def test_the_loop_check_is_silent_where_it_cannot_tell_or_must_not_call() -> None:
    """No ControlRateWarning for a hold whose loop is unstable anyway (the UnstableLoopWarning says
    that: sampling faster would not help), for a run too short for the hold to grow ×e, or with
    accuracy_check="off" through accuracy=; a subclass of a built-in controller (the user's own
    code, maybe stateful) is not called for the check; a run saved too sparsely says it cannot
    tell; and an exponential past the floats in one period blames no hold."""
    from coopdyn.accuracy import StartLoop, sampled_instability
    from coopdyn.cooperative import ObjectImpedance

    undamped = cd.scenes.facing_arms("panda", stiffness=1e4)
    damped = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    pd = GravityCompensationPD(damped, kp=100.0, kd=20.0)

    def said(scene: cd.Scene, controller: object, t_final: float, **options: object) -> dict[type, str]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cd.simulate(scene, t_final, controller, "trapezoid", **options)  # type: ignore[arg-type]
        return {w.category: str(w.message) for w in caught}

    unstable = said(undamped, ObjectImpedance(undamped), 1.0, dt=1e-3, control_dt=1e-3)
    assert cd.UnstableLoopWarning in unstable and cd.ControlRateWarning not in unstable
    assert cd.ControlRateWarning not in said(damped, pd, 1e-3, dt=1.25e-4, control_dt=5e-4)  # (×1.07 over the run)
    options = dict(dt=1.25e-4, control_dt=5e-4, accuracy=1.0, accuracy_check="off")
    assert cd.ControlRateWarning not in said(damped, pd, 0.1, **options)
    sparse = said(damped, pd, 0.3, dt=1.25e-4, control_dt=5e-4, save_every=1200)
    assert "this 0.3 s run saved too few samples (3) to tell whether it shows it" in sparse[cd.ControlRateWarning]

    class Remembering(GravityCompensationPD):
        calls = 0

        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            Remembering.calls += 1
            return super().__call__(t, q, v)

    assert cd.ControlRateWarning not in said(damped, Remembering(damped, kp=100.0, kd=20.0), 0.3, dt=1.25e-4, control_dt=5e-4)
    assert Remembering.calls == 600  # (one per sample: not called for the check)
    no_gain = StartLoop(np.array([[100.0]]), np.array([[1.0]]), np.array([[0.0]]))
    assert sampled_instability(no_gain, 10.0) is None  # (e^1000 over a period: no hold to blame)


def test_a_loop_that_grows_past_the_floats_over_a_period_is_still_reported_as_diverged() -> None:
    """A gain of the wrong sign (+50·v) sampled every second: the loop grows past the floats' range
    over a period, and the divergence is still the error (the hold's diagnosis overflowed once)."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    arm, inner = np.array(scene.arm_joints), GravityCompensationPD(scene, kp=0.0, kd=0.0)

    def wrong_sign(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return inner(t, q, v) + 50.0 * v[arm]

    with warnings.catch_warnings(), pytest.raises(cd.errors.DivergenceError, match=r"the simulation diverged at t = 2\.0"):
        warnings.simplefilter("ignore")
        cd.simulate(scene, 3.0, wrong_sign, "rk4", dt=1e-3, control_dt=1.0)
    with pytest.raises(cd.errors.SimulationError, match="sensitivities: diverged"):
        cd.Sensitivity(scene, "rk4", controller=wrong_sign).trajectory(3, 1.0, dt=1e-3)


@pytest.mark.parametrize(
    ("control_dt", "dt", "message"),
    [
        (1e-3, 3e-4, r"whole multiple of dt = 0.0003 s.*Use dt = 0.00025 s"),
        (1e-3, 2e-3, r"whole multiple of dt = 0.002 s.*Use dt = 0.001 s"),
        (0.0, 1e-3, r"control_dt must be None .* or >= 1e-12"),
        (-1e-3, 1e-3, r"control_dt must be None"),
        (float("nan"), 1e-3, r"control_dt"),
        ("1ms", 1e-3, r"control_dt"),
        (1e308, 1e-3, r"controller would be called once"),  # (its ratio to dt overflowed: a raw OverflowError)
    ],
)
def test_a_sample_period_the_steps_cannot_land_on_is_refused(
    pandas: cd.Scene, control_dt: object, dt: float, message: str
) -> None:
    with pytest.raises(SimulationError, match=message):
        cd.simulate(pandas, 0.01, controller=GravityCompensationPD(pandas), dt=dt, control_dt=control_dt)  # type: ignore[arg-type]


def test_a_scene_file_and_a_sweep_carry_the_sample_period(tmp_path: object) -> None:
    """``[simulation] control_dt`` reaches the run (and a sweep's table); a bad one names its line."""
    from pathlib import Path

    folder = Path(str(tmp_path))
    text = (Path(__file__).parents[1] / "examples" / "scenes" / "linear_book.toml").read_text(encoding="utf-8")
    good = folder / "held.toml"
    good.write_text(text.replace("[simulation]", "[simulation]\ncontrol_dt = 0.002"), encoding="utf-8")
    assert scenefile.load(good).control_dt == 0.002
    bad = folder / "bad.toml"
    bad.write_text(text.replace("[simulation]", "[simulation]\ncontrol_dt = -0.002"), encoding="utf-8")
    with pytest.raises(SceneFileError, match=r"control_dt.*>= 1e-12"):
        scenefile.load(bad)
    bad.write_text(text.replace("[simulation]", "[simulation]\ncontrol_dt = 0.0003"), encoding="utf-8")  # (dt = 1 ms, rk4)
    with pytest.raises(SceneFileError, match=r"line \d+: \[simulation\] control_dt: .*whole multiple of dt"):
        scenefile.load(bad)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = cd.sweep(lambda k: cd.Case(cd.scenes.linear_book(), duration=0.01, control_dt=k), {"k": [0.002]}, progress=False)
    assert list(table["control_dt_s"]) == [0.002]


def test_a_period_of_more_samples_than_max_steps_is_refused_before_it_runs(book: cd.Scene) -> None:
    """Every sample starts a step: a 1 ns period over 10 ms with dopri5 is 1e7 steps — refused up
    front, naming control_dt (it ran 2e6 steps, then blamed "a fast mode")."""
    with pytest.raises(SimulationError, match=r"control_dt = 1e-09 s over t_final = 0.01 s is 1e\+07 controller samples"):
        cd.simulate(book, 0.01, integrator="dopri5", dt=1e-3, control_dt=1e-9)
    with pytest.raises(SimulationError, match="controller samples"):
        cd.Simulator(book, None, "dopri5", 1e-3, control_dt=1e-9).run(0.01)


def test_a_period_a_hair_off_a_multiple_of_dt_stays_on_the_step_grid(pandas: cd.Scene, start: np.ndarray) -> None:
    """A period accepted as 2·dt (within 1e-9) is that multiple: the controller is called at
    0, 2, 4, … ms, not one step late once the round-off has accumulated (it was, from the 4th)."""
    controller = Counting(pandas)
    cd.simulate(pandas, 0.03, controller=controller, dt=1e-3, v0=start, control_dt=2e-3 * (1 + 5e-10), accuracy_check="off")
    assert np.allclose(controller.times, np.arange(15) * 2e-3, rtol=0, atol=1e-12)


def test_a_controller_that_reuses_its_output_buffer(pandas: cd.Scene, start: np.ndarray) -> None:
    """A Python controller returning the same array every call: each saved torque is that call's
    (the Python loop kept references, all showing the last output), the same in both loops, with
    and without a hold, and no false energy alarm."""
    pd = GravityCompensationPD(pandas)
    buffer = np.zeros(pandas.n_actuated)

    def reusing(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        buffer[:] = pd(t, q, v)
        return buffer

    for control_dt in (None, 1e-3):
        runs = [
            cd.simulate(
                pandas,
                0.06,
                controller=reusing,
                dt=5e-4,
                v0=start,
                control_dt=control_dt,
                loop=loop,
                accuracy_check="off",
                energy_check="raise",
            )
            for loop in ("python", "compiled")
        ]
        assert np.max(np.abs(runs[0].tau - runs[1].tau)) < 1e-9
        assert np.ptp(runs[0].tau, axis=0).max() > 1.0
