"""The compiled step loop (src/native/loop.hpp) against the Python loop: the same steps, samples,
torques, counters, warnings and errors, to round-off — for every built-in integrator and
controller — and the cases that must stay in Python."""

from __future__ import annotations

import dataclasses
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.control import ComputedTorque, GravityCompensationPD
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.errors import StepMatrixError
from coopdyn.integrators import INTEGRATORS, RK4, DormandPrince, Exponential, GeneralizedAlpha, LinearlyImplicitEuler, Trapezoid
from coopdyn.scenes import object_start

#: every built-in with a compiled version (from the registry: a new one is tested here by itself)
#: but the exponential integrator, which needs a linear scene (tested on the book system below),
#: and variants whose settings take other paths through the compiled twins
VARIANTS = [LinearlyImplicitEuler(jacobian_every=3), Trapezoid(rho_inf=0.5), GeneralizedAlpha(rho_inf=0.3)]
METHODS: list[object] = [
    *(name for name, cls in INTEGRATORS.items() if "compiled_spec" in cls.__dict__ and name != "exponential"),
    *VARIANTS,
    DormandPrince(rtol=1e-7, atol=1e-9),
]


def _both(scene: cd.Scene, t_final: float, **kwargs: object) -> tuple[cd.Result, cd.Result]:
    py = cd.simulate(scene, t_final, loop="python", **kwargs)  # type: ignore[arg-type]
    co = cd.simulate(scene, t_final, loop="compiled", **kwargs)  # type: ignore[arg-type]
    assert (py.loop, co.loop) == ("python", "compiled")
    return py, co


def _assert_same(py: cd.Result, co: cd.Result, rtol: float = 1e-9) -> None:
    assert co.t.shape == py.t.shape and np.allclose(co.t, py.t, rtol=0, atol=1e-12)
    for name in ("q", "v", "tau"):
        a, b = getattr(py, name), getattr(co, name)
        assert a.shape == b.shape, name
        if a.size:
            assert np.max(np.abs(a - b)) <= rtol * max(1.0, np.max(np.abs(a))), name
    for name in ("n_rhs", "n_jac", "n_factor", "n_steps", "n_rejected", "status"):
        assert getattr(co, name) == getattr(py, name), name


@pytest.mark.parametrize("method", METHODS, ids=str)
def test_every_built_in_method_gives_the_python_loops_result(pandas: cd.Scene, method: object) -> None:
    """Two Pandas + box under gravity compensation + PD, perturbed start, 0.1 s."""
    v0 = np.random.default_rng(1).normal(size=pandas.nv) * 0.3
    py, co = _both(pandas, 0.1, controller=GravityCompensationPD(pandas), integrator=method, dt=1e-3, v0=v0, save_every=3)
    _assert_same(py, co)


@pytest.fixture(scope="module")
def damped() -> cd.Scene:
    return cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)


@pytest.mark.parametrize("method", ["implicit_euler", "rk4", "trapezoid", "dopri5"])
def test_object_impedance_with_the_book_task_runs_compiled_with_the_same_result(damped: cd.Scene, method: str) -> None:
    """The demo's controller (grip, lift, oscillate) over the grip and the lift's start, 1 s."""
    ctrl = ObjectImpedance(damped, GripLiftOscillate(start=object_start(damped), squeeze=20.0, t_lift=0.5))
    py, co = _both(damped, 1.0, controller=ctrl, integrator=method, dt=5e-4 if method == "rk4" else 1e-3, save_every=10)
    _assert_same(py, co)


@pytest.mark.parametrize("measure", ["tips", "object"])
def test_object_impedance_on_a_strip_runs_compiled_with_the_same_result(measure: str) -> None:
    """On an elastic strip, read at the tool frames (its default) and at its middle node: the
    compiled twin estimates the object frame from the tools as the Python law does."""
    strip = cd.scenes.held_beam(n_elements=2)
    task = GripLiftOscillate(start=object_start(strip), squeeze=5.0, t_grip=0.05, t_lift=0.1, lift_duration=0.2)
    ctrl = ObjectImpedance(strip, task, measure=measure, stiffness=(100.0, 2.0), damping=(10.0, 0.2))
    py, co = _both(strip, 0.3, controller=ctrl, integrator="trapezoid", dt=1e-3, save_every=10)
    _assert_same(py, co)


def test_a_controller_built_for_a_twin_scene_runs_compiled_with_its_own_model(damped: cd.Scene) -> None:
    """The demo's controller built on the nominal scene, run on a twin with other grasps and a
    heavier box (what identification does): compiled, equal to the Python loop, where the
    controller keeps its own model; a scene with other frames leaves it to Python."""
    from coopdyn.compiled import twin_scenes
    from coopdyn.parameters import with_parameters

    ctrl = ObjectImpedance(damped, GripLiftOscillate(start=object_start(damped), squeeze=20.0))
    twin = with_parameters(damped, {"left.k_linear": 1.3e4, "right.d_angular": 0.5, "object.mass": 2.6})
    from coopdyn.closed_loop import System
    from coopdyn.compiled import controller_settings

    assert twin_scenes(damped, twin) and twin_scenes(twin, damped)
    assert controller_settings(twin, System(cd.Dynamics(twin), ctrl))["kind"] == "object_impedance"  # (not a callback)
    py, co = _both(twin, 0.3, controller=ctrl, integrator="rk4", dt=1e-3, save_every=10)
    _assert_same(py, co)
    moved = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002, box_size=(0.2, 0.22, 0.2))
    assert not twin_scenes(damped, moved)  # (other grasp frames)
    assert controller_settings(moved, System(cd.Dynamics(moved), ctrl))["kind"] == "python"
    assert not twin_scenes(damped, cd.scenes.facing_arms("panda", stiffness=1e4, gravity=(0.0, 0.0, -9.0)))
    higher = cd.Scene(
        damped.arm_specs,
        dataclasses.replace(damped.object, pose=pin.SE3(np.eye(3), object_start(damped) + np.array([0.0, 0.0, 0.05]))),
        damped.interconnection_specs,
    )
    assert not twin_scenes(damped, higher)  # (the object joint placed elsewhere)


def test_object_impedance_holding_computed_torque_and_no_controller(damped: cd.Scene) -> None:
    for ctrl in (ObjectImpedance(damped), ComputedTorque(damped), None):
        py, co = _both(damped, 0.2, controller=ctrl, integrator="implicit_euler", dt=1e-3)
        _assert_same(py, co)


@pytest.mark.parametrize(
    "method", ["rk4", "trapezoid", "generalized_alpha", "dopri5", "exponential", Exponential("foh")], ids=str
)
def test_open_loop_drives_on_the_book_case(book: cd.Scene, method: object) -> None:
    d1, d2 = cd.scenes.book_task()
    py, co = _both(book, 3.0, controller=cd.scenes.drives_controller(d1, d2), integrator=method, dt=1e-3, save_every=7)
    _assert_same(py, co)


def test_gravity_compensation_outside_a_right_hand_side(book: cd.Scene) -> None:
    """The compiled GravityCompensationPD reads g(q) off the kernel's kinematics. The exponential
    step asks for torques at its predictor states without evaluating the dynamics, so the loop
    must run that pass itself (else the kernel refuses: no kinematics): the Python loop's torques
    and states. (On the book's vertical sliders g is constant; a q-dependent g read outside a
    right-hand side — each run's last sample — is compared on the Pandas above.)"""
    ctrl = GravityCompensationPD(book, 50.0, 5.0)
    py, co = _both(book, 0.5, controller=ctrl, integrator="exponential", dt=1e-3, v0=np.full(book.nv, 0.1), save_every=7)
    assert co.status == "completed" and np.min(np.abs(co.tau)) > 50.0  # gravity is most of the torque here
    _assert_same(py, co)


_PLANAR_ARM = """<?xml version="1.0"?>
<robot name="planar_arm">
  <link name="base"/>
  <link name="carriage">
    <inertial><origin xyz="0.05 0.02 0.1"/><mass value="3.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.04"/></inertial>
  </link>
  <joint name="plane" type="planar">
    <parent link="base"/><child link="carriage"/>
    <origin xyz="0 0 0.5" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
  </joint>
  <link name="forearm">
    <inertial><origin xyz="0.15 0 0"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="carriage"/><child link="forearm"/>
    <origin xyz="0.1 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="10"/>
  </joint>
  <link name="tip"/>
  <joint name="tip_joint" type="fixed"><parent link="forearm"/><child link="tip"/><origin xyz="0.3 0 0"/></joint>
</robot>
"""


def test_gravity_compensation_on_a_joint_the_kinematic_gravity_does_not_take(tmp_path: Path) -> None:
    """An arm on a planar joint (three degrees of freedom, a configuration-dependent motion
    subspace): the kernel cannot read g(q) off its kinematics pass, so the compiled
    GravityCompensationPD takes it from Pinocchio's RNEA — and gives the Python loop's run."""
    urdf = tmp_path / "planar_arm.urdf"
    urdf.write_text(_PLANAR_ARM)
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[0.4, 0.0, 0.6])
    stiffness = cd.diagonal([1e3] * 3, [10.0] * 3)
    scene = cd.Scene([cd.Arm("a", str(urdf), tip_frame="tip")], box, [cd.Interconnection("a", stiffness=stiffness)])
    nat = cd.Dynamics(scene, backend="native")
    with pytest.raises(ValueError, match="revolute, prismatic or helical"):
        nat._kernel.gravity(scene.q0)  # type: ignore[attr-defined]
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.1
    ctrl = GravityCompensationPD(scene, 20.0, 2.0)
    py, co = _both(scene, 0.2, controller=ctrl, integrator="rk4", dt=1e-3, v0=v0, save_every=5)
    assert np.max(np.abs(co.tau)) > 10.0  # a torque that matters: gravity's, on the elbow and the carriage
    _assert_same(py, co)


def test_python_pieces_run_in_the_python_loop(pandas: cd.Scene) -> None:
    """A subclass of a built-in method, an object wrench: the Python loop, chosen automatically;
    loop='compiled' says which piece is Python. A Python controller runs compiled (called back)."""

    def ctrl(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.zeros(pandas.n_actuated)

    class MyRK4(RK4):
        pass

    assert cd.simulate(pandas, 0.01, controller=ctrl).loop == "compiled"
    assert cd.simulate(pandas, 0.01, integrator=MyRK4()).loop == "python"
    assert cd.simulate(pandas, 0.01, object_wrench=lambda t: np.zeros(6)).loop == "python"
    assert cd.simulate(pandas, 0.01, backend="python").loop == "python"
    assert cd.simulate(pandas, 0.01).loop == "compiled"
    with pytest.raises(cd.SimulationError, match=r"cannot run this simulation: the integrator MyRK4.* has no compiled version"):
        cd.simulate(pandas, 0.01, integrator=MyRK4(), loop="compiled")


@pytest.mark.parametrize("method", METHODS, ids=str)
def test_a_python_controller_called_from_the_compiled_loop_gives_the_python_loops_result(
    pandas: cd.Scene, method: object
) -> None:
    """A user's PD + gravity compensation written in Python (no compiled twin): called back from
    the compiled loop at every evaluation, the same steps, samples, torques and counters as the
    Python loop, to round-off."""
    law = GravityCompensationPD(pandas)

    def users_controller(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return law(t, q, v)

    v0 = np.random.default_rng(1).normal(size=pandas.nv) * 0.3
    py, co = _both(pandas, 0.1, controller=users_controller, integrator=method, dt=1e-3, v0=v0, save_every=3)
    _assert_same(py, co)


def test_a_python_controller_that_fails_in_the_compiled_loop_raises_as_in_python(pandas: cd.Scene) -> None:
    """Its exception, NaN torques, a wrong shape, writing into q: the same ControllerError and
    message from both loops (the compiled loop re-raises what the controller did)."""
    law = GravityCompensationPD(pandas)

    def raises(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        if t > 0.005:
            raise ValueError("boom")
        return law(t, q, v)

    def nan(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return law(t, q, v) * (np.nan if t > 0.005 else 1.0)

    def short(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return law(t, q, v)[:-1]

    def writes(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        q[0] = 0.0
        return law(t, q, v)

    for ctrl, message in (
        (raises, r"the controller raised ValueError at t = 0.0055 s: boom"),
        (nan, r"non-finite torques at t = 0.0055 s"),
        (short, r"returned shape \(13,\)"),
        (writes, r"read-only \(q and v are read-only"),
    ):
        for loop in ("python", "compiled"):
            with pytest.raises(cd.errors.ControllerError, match=message):
                cd.simulate(pandas, 0.02, controller=ctrl, integrator="rk4", dt=1e-3, loop=loop, accuracy_check="off")
    with pytest.raises(cd.SimulationError, match=r"loop must be one of \['auto', 'compiled', 'python'\], got 'fast'"):
        cd.simulate(pandas, 0.01, loop="fast")


def test_a_python_controllers_output_of_any_kind_is_taken_as_in_the_python_loop(pandas: cd.Scene) -> None:
    """The compiled loop takes a float64 vector as it is (also a strided view, or one buffer the
    controller reuses each call) and converts lists and other dtypes as the Python loop does: the
    same run; the controller's own exception is the ControllerError's cause; coopdyn's errors and
    Ctrl-C pass through as they are."""
    law = GravityCompensationPD(pandas)
    buffer = np.zeros(pandas.n_actuated)
    wide = np.zeros((pandas.n_actuated, 2))

    def reused(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        buffer[:] = law(t, q, v)
        return buffer

    def strided(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        wide[:, 1] = law(t, q, v)
        return wide[:, 1]

    def as_list(t: float, q: np.ndarray, v: np.ndarray) -> list[float]:
        return law(t, q, v).tolist()

    def single(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return law(t, q, v).astype(np.float32)

    reference = cd.simulate(pandas, 0.02, controller=law, integrator="rk4", dt=1e-3, loop="python", accuracy_check="off")
    for ctrl in (reused, strided, as_list, single):
        for loop in ("python", "compiled"):
            res = cd.simulate(pandas, 0.02, controller=ctrl, integrator="rk4", dt=1e-3, loop=loop, accuracy_check="off")
            assert res.loop == loop
            tol = 1e-5 if ctrl is single else 1e-12  # float32 torques: a relative 6e-8 per sample
            assert np.max(np.abs(res.q - reference.q)) < tol, (ctrl.__name__, loop)

    def swapped(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:  # big-endian doubles: converted, not read raw
        return law(t, q, v).astype(">f8")

    for loop in ("python", "compiled"):
        res = cd.simulate(pandas, 0.02, controller=swapped, integrator="rk4", dt=1e-3, loop=loop, accuracy_check="off")
        assert np.max(np.abs(res.q - reference.q)) < 1e-12, loop

    class Unprintable(Exception):
        def __str__(self) -> str:
            raise RuntimeError("its str() failed")

    def unprintable(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        raise Unprintable()

    for loop in ("python", "compiled"):  # what naming the error raises, as in the Python loop
        with pytest.raises(RuntimeError, match="its str\\(\\) failed"):
            cd.simulate(pandas, 0.01, controller=unprintable, integrator="rk4", dt=1e-3, loop=loop)

    def fails(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        raise ZeroDivisionError("from the law")

    with pytest.raises(cd.errors.ControllerError, match="raised ZeroDivisionError at t = 0 s") as info:
        cd.simulate(pandas, 0.01, controller=fails, integrator="rk4", dt=1e-3, loop="compiled")
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    # a failed run's error does not keep its loop alive through a cycle the collector cannot see
    import gc
    import weakref

    alive = []
    for _ in range(3):
        try:
            cd.simulate(pandas, 0.01, controller=fails, integrator="rk4", dt=1e-3, loop="compiled")
        except cd.errors.ControllerError as exc:
            alive.append(weakref.ref(exc))
    del info
    gc.collect()
    assert not any(ref() is not None for ref in alive)
    for error in (KeyboardInterrupt("stop"), cd.errors.SceneError("the user's own scene check")):

        def passes(t: float, q: np.ndarray, v: np.ndarray, error: BaseException = error) -> np.ndarray:
            raise error

        with pytest.raises(type(error)) as caught:
            cd.simulate(pandas, 0.01, controller=passes, integrator="rk4", dt=1e-3, loop="compiled", progress=False)
        assert caught.value is error


def test_a_divergence_in_the_compiled_loop_is_reported_like_in_python() -> None:
    """rk4 far above its stability limit: the same DivergenceError, time and partial result."""
    stiff = cd.scenes.facing_arms("panda", stiffness=1e6)
    errors = []
    for loop in ("python", "compiled"):
        with pytest.raises(cd.DivergenceError) as info, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cd.simulate(stiff, 1.0, controller=GravityCompensationPD(stiff), integrator="rk4", dt=2e-3, loop=loop)
        errors.append(info.value)
    py, co = errors
    assert str(co) == str(py)
    assert co.result.loop == "compiled" and co.result.status == "diverged"
    # The loops evaluate g(q) by different formulas, equal to round-off (the compiled one reads it
    # off the kernel's kinematics); the unstable step grows that round-off (~1e-12 relative) by
    # ~1e4 before the speed check stops the run, |q̇| from 0 to ~8e3: 1e-8.
    assert np.max(np.abs(co.result.v[-1])) > 1e3
    _assert_same(py.result, co.result, rtol=1e-8)


def test_energy_warning_is_the_same_in_both_loops() -> None:
    """The book case with springs too stiff for symplectic Euler at 1 ms: the monitor warns before
    the divergence, with the same text in both loops, attributed to the caller."""
    stiff = cd.scenes.linear_book(c_p=2e8, c_k=2e8, d_p=0.0, d_k=0.0)
    ctrl = cd.scenes.drives_controller(*cd.scenes.book_task())
    texts, errors = [], []
    for loop in ("python", "compiled"):
        with warnings.catch_warnings(record=True) as caught, pytest.raises(cd.DivergenceError) as info:
            warnings.simplefilter("always")
            cd.simulate(stiff, 1.0, controller=ctrl, integrator="symplectic_euler", dt=1e-3, loop=loop)
        energy = [w for w in caught if issubclass(w.category, cd.EnergyBalanceWarning)]
        assert all(w.filename == __file__ for w in energy)
        texts.append([str(w.message) for w in energy])
        errors.append(str(info.value))
    assert len(texts[0]) == 1 and texts[1] == texts[0]
    assert errors[1] == errors[0]


def test_ctrl_c_during_a_compiled_run_keeps_the_trajectory(pandas: cd.Scene) -> None:
    """A KeyboardInterrupt arrives between chunks: SimulationInterrupted with the samples so far."""
    import _thread

    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(cd.SimulationInterrupted) as info:
            cd.simulate(
                pandas, 200.0, controller=GravityCompensationPD(pandas), integrator="implicit_euler", dt=1e-3, save_every=10
            )
    finally:
        timer.cancel()
    res = info.value.result
    assert res.loop == "compiled" and res.status == "interrupted"
    assert 0.0 < res.t[-1] < 200.0 and np.all(np.isfinite(res.tau)) and len(res.t) == len(res.tau)
    assert res.n_steps >= round(res.t[-1] / 1e-3)


def test_the_compiled_loop_releases_the_gil(pandas: cd.Scene, monkeypatch: pytest.MonkeyPatch) -> None:
    """While one thread runs a compiled simulation in long chunks (the run is ~1 s of work),
    another thread keeps running Python: its longest wait for the GIL stays far below the run."""
    monkeypatch.setattr(cd.compiled, "CHUNK_SECONDS", 10.0)  # chunks of ~10 s: the whole run in one or two
    done = threading.Event()
    gaps = [0.0]

    def spin() -> None:
        last = time.perf_counter()
        while not done.is_set():
            now = time.perf_counter()
            gaps[0] = max(gaps[0], now - last)
            last = now

    thread = threading.Thread(target=spin)
    thread.start()
    try:
        t0 = time.perf_counter()
        res = cd.simulate(pandas, 100.0, integrator="implicit_euler", dt=1e-3, save_every=1000, energy_check="off")
        wall = time.perf_counter() - t0
    finally:
        done.set()
        thread.join()
    assert res.loop == "compiled" and res.n_steps == 100_000
    assert gaps[0] < 0.25 * wall, (gaps[0], wall)


@pytest.mark.parametrize("name", ["pandas_ball", "three_pandas", "hung_box"])
@pytest.mark.parametrize("method", ["rk4", "trapezoid", "dopri5"])
def test_ball_springs_three_arms_and_a_fixture_in_the_compiled_loop(name: str, method: str) -> None:
    """The elements and scene shapes of the kernel's parity suite, through both loops."""
    from tests.test_native import SCENES

    scene = SCENES[name]
    ctrl = GravityCompensationPD(scene) if scene.n_actuated else None
    v0 = np.random.default_rng(6).normal(size=scene.nv) * 0.2
    py, co = _both(scene, 0.1, controller=ctrl, integrator=method, dt=5e-4, v0=v0, save_every=4)
    _assert_same(py, co)


def test_a_step_matrix_failure_names_the_same_time_and_step_in_both_loops(pandas: cd.Scene) -> None:
    """A negative joint stiffness from the controller's gains makes the step matrix indefinite."""
    ctrl = GravityCompensationPD(pandas, kp=1.0, kd=5.0)
    ctrl.kp[:] = -1e6  # the constructor refuses it; set behind its back to reach the step matrix
    errors = []
    for loop in ("python", "compiled"):
        with pytest.raises(StepMatrixError) as info:
            cd.simulate(pandas, 0.1, controller=ctrl, integrator="implicit_euler", dt=1e-3, loop=loop)
        errors.append(info.value)
    assert str(errors[1]) == str(errors[0]) and "at t = 0 s (implicit_euler, dt = 0.001 s)" in str(errors[0])
    _assert_same(errors[0].result, errors[1].result)


def test_python_references_are_called_never_compiled_as_the_default(damped: cd.Scene, book: cd.Scene) -> None:
    """A reference or drive assigned after construction is Python code: never compiled as the
    default it replaced — the controller is called back from the compiled loop, with the same
    result as the Python loop."""
    ctrl = ComputedTorque(damped)
    q0 = ctrl.reference(0.0)[0] + 0.01
    ctrl.reference = lambda t: (q0, np.zeros_like(q0), np.zeros_like(q0))
    assert ctrl.compiled_spec(damped) is None
    py, co = _both(damped, 0.01, controller=ctrl, integrator="implicit_euler")
    _assert_same(py, co)
    d1, _ = cd.scenes.book_task()
    drives = cd.scenes.drives_controller(d1, lambda t: 300.0)
    assert drives.compiled_spec(book) is None
    res = cd.simulate(book, 0.01, controller=drives)
    assert res.loop == "compiled" and res.tau[-1, 1] == 300.0


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("frequency", 0.0, r"frequency must be > 0 \[Hz\]"),
        ("cycles", -1, "cycles must be >= 0"),
        ("lift", np.nan, r"lift \[m\] must be finite"),
        ("start", (np.nan, 0.0, 0.5), "start must be finite"),
        ("rotation", np.ones((3, 3)), "rotation must be a rotation matrix"),
    ],
)
def test_grip_lift_oscillate_refuses_what_neither_loop_can_run(field: str, value: float, message: str) -> None:
    with pytest.raises(cd.SceneError, match=message):
        GripLiftOscillate(**{"start": (0.0, 0.0, 0.5), field: value})


def test_fractional_cycles_are_the_same_in_both_loops(damped: cd.Scene) -> None:
    task = GripLiftOscillate(
        start=object_start(damped), t_grip=0.1, t_lift=0.1, lift_duration=0.2, t_osc=0.3, cycles=1.5, frequency=5.0
    )
    py, co = _both(damped, 0.7, controller=ObjectImpedance(damped, task), integrator="implicit_euler", dt=1e-3, save_every=10)
    _assert_same(py, co)


def test_the_kernel_and_python_name_the_statuses_alike() -> None:
    from coopdyn.dynamics.backend import kernel_module

    assert tuple(kernel_module().STATUSES) == cd.compiled.STATUS_NAMES


def test_a_controller_run_compiled_makes_no_pinocchio_data() -> None:
    """A built-in controller makes its Pinocchio Data (nv³ derivative tensors: gigabytes on a
    long beam) only when its Python law runs: a compiled run leaves it unmade; the Python law,
    called, gives the torque its compiled twin applied."""
    scene = cd.scenes.held_beam(n_elements=4)
    pd = GravityCompensationPD(scene)
    result = cd.simulate(scene, 2e-3, controller=pd, integrator="implicit_euler", dt=1e-3, accuracy_check="off")
    if result.loop != "compiled":
        pytest.skip("coopdyn._native is not built")
    assert "_scratch_data" not in vars(pd)
    tau = pd(0.0, result.q[0], result.v[0])
    assert "_scratch_data" in vars(pd)
    np.testing.assert_allclose(tau, result.tau[0], rtol=0, atol=1e-9 * np.abs(tau).max())
