"""coopdyn.simulate: what it returns and what it refuses."""

from __future__ import annotations

import numpy as np
import pytest

import coopdyn as cd


def test_result_shapes_and_saving(book: cd.Scene) -> None:
    res = cd.simulate(book, 0.0105, dt=1e-3, save_every=4)
    np.testing.assert_allclose(res.t, [0.0, 0.004, 0.008, 0.0105])  # last step shortened, final state kept
    assert res.q.shape == (4, book.nq) and res.v.shape == (4, book.nv) and res.tau.shape == (4, 2)
    assert res.wrench(1).shape == (4, 6) and res.deformation(0).shape == (4, 6)
    assert res.n_rhs == 11 * 4
    np.testing.assert_allclose(res.elastic_energy(0) + res.elastic_energy(1), res.energy().elastic)


def test_symplectic_euler_is_first_order(book: cd.Scene) -> None:
    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)
    dts = np.array([4e-4, 2e-4, 1e-4])
    errors = []
    for dt in dts:
        res = cd.simulate(book, 0.2, controller=ctrl, integrator="symplectic_euler", dt=dt)
        exact = cd.reference.linear_book_exact(res.t, d1, d2)
        errors.append(np.max(np.abs(cd.scenes.book_positions(res.q, book) - exact.Y)))
    assert np.polyfit(np.log(dts), np.log(errors), 1)[0] == pytest.approx(1.0, abs=0.3)


def test_rk4_keeps_fourth_order_on_a_free_flyer(pandas: cd.Scene) -> None:
    """Two Pandas and a free-flying box (k = 1e4): the Lie-group chart keeps RK4 at order 4."""
    rng = np.random.default_rng(3)
    v0 = rng.normal(size=pandas.nv) * 0.5
    ref = cd.simulate(pandas, 0.04, dt=2.5e-5, v0=v0)
    dts = np.array([8e-4, 4e-4, 2e-4])
    errors = []
    for dt in dts:
        res = cd.simulate(pandas, 0.04, dt=dt, v0=v0)
        errors.append(np.max(np.abs(res.object_position()[-1] - ref.object_position()[-1])))
    assert np.polyfit(np.log(dts), np.log(errors), 1)[0] == pytest.approx(4.0, abs=0.3)


def test_an_adaptive_method_shrinks_a_step_that_goes_non_finite() -> None:
    """Two Pandas holding the 4-element beam (node modes |λ| ≈ 1e6/s), no controller, dopri5 with
    a first step of 1 ms: the first attempts blow up (one turns a node by 2π, where the exponential
    map's Jacobian is singular). Both loops shrink the step and finish, equal to round-off, where
    the compiled loop reported a divergence and the Python loop raised numpy's LinAlgError."""
    scene = cd.scenes.held_beam()
    v0 = np.random.default_rng(1).normal(size=scene.nv) * 0.1
    runs = [
        cd.simulate(scene, 0.003, integrator="dopri5", dt=1e-3, v0=v0, loop=loop, progress=False, accuracy_check="off")
        for loop in ("python", "compiled")
    ]
    assert [r.status for r in runs] == ["completed", "completed"]
    assert np.allclose(runs[0].q, runs[1].q, rtol=0, atol=1e-9)


def test_a_runaway_trial_stage_is_not_the_controllers_fault() -> None:
    """The held beam under ObjectImpedance, dopri5 with a 1 ms first step: the first attempts'
    stages reach |v| ~ 1e66, where the compiled controller's torques overflow to NaN (the Python
    one's to 1e89). A non-finite torque at a state past max_speed is the state's doing: both
    loops reject the attempt and finish equal to round-off, where the compiled loop reported a
    ControllerError. At a sane state a NaN torque is still the controller's error (tested above)."""
    from coopdyn.cooperative import ObjectImpedance

    scene = cd.scenes.held_beam()
    v0 = np.random.default_rng(1).normal(size=scene.nv) * 0.1
    settings = {"integrator": "dopri5", "dt": 1e-3, "v0": v0, "progress": False, "accuracy_check": "off"}
    runs = [cd.simulate(scene, 0.003, controller=ObjectImpedance(scene), loop=lp, **settings) for lp in ("python", "compiled")]
    assert [r.status for r in runs] == ["completed", "completed"]
    assert np.allclose(runs[0].q, runs[1].q, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dt": 0.0}, r"dt must be >= 1e-12 \[s\].*got 0.0"),
        ({"dt": float("nan")}, r"dt \[s\] must be finite"),
        ({"t_final": -1.0}, r"t_final must be >= 0 \[s\], got -1.0"),
        (
            {"integrator": "rk45"},
            r"unknown integrator 'rk45'; valid: \['dop853', 'dopri5', 'exponential', 'generalized_alpha', 'implicit_euler',",
        ),
        ({"save_every": 0}, r"save_every must be an integer >= 1"),
        ({"q0": np.zeros(2)}, r"q \(a configuration\) must have shape \(3,\), got shape \(2,\)"),
        ({"v0": [np.inf, 0, 0]}, r"v \(a velocity\) must be finite"),
    ],
)
def test_bad_arguments(book: cd.Scene, kwargs: dict[str, object], message: str) -> None:
    args: dict[str, object] = {"t_final": 0.01, "dt": 1e-3, **kwargs}
    with pytest.raises(cd.CoopdynError, match=message):
        cd.simulate(book, **args)  # type: ignore[arg-type]


def test_controller_of_wrong_length(book: cd.Scene) -> None:
    with pytest.raises(cd.ControllerError, match=r"returned shape \(3,\) at t = 0 s; it must return .* shape \(2,\)"):
        cd.simulate(book, 0.01, controller=lambda t, q, v: np.zeros(3))


def test_controller_returning_nan(book: cd.Scene) -> None:
    with pytest.raises(cd.ControllerError, match=r"non-finite torques at t = 0.002 s \(entries \[1\]\)"):
        cd.simulate(book, 0.01, controller=lambda t, q, v: np.array([0.0, np.nan if t > 0.0015 else 0.0]), dt=1e-3)


@pytest.mark.filterwarnings("ignore::coopdyn.EnergyBalanceWarning")  # it also breaks the energy balance first
def test_divergence_raises_instead_of_returning_nan() -> None:
    """Symplectic Euler far beyond its stability limit stops with a diagnosis and the partial run."""
    stiff = cd.scenes.linear_book(c_p=2e8, c_k=2e8, d_p=0.0, d_k=0.0)
    with pytest.raises(cd.DivergenceError, match=r"diverged at t = .* with symplectic_euler at dt = 0.001 s") as info:
        cd.simulate(stiff, 5.0, integrator="symplectic_euler", dt=1e-3)
    message = str(info.value)
    assert "the mode that limits symplectic_euler's step has |λ| = " in message
    assert "stable at dt = 1 ms: dop853, implicit_euler, ros2, trapezoid, generalized_alpha, exponential" in message
    partial = info.value.result
    assert isinstance(partial, cd.Result) and 0 < partial.t[-1] < 5.0 and np.all(np.isfinite(partial.q))


@pytest.mark.parametrize("method", ["symplectic_euler", "rk4", "implicit_euler", "ros2", "dopri5", "exponential"])
def test_saved_torques_are_the_controllers_without_extra_calls(book: cd.Scene, method: str) -> None:
    """Result.tau is the controller's output at each saved state; a saved sample reuses the torque of
    the step taken from it, so saving every step costs no controller calls beyond the integrator's."""
    d1, d2 = cd.scenes.book_task()
    drives = cd.scenes.drives_controller(d1, d2)
    calls = [0]

    def ctrl(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        calls[0] += 1
        return drives(t, q, v) + 10.0 * v[book.actuated]  # state feedback: a stale torque would show

    # (accuracy_check off: a run the screen cannot clear is checked by a second, dopri5, run)
    res = cd.simulate(book, 0.6, controller=ctrl, integrator=method, dt=0.01, energy_check="off", accuracy_check="off")
    if method == "exponential" and res.loop == "python":  # no evaluation to reuse: one extra call per saved sample
        assert calls[0] == res.n_rhs + res.t.size
    else:  # the integrator's calls (n_rhs counts them) + the final state's sample
        assert calls[0] <= res.n_rhs + 1
    expected = np.array([drives(t, q, v) + 10.0 * v[book.actuated] for t, q, v in zip(res.t, res.q, res.v, strict=True)])
    np.testing.assert_array_equal(res.tau, expected)


def test_a_controller_built_for_another_scene_says_so() -> None:
    """A built-in controller carries its scene (its own model of the robot): given another scene's
    run, the error says so rather than that its gains have the wrong shape."""
    from coopdyn.control import GravityCompensationPD

    pandas = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    book = cd.scenes.linear_book()
    with pytest.raises(cd.ControllerError, match=r"\(GravityCompensationPD\) was built for another scene, of nq = 21"):
        cd.simulate(book, 0.01, GravityCompensationPD(pandas), "rk4", dt=1e-3)

    class Holding:  # a user's controller may keep any scene it likes
        scene = pandas

        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            return np.zeros(2)

    assert cd.simulate(book, 0.01, Holding(), "rk4", dt=1e-3).status == "completed"
