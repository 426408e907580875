"""Identification (coopdyn.identify): a hidden parameter set is recovered from noisy synthetic
measurements within the uncertainty the fit reports, the same with exact and finite-difference
Jacobians; bad measurements are refused with what is expected."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.dynamics import Dynamics
from coopdyn.errors import FitWarning, SceneError, SimulationError
from coopdyn.identify import Measurements, identify
from coopdyn.parameters import parameters, with_parameters

TRUTH = {"left.k_linear": 1.3e4, "right.k_linear": 0.8e4, "left.d_linear": 150.0, "object.mass": 2.4}
NOISE = (1e-4, 0.1, 0.01)  # joint angles [rad], forces [N], moments [N·m]


def measure(scene: cd.Scene, seed: int, n: int = 60, period: float = 2e-3) -> Measurements:
    """Gravity compensation plus random torques played on the hidden scene, sampled every period,
    with Gaussian sensor noise."""
    hidden = with_parameters(scene, TRUTH)
    rng = np.random.default_rng(seed)
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    U = g + 3.0 * rng.normal(size=(n, scene.n_actuated))
    run = cd.rollout(hidden, U[None], period=period, dt=period / 2, integrator="rk4", threads=1)
    Q, V = run.q[0], run.v[0]
    dyn = Dynamics(hidden)
    W = np.array([[e.G_f_G for e in dyn.element_states(q, v)[: len(scene.links)]] for q, v in zip(Q, V, strict=True)])
    q_idx = [next(j.idx_q for j in scene.model.joints[1:] if j.idx_v == i) for i in scene.arm_joints]
    joints = Q[:, q_idx] + NOISE[0] * rng.normal(size=(n + 1, len(q_idx)))
    W = W + np.concatenate([NOISE[1] * rng.normal(size=(n + 1, 2, 3)), NOISE[2] * rng.normal(size=(n + 1, 2, 3))], axis=2)
    return Measurements(period, joints, W, U, *NOISE)


@pytest.fixture(scope="module")
def damped() -> cd.Scene:
    return cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.01)


def test_the_hidden_parameters_are_recovered_within_their_uncertainty(damped: cd.Scene) -> None:
    m = measure(damped, seed=3)
    fits = [identify(damped, m, list(TRUTH), dt=1e-3, jacobian=j) for j in ("exact", "finite-differences")]
    exact, fd = fits
    for name, value in TRUTH.items():
        lo, hi = exact.interval(name, 3.0)
        assert lo < value < hi, (name, exact.estimate[name], exact.std[name])
        assert exact.std[name] < 0.01 * value  # (the data do determine it)
        assert abs(fd.estimate[name] - exact.estimate[name]) < 0.05 * exact.std[name]
    assert 0.85 < exact.residual_rms < 1.15  # the noise levels given are the true ones
    assert exact.joint_rms == pytest.approx(NOISE[0], rel=0.15)
    assert exact.wrench_rms is not None and exact.wrench_rms[0] == pytest.approx(NOISE[1], rel=0.15)
    assert exact.scene.links[0].element.K[0, 0] == exact.estimate["left.k_linear"]
    assert exact.jacobians >= 1 and exact.evaluations >= exact.jacobians
    text = exact.summary()
    assert "left.k_linear" in text and "N/m" in text and "exact" in text
    # wrong noise levels show in the residual: σ given 10× too small → RMS ~10
    others = with_parameters(damped, {k: v for k, v in TRUTH.items() if k != "left.k_linear"})
    with pytest.warns(FitWarning, match="weighted residual RMS is 9.*the wrench's frame"):
        loud = identify(
            others, Measurements(m.period, m.joints, m.wrench, m.torques, *(x / 10 for x in NOISE)), ["left.k_linear"], dt=1e-3
        )
    assert 8.5 < loud.residual_rms < 11.5


def test_stiff_grasps_are_identified_through_an_implicit_methods_sensitivities() -> None:
    """Grasps of 1e6 N/m, 500 Hz data, the model run by the trapezoid (whose step derivatives
    include its matrices' own variation): the truth within 3σ, exact and finite-difference fits
    agree."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e6, damping=0.01)
    truth = {"left.k_linear": 1.3e6, "right.k_angular": 0.8e4}
    hidden = with_parameters(scene, truth)
    rng = np.random.default_rng(3)
    n, period, noise = 60, 2e-3, (1e-5, 0.1, 0.01)
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    U = g + 3.0 * rng.normal(size=(n, scene.n_actuated))
    run = cd.rollout(hidden, U[None], period=period, dt=1e-3, integrator="trapezoid", threads=1)
    dyn = Dynamics(hidden)
    W = np.array([[e.G_f_G for e in dyn.element_states(q, v)] for q, v in zip(run.q[0], run.v[0], strict=True)])
    q_idx = [next(j.idx_q for j in scene.model.joints[1:] if j.idx_v == i) for i in scene.arm_joints]
    joints = run.q[0][:, q_idx] + noise[0] * rng.normal(size=(n + 1, len(q_idx)))
    W = W + np.concatenate([noise[1] * rng.normal(size=(n + 1, 2, 3)), noise[2] * rng.normal(size=(n + 1, 2, 3))], axis=2)
    m = Measurements(period, joints, W, U, *noise)
    exact, fd = (
        identify(scene, m, list(truth), dt=1e-3, jacobian=j, integrator="trapezoid") for j in ("exact", "finite-differences")
    )
    assert exact.exact
    for name, value in truth.items():
        lo, hi = exact.interval(name, 3.0)
        assert lo < value < hi, (name, exact.estimate[name], exact.std[name])
        assert abs(fd.estimate[name] - exact.estimate[name]) < 0.05 * exact.std[name]
    assert 0.85 < exact.residual_rms < 1.15


def test_grasp_positions_are_identified_with_the_stiffness() -> None:
    """Where the grasps sit on the object (6 and 4 mm off the nominal) and a stiffness, from
    500 Hz joint angles and grasp wrenches: the truth within 3σ, exact and finite-difference fits
    agree, and the positions may be negative (no bound)."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.01)
    nominal = {p.name: p.value for p in parameters(scene, ["left.grasp_y", "right.grasp_z"])}
    truth = {
        "left.grasp_y": nominal["left.grasp_y"] + 0.006,
        "right.grasp_z": nominal["right.grasp_z"] - 0.004,
        "left.k_linear": 1.2e4,
    }
    hidden = with_parameters(scene, truth)
    rng = np.random.default_rng(3)
    n, period = 60, 2e-3
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    U = g + 3.0 * rng.normal(size=(n, scene.n_actuated))
    run = cd.rollout(hidden, U[None], period=period, dt=1e-3, q0=scene.q0, integrator="rk4", threads=1)
    dyn = Dynamics(hidden)
    W = np.array([[e.G_f_G for e in dyn.element_states(q, v)] for q, v in zip(run.q[0], run.v[0], strict=True)])
    q_idx = [next(j.idx_q for j in scene.model.joints[1:] if j.idx_v == i) for i in scene.arm_joints]
    joints = run.q[0][:, q_idx] + NOISE[0] * rng.normal(size=(n + 1, len(q_idx)))
    W = W + np.concatenate([NOISE[1] * rng.normal(size=(n + 1, 2, 3)), NOISE[2] * rng.normal(size=(n + 1, 2, 3))], axis=2)
    m = Measurements(period, joints, W, U, *NOISE, q0=scene.q0, v0=scene.v0)
    exact, fd = (identify(scene, m, list(truth), dt=1e-3, jacobian=j) for j in ("exact", "finite-differences"))
    assert exact.exact and exact.estimate["left.grasp_y"] < 0.0  # (a negative position: no bound at 0)
    for name, value in truth.items():
        lo, hi = exact.interval(name, 3.0)
        assert lo < value < hi, (name, exact.estimate[name], exact.std[name])
        assert abs(fd.estimate[name] - exact.estimate[name]) < 0.05 * exact.std[name]
    assert exact.std["left.grasp_y"] < 1e-4 and "grasp_y" in exact.summary() and " mm" in exact.summary()
    guess = identify(scene, m, list(truth), initial={"left.grasp_y": -0.093}, dt=1e-3)
    assert guess.start["left.grasp_y"] == -0.093 and "-93  " in guess.summary()  # (the start the fit used, in mm)


@pytest.mark.slow
def test_the_reported_uncertainty_covers_the_truth_as_often_as_it_says(damped: cd.Scene) -> None:
    """Over 12 noise draws, |estimate − truth| < 2σ about 95 % of the time for each parameter."""
    inside = 0
    names = ["left.k_linear", "object.mass"]
    others = with_parameters(damped, {k: v for k, v in TRUTH.items() if k not in names})  # (the rest known)
    for seed in range(12):
        fit = identify(others, measure(damped, seed=100 + seed, n=40), names, dt=1e-3)
        inside += sum(abs(fit.estimate[k] - TRUTH[k]) < 2.0 * fit.std[k] for k in ("left.k_linear", "object.mass"))
    assert inside >= 20  # of 24: the binomial(24, 0.95) falls below 20 with probability < 0.01


def test_bad_measurements_are_refused(damped: cd.Scene) -> None:
    m = measure(damped, seed=1, n=5)
    with pytest.raises(SimulationError, match=r"measurements.torques must be \(4, 14\)"):
        identify(damped, Measurements(m.period, m.joints[:-1], m.wrench[:-1], m.torques), ["left.k_x"])
    with pytest.raises(SimulationError, match=r"measurements.wrench must be \(6, 2, 6\)"):
        identify(damped, Measurements(m.period, m.joints, m.wrench[:, :1], m.torques), ["left.k_x"])
    with pytest.raises(SimulationError, match=r"measurements.joints must be \(N \+ 1, 14\)"):
        identify(damped, Measurements(m.period, m.joints[:, :3], m.wrench, m.torques), ["left.k_x"])
    with pytest.raises(SimulationError, match="joint_noise"):
        identify(damped, Measurements(m.period, m.joints, m.wrench, m.torques, joint_noise=0.0), ["left.k_x"])
    with pytest.raises(SimulationError, match="give them, or the controller that ran"):
        identify(damped, Measurements(m.period, m.joints, m.wrench), ["left.k_x"])
    with pytest.raises(SimulationError, match="closed-loop fit computes the torques"):
        identify(damped, m, ["left.k_x"], controller=lambda t, q, v: np.zeros(14))
    with pytest.raises(SimulationError, match="not among the parameters"):
        identify(damped, m, ["left.k_x"], initial={"right.k_x": 1.0})
    with pytest.raises(SimulationError, match="'exact' or 'finite-differences'"):
        identify(damped, m, ["left.k_x"], jacobian="fd")
    with pytest.raises(SceneError, match="unknown parameter"):
        identify(damped, m, ["left.stiffness"])
    with pytest.raises(SimulationError, match=r"must be a coopdyn\.identify\.Measurements"):
        identify(damped, (m.torques, m.joints), ["left.k_x"])  # type: ignore[arg-type]
    with pytest.raises(SimulationError, match="adapts its step in a run"):
        identify(damped, m, ["left.k_x"], integrator="dopri5")
    with pytest.raises(SimulationError, match="the exponential integrator needs a linear scene") as caught:
        identify(damped, m, ["left.k_x"], integrator="exponential")
    assert "diverged during the fit" not in str(caught.value)  # (a refusal, passed on as it is)
    with pytest.raises(SimulationError, match=r"LinearlyImplicitEuler\(jacobian_every=3\) is not differentiated"):
        identify(damped, m, ["left.k_x"], integrator=cd.integrators.LinearlyImplicitEuler(jacobian_every=3))
    with pytest.raises(SimulationError, match="must divide the period"):
        identify(damped, m, ["left.k_x"], dt=3e-4)
    with pytest.raises(SimulationError, match="max_iterations must be a positive integer"):
        identify(damped, m, ["left.k_x"], max_iterations=0)
    with pytest.raises(SimulationError, match="controller must be a callable"):
        identify(damped, Measurements(m.period, m.joints, m.wrench), ["left.k_x"], controller=3)  # type: ignore[arg-type]
    undamped = cd.scenes.facing_arms("panda", stiffness=1e4)
    with pytest.raises(SimulationError, match=r"left\.d_linear is 0 N·s/m in the scene.*initial=\{'left\.d_linear': \.\.\.\}"):
        identify(undamped, m, ["left.d_linear"])
    with pytest.raises(SimulationError, match="initial must be a dict of start values by name, got str"):
        identify(damped, m, ["left.k_x"], initial="left.k_x")  # type: ignore[arg-type]
    for jacobian in ("exact", "finite-differences"):  # (differences read the rigid elements' zero wrench)
        with pytest.raises(SceneError, match=r"rigid grasps .*fit the elastic scene they stand for"):
            identify(cd.rigid_limit(damped), m, ["object.mass"], jacobian=jacobian)


def test_measurements_from_a_run_refuse_bad_arguments(damped: cd.Scene) -> None:
    run = cd.simulate(damped, 0.01, integrator="rk4", dt=1e-3, accuracy_check="off")
    with pytest.raises(SimulationError, match=r"result must be a coopdyn\.Result, got NoneType"):
        Measurements.from_result(None)  # type: ignore[arg-type]
    bad_arguments = (
        ({"joint_noise": -1.0}, "joint_noise"),
        ({"force_noise": "a"}, "force_noise"),
        ({"open_loop": "no"}, "open_loop"),
    )
    for bad, message in bad_arguments:
        with pytest.raises(SimulationError, match=message):
            Measurements.from_result(run, **bad)  # type: ignore[arg-type]


def test_measurements_from_a_run_read_the_wrench_in_the_grasp_frames_axes(damped: cd.Scene) -> None:
    from coopdyn.control import GravityCompensationPD

    run = cd.simulate(damped, 0.05, GravityCompensationPD(damped), "rk4", dt=1e-3, control_dt=1e-3, accuracy_check="off")
    m = Measurements.from_result(run, open_loop=True)
    dyn = Dynamics(damped)
    k = 30
    local = [e.G_f_G for e in dyn.element_states(run.q[k], run.v[k])[:2]]
    np.testing.assert_allclose(m.wrench[k], local, rtol=0, atol=1e-12)
    assert np.max(np.abs(m.wrench[k] - run.wrenches()[k])) > 1e-3  # (world axes differ)
    assert m.period == pytest.approx(1e-3) and m.torques is not None and m.torques.shape == (50, 14)
    continuous = cd.simulate(damped, 0.02, GravityCompensationPD(damped), "rk4", dt=1e-3, accuracy_check="off")
    with pytest.raises(SimulationError, match=r"do not replay it .* control_dt = 0\.001 s"):
        Measurements.from_result(continuous, open_loop=True)  # (τ sampled at every stage, not held)
    assert Measurements.from_result(continuous).torques is None  # (a closed-loop fit needs none)
    rigid = cd.rigid_limit(damped)
    with pytest.raises(SimulationError, match="rigid grasps, whose wrenches are constraint forces"):
        Measurements.from_result(cd.simulate(rigid, 0.01, None, "rk4", dt=1e-3, accuracy_check="off"))
    # perfect data, replayed open loop from 10 % off: the fit returns to the scene's value
    fit = identify(damped, m, ["left.k_linear"], initial={"left.k_linear": 1.1e4})
    assert fit.estimate["left.k_linear"] == pytest.approx(1e4, rel=1e-6) and fit.residual_rms < 1e-3
