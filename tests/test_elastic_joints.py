"""Elastic joints (Spong's reduced model): closed forms, limits, conservation, both backends.

The model (coopdyn/model/elastic_joints.py): per elastic joint a motor angle θ with inertia B,
``M(q)q̈ + h = K(θ − q) + D(θ̇ − q̇) + Jᵀf``, ``Bθ̈ + K(θ − q) + D(θ̇ − q̇) = τ_m``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.control import GravityCompensationPD, MotorPD, ObjectImpedance
from coopdyn.errors import SceneError

PLANAR = str(Path(__file__).resolve().parents[1] / "urdf" / "planar_3r.urdf")


def free_arm_scene(
    elasticity: cd.JointElasticity | None,
    locked: tuple[str, ...] = (),
    gravity: tuple[float, float, float] = (0, 0, -9.81),
    fixture_damping: float = 200.0,
) -> cd.Scene:
    """The planar 3R arm, free (the scene's box hangs on a world fixture, away from it)."""
    q0 = {"joint1": 0.3, "joint2": -0.5, "joint3": 0.4}
    kept = [v for k, v in q0.items() if k not in locked]
    arm = cd.Arm("arm", PLANAR, tip_frame="tip", q0=kept, locked_joints={k: q0[k] for k in locked}, elasticity=elasticity)
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[1.0, 0.0, 0.5])
    damping = cd.diagonal(fixture_damping, fixture_damping / 100) if fixture_damping else None
    fixture = cd.Interconnection(None, stiffness=cd.diagonal(1e4, 1e3), damping=damping)
    return cd.Scene([arm], box, [fixture], gravity=gravity)


def two_inertia(K: float, B: float, D: float = 0.0) -> tuple[cd.Scene, float]:
    """One revolute joint (the planar arm with joints 2 and 3 locked) without gravity; its
    link inertia I_l about the axis [kg·m²]."""
    scene = free_arm_scene(cd.JointElasticity(K, B, damping=D), locked=("joint2", "joint3"), gravity=(0, 0, 0))
    link = int(scene.arms[0].v_index[0])
    I_l = float(pin.crba(scene.model, scene.model.createData(), scene.q0)[link, link])
    return scene, I_l


def test_two_inertia_resonance_from_the_linearisation() -> None:
    K, B = 2000.0, 0.05
    scene, I_l = two_inertia(K, B)
    for backend in ("python", "native"):
        lin = cd.linearize(scene, backend=backend)
        arm = np.r_[scene.arms[0].v_index, scene.arms[0].motor_v_index]
        n = scene.nv
        rows = np.r_[arm, n + arm]
        w = np.sort(np.abs(np.linalg.eigvals(lin.A[np.ix_(rows, rows)]).imag))
        assert w[-1] == pytest.approx(np.sqrt(K * (1 / I_l + 1 / B)), rel=1e-9)
        assert w[0] == pytest.approx(0.0, abs=1e-6)  # the rigid-body mode
        # the antiresonance: the motor's response to its own torque vanishes at √(K/I_l)
        w_a = np.sqrt(K / I_l)
        motor = int(scene.arms[0].motor_v_index[0])
        B_in = lin.B[np.ix_(rows, [0])]
        A = lin.A[np.ix_(rows, rows)]
        gain = [abs(np.linalg.solve(1j * w * np.eye(4) - A, B_in)[list(arm).index(motor), 0]) for w in (w_a, 0.5 * w_a)]
        assert gain[0] < 1e-9 * gain[1]


@pytest.mark.parametrize("loop", ["python", "compiled"])
def test_two_inertia_from_simulated_responses(loop: str) -> None:
    """Free vibration from a deflection at rest swings at ω_r; a motor torque at ω_a, from its
    steady state, leaves the motor still (the link absorbs it)."""
    K, B = 2000.0, 0.05
    scene, I_l = two_inertia(K, B)
    link, motor = int(scene.arms[0].q_index[0]), int(scene.arms[0].motor_q_index[0])
    w_r, w_a = np.sqrt(K * (1 / I_l + 1 / B)), np.sqrt(K / I_l)
    q0 = scene.q0.copy()
    q0[motor] += 0.01
    run = cd.simulate(scene, 2 * np.pi / w_r * 10, None, "rk4", dt=2 * np.pi / w_r / 400, q0=q0, loop=loop)
    delta = run.q[:, motor] - run.q[:, link]
    up = np.flatnonzero((delta[:-1] < 0) & (delta[1:] >= 0))
    t_up = run.t[up] - delta[up] * (run.t[up + 1] - run.t[up]) / (delta[up + 1] - delta[up])
    assert np.diff(t_up).mean() == pytest.approx(2 * np.pi / w_r, rel=1e-6)

    T = 0.5  # [N·m]
    v0 = np.zeros(scene.nv)
    v0[scene.arms[0].v_index[0]] = -T / K * w_a  # q = −T/K sin(ω_a t), θ = 0
    periods = 5 * 2 * np.pi / w_a

    def drive(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.array([T * np.sin(w_a * t)])

    run = cd.simulate(scene, periods, drive, "rk4", dt=2 * np.pi / w_r / 200, q0=scene.q0, v0=v0, loop=loop)
    assert np.abs(run.q[:, link] - scene.q0[link]).max() == pytest.approx(T / K, rel=1e-3)
    assert np.abs(run.q[:, motor] - scene.q0[motor]).max() < 1e-6 * T / K


def test_static_deflection_at_rest() -> None:
    """The scene starts its motors at θ = q + K⁻¹ g(q): the arm is at rest under its weight."""
    K = np.array([3000.0, 2000.0, 800.0])
    scene = free_arm_scene(cd.JointElasticity(K, 0.1))
    arm = scene.arms[0]
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[arm.v_index]
    deflection = scene.joint_springs.deflection(scene.q0)
    np.testing.assert_allclose(deflection, g / K, rtol=1e-12)
    for backend in ("python", "native"):
        a = cd.Dynamics(scene, backend).acceleration(scene.q0, scene.v0, np.zeros(3))
        assert np.abs(a[np.r_[arm.v_index]]).max() < 1e-10
        # the motors need τ_m = K(θ − q) = g(q) to stay: without it they accelerate by −g/B
        np.testing.assert_allclose(a[arm.motor_v_index], -g / 0.1, rtol=1e-10)
        a = cd.Dynamics(scene, backend).acceleration(scene.q0, scene.v0, g)
        assert np.abs(a[np.r_[arm.v_index, arm.motor_v_index]]).max() < 1e-11


def test_stiff_joints_converge_to_the_rigid_arm_with_armature_at_order_one_over_k() -> None:
    """K → ∞: the link follows the rigid arm whose joints carry the motor inertia as armature,
    (M(q) + B) q̈ + h = τ (integrated here from Pinocchio directly), with an error O(1/K)."""
    from scipy.integrate import solve_ivp

    B, T = 0.02, 0.3
    rigid = free_arm_scene(None)
    model, data = rigid.model, rigid.model.createData()
    idx = rigid.arms[0].v_index

    def torque(t: float, q_link: np.ndarray) -> np.ndarray:
        q = rigid.q0.copy()
        q[idx] = q_link
        return pin.computeGeneralizedGravity(model, data, q)[idx] * 0.9 + np.array([2.0, -1.0, 0.5]) * np.sin(8 * t)

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        q = rigid.q0.copy()
        q[idx], v = x[:3], np.zeros(rigid.nv)
        v[idx] = x[3:]
        M = pin.crba(model, data, q)[np.ix_(idx, idx)] + B * np.eye(3)
        h = pin.nonLinearEffects(model, data, q, v)[idx]
        return np.r_[x[3:], np.linalg.solve(M, torque(t, x[:3]) - h)]

    times = np.linspace(0, T, 61)
    ref = solve_ivp(rhs, (0, T), np.r_[rigid.q0[idx], np.zeros(3)], t_eval=times, rtol=1e-11, atol=1e-12).y[:3].T
    geared = free_arm_scene(cd.JointElasticity(np.inf, B))  # K = inf: coopdyn's own rigid arm with B as armature
    run = cd.simulate(geared, T, lambda t, q, v: torque(t, q[idx]), "dopri5", dt=1e-4, loop="python")
    limit = np.array([np.interp(times, run.t, run.q[:, i]) for i in idx]).T
    assert np.abs(limit - ref).max() < 1e-8
    errors = []
    for K in (2e4, 8e4, 3.2e5):
        scene = free_arm_scene(cd.JointElasticity(K, B, damping=2 * np.sqrt(K * B)))
        arm = scene.arms[0]

        def control(t: float, q: np.ndarray, v: np.ndarray, arm: object = arm) -> np.ndarray:
            return torque(t, q[scene.arms[0].q_index])

        run = cd.simulate(scene, T, control, "dopri5", dt=1e-4, save_every=1, loop="python")
        q = np.array([np.interp(times, run.t, run.q[:, i]) for i in arm.q_index]).T
        errors.append(np.abs(q - ref).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.0) & (ratios < 5.5)), (errors, ratios)


@pytest.mark.parametrize("backend", ["python", "native"])
def test_energy_is_conserved_undamped_at_the_method_order(backend: str) -> None:
    scene = free_arm_scene(cd.JointElasticity([3000.0, 2000.0, 800.0], 0.05), fixture_damping=0.0)
    q0 = scene.q0.copy()
    q0[scene.arms[0].motor_q_index] += [0.02, -0.03, 0.01]
    dyn = cd.Dynamics(scene, backend)
    e0 = dyn.energy(q0, scene.v0).total
    drift = []
    for dt in (4e-4, 2e-4):
        run = cd.simulate(scene, 0.2, None, "rk4", dt=dt, q0=q0, backend=backend, energy_check="off")
        drift.append(abs(dyn.energy(run.q[-1], run.v[-1]).total - e0))
    # rk4 is fourth order; on an oscillation its energy error falls faster (h⁶ for a linear one)
    assert 2**4 * 0.85 < drift[0] / drift[1] < 2**6 * 1.2
    assert drift[1] < 1e-6 * e0


def test_backends_agree_on_elastic_joints() -> None:
    base = cd.scenes.facing_arms("panda", stiffness=1e4)
    el = cd.JointElasticity(stiffness=5000.0, motor_inertia=0.4, damping=3.0, motor_damping=0.5)
    scene = cd.Scene([a.replace(elasticity=el) for a in base.arm_specs], base.object, base.interconnection_specs)
    rng = np.random.default_rng(3)
    py, nat = cd.Dynamics(scene, "python"), cd.Dynamics(scene, "native")
    for _ in range(3):
        q = pin.integrate(scene.model, scene.q0, 0.05 * rng.standard_normal(scene.nv))
        v, tau = rng.standard_normal(scene.nv), 5 * rng.standard_normal(scene.n_actuated)
        np.testing.assert_allclose(nat.acceleration(q, v, tau), py.acceleration(q, v, tau), rtol=1e-9, atol=1e-9)
        for a, b in zip(nat.implicit_terms(q, v, tau), py.implicit_terms(q, v, tau), strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
        assert nat.last_dissipation == pytest.approx(py.last_dissipation, rel=1e-10)
        dn, dp = nat.derivatives(q, v, tau), py.derivatives(q, v, tau)
        np.testing.assert_allclose(dn.da_dq, dp.da_dq, rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(dn.da_dv, dp.da_dv, rtol=1e-9, atol=1e-9)


def test_derivatives_against_finite_differences() -> None:
    scene = free_arm_scene(cd.JointElasticity([3000.0, 2000.0, 800.0], 0.05, damping=1.5))
    rng = np.random.default_rng(0)
    q = pin.integrate(scene.model, scene.q0, 0.1 * rng.standard_normal(scene.nv))
    v, tau = rng.standard_normal(scene.nv), rng.standard_normal(3)
    dyn = cd.Dynamics(scene, "python")
    d = dyn.derivatives(q, v, tau)
    eps = 1e-6
    E = np.eye(scene.nv)

    def at(dq: np.ndarray) -> np.ndarray:
        return dyn.acceleration(pin.integrate(scene.model, q, dq), v, tau)

    fd_q = np.array([(at(eps * e) - at(-eps * e)) / (2 * eps) for e in E]).T
    fd_v = np.array([(dyn.acceleration(q, v + eps * e, tau) - dyn.acceleration(q, v - eps * e, tau)) / (2 * eps) for e in E]).T
    np.testing.assert_allclose(d.da_dq, fd_q, rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(d.da_dv, fd_v, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("gravity", ["constant", "online"])
def test_motor_pd_regulates_to_the_target(gravity: str) -> None:
    """Tomei's and De Luca–Siciliano–Zollo's laws bring the link to q_d, the motor to
    θ_d = q_d + K⁻¹ g(q_d), from a start away from both, measuring only the motors."""
    K = np.array([3000.0, 2000.0, 800.0])
    scene = free_arm_scene(cd.JointElasticity(K, 0.05, damping=1.0))
    arm = scene.arms[0]
    q_d = scene.q0[arm.q_index] + np.array([0.3, -0.2, 0.25])
    pd = MotorPD(scene, kp=300.0, kd=20.0, q_des=q_d, gravity=gravity)
    run = cd.simulate(scene, 4.0, pd, "dopri5", dt=1e-3)
    q_end = run.q[-1]
    np.testing.assert_allclose(q_end[arm.q_index], q_d, atol=1e-6)
    q_rest = scene.q0.copy()
    q_rest[arm.q_index] = q_d
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), q_rest)[arm.v_index]
    np.testing.assert_allclose(scene.joint_springs.deflection(q_end), g / K, atol=1e-6)


def test_motor_pd_compiled_equals_python() -> None:
    scene = free_arm_scene(cd.JointElasticity([3000.0, 2000.0, 800.0], 0.05, damping=1.0))
    q_d = scene.q0[scene.arms[0].q_index] + 0.1
    for gravity in ("constant", "online"):
        pd = MotorPD(scene, q_des=q_d, gravity=gravity)
        runs = [cd.simulate(scene, 0.3, pd, "implicit_euler", dt=1e-3, loop=loop) for loop in ("python", "compiled")]
        np.testing.assert_allclose(runs[1].q, runs[0].q, atol=1e-11)
        np.testing.assert_allclose(runs[1].tau, runs[0].tau, atol=1e-8)


def test_elastic_joints_in_a_cooperative_scene_run_compiled_with_every_method() -> None:
    base = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.02)
    el = cd.JointElasticity(stiffness=8000.0, motor_inertia=0.4, damping=5.0)
    scene = cd.Scene([a.replace(elasticity=el) for a in base.arm_specs], base.object, base.interconnection_specs)
    pd = MotorPD(scene)
    finals = {}
    for method in ("rk4", "implicit_euler", "trapezoid", "generalized_alpha", "dopri5"):
        run = cd.simulate(scene, 0.2, pd, method, dt=5e-4, loop="compiled")
        finals[method] = run.q[-1]
    ref = finals.pop("dopri5")
    for method, q in finals.items():
        assert np.abs(q - ref).max() < 1e-4, method  # (implicit Euler: 2e-5; the others below 1e-7)


def test_rigid_joint_controllers_refuse_elastic_arms() -> None:
    scene = free_arm_scene(cd.JointElasticity(3000.0, 0.05))
    for make in (lambda: GravityCompensationPD(scene), lambda: cd.control.ComputedTorque(scene)):
        with pytest.raises(SceneError, match=r"elastic ones.*MotorPD"):
            make()


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (cd.JointElasticity(-1.0, 0.1), r"stiffness must be > 0 \[N·m/rad\]"),
        (cd.JointElasticity(1000.0, 0.0), r"motor_inertia must be > 0 \[kg·m²\]"),
        (cd.JointElasticity([1.0, 2.0], 0.1), "stiffness must be a scalar or have 3 entries"),
        (cd.JointElasticity(1000.0, 0.1, damping=-1), "damping must be >= 0"),
        (cd.JointElasticity(1000.0, 0.1, joints=["joint9"]), "names 'joint9'.*Joints"),
        (cd.JointElasticity(1000.0, 0.1, joints=["joint1", "joint1"]), "twice"),
        (cd.JointElasticity(1000.0, 0.1, gear_ratio=0.5), "gear_ratio"),
        (cd.JointElasticity(float("nan"), 0.1), r"stiffness \[N·m/rad\] must be finite"),
        (cd.JointElasticity(True, 0.1), "stiffness .*must be numeric"),  # type: ignore[arg-type]
        (cd.JointElasticity(1e308, 0.1), r"stiffness above 1e\+12 .*give math\.inf"),
        (cd.JointElasticity("stiff", 0.1), "stiffness"),  # type: ignore[arg-type]
        ({"stiffness": 1.0}, r"must be a coopdyn\.JointElasticity"),
    ],
)
def test_bad_elasticity_is_refused_by_name(spec: object, message: str) -> None:
    with pytest.raises(SceneError, match=message):
        free_arm_scene(spec)  # type: ignore[arg-type]


def test_a_locked_joint_cannot_be_elastic_and_a_slider_s_units_are_linear() -> None:
    with pytest.raises(SceneError, match="'joint3', a locked joint"):
        free_arm_scene(cd.JointElasticity(1e3, 0.1, joints=["joint3"]), locked=("joint3",))
    slider = cd.Arm("s", str(PLANAR.replace("planar_3r", "slider_z")), tip_frame="tip", elasticity=cd.JointElasticity(-1.0, 1.0))
    with pytest.raises(SceneError, match=r"stiffness must be > 0 \[N/m\]"):
        cd.Scene([slider], cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[1, 0, 0]), [cd.Interconnection(None, stiffness=1e3)])


def test_values_pair_with_the_joints_as_named() -> None:
    scene = free_arm_scene(cd.JointElasticity([4000.0, 800.0], [0.1, 0.2], joints=["joint3", "joint1"]))
    springs, arm = scene.joint_springs, scene.arms[0]
    assert springs.link_v.tolist() == [arm.v_index[0], arm.v_index[2]]  # (kept in the arm's joint order)
    assert springs.stiffness.tolist() == [800.0, 4000.0]
    M = pin.crba(scene.model, scene.model.createData(), scene.q0)
    assert M[springs.motor_v[0], springs.motor_v[0]] == pytest.approx(0.2)


PLANAR_BASE = """<?xml version="1.0"?>
<robot name="planar_base">
  <link name="base"/>
  <link name="cart"><inertial><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="plane" type="planar"><parent link="base"/><child link="cart"/><axis xyz="0 0 1"/></joint>
  <link name="arm"><inertial><origin xyz="0.25 0 0"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="elbow" type="revolute"><parent link="cart"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
  <link name="tip"/>
  <joint name="tip_joint" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="0.5 0 0"/></joint>
</robot>
"""


@pytest.mark.parametrize("backend", ["python", "native"])
def test_an_elastic_joint_after_a_multi_dof_joint(tmp_path: Path, backend: str) -> None:
    """A planar joint (3 velocities) then an elastic elbow: the elbow's torque goes to its motor,
    the planar joint keeps its three entries, and the backends and loops agree."""
    urdf = tmp_path / "planar_base.urdf"
    urdf.write_text(PLANAR_BASE)
    arm = cd.Arm("a", str(urdf), tip_frame="tip", elasticity=cd.JointElasticity(1000.0, 0.1, joints=["elbow"]))
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[0.5, 0.0, 0.0])
    scene = cd.Scene([arm], box, [cd.Interconnection("a", stiffness=cd.diagonal(1e4, 1e2))], gravity=(0, 0, 0))
    info = scene.arms[0]
    assert info.elastic.tolist() == [3] and scene.actuated.tolist() == [0, 1, 2, int(info.motor_v_index[0])]
    assert scene.joint_springs.link_v.tolist() == [3]
    rng = np.random.default_rng(1)
    q = pin.integrate(scene.model, scene.q0, 0.1 * rng.standard_normal(scene.nv))
    v, tau = rng.standard_normal(scene.nv), rng.standard_normal(scene.n_actuated)
    reference = cd.Dynamics(scene, "python").acceleration(q, v, tau)
    np.testing.assert_allclose(cd.Dynamics(scene, backend).acceleration(q, v, tau), reference, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("robot", ["kinova", "ur5"])
def test_continuous_and_revolute_arms_agree_on_both_backends(robot: str) -> None:
    """The Kinova's continuous joints (q a (cos, sin) pair, the deflection by atan2) and the UR5's
    revolute ones: the native kernel equals the Python reference, and the derivatives match
    finite differences."""
    arm = cd.Arm("a", robot, elasticity=cd.JointElasticity(3e3, 0.2, damping=1.0))
    tip = cd.scenes.facing_arms(robot).arm_specs[0]
    arm = arm.replace(q0=tip.q0, base=tip.base)
    obj = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[2.0, 0.0, 0.5])
    scene = cd.Scene([arm], obj, [cd.Interconnection(None, stiffness=1e3)])
    if robot == "kinova":
        assert scene.joint_springs.continuous.any()
    rng = np.random.default_rng(4)
    q = pin.integrate(scene.model, scene.q0, 0.1 * rng.standard_normal(scene.nv))
    v, tau = rng.standard_normal(scene.nv), rng.standard_normal(scene.n_actuated)
    py, nat = cd.Dynamics(scene, "python"), cd.Dynamics(scene, "native")
    np.testing.assert_allclose(nat.acceleration(q, v, tau), py.acceleration(q, v, tau), rtol=1e-9, atol=1e-9)
    d = nat.derivatives(q, v, tau)
    eps = 1e-6
    fd = np.array(
        [
            (
                py.acceleration(pin.integrate(scene.model, q, eps * e), v, tau)
                - py.acceleration(pin.integrate(scene.model, q, -eps * e), v, tau)
            )
            / (2 * eps)
            for e in np.eye(scene.nv)
        ]
    ).T
    np.testing.assert_allclose(d.da_dq, fd, rtol=1e-5, atol=1e-4 * np.abs(fd).max())


def test_the_book_with_elastic_sliders_stays_linear() -> None:
    """Motors are rotors on the world about a fixed axis: the book's prismatic system with
    elastic sliders is still linear (its exact discretisation applies)."""
    book = cd.scenes.linear_book()
    arms = [a.replace(elasticity=cd.JointElasticity(5e4, 2.0)) for a in book.arm_specs]
    scene = cd.Scene(arms, book.object, book.interconnection_specs, gravity=book.gravity)
    assert scene.nonlinearity() is None
    run = cd.simulate(scene, 0.05, None, "exponential", dt=1e-3)
    ref = cd.simulate(scene, 0.05, None, "dopri5", dt=1e-3)
    assert np.abs(run.q[-1] - ref.q[-1]).max() < 1e-7


def test_some_joints_elastic_and_gear_reflection() -> None:
    scene = free_arm_scene(cd.JointElasticity(1000.0, 1e-4, gear_ratio=50.0, joints=["joint2"]))
    arm = scene.arms[0]
    assert arm.elastic.tolist() == [1] and scene.nv == 3 + 1 + 6
    M = pin.crba(scene.model, scene.model.createData(), scene.q0)
    assert M[arm.motor_v_index[0], arm.motor_v_index[0]] == pytest.approx(50.0**2 * 1e-4)
    assert scene.actuated.tolist() == [arm.v_index[0], arm.motor_v_index[0], arm.v_index[2]]
    q_names, v_names = scene.coordinates()
    assert "arm/joint2.motor [rad]" in q_names and "arm/joint2.motor [rad/s]" in v_names


def elastic_pandas() -> cd.Scene:
    """The demo's scene with every joint of both arms elastic (examples/elastic_joints.py's)."""
    base = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    el = cd.JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0)
    return cd.Scene([a.replace(elasticity=el) for a in base.arm_specs], base.object, base.interconnection_specs)


def test_object_impedance_holds_elastic_arms_only_with_its_fast_term() -> None:
    """The closed loop's linearisation at the hold: ObjectImpedance's torques sent to the motors
    as they are leave a 17.8 Hz transmission mode growing; Spong's fast term K_v (q̇ − θ̇) at its
    default damps every mode."""
    scene = elastic_pandas()
    growth = {}
    for kv in (0.0, None):
        A = cd.linearize(scene, controller=ObjectImpedance(scene, transmission_damping=kv)).A
        growth[kv] = float(np.linalg.eigvals(A).real.max())  # [1/s]
    assert growth[0.0] > 0.5
    assert growth[None] < -1.0


def test_grip_lift_oscillate_on_elastic_arms_compiled_equals_python() -> None:
    from coopdyn.cooperative import GripLiftOscillate
    from coopdyn.scenes import object_start

    scene = elastic_pandas()
    controller = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0))
    runs = [cd.simulate(scene, 0.3, controller, "trapezoid", dt=1e-3, loop=loop) for loop in ("python", "compiled")]
    np.testing.assert_allclose(runs[1].q, runs[0].q, atol=1e-12)
    np.testing.assert_allclose(runs[1].tau, runs[0].tau, atol=1e-10)
    kp, kd = controller.gains()
    motors = np.isin(scene.actuated, scene.joint_springs.motor_v)
    assert np.all(kp[motors] == 0.0) and np.all(kd[motors] > 0.0)  # the fast term's −∂τ/∂θ̇, on the motors


def test_infinite_stiffness_is_the_rigid_joint_with_the_motor_inertia_as_armature(tmp_path: Path) -> None:
    """K = inf: no motor coordinate, B on the joint's diagonal of the mass matrix, the motor
    friction on the joint; it survives a scene file (TOML has inf)."""
    import math

    from coopdyn.model.description import build, describe

    spec = cd.JointElasticity([math.inf, 2000.0, math.inf], 0.05, motor_damping=0.3)
    scene = free_arm_scene(spec)
    rigid = free_arm_scene(None)
    arm = scene.arms[0]
    assert arm.elastic.tolist() == [1] and scene.nv == rigid.nv + 1
    assert arm.damping.tolist() == [0.3, 0.0, 0.3] and arm.motor_damping.tolist() == [0.3]
    q = scene.q0
    M, M_rigid = (pin.crba(s.model, s.model.createData(), s.q0) for s in (scene, rigid))
    link = arm.v_index[[0, 2]]
    np.testing.assert_allclose(np.diag(M)[link] - np.diag(M_rigid)[link], 0.05, rtol=1e-12)
    assert describe(build(describe(scene)))["arms"][0]["elasticity"]["stiffness"] == ["inf", 2000.0, "inf"]  # (JSON-safe)
    res = cd.simulate(scene, 0.01, None, "rk4", dt=1e-3)
    res.save(tmp_path / "geared.npz")  # (a saved result's description is JSON)
    assert cd.Result.load(tmp_path / "geared.npz").scene.arms[0].damping.tolist() == [0.3, 0.0, 0.3]
    for backend in ("python", "native"):
        e = cd.Dynamics(scene, backend).energy(q, np.ones(scene.nv))
        assert e.kinetic == pytest.approx(0.5 * np.ones(scene.nv) @ M @ np.ones(scene.nv), rel=1e-12)


def test_the_advisor_compares_the_joint_modes_with_the_bandwidth() -> None:
    """The transmission mode of the one-joint arm is the two-inertia resonance; below 5× the
    bandwidth the joints stay elastic, above it rigid joints with the motor inertia do, and the
    rigid-joint model is measured beside the others."""
    K, B = 2000.0, 0.05
    scene, I_l = two_inertia(K, B)
    w_r = np.sqrt(K * (1 / I_l + 1 / B)) / (2 * np.pi)  # [Hz]
    advice = cd.advise_model(scene, bandwidth=w_r / 4)
    assert advice.joint_mode_hz == pytest.approx(w_r, rel=1e-9)
    assert advice.joints == "elastic" and "keep the elastic joints" in str(advice)
    advice = cd.advise_model(scene, bandwidth=w_r / 6)
    assert advice.joints == "rigid" and "rigid joints" in [c.model for c in advice.costs]
    rigid_row = next(c for c in advice.costs if c.model == "rigid joints")
    assert rigid_row.states == scene.nq + scene.nv - 2  # (one motor fewer: its angle and its speed)
    assert cd.advise_model(free_arm_scene(None)).joint_mode_hz is None


def test_everything_elastic_arms_joints_grasps_and_a_beam() -> None:
    """The book's fourth system: elastic arms holding an elastic object. Both backends agree, the
    compiled loop runs it, and undamped it keeps its energy (at the method's order)."""
    base = cd.scenes.held_beam("panda", n_elements=4, beam_damping=0.0)
    el = cd.JointElasticity(stiffness=5e3, motor_inertia=0.3)
    scene = cd.Scene([a.replace(elasticity=el) for a in base.arm_specs], base.object, base.interconnection_specs)
    rng = np.random.default_rng(5)
    arms = np.r_[scene.arm_joints, scene.joint_springs.motor_v]  # (a random shape of the beam is a 1e7 N/m kick)
    dq = np.zeros(scene.nv)
    dq[arms] = 0.01 * rng.standard_normal(arms.size)
    q = pin.integrate(scene.model, scene.q0, dq)
    v, tau = np.zeros(scene.nv), rng.standard_normal(scene.n_actuated)
    v[arms] = rng.standard_normal(arms.size)
    np.testing.assert_allclose(
        cd.Dynamics(scene, "native").acceleration(q, v, tau),
        cd.Dynamics(scene, "python").acceleration(q, v, tau),
        rtol=1e-9,
        atol=1e-7,
    )
    dyn = cd.Dynamics(scene, "native")
    e0 = dyn.energy(q, 0.1 * v).total
    drift = []
    for dt in (1e-5, 5e-6):  # (the beam's fastest element mode: 8.6 kHz; |λ|·dt ≤ 0.54)
        run = cd.simulate(scene, 0.01, None, "rk4", dt=dt, q0=q, v0=0.1 * v, loop="compiled", energy_check="off")
        drift.append(abs(dyn.energy(run.q[-1], run.v[-1]).total - e0))
    assert drift[0] / drift[1] > 2**4 * 0.85 and drift[1] < 1e-6 * abs(e0)


def test_a_sweep_sets_the_joints_stiffness_through_the_arms_elasticity_table() -> None:
    from coopdyn.sweeps.spec import put

    doc = {"arms": [{"name": "a", "elasticity": {"stiffness": 1.0, "motor_inertia": 0.1}}, {"name": "b"}]}
    put(doc, "arms.0.elasticity.stiffness", 5e3)
    assert doc["arms"][0]["elasticity"]["stiffness"] == 5e3
    with pytest.raises(cd.errors.SweepError, match="entry has no 'elasticity' table"):
        put(doc, "arms.elasticity.stiffness", 7e3)  # arm b has none
    with pytest.raises(cd.errors.SweepError, match="not deeper"):
        put(doc, "arms.elasticity.stiffness.x", 1.0)


def test_the_run_figure_draws_the_motor_torques(tmp_path: Path) -> None:
    from coopdyn.cooperative import GripLiftOscillate
    from coopdyn.scenes import object_start
    from coopdyn.viz.plotting import cooperative_figure

    scene = elastic_pandas()
    task = GripLiftOscillate(start=object_start(scene), squeeze=20.0)
    res = cd.simulate(scene, 0.1, ObjectImpedance(scene, task), "trapezoid", dt=1e-3)
    fig = cooperative_figure(res, task, tmp_path / "run.png")
    labels = fig.axes[3].get_legend_handles_labels()[1]
    assert labels[0] == "left/panda_joint1.motor" and len(labels) == scene.n_actuated


def test_the_kernel_eliminates_the_motors_from_the_step_matrix_exactly() -> None:
    """The compiled kernel factors only the links' Schur complement of the step matrix (the
    motors' block is diagonal): its solves equal the Python backend's full Cholesky, and whole
    implicit runs on both backends agree."""
    scene = elastic_pandas()
    rng = np.random.default_rng(2)
    q = pin.integrate(scene.model, scene.q0, 0.05 * rng.standard_normal(scene.nv))
    v, tau = rng.standard_normal(scene.nv), rng.standard_normal(scene.n_actuated)
    kp, kd = np.full(scene.n_actuated, 40.0), np.full(scene.n_actuated, 4.0)
    solutions = []
    for backend in ("native", "python"):
        dyn = cd.Dynamics(scene, backend)
        f, M, K, D = dyn.implicit_terms(q, v, tau)
        dyn.factor(M, K, D, 1e-3, kp, kd)
        solutions.append(dyn.solve(v, f))
    for a, b in zip(*solutions, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10)
    pd = MotorPD(scene)
    for method in ("implicit_euler", "trapezoid", "generalized_alpha"):
        runs = [cd.simulate(scene, 0.1, pd, method, dt=1e-3, backend=b, energy_check="off") for b in ("native", "python")]
        np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-10)


def test_a_scene_file_controls_elastic_arms_and_names_a_bad_elasticity_key(tmp_path: Path) -> None:
    from coopdyn.io.scenefile import SceneFileError, load

    text = (Path(__file__).resolve().parents[1] / "examples" / "scenes" / "two_ur5s_elastic_joints.toml").read_text()
    text = text.replace('[controller]\ntype = "object_impedance"', '[controller]\ntype = "motor_pd"\n[unused]').split("[unused]")[
        0
    ]
    path = tmp_path / "motor_pd.toml"
    path.write_text(text + '\n[simulation]\nduration = 0.1\nintegrator = "trapezoid"\n')
    loaded = load(path)
    assert isinstance(loaded.controller, MotorPD)
    bad = tmp_path / "typo.toml"
    bad.write_text(
        text.replace("stiffness = 2e4, motor_inertia", "stifness = 2e4, motor_inertia", 1) + "\n[simulation]\nduration = 0.1\n"
    )
    with pytest.raises(SceneFileError, match=r"line 16: \[\[arms\]\] #1 elasticity\.stifness: unknown key.*stiffness"):
        load(bad)


def test_what_takes_rigid_joints_only_says_so() -> None:
    scene = free_arm_scene(None)
    with pytest.raises(SceneError, match="transmission_damping is for arms with elastic joints"):
        ObjectImpedance(cd.scenes.facing_arms("panda"), transmission_damping=5.0)
    with pytest.raises(SceneError, match="one value per elastic joint"):
        ObjectImpedance(elastic_pandas(), transmission_damping=[1.0, 2.0])
    from coopdyn.bench.drake_scene import DrakeScene
    from coopdyn.bench.exudyn_scene import ExudynScene

    elastic = free_arm_scene(cd.JointElasticity(1e3, 0.1))
    for peer in (DrakeScene, ExudynScene):
        with pytest.raises(cd.errors.SimulationError, match="does not model elastic joints"):
            peer(elastic, None)
    assert scene.joint_springs.size == 0


def test_an_elasticity_sub_table_s_bad_key_has_its_line(tmp_path: Path) -> None:
    from coopdyn.io.scenefile import SceneFileError, load

    text = (Path(__file__).resolve().parents[1] / "examples" / "scenes" / "two_ur5s_elastic_joints.toml").read_text()
    first = (
        "elasticity = { stiffness = 2e4, motor_inertia = 0.2, damping = 5.0 }   # [N·m/rad], [kg·m²] at the joint, [N·m·s/rad]\n"
    )
    assert first in text
    head, tail = text.split(first)
    second_arm = tail.index("[[arms]]")
    sub = "[arms.elasticity]\nstiffness = 2e4\nmotor_inertia = 0.2\ndampin = 5.0\n\n"
    path = tmp_path / "sub.toml"
    path.write_text(head + tail[:second_arm] + sub + tail[second_arm:])
    line = (head + tail[:second_arm] + sub).splitlines().index("dampin = 5.0") + 1
    with pytest.raises(SceneFileError, match=rf"line {line}: \[\[arms\]\] #1 elasticity\.dampin: unknown key"):
        load(path)


def test_a_result_saved_with_other_columns_is_refused(tmp_path: Path) -> None:
    """A saved result whose columns are not its rebuilt scene's (an older layout) is refused,
    not read with its coordinates in the wrong places."""
    import json

    scene = free_arm_scene(cd.JointElasticity(2e3, 0.05))
    res = cd.simulate(scene, 0.01, None, "rk4", dt=1e-3)
    res.save(tmp_path / "run.npz")
    arrays = dict(np.load(tmp_path / "run.npz"))
    meta = json.loads(str(arrays["meta"]))
    meta["columns"]["q"] = meta["columns"]["q"][::-1]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "old.npz", **arrays)
    with pytest.raises(cd.errors.SimulationError, match="q columns are not those its rebuilt scene has"):
        cd.Result.load(tmp_path / "old.npz")


def test_the_viewer_draws_the_arms_at_their_motor_angles(tmp_path: Path) -> None:
    """The animation's ghost arms are the elastic arms at their motor angles θ: at ×1 each ghost
    geometry sits where the arm's own does with its links turned to θ; by default the run's
    largest deflection is drawn 0.15 rad, and the legend says by how much it is magnified. A
    rigid scene has no ghost."""
    from coopdyn.cooperative import GripLiftOscillate
    from coopdyn.scenes import object_start
    from coopdyn.viz import viewer

    scene = elastic_pandas()
    task = GripLiftOscillate(start=object_start(scene), squeeze=20.0)
    res = cd.simulate(scene, 0.1, ObjectImpedance(scene, task), "trapezoid", dt=1e-3)
    vis = viewer._meshcat().Visualizer(window=viewer.RecordingWindow())
    animator = viewer._Animator(scene, vis, "collision", deflection=1.0)
    q, wrenches = res.q[-1], res.wrenches()[-1]
    at_motors = q.copy()  # (the Pandas' joints come first, one coordinate each: q index = v index)
    at_motors[scene.joint_springs.link_v] = q[np.concatenate([info.motor_q_index for info in scene.arms])]
    own = {name.removeprefix("coopdyn/"): T for name, T, _ in animator.poses(at_motors, wrenches) if "/visuals/" in name}
    ghost = [(name, T) for name, T, _ in animator.poses(q, wrenches) if name.startswith("coopdyn/motors/")]
    assert len(ghost) == sum(1 for name in own if name.startswith("visuals/") and "panda" in name) > 10
    assert np.abs(res.joint_deflection()[-1]).max() > 1e-4  # the ghost is not the arm itself
    for name, T in ghost:
        assert np.allclose(T, own[name.removeprefix("coopdyn/motors/")], atol=1e-12), name
    scale = viewer.deflection_scale(res)
    assert np.isclose(scale * np.abs(res.joint_deflection()).max(), viewer.GHOST_DEFLECTION)
    assert f"deflection θ − q drawn ×{scale:.3g}" in viewer._legend(0.01, 20.0, scale)
    rigid = cd.simulate(cd.scenes.facing_arms("panda"), 0.01, integrator="rk4", dt=1e-3)
    assert viewer.deflection_scale(rigid) == 1.0
    assert not viewer._Animator(rigid.scene, vis, "collision").ghost_nodes
