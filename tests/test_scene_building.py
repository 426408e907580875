"""Scene building: the merged model, defaults, and the error a user gets on bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.resources import urdf_path


def test_merged_model_of_two_pandas(pandas: cd.Scene) -> None:
    """Fingers locked (7 + 7 joints), then a free-flying box: nq = 21, nv = 20."""
    assert (pandas.nq, pandas.nv, pandas.n_actuated) == (21, 20, 14)
    assert pandas.arms[0].joint_names[0] == "left/panda_joint1"
    assert pandas.model.frames[pandas.arms[1].tip_frame].name == "right/panda_hand_tcp"
    np.testing.assert_array_equal(pandas.actuated, np.arange(14))
    np.testing.assert_array_equal(pandas.object_v, np.arange(14, 20))


def test_facing_arms_is_mirror_symmetric(pandas: cd.Scene) -> None:
    """Same joint configuration for both arms, tools on the box faces at y = ∓0.1 m."""
    q_left, q_right = (pandas.q0[a.q_index] for a in pandas.arms)
    np.testing.assert_array_equal(q_left, q_right)
    data = pandas.model.createData()
    pin.framesForwardKinematics(pandas.model, data, pandas.q0)
    np.testing.assert_allclose(data.oMf[pandas.arms[0].tip_frame].translation, [0.0, -0.1, 0.7], atol=1e-9)
    np.testing.assert_allclose(data.oMf[pandas.arms[1].tip_frame].translation, [0.0, 0.1, 0.7], atol=1e-9)


def test_box_inertia() -> None:
    box = cd.RigidObject.box(12.0, (1.0, 2.0, 3.0))
    np.testing.assert_allclose(np.diag(box.inertia), [13.0, 10.0, 5.0])


def test_stiffness_shorthands() -> None:
    np.testing.assert_array_equal(cd.diagonal(1e4, [1.0, 2.0, 3.0]), np.diag([1e4, 1e4, 1e4, 1.0, 2.0, 3.0]))
    K = cd.axial(5.0, "x")
    assert K[0, 0] == 5.0 and np.count_nonzero(K) == 1


def _one_slider(**ic: object) -> cd.Scene:
    arm = cd.Arm("a", urdf_path("slider_z.urdf"), tip_frame="tip")
    obj = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), joint="prismatic")
    return cd.Scene([arm], obj, [cd.Interconnection("a", **ic)])  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"stiffness": np.diag([1.0, 2, 3, 4, 5, -6])}, r"stiffness must be positive semi-definite.*smallest eigenvalue is -6"),
        ({"stiffness": np.triu(np.ones((6, 6)))}, r"stiffness must be symmetric"),
        ({"stiffness": np.ones(5)}, r"stiffness must be a 6x6 matrix, a 6-vector diagonal or a scalar"),
        ({"stiffness": [np.nan] * 6}, r"stiffness must be finite"),
        ({"stiffness": np.zeros(6)}, r"stiffness and damping are both zero"),
    ],
)
def test_bad_interconnection_matrices(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(cd.SceneError, match=message):
        _one_slider(**kwargs)


def test_unknown_robot_name_suggests_close_names() -> None:
    with pytest.raises(cd.ModelLoadError, match=r"unknown robot 'pnada'.*Did you mean 'panda'"):
        cd.Scene([cd.Arm("a", "pnada")], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_missing_urdf_file() -> None:
    with pytest.raises(cd.ModelLoadError, match=r"URDF file not found: /nowhere/arm.urdf"):
        cd.Scene([cd.Arm("a", "/nowhere/arm.urdf")], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_unknown_tip_frame_suggests_close_names() -> None:
    arm = cd.Arm("a", "panda", tip_frame="panda_hand_tpc")
    with pytest.raises(cd.SceneError, match=r"no frame named 'panda_hand_tpc'.*Did you mean 'panda_hand_tcp'"):
        cd.Scene([arm], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_unknown_locked_joint_lists_the_joints() -> None:
    arm = cd.Arm("a", "panda", locked_joints=["panda_finger_joint3"])
    with pytest.raises(
        cd.SceneError, match=r"no joint named 'panda_finger_joint3'. Did you mean 'panda_finger_joint2', 'panda_finger_joint1'"
    ):
        cd.Scene([arm], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_a_joint_locked_twice_is_refused_by_name() -> None:
    """Found by the slow fuzz run: Pinocchio refused a repeated locked joint with a ValueError."""
    arm = cd.Arm("a", urdf_path("slider_z.urdf"), tip_frame="tip", locked_joints=["slide", "slide"])
    with pytest.raises(cd.SceneError, match=r"locked_joints names \['slide'\] more than once"):
        cd.Scene([arm], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_interconnection_to_unknown_arm() -> None:
    arm = cd.Arm("left", urdf_path("slider_z.urdf"), tip_frame="tip")
    with pytest.raises(cd.SceneError, match=r"names arm 'lft'.*Did you mean 'left'"):
        cd.Scene([arm], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("lft", np.ones(6))])


def test_q0_outside_joint_limits() -> None:
    arm = cd.Arm("a", "panda", q0=[0.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0])  # joint 4 must be < -0.0698
    with pytest.raises(cd.SceneError, match=r"q0 of joint 'panda_joint4' is 0.5, outside its limits"):
        cd.Scene([arm], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        (lambda: cd.RigidObject.box(0.0, (0.1, 0.1, 0.1)), r"box mass must be > 0 \[kg\]"),
        (lambda: cd.RigidObject(1.0, np.diag([1.0, 1.0, 3.0])), r"violates the triangle inequality"),
        (lambda: cd.RigidObject(1.0, np.diag([1.0, 1.0, -1.0])), r"must be positive definite"),
        (lambda: cd.RigidObject(1.0, np.eye(3), joint="spherical"), r"object joint must be one of \('freeflyer'"),
    ],
)
def test_bad_object(obj: object, message: str) -> None:
    arm = cd.Arm("a", urdf_path("slider_z.urdf"), tip_frame="tip")
    with pytest.raises(cd.SceneError, match=message):
        cd.Scene([arm], obj(), [cd.Interconnection("a", np.ones(6))])  # type: ignore[operator]


def test_duplicate_arm_names() -> None:
    arm = cd.Arm("a", urdf_path("slider_z.urdf"), tip_frame="tip")
    with pytest.raises(cd.SceneError, match=r"arm names must be unique, got \['a', 'a'\]"):
        cd.Scene([arm, arm], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_a_scene_is_immutable_and_its_arrays_read_only(pandas: cd.Scene) -> None:
    with pytest.raises(cd.SceneError, match="a Scene is immutable"):
        pandas.q0 = pandas.q0  # type: ignore[misc]
    for array in (pandas.q0, pandas.v0, pandas.actuated, pandas.gravity, pandas.arms[0].v_index, pandas.links[0].element.K):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 1.0


def test_a_scene_pickles_without_reading_any_urdf(pandas: cd.Scene) -> None:
    import pickle

    from coopdyn.model import arm

    before = arm._parsed.cache_info().misses
    copy = pickle.loads(pickle.dumps(pandas))
    assert arm._parsed.cache_info().misses == before
    np.testing.assert_array_equal(copy.q0, pandas.q0)
    q, v = pandas.q0, np.full(pandas.nv, 0.1)
    tau = np.zeros(pandas.n_actuated)
    np.testing.assert_array_equal(cd.Dynamics(copy).acceleration(q, v, tau), cd.Dynamics(pandas).acceleration(q, v, tau))


def test_each_urdf_is_parsed_once(tmp_path: Path) -> None:
    """Two arms from one URDF file, the IK of facing_arms and the viewer's geometry: one parse."""
    from coopdyn.model import arm

    urdf = tmp_path / "slider.urdf"
    urdf.write_text(urdf_path("slider_z.urdf").read_text())
    before = arm._parsed.cache_info().misses
    arms = [cd.Arm(n, urdf, tip_frame="tip", q0=[z]) for n, z in (("a", 0.15), ("b", 0.25))]
    box = cd.RigidObject(1.0, np.eye(3) * 0.01, pose=[0.0, 0.0, 0.2], joint="prismatic")
    links = [cd.Interconnection("a", cd.axial(1e3)), cd.Interconnection("b", cd.axial(1e3))]
    cd.Scene(arms, box, links)
    cd.Scene(arms, box, links)
    assert arm._parsed.cache_info().misses == before + 1


def test_two_pandas_hold_a_box_with_ball_springs_on_the_native_backend(pandas: cd.Scene) -> None:
    links = [
        cd.Interconnection(ic.arm, stiffness=[1e4, 2e4, 3e4], damping=20.0, element="ball") for ic in pandas.interconnection_specs
    ]
    scene = cd.Scene(pandas.arm_specs, pandas.object, links, gravity=pandas.gravity)
    ctrl = cd.control.GravityCompensationPD(scene, 50.0, 5.0)
    res = cd.simulate(scene, 0.5, controller=ctrl, integrator="implicit_euler", dt=1e-3, backend="native", save_every=50)
    assert res.backend == "native" and res.deformation(0).shape == (res.t.size, 3)
    # a point grasp: no moment on the object about the grasp point, and the box is carried
    np.testing.assert_allclose(res.wrench(0)[:, 3:], 0.0, atol=1e-12)
    assert res.wrench(0)[-1, 2] + res.wrench(1)[-1, 2] == pytest.approx(2.0 * 9.81, rel=0.2)


def test_stiffness_up_to_the_float_limit_is_validated_without_overflow() -> None:
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1))
    huge = np.full(6, 1e308)
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=huge)])
    np.testing.assert_array_equal(np.diag(scene.links[0].element.K), huge)
    with pytest.raises(cd.SceneError, match="smallest eigenvalue is -1e\\+308"):
        cd.Scene([], box, [cd.Interconnection(None, stiffness=np.diag([1e308] * 5 + [-1e308]))])


def test_an_arm_with_continuous_joints_takes_its_angles_or_rounded_pairs() -> None:
    """A Kinova (three continuous joints: nq 9, nv 6) takes q0 as six angles [rad] — each
    continuous one becomes its (cos θ, sin θ) — or as the configuration, a pair rounded to two
    decimals normalised (its angle is unchanged); a pair that is no (cos, sin), or a wrong
    length, is refused with the joint and both accepted lengths."""
    from coopdyn.model.arm import load_arm

    angles = np.array([0.1, 2.9, 1.0, 0.4, 1.5, 0.6])
    exact = load_arm(cd.Arm("k", "kinova", q0=angles))
    assert exact.q0.shape == (9,)
    np.testing.assert_allclose(exact.q0[:2], [np.cos(0.1), np.sin(0.1)], atol=1e-15)
    rounded = load_arm(cd.Arm("k", "kinova", q0=np.round(exact.q0, 2)))
    model = rounded.model
    for j in range(1, model.njoints):
        if model.joints[j].nq == 2:  # (each continuous pair: unit length, its angle as rounded)
            i = model.joints[j].idx_q
            assert np.hypot(*rounded.q0[i : i + 2]) == pytest.approx(1.0, abs=1e-15)
            angle = np.arctan2(*np.round(exact.q0, 2)[i : i + 2][::-1])
            assert np.arctan2(rounded.q0[i + 1], rounded.q0[i]) == pytest.approx(angle, abs=1e-14)
    with pytest.raises(cd.SceneError, match=r"continuous joint 'j2s6s200_joint_1' takes \(cos θ, sin θ\).*got \(1, 1\)"):
        load_arm(cd.Arm("k", "kinova", q0=np.ones(9)))
    with pytest.raises(cd.SceneError, match=r"q0 must have 9 values \(the configuration\) or 6 \(one per joint"):
        load_arm(cd.Arm("k", "kinova", q0=np.ones(4)))


def test_arms_of_different_robots_are_placed_around_a_box_in_python() -> None:
    """cd.place_arm: a UR5 and a Kinova, each started with its tool frame on a face of a 0.15 m box
    (to 1e-8 m and rad), hold it without a far-grasp warning; left in their reference postures
    they warn with the distance; a target out of reach is refused with its distance and the
    arm's reach."""
    import warnings

    box = cd.RigidObject.box(1.0, (0.15, 0.15, 0.15), pose=[0.0, 0.0, 0.5])
    ur5 = cd.Arm(
        "ur5", "ur5", tip_frame="tool0", base=pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.pi / 2), np.array([0.0, -0.5, 0.0]))
    )
    kinova = cd.Arm("kinova", "kinova", base=pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, -np.pi / 2), np.array([0.0, 0.5, 0.0])))
    targets = {  # tool z axis into the box through its ±y faces
        "ur5": pin.SE3(pin.rpy.rpyToMatrix(-np.pi / 2, 0.0, 0.0), np.array([0.0, -0.075, 0.5])),
        "kinova": pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0.0, 0.0), np.array([0.0, 0.075, 0.5])),
    }
    links = [cd.Interconnection(name, stiffness=1e4) for name in targets]
    with pytest.warns(cd.SceneWarning, match="grasps the object"):
        cd.Scene([ur5, kinova], box, links)
    placed = [cd.place_arm(arm, targets[arm.name]) for arm in (ur5, kinova)]
    with warnings.catch_warnings():
        warnings.simplefilter("error", cd.SceneWarning)
        scene = cd.Scene(placed, box, links)
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    for lk in scene.links:
        assert np.max(np.abs(pin.log6(data.oMf[lk.tip_frame].actInv(targets[lk.name])).vector)) < 1e-8
    with pytest.raises(cd.SceneError, match=r"the target is 1.66 m from the arm's base, which reaches at most [0-9.]+ m"):
        cd.place_arm(ur5, [0.0, -2.0, 0.7])
    with pytest.raises(cd.SceneError, match=r"place_arm places a coopdyn.Arm, got 'ur5'"):
        cd.place_arm("ur5", targets["ur5"])  # type: ignore[arg-type]
    with pytest.raises(cd.SceneError, match=r"arm 'ur5': tool_pose must be finite"):
        cd.place_arm(ur5, [np.nan, 0.0, 0.5])


def test_angles_that_look_like_degrees_are_named() -> None:
    """Angles are in radians. A Panda's q0 in degrees is outside its limits: the error says so
    and gives the radians; a continuous joint (no limits) or an rpy in a pose beyond ±2π warns
    with the figure; angles within ±2π pass silently."""
    import warnings

    from coopdyn.model.arm import load_arm
    from coopdyn.model.description import build, describe

    degrees = [0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0]
    with pytest.raises(cd.SceneError, match=r"'panda_joint2' is -45, .*\(in degrees\? -45° is -0.785398 rad"):
        load_arm(cd.Arm("a", "panda", q0=degrees))
    with pytest.warns(cd.SceneWarning, match=r"continuous joint 'j2s6s200_joint_6' has 90 rad \(5157°\).*give 1.5708"):
        load_arm(cd.Arm("k", "kinova", q0=[0.1, 2.9, 1.0, 0.4, 1.5, 90.0]))
    doc = describe(cd.scenes.facing_arms("panda"))
    doc["arms"][0]["base"] = {"translation": [0.0, -0.6, 0.0], "rpy": [0.0, 0.0, 90.0]}
    with pytest.warns(cd.SceneWarning, match=r"arms\[0\].base.rpy has 90 rad \(5157°\)"):
        build(doc)
    with warnings.catch_warnings():
        warnings.simplefilter("error", cd.SceneWarning)
        load_arm(cd.Arm("k", "kinova", q0=[0.1, 2.9, 1.0, 0.4, 1.5, -6.2]))
        doc["arms"][0]["base"]["rpy"] = [0.0, 0.0, np.pi / 2]
        build(doc)


def test_grasps_far_too_soft_for_the_object_warn_with_the_sag() -> None:
    """A stiffness thought in N/mm (10 for 10 N/mm): the 2 kg box would hang about 1 m below its
    start on its grasps — the run warns with that figure; at 1e4 N/m (2 mm of sag) it does not,
    nor on the book's sliders, the held strip or the planar arms' beam."""
    import warnings

    soft = cd.scenes.facing_arms("panda", stiffness=10.0)
    with pytest.warns(cd.SceneWarning, match=r"would come to rest 9\d\d mm from where it starts, \d+% of its size \(200 mm\)"):
        cd.simulate(soft, 0.01, dt=1e-3)
    for scene in (cd.scenes.facing_arms("panda", stiffness=1e4), cd.scenes.linear_book(), cd.scenes.held_beam(n_elements=2)):
        with warnings.catch_warnings():
            warnings.simplefilter("error", cd.SceneWarning)
            cd.simulate(scene, 0.01, dt=1e-3, integrator="trapezoid")
