"""Cooperative control: load distribution, internal force, designed object impedance."""

from __future__ import annotations

import re
import warnings
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import curve_fit

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.grasp import distribute, grasp_matrix, split, squeeze_force, squeeze_forces
from coopdyn.scenes import object_start


@pytest.mark.parametrize("n_grasps", [2, 3, 4])
@pytest.mark.parametrize("seed", range(5))
def test_non_squeezing_distribution_has_no_internal_force(n_grasps: int, seed: int) -> None:
    """Random grasp geometry and object wrench: G⁺F reproduces F, has no internal part, and no
    pair of grasps pushes against each other along the line joining them."""
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n_grasps, 3)) * 0.3
    F = rng.normal(size=6) * np.array([20, 20, 20, 3, 3, 3])
    G = grasp_matrix(points)
    f = distribute(G, F)
    np.testing.assert_allclose(G @ f.reshape(-1), F, atol=1e-12)
    np.testing.assert_allclose(split(G, f).internal, 0.0, atol=1e-12)
    for i in range(n_grasps):
        for j in range(i + 1, n_grasps):
            e = (points[j] - points[i]) / np.linalg.norm(points[j] - points[i])
            assert abs((f[i, :3] - f[j, :3]) @ e) < 1e-12
    np.testing.assert_allclose(squeeze_force(points, f), 0.0, atol=1e-12)


@pytest.mark.parametrize("n_grasps", [2, 3, 5])
def test_batched_squeeze_equals_the_pseudo_inverse_projection(n_grasps: int) -> None:
    """The closed-form G⁺G of many samples at once (what Result.squeeze uses) is the SVD one."""
    rng = np.random.default_rng(n_grasps)
    points, wrenches = rng.normal(size=(40, n_grasps, 3)), rng.normal(size=(40, n_grasps, 6)) * 10
    expected = np.array([squeeze_force(p, w) for p, w in zip(points, wrenches, strict=True)])
    np.testing.assert_allclose(squeeze_forces(points, wrenches), expected, rtol=0, atol=1e-12)


def test_task_positions_at_once_equal_the_reference_sample_by_sample() -> None:
    task = GripLiftOscillate(start=(0.1, 0.2, 0.3), axis=(1.0, 2.0, 0.5), cycles=1.5, frequency=2.0, lift=-0.2)
    t = np.linspace(-0.5, 8.0, 3001)  # before, through every phase, after
    expected = np.array([task(s).position for s in t])
    np.testing.assert_allclose(task.positions(t), expected, rtol=0, atol=1e-15)


def test_internal_part_exerts_no_resultant() -> None:
    rng = np.random.default_rng(1)
    points = rng.normal(size=(3, 3))
    G = grasp_matrix(points)
    parts = split(G, rng.normal(size=(3, 6)))
    np.testing.assert_allclose(G @ parts.internal.reshape(-1), 0.0, atol=1e-12)


def test_commanded_internal_force_is_reached() -> None:
    """Grip with 20 N and hold: each interconnection's squeeze settles within 1 % of it."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    task = GripLiftOscillate(start=object_start(scene), squeeze=20.0, lift=0.0, amplitude=0.0)
    res = cd.simulate(scene, 2.0, controller=ObjectImpedance(scene, task), integrator="implicit_euler", dt=1e-3, save_every=100)
    np.testing.assert_allclose(res.squeeze()[-1], 20.0, rtol=0.01)
    moving, internal = res.wrench_split()
    np.testing.assert_allclose(
        moving[-1].sum(axis=0)[:3], scene.object.mass * -scene.gravity, rtol=1e-3, atol=1e-9
    )  # carries the weight
    assert np.linalg.norm(internal[-1, 0, :3]) == pytest.approx(20.0, rel=0.01)


def _step_response(t: np.ndarray, z: np.ndarray, wn0: float, zeta0: float) -> tuple[float, float]:
    """(ω_n, ζ) of a step response, by a least-squares fit of
    z(t) = z∞ + A e^{−ζω_n t} cos(ω_d t + φ) (initial guess from the design)."""

    def model(s: np.ndarray, z_inf: float, a: float, wn: float, zeta: float, phi: float) -> np.ndarray:
        return z_inf + a * np.exp(-zeta * wn * s) * np.cos(wn * np.sqrt(1 - zeta**2) * s + phi)

    s = t - t[0]
    guess = (z[-1], z[0] - z[-1], wn0, zeta0, 0.0)
    params, _ = curve_fit(model, s, z, p0=guess, maxfev=20000)
    return float(params[2]), float(params[3])


def test_object_answers_a_step_wrench_with_the_designed_dynamics() -> None:
    """Stiff interconnections (1e6 N/m): a 5 N step on the box along z rings at the designed
    ω_n = √(k/m_eff) with the designed ζ, each within 5 %."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e6)
    k, zeta = 4000.0, 0.3  # object stiffness [N/m], damping ratio
    probe = ObjectImpedance(scene, stiffness=(k, 100.0), damping=(0.0, 6.0))
    m_eff, d_arms, _ = probe.effective()
    ctrl = ObjectImpedance(scene, stiffness=(k, 100.0), damping=(2 * zeta * np.sqrt(k * m_eff) - d_arms, 6.0))
    m, d, kk = ctrl.effective()
    wn_design, zeta_design = np.sqrt(kk / m), d / (2 * np.sqrt(kk * m))
    assert zeta_design == pytest.approx(zeta)

    def step(t: float) -> np.ndarray:
        return np.array([0.0, 0.0, 5.0 if t >= 0.1 else 0.0, 0.0, 0.0, 0.0])

    res = cd.simulate(scene, 1.0, controller=ctrl, integrator="implicit_euler", dt=2e-4, save_every=5, object_wrench=step)
    after = res.t >= 0.1
    wn, z = _step_response(res.t[after], res.object_position()[after, 2], wn_design, zeta_design)
    assert wn == pytest.approx(wn_design, rel=0.05)
    assert z == pytest.approx(zeta_design, rel=0.05)
    rise = res.object_position()[-1, 2] - res.object_position()[0, 2]
    assert rise == pytest.approx(5.0 / k, rel=0.05)  # static compliance 1/k


def test_object_impedance_refuses_negative_gains(pandas: cd.Scene) -> None:
    with pytest.raises(cd.SceneError, match=r"damping \(linear\) must be >= 0 \[N·s/m\], got -1.0"):
        ObjectImpedance(pandas, damping=(-1.0, 6.0))


@pytest.mark.parametrize("robot", ["ur5", "kinova"])
def test_facing_arms_for_other_robots(robot: str) -> None:
    """Any example-robot-data arm: mirror-symmetric IK solution, tools on the box faces."""
    scene = cd.scenes.facing_arms(robot)
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    left, right = (data.oMf[a.tip_frame].translation for a in scene.arms)
    box = data.oMf[scene.object_frame].translation
    np.testing.assert_allclose(left, box - np.array([0.0, 0.1, 0.0]), atol=1e-8)
    np.testing.assert_allclose(right, box + np.array([0.0, 0.1, 0.0]), atol=1e-8)
    res = cd.simulate(scene, 0.05, controller=cd.control.GravityCompensationPD(scene), integrator="implicit_euler", dt=1e-3)
    assert np.all(np.isfinite(res.q))


def _pinv_torques(ctrl: ObjectImpedance, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """ObjectImpedance's law written with SVD pseudo-inverses (G⁺, J⁺), as the definition says."""
    scene, model = ctrl.scene, ctrl.scene.model
    data = model.createData()
    pin.forwardKinematics(model, data, q, v)
    pin.updateFramePlacements(model, data)
    ctrl._data = data
    F, ref = ctrl.object_wrench(t, q, v)
    points = np.array([data.oMf[g].translation for g, _, _ in ctrl._links])
    G, c = grasp_matrix(points), points.mean(axis=0)
    F_c = F.copy()
    F_c[3:] += np.cross(data.oMf[scene.object_frame].translation - c, F[:3])
    f = np.linalg.pinv(G) @ F_c
    if ref.squeeze:
        inward = np.concatenate([np.r_[ref.squeeze * (c - p) / np.linalg.norm(c - p), 0, 0, 0] for p in points])
        f += inward - np.linalg.pinv(G) @ (G @ inward)
    pin.computeJointJacobians(model, data, q)
    nle, posture = pin.nonLinearEffects(model, data, q, v), pin.difference(model, q, scene.q0)
    out = []
    for (g_id, t_id, arm), f_i in zip(ctrl._links, f.reshape(-1, 6), strict=True):
        J = pin.getFrameJacobian(model, data, t_id, pin.LOCAL_WORLD_ALIGNED)[:, arm.v_index]
        w = f_i.copy()
        w[3:] += np.cross(data.oMf[g_id].translation - data.oMf[t_id].translation, f_i[:3])
        N = np.eye(arm.v_index.size) - J.T @ np.linalg.pinv(J).T
        vi = v[arm.v_index]
        x = ctrl.null_stiffness * posture[arm.v_index] - ctrl.null_damping * vi
        out.append(J.T @ w + nle[arm.v_index] - ctrl.joint_damping * vi + N @ x)
    return np.concatenate(out)


@pytest.mark.parametrize(("robot", "n_arms"), [("panda", 2), ("panda", 3), ("ur5", 2)])
def test_object_impedance_closed_form_equals_the_pseudo_inverse_law(robot: str, n_arms: int) -> None:
    """The closed-form G⁺ (block-diagonal G Gᵀ) and null-space projector give the torques of the
    SVD pseudo-inverse definition to 1e-9 relative, at random states and task times."""
    scene = cd.scenes.facing_arms(robot, stiffness=1e4, n_arms=n_arms)
    ctrl = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0))
    rng = np.random.default_rng(5)
    for t in (0.3, 1.0, 2.6):
        q = pin.integrate(scene.model, scene.q0, rng.normal(size=scene.nv) * 0.05)
        v = rng.normal(size=scene.nv) * 0.3
        tau = ctrl(t, q, v)
        expected = _pinv_torques(ObjectImpedance(scene, ctrl.reference), t, q, v)
        assert np.max(np.abs(tau - expected)) <= 1e-9 * np.max(np.abs(expected))


def test_grip_lift_oscillate_holds_the_objects_starting_orientation() -> None:
    """The held strip starts turned 90° about z: with the task's default rotation the controller
    holds that orientation (no twist commanded at rest, in Python and in its compiled spec), as
    the docstring says, instead of the world axes (which commanded −15.7 N·m)."""
    import pinocchio as pin

    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.scenes import object_start

    scene = cd.scenes.held_beam()
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    R0 = data.oMf[scene.object_frame].rotation
    assert pin.log3(R0)[2] == pytest.approx(np.pi / 2, abs=1e-6)  # (the premise: turned 90°)
    ctrl = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=0.0))
    assert np.allclose(ctrl.reference(0.0).rotation, R0, atol=1e-12)
    spec = ctrl.compiled_spec(scene)
    assert spec is not None and np.allclose(spec.task.rotation, R0, atol=1e-12)
    explicit = np.eye(3)  # (the world axes, asked for: honoured, with a warning that the strip starts turned)
    with pytest.warns(cd.SceneWarning, match="rad away"):
        ctrl = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), rotation=explicit))
    assert np.array_equal(ctrl.reference(1.0).rotation, explicit)


def test_a_task_that_starts_away_from_the_object_warns_with_the_distance(pandas: cd.Scene) -> None:
    """The README's old quick start hard-coded start=[0, 0, 0.7]; a typo (1.7) gave −309 N of
    tension, silently. A task starting away from the object's pose warns with the distance and
    the fix; one starting on it does not."""
    import warnings

    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.scenes import object_start

    here = object_start(pandas)
    with pytest.warns(cd.SceneWarning, match=r"starts 1 m and 0 rad away.*object_start\(scene\)"):
        ObjectImpedance(pandas, GripLiftOscillate(start=here + np.array([0.0, 0.0, 1.0])))
    with pytest.warns(cd.SceneWarning, match=r"0\.3 rad away"):
        R = pin.exp3(np.array([0.0, 0.0, 0.3]))
        ObjectImpedance(pandas, GripLiftOscillate(start=here, rotation=R))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ObjectImpedance(pandas, GripLiftOscillate(start=here))
        ObjectImpedance(pandas)  # (holding the start pose)


def test_tips_measurement_holds_a_flexible_strip_where_the_object_frame_cannot() -> None:
    """Two Pandas hold an aluminium strip with ObjectImpedance's default gains: fed back at the
    strip's middle node (non-collocated, through the strip's compliance) the linearised closed
    loop has growing modes; read at the arms' own tool frames (collocated, the default for an
    elastic object) every mode decays."""
    scene = cd.scenes.held_beam(n_elements=4)
    assert ObjectImpedance(scene).measure == "tips" and ObjectImpedance(cd.scenes.facing_arms("panda")).measure == "object"
    growth = {
        m: cd.linearize(scene, controller=ObjectImpedance(scene, measure=m)).eigenvalues.real.max() for m in ("object", "tips")
    }
    assert growth["object"] > 1.0 and growth["tips"] < 0.0, growth


def test_tips_and_object_measurements_agree_on_a_rigid_box_at_rest(pandas: cd.Scene) -> None:
    """On a rigid box whose grasps are unloaded at the start, both readings see the same object
    pose and velocity: the controllers command the same torques."""
    rng = np.random.default_rng(2)
    v = 0.1 * rng.normal(size=pandas.nv)
    v[pandas.object_v] = 0.0
    tips, frame = ObjectImpedance(pandas, measure="tips"), ObjectImpedance(pandas, measure="object")
    for law in (tips, frame):
        pin.forwardKinematics(pandas.model, law._data, pandas.q0, v)
        pin.updateFramePlacements(pandas.model, law._data)
    p_t, R_t, _, _ = tips.object_state()
    p_o, R_o, _, _ = frame.object_state()
    np.testing.assert_allclose(p_t, p_o, atol=1e-12)
    np.testing.assert_allclose(R_t, R_o, atol=1e-12)
    with pytest.raises(cd.SceneError, match="measure must be one of"):
        ObjectImpedance(pandas, measure="grasps")


def test_an_unstable_closed_loop_is_said_so_in_the_warning_and_the_divergence() -> None:
    """The strip read at its middle node with the default gains: implicit Euler at 1 ms damps the
    growing bending mode and its run is warned about, saying the closed loop is unstable with the
    growing mode from the exact linearisation; a longer run diverges and says the same."""
    scene = cd.scenes.held_beam(n_elements=4)
    controller = ObjectImpedance(scene, measure="object")
    growing = r"has a 3\d\d(\.\d)? Hz mode growing at \d+(\.\d+)? /s"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cd.simulate(scene, 0.3, controller=controller, integrator="implicit_euler", dt=1e-3)
    said = {w.category: str(w.message) for w in caught}
    assert re.search(r"the closed loop " + growing + r" .*: it is unstable", said[cd.AccuracyWarning])
    # the loop's own warning, whatever the method: the run's figures are an instability's
    assert re.search(r"^The closed loop under this controller is unstable: .* it " + growing, said[cd.UnstableLoopWarning])
    said = r"From the start the closed loop is unstable: linearised exactly there, it "
    with pytest.raises(cd.DivergenceError, match=said + growing):
        cd.simulate(scene, 1.0, controller=controller, integrator="implicit_euler", dt=1e-3, accuracy_check="off")
    with warnings.catch_warnings():
        warnings.simplefilter("error", cd.AccuracyWarning)  # read at the tips: stable, and the trapezoid resolves what matters
        cd.simulate(scene, 0.3, controller=ObjectImpedance(scene), integrator="trapezoid", dt=1e-3)


def test_an_unstable_loop_is_said_so_whatever_the_method_and_only_then() -> None:
    """ObjectImpedance on undamped Panda grasps (k = 1e4 N/m): its loop, linearised exactly at the
    start, has a 28.1 Hz mode growing at 22.8 /s. Over 1 s the grasp forces grow ×2.5: the
    trapezoid's run is accurate (the reference is just as unstable) yet its figures are an
    instability's, and an UnstableLoopWarning says so; over 0.3 s they have grown ×1.27 only, and
    the warning says the figures hold for that duration. With the demo's damped grasps, with
    accuracy_check="off", or under a user's own controller (not probed) nothing is said."""
    undamped = cd.scenes.facing_arms("panda", stiffness=1e4)

    def loop_warnings(scene: cd.Scene, controller: Any, duration: float = 1.0, **options: Any) -> list[str]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cd.simulate(scene, duration, controller, "trapezoid", dt=1e-3, **options)
        return [str(w.message) for w in caught if w.category is cd.UnstableLoopWarning]

    (message,) = loop_warnings(undamped, ObjectImpedance(undamped))
    assert message.startswith("The closed loop under this controller is unstable: linearised exactly at the start")
    assert "a 28.1 Hz mode growing at 22.8 /s (×e every 43.9 ms)" in message
    assert "this 1 s run's grasp forces grow ×2.55 from its first third to its last: its motion is that instability's" in message
    (short,) = loop_warnings(undamped, ObjectImpedance(undamped), duration=0.3)
    assert "within this 0.3 s run it has not grown visibly (its grasp forces ×1.27" in short
    assert "a longer run, or a larger disturbance, would show it" in short
    damped = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    assert not loop_warnings(damped, ObjectImpedance(damped))
    assert not loop_warnings(undamped, ObjectImpedance(undamped), accuracy_check="off")
    inner = ObjectImpedance(undamped)
    assert not loop_warnings(undamped, lambda t, q, v: inner(t, q, v))


def test_internal_moments_turn_a_tool_back_towards_the_other_and_damp_it() -> None:
    """Two planar arms hold a beam; the left tool alone turns by δ about x (its last joint) and
    spins at ω: the tools' estimates of the object's orientation are ±δ/2 from their mean and
    ±ω/2 from their mean spin, so the internal moments are ∓(k δ/2 + d ω/2) about x on the left
    and right tool — opposite, with no resultant — and torque the left arm's last joint back."""
    scene = cd.scenes.planar_arms_beam(n_elements=2)
    k, d, delta, omega = 100.0, 6.0, 1e-4, 2e-3
    law = ObjectImpedance(scene, internal=(k, d))
    last = scene.arms[0].v_index[-1]  # the left arm's wrist joint, about world x
    q, v = scene.q0.copy(), np.zeros(scene.nv)
    q[scene.arms[0].q_index[-1]] += delta
    v[last] = omega
    law(0.0, q, v)  # (reads the kinematics at this state)
    m = law.internal_moments()
    expected = -(k * delta / 2 + d * omega / 2)
    np.testing.assert_allclose(m[0], [expected, 0.0, 0.0], rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(m[1], [-expected, 0.0, 0.0], rtol=1e-3, atol=1e-9)
    with pytest.raises(cd.SceneError, match=r"internal must be a pair \(stiffness \[N·m/rad\], damping"):
        ObjectImpedance(scene, internal=5.0)
    with pytest.raises(cd.SceneError, match=r"internal .* needs measure='tips'"):
        ObjectImpedance(scene, measure="object", internal=(1.0, 0.0))


def test_two_planar_arms_carry_a_beam_stably() -> None:
    """The benchmark scenario of flexible-object handling: two 3R arms in a vertical plane hold
    a 1 m strip. The inverse kinematics puts each tool on its end of the beam, pointing along it;
    read at the tools the linearised closed loop decays in every mode (read at the middle node,
    it does not)."""
    scene = cd.scenes.planar_arms_beam()
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    for lk, end, axis in zip(scene.links, (-0.5, 0.5), (1.0, -1.0), strict=True):
        tip = data.oMf[lk.tip_frame]
        np.testing.assert_allclose(tip.translation, [0.0, end, 0.5], atol=1e-12)
        np.testing.assert_allclose(tip.rotation[:, 2], [0.0, axis, 0.0], atol=1e-12)
    growth = {
        m: cd.linearize(scene, controller=ObjectImpedance(scene, measure=m)).eigenvalues.real.max() for m in ("tips", "object")
    }
    assert growth["tips"] < 0.0 < growth["object"], growth
    with pytest.raises(cd.SceneError, match="out of the arm's reach"):
        cd.scenes.planar_arms_beam(reach=2.0)
