"""The rigid limit (coopdyn.rigid_limit): exact rigid motion, the 1/k convergence of the elastic
model to it, the least-norm force distribution of redundant rigid grasps, and Baumgarte drift."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.problems.linear_book import Drive
from coopdyn.scenes import book_positions, drives_controller, linear_book

TAU1, TAU2 = 400.0, 300.0  # [N] constant drive forces on the book's tips


def _drives() -> object:
    return drives_controller(Drive.constant(TAU1), Drive.constant(TAU2))


def _rigid_book() -> cd.Result:
    rigid = cd.rigid_limit(linear_book())
    return cd.simulate(rigid, 0.5, controller=_drives(), integrator="rk4", dt=1e-3, save_every=10)


def test_rigid_book_moves_as_one_body_with_the_closed_form_contact_forces() -> None:
    """Welded, the book's three masses accelerate together at a = (τ1 + τ2)/(m1 + m + m2) − g
    (rk4 is exact for the quadratic motion), and each contact force is what its tip's own
    Newton equation leaves: F1 = τ1 − m1 (a + g) on the object, −F1 on the tip."""
    res = _rigid_book()
    a = (TAU1 + TAU2) / 50.0 - 9.81
    Y = book_positions(res.q, res.scene)
    for k, y0 in enumerate((0.15, 0.20, 0.25)):
        np.testing.assert_allclose(Y[:, k], y0 + 0.5 * a * res.t**2, rtol=0, atol=1e-12)
    F1, F2 = TAU1 - 12.5 * (a + 9.81), TAU2 - 12.5 * (a + 9.81)
    np.testing.assert_allclose(res.wrench(0)[:, 2], F1, rtol=1e-9)
    np.testing.assert_allclose(res.wrench(1)[:, 2], F2, rtol=1e-9)
    np.testing.assert_allclose(res.arm_wrench(0)[:, 2], -F1, rtol=1e-9)
    position, rotation = res.constraint_drift()
    assert position.shape == (len(res.t), 2) and position.max() < 1e-12 and rotation.max() < 1e-12


def test_elastic_object_motion_converges_to_the_rigid_one_as_one_over_k() -> None:
    """The book's springs stiffened by s (dampers by √s, so the damping ratio stays): the
    object's largest departure from the rigid motion falls as 1/s (log-log slope 1 ± 0.01; the
    exponential integrator is exact here, so the difference is the model's alone)."""
    rigid_y = book_positions(_rigid_book().q, linear_book())[:, 1]
    scales = np.array([10.0, 100.0, 1e3, 1e4])
    gaps = []
    for s in scales:
        scene = linear_book(c_p=2e4 * s, c_k=1e4 * s, d_p=500 * np.sqrt(s), d_k=1000 * np.sqrt(s))
        res = cd.simulate(scene, 0.5, controller=_drives(), integrator="exponential", dt=1e-3, save_every=10)
        gaps.append(np.abs(book_positions(res.q, scene)[:, 1] - rigid_y).max())
    slope = -np.polyfit(np.log(scales), np.log(gaps), 1)[0]
    assert slope == pytest.approx(1.0, abs=0.01)


def test_panda_grasps_converge_to_the_rigid_limit_as_one_over_k() -> None:
    """Two Pandas lifting the box under ObjectImpedance: the rigid limit runs with the same
    controller, and the elastic box's path approaches it by ≈ 10× per decade of k. (The grasps
    are damped, D = 0.002 s·K, as the demo's: on undamped ones the loop is unstable.)"""
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.scenes import facing_arms, object_start

    base = facing_arms("panda", stiffness=1e4, damping=0.002)
    task = GripLiftOscillate(start=object_start(base), t_grip=0.05, t_lift=0.05, lift_duration=0.3, lift=0.05)
    rigid = cd.rigid_limit(base)
    ref = cd.simulate(rigid, 0.4, controller=ObjectImpedance(rigid, task), integrator="rk4", dt=5e-4, save_every=20)
    assert np.ptp(ref.object_position()[:, 2]) > 0.04  # it lifted
    assert max(d.max() for d in ref.constraint_drift()) < 1e-9
    gaps = []
    for k in (1e5, 1e6):
        scene = facing_arms("panda", stiffness=k, damping=0.002)
        res = cd.simulate(scene, 0.4, controller=ObjectImpedance(scene, task), integrator="rk4", dt=2.5e-4, save_every=40)
        gaps.append(np.abs(res.object_position() - ref.object_position()).max())
    assert 7.0 < gaps[0] / gaps[1] < 14.0


def _fixture_box(K1: np.ndarray, K2: np.ndarray, e: np.ndarray) -> cd.Scene:
    """A free 2 kg box on two world fixtures 0.3 m apart, the second off by the pose error e."""
    box = cd.RigidObject.box(2.0, [0.3, 0.1, 0.1], pose=[0.0, 0.0, 0.5])
    grasps = [pin.SE3(np.eye(3), np.array([x, 0.0, 0.0])) for x in (-0.15, 0.15)]
    world = [pin.SE3(np.eye(3), np.array([x, 0.0, 0.5])) for x in (-0.15, 0.15)]
    links = [
        cd.Interconnection(None, stiffness=K1, grasp=grasps[0], fixture=world[0]),
        cd.Interconnection(None, stiffness=K2, grasp=grasps[1], fixture=world[1] * pin.exp6(e)),
    ]
    return cd.Scene([], box, links)


def test_redundant_rigid_grasps_take_the_least_norm_forces_where_elastic_ones_follow_stiffness() -> None:
    """Force uncertainty: two rigid grasps on a box can share its weight in infinitely many
    ways. The rigid solver returns the least-norm one, λ = pinv(G) w (G: the stacked grasp
    Jacobians), with no internal force, whatever the stiffness ratio; the elastic model's
    internal force changes with the ratio K1/K2 and the grasp error e."""
    from coopdyn.dynamics.constrained import ConstrainedDynamics
    from coopdyn.statics import equilibrium

    e = np.array([1e-3, 0.0, 0.0, 0.0, 0.0, 0.0])
    squeezes = []
    for ratio in (0.5, 2.0):
        scene = _fixture_box(np.diag([1e4 * ratio] * 3 + [1e2] * 3), np.diag([1e4] * 3 + [1e2] * 3), e)
        rest = equilibrium(scene, tol=1e-10)
        res = cd.Result(scene, np.zeros(1), rest.q[None], np.zeros((1, scene.nv)), np.zeros((1, 0)), "statics", 1.0, 0, 0.0)
        squeezes.append(res.wrench(0)[0, 0])  # x force on the box at grasp 0: the squeeze
        with pytest.warns(UserWarning, match="start deformed"):  # the grasp error: a rigid model has none
            rigid = cd.rigid_limit(scene)
        dyn = cd.Dynamics(rigid)
        assert isinstance(dyn, ConstrainedDynamics)
        q = rigid.q0
        lam = dyn.constraint_wrenches(q, np.zeros(rigid.nv), np.zeros(0))
        data = rigid.model.createData()
        pin.computeJointJacobians(rigid.model, data, q)
        G = np.vstack([pin.getFrameJacobian(rigid.model, data, lk.grasp_frame, pin.LOCAL) for lk in rigid.links])
        weight = pin.rnea(rigid.model, data, q, np.zeros(6), np.zeros(6))  # what the grasps must hold
        np.testing.assert_allclose(lam.ravel(), np.linalg.pinv(G.T) @ weight, rtol=0, atol=1e-7)
        assert abs(lam[0, 0]) < 1e-7 and abs(lam[1, 0]) < 1e-7  # no squeeze
    k_series = [1e4 * r * 1e4 / (1e4 * r + 1e4) for r in (0.5, 2.0)]
    np.testing.assert_allclose(np.abs(squeezes), np.array(k_series) * 1e-3, rtol=1e-3)  # the series law


def test_baumgarte_closes_an_initial_drift_critically_damped() -> None:
    """A box on one rigid fixture, started 1 mm off it: the drift obeys ë = −Kp e − Kd ė
    exactly (pure translation, no gravity), e(t) = e0 (1 + ωt) e^{−ωt} with ω = 50 rad/s."""
    box = cd.RigidObject.box(2.0, [0.1, 0.1, 0.1])
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=[1e4] * 6)], gravity=[0.0, 0.0, 0.0])
    rigid = cd.rigid_limit(scene, baumgarte=(2500.0, 100.0))
    q0 = rigid.q0.copy()
    q0[0] -= 1e-3
    res = cd.simulate(rigid, 0.2, integrator="rk4", dt=1e-4, save_every=10, q0=q0)
    expected = 1e-3 * (1 + 50 * res.t) * np.exp(-50 * res.t)
    np.testing.assert_allclose(res.constraint_drift()[0][:, 0], expected, rtol=1e-6, atol=1e-13)


def test_rigid_limit_refusals() -> None:
    rigid = cd.rigid_limit(linear_book())
    with pytest.raises(cd.SimulationError, match="explicit method"):
        cd.simulate(rigid, 0.1, integrator="implicit_euler")
    with pytest.raises(cd.SimulationError, match="object_wrench"):
        cd.simulate(rigid, 0.1, object_wrench=lambda t: np.zeros(6))
    with pytest.raises(cd.BackendError if hasattr(cd, "BackendError") else cd.CoopdynError, match="rigid grasps"):
        cd.Dynamics(rigid, backend="native")
    with pytest.raises(cd.SceneError, match="baumgarte"):
        cd.rigid_limit(linear_book(), baumgarte=(-1.0, 2.0))
    with pytest.raises(cd.SceneError, match="numeric"):
        cd.rigid_limit(linear_book(), baumgarte="stiff")
    with pytest.raises(cd.SceneError, match="rigid_limit takes"):
        cd.rigid_limit("scene")  # type: ignore[arg-type]


def test_the_rigid_limit_of_a_held_beam_keeps_each_grasp_at_its_node() -> None:
    """A beam's grasps are placed in its reference frame: the rigid limit must put each rigid grasp
    where the elastic one held the beam (it once put both on the middle node)."""
    import pinocchio as pin

    scene = cd.scenes.held_beam()
    rigid = cd.rigid_limit(scene)
    d0, d1 = scene.model.createData(), rigid.model.createData()
    pin.framesForwardKinematics(scene.model, d0, scene.q0)
    pin.framesForwardKinematics(rigid.model, d1, rigid.q0)
    for elastic, stiff in zip(scene.links, rigid.links, strict=True):
        gap = d0.oMf[elastic.tip_frame].translation - d1.oMf[stiff.grasp_frame].translation
        assert np.linalg.norm(gap) < 1e-9


def test_the_rigid_limit_of_a_beam_scene_is_all_rigid() -> None:
    """A held strip's rigid limit is one rigid body of the strip's mass on welded grasps (its own
    16 kHz elements left elastic made rk4 diverge at t = 2 ms): rk4 at 1 ms runs it while the
    arms and strip sag together, and the grasps stay closed (drift below 0.1 mm, 1 mrad)."""
    import warnings

    from coopdyn.scenes import held_beam

    beam = held_beam()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (grasp preloads dropped: reported elsewhere)
        rigid = cd.rigid_limit(beam)
    assert type(rigid.object).__name__ == "RigidObject"
    assert rigid.object.mass_and_com()[0] == pytest.approx(beam.object.mass_and_com()[0], rel=1e-12)
    res = cd.simulate(rigid, 0.2, dt=1e-3)
    assert res.status == "completed"
    translation, rotation = res.constraint_drift()
    assert translation.max() < 1e-4 and rotation.max() < 1e-3
    assert np.ptp(res.object_position()[:, 2]) > 1e-3  # (it moved: unheld arms fall with it)
