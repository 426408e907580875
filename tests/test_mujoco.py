"""coopdyn.mujoco: coopdyn's interconnection law and compiled controllers as MuJoCo's C callbacks —
the same accelerations as coopdyn's at random states and times, the kernel's Jacobian-free
passive force equal to Σ Jrᵀ f, a user's own model with more in it, the refusals, and the
callbacks put back on exit."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.control import GravityCompensationPD
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.dynamics import Dynamics
from coopdyn.errors import SimulationError
from coopdyn.integrators import DormandPrince
from coopdyn.scenes import object_start

mujoco = pytest.importorskip("mujoco")
from coopdyn.mujoco import Callbacks, mjcf  # noqa: E402


@pytest.fixture(scope="module")
def damped() -> cd.Scene:
    return cd.scenes.facing_arms("panda", stiffness=1e5, damping=0.002, joint_damping=0.5)


def test_the_passive_force_without_jacobians_is_the_sum_of_jr_transpose_f(damped: cd.Scene) -> None:
    """Kernel.passive_force (the elements' wrenches summed over subtrees, one pass from the
    leaves) equals Σ Jrᵀ f from the frame Jacobians (Kernel.spring_force), at random states."""
    dyn = Dynamics(damped, "native")
    kernel = dyn._kernel  # type: ignore[attr-defined]
    model = mujoco.MjModel.from_xml_string(mjcf(damped))
    rng = np.random.default_rng(0)
    with Callbacks(damped, model) as cb:
        data = mujoco.MjData(model)
        for _ in range(5):
            q = pin.integrate(damped.model, damped.q0, rng.normal(size=damped.nv) * 0.05)
            v = rng.normal(size=damped.nv) * 0.3
            cb.set_state(data, q, v)
            mujoco.mj_forward(model, data)
            Q = kernel.spring_force(q, v)
            assert np.linalg.norm(Q) > 10.0
            # MuJoCo's qfrc_passive = joint damping + Q in MuJoCo's coordinates
            back = np.zeros(damped.nv)
            back[cb._v_pin] = data.qfrc_passive[cb._v_mj] + data.qvel[cb._v_mj] * model.dof_damping[cb._v_mj]
            _, iv, qa, da = cb._free
            w, x, y, z = data.qpos[qa + 3 : qa + 7]
            rot = pin.Quaternion(w, x, y, z).matrix()  # (MuJoCo's free joint: ṗ, hence its force, in world axes)
            back[iv : iv + 3] = rot.T @ data.qfrc_passive[da : da + 3]
            back[iv + 3 : iv + 6] = data.qfrc_passive[da + 3 : da + 6]
            assert np.max(np.abs(back - Q)) <= 1e-9 * np.max(np.abs(Q))


@pytest.mark.parametrize("controller", ["none", "gravity_pd", "grip_lift_oscillate"])
def test_mujocos_accelerations_are_coopdyns(damped: cd.Scene, controller: str) -> None:
    """With the callbacks, MuJoCo's q̈ equals coopdyn's at random states and times (the
    grip–lift–oscillate task reads MuJoCo's time), to round-off."""
    ctrl = {
        "none": None,
        "gravity_pd": GravityCompensationPD(damped),
        "grip_lift_oscillate": ObjectImpedance(damped, GripLiftOscillate(start=object_start(damped), squeeze=20.0, t_lift=0.5)),
    }[controller]
    model = mujoco.MjModel.from_xml_string(mjcf(damped, "RK4", 1e-3))
    assert Callbacks(damped, model, ctrl).check(n=5) < 1e-12


def test_a_users_own_model_with_more_in_it_runs_coopdyns_law(damped: cd.Scene) -> None:
    """The scene's model with a floor, a site and an extra actuated body of the user's: the
    callbacks map joints and motors by name, leave the rest to MuJoCo, and RK4 steps the grasp
    as coopdyn's rk4 does (the same error against a tight reference over 0.2 s); four law
    evaluations per step."""
    xml = mjcf(damped, "RK4", 1e-3)
    extra = (
        '    <geom name="floor" type="plane" size="2 2 0.1" pos="0 0 -1"/>\n'
        '    <body name="users_cart" pos="3 0 0"><joint name="users_slide" type="slide" axis="1 0 0"/>'
        '<inertial pos="0 0 0" mass="1" diaginertia="0.1 0.1 0.1"/><site name="users_site"/></body>\n'
    )
    xml = xml.replace("  </worldbody>", extra + "  </worldbody>")
    xml = xml.replace("  </actuator>", '    <motor joint="users_slide" ctrllimited="false"/>\n  </actuator>')
    xml = xml.replace("  <actuator>", "  <actuator>\n" + '    <velocity joint="users_slide" kv="1"/>\n', 1)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    pd = GravityCompensationPD(damped)
    v0 = np.random.default_rng(2).normal(size=damped.nv) * 0.3
    with Callbacks(damped, model, pd) as cb:
        cb.set_state(data, damped.q0, v0)
        mujoco.mj_step(model, data, nstep=200)
        cb.raise_if_failed()
        assert cb.evaluations == 800
        q, _ = cb.state(data)
    mine = cd.simulate(damped, 0.2, controller=pd, integrator="rk4", dt=1e-3, v0=v0, accuracy_check="off")
    tight = cd.simulate(damped, 0.2, controller=pd, integrator=DormandPrince(rtol=1e-12, atol=1e-14), v0=v0)
    error_mj = np.max(np.abs(pin.difference(damped.model, q, tight.q[-1])))
    error_cd = np.max(np.abs(pin.difference(damped.model, mine.q[-1], tight.q[-1])))
    assert error_mj < 1e-8 and error_mj < 3.0 * error_cd  # both RK4 (MuJoCo's free joint in its own coordinates)


def test_the_callbacks_are_put_back_on_exit_and_nest(damped: cd.Scene) -> None:
    """Leaving a block puts back the user's own callbacks; an inner block's law gives way to the
    outer one's when it ends; a block of the same Callbacks cannot be entered twice."""
    model = mujoco.MjModel.from_xml_string(mjcf(damped))
    data = mujoco.MjData(model)

    def mine(m: object, d: object) -> None:
        return None

    mujoco.set_mjcb_passive(mine)
    mujoco.set_mjcb_control(mine)
    try:
        outer, inner = Callbacks(damped, model), Callbacks(damped, model, GravityCompensationPD(damped))
        with outer:
            assert mujoco.get_mjcb_passive() is not mine
            with inner:
                mujoco.mj_forward(model, data)
            mujoco.mj_forward(model, data)
            with pytest.raises(SimulationError, match="already installed"), outer:
                pass
            assert outer.check(n=1) < 1e-12  # (inside its own block too)
        assert (inner.evaluations, outer.evaluations) == (1, 2)
        assert mujoco.get_mjcb_passive() is mine and mujoco.get_mjcb_control() is mine
    finally:
        mujoco.set_mjcb_passive(None)
        mujoco.set_mjcb_control(None)


def test_the_law_outlives_a_forgotten_block(damped: cd.Scene) -> None:
    """Callbacks entered and dropped without leaving: the installed law keeps its kernel alive (no
    use after free), and the next block replaces it."""
    import gc

    model = mujoco.MjModel.from_xml_string(mjcf(damped))
    data = mujoco.MjData(model)
    Callbacks(damped, model).__enter__()
    gc.collect()
    mujoco.mj_forward(model, data)  # the dropped Callbacks' law, still alive
    assert np.all(np.isfinite(data.qacc))
    with Callbacks(damped, model) as cb:
        mujoco.mj_forward(model, data)
    assert cb.evaluations == 1
    mujoco.set_mjcb_passive(None)


def test_control_alone_computes_its_torque(damped: cd.Scene) -> None:
    """mj_forwardSkip past the velocity stage runs the control callback without the passive one:
    the torque is computed for the state MuJoCo has now, not reused from an earlier state."""
    pd = GravityCompensationPD(damped)
    model = mujoco.MjModel.from_xml_string(mjcf(damped))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(5)
    with Callbacks(damped, model, pd) as cb:
        cb.set_state(data, damped.q0, damped.v0)
        mujoco.mj_forward(model, data)
        q = pin.integrate(damped.model, damped.q0, rng.normal(size=damped.nv) * 0.05)
        v = rng.normal(size=damped.nv) * 0.3
        cb.set_state(data, q, v)
        mujoco.mj_forwardSkip(model, data, mujoco.mjtStage.mjSTAGE_VEL, 0)
        expected = pd(0.0, q, v)
        assert np.allclose(data.ctrl[cb._motor_ctrl], expected[cb._motor_tau], rtol=1e-12, atol=1e-9)


def test_what_it_refuses(damped: cd.Scene) -> None:
    xml = mjcf(damped)
    first = damped.model.names[1]
    missing = mujoco.MjModel.from_xml_string(xml.replace(f'"{first}"', '"renamed"'))
    with pytest.raises(SimulationError, match=f"no joint named '{first}'"):
        Callbacks(damped, missing)
    geared = mujoco.MjModel.from_xml_string(xml.replace('ctrllimited="false"/>', 'ctrllimited="false" gear="2"/>', 1))
    with pytest.raises(SimulationError, match="must be a plain motor"):
        Callbacks(damped, geared, GravityCompensationPD(damped))
    bare = mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(SimulationError, match="no compiled twin"):
        Callbacks(damped, bare, lambda t, q, v: np.zeros(damped.n_actuated))
    twice = mujoco.MjModel.from_xml_string(xml.replace("  </actuator>", f'    <motor joint="{first}"/>\n  </actuator>'))
    with pytest.raises(SimulationError, match="exactly one actuator"):
        Callbacks(damped, twice, GravityCompensationPD(damped))
    limited = mujoco.MjModel.from_xml_string(
        xml.replace('ctrllimited="false"/>', 'ctrllimited="false" forcelimited="true" forcerange="-1 1"/>', 1)
    )
    with pytest.raises(SimulationError, match="must be a plain motor"):
        Callbacks(damped, limited, GravityCompensationPD(damped))
    no_motors = mujoco.MjModel.from_xml_string(xml.split("  <actuator>")[0] + "</mujoco>\n")
    Callbacks(damped, no_motors)  # (the law alone needs no motor)
    with pytest.raises(SimulationError, match="exactly one actuator"):
        Callbacks(damped, no_motors, GravityCompensationPD(damped))


def test_the_documented_example_runs() -> None:
    """docs/mujoco.md's example, as written: one second of two Pandas in MuJoCo with coopdyn's
    law and controller, one law evaluation per implicitfast step."""
    import contextlib
    import io
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "mujoco.md").read_text(encoding="utf-8")
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/mujoco.md", "exec"), {})
    assert out.getvalue().startswith("1000 law evaluations; object at")


@pytest.mark.parametrize("controller", ["none", "motor_pd", "grip_lift_oscillate"])
def test_elastic_joints_are_two_hinges_and_a_tendon_with_coopdyns_accelerations(controller: str) -> None:
    """An elastic joint in MuJoCo: the motor's hinge on the world with the rotor inertia as
    armature, a fixed tendon θ − q with K and D to the link's hinge; q̈ equals coopdyn's at random
    states, without a controller, under MotorPD and under the grip-lift-oscillate task."""
    from coopdyn.control import MotorPD

    base = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    el = cd.JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0, motor_damping=0.2)
    scene = cd.Scene([a.replace(elasticity=el) for a in base.arm_specs], base.object, base.interconnection_specs)
    ctrl = {
        "none": None,
        "motor_pd": MotorPD(scene),
        "grip_lift_oscillate": ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0)),
    }[controller]
    model = mujoco.MjModel.from_xml_string(mjcf(scene, "RK4", 1e-3))
    assert model.ntendon == 14
    assert Callbacks(scene, model, ctrl).check(n=5) < 1e-12
