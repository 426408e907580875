"""Every front door answers bad input with a CoopdynError naming what was given and what is
valid; runs that cannot finish are refused up front; a stable method that cannot resolve a mode
says so; Ctrl-C and failing disks lose nothing that was computed.

Each cluster the fuzzing of the first release found is reproduced here."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import coopdyn as cd
from coopdyn.control import ComputedTorque, GravityCompensationPD
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.io.scenefile import load
from coopdyn.outputs import write_outputs
from coopdyn.problems.facing_arms import object_start

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


def default_sigint() -> None:
    """``preexec_fn`` for subprocesses that receive SIGINT: the default disposition, even when
    this process was started ignoring it (see conftest.py)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _zero(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.zeros(2)


SIMULATE_CASES = [
    ({"t_final": 10**400}, cd.SimulationError, r"t_final \[s\] must be within the float range"),
    ({"dt": 5e-324}, cd.SimulationError, r"dt must be >= 1e-12 \[s\]"),
    ({"dt": 0}, cd.SimulationError, r"dt must be >= 1e-12 \[s\]"),
    ({"dt": "1e-3"}, cd.SimulationError, r"dt \[s\] must be numeric, got '1e-3'"),
    ({"dt": 1e-3 + 1e-9j}, cd.SimulationError, r"dt \[s\] must be real"),
    ({"t_final": 1.0, "dt": 1e-9}, cd.SimulationError, r"asks for 1e\+09 steps, more than max_steps"),
    ({"q0": "abc"}, cd.SceneError, r"q \(a configuration\) must be numeric, got 'abc'"),
    ({"q0": np.array([0.15, 0.25, 0.0]) + 1e-3j}, cd.SceneError, r"q \(a configuration\) must be real"),
    ({"v0": np.array([None, 0, 0])}, cd.SceneError, r"v \(a velocity\) must be numeric"),
    ({"controller": 5}, cd.ControllerError, r"controller must be a callable controller\(t, q, v\)"),
    ({"controller": lambda t, q, v: "abc"}, cd.ControllerError, r"the controller's output must be numeric, got 'abc'"),
    ({"controller": lambda t, q, v: {"tau": 1}}, cd.ControllerError, r"the controller's output must be numeric"),
    ({"controller": lambda t, q, v: np.zeros(2) + 1j}, cd.ControllerError, r"the controller's output must be real"),
    ({"controller": lambda t, q, v: [0.0]}, cd.ControllerError, r"returned shape \(1,\)"),
    ({"integrator": 3.5}, cd.SimulationError, r"unknown integrator 3.5; valid"),
    ({"integrator": ["rk4"]}, cd.SimulationError, r"unknown integrator \['rk4'\]"),
    ({"energy_check": [1]}, cd.SimulationError, r"energy_check must be one of \['warn', 'raise', 'off'\], got \[1\]"),
    ({"max_speed": float("inf")}, cd.SimulationError, r"max_speed \[rad/s or m/s\] must be finite"),
    ({"max_speed": -1.0}, cd.SimulationError, r"max_speed must be > 0"),
    ({"save_every": 2.0}, cd.SimulationError, r"save_every must be an integer >= 1, got 2.0"),
    ({"progress": "yes"}, cd.SimulationError, r"progress must be True or False"),
    ({"object_wrench": 3}, cd.ControllerError, r"object_wrench must be a callable"),
    ({"object_wrench": lambda t: "x"}, cd.ControllerError, r"object_wrench\(t\) must be numeric"),
    ({"max_steps": 0}, cd.SimulationError, r"max_steps must be an integer >= 1 or None \(no limit\), got 0"),
    ({"max_memory": "lots"}, cd.SimulationError, r"max_memory \[bytes\] must be numeric"),
    ({"save_every": 2**63}, cd.SimulationError, r"save_every must be at most 2\*\*53"),
    ({"integrator": cd.integrators.RK4}, cd.SimulationError, r"the class RK4, not an instance: give RK4\(\)"),
    ({"integrator": "RK4"}, cd.SimulationError, r"unknown integrator 'RK4'.* Did you mean 'rk4'\?"),
    (
        {"integrator": cd.integrators.DormandPrince(h_min=1.0), "dt": 1e-3},
        cd.SimulationError,
        r"h_min = 1 s is above dt = 0.001 s",
    ),
    ({"v0": [0.0, 0.0, 2e4]}, cd.SimulationError, r"v0\[2\] = 20000 \[rad/s or m/s\] is faster than max_speed = 10000"),
    (  # a float32's 0.001 is not 0.001: the message shows it, not a contradiction
        {"dt": np.float32(1e-3), "control_dt": 2e-3},
        cd.SimulationError,
        r"control_dt = 0.002 s must be a whole multiple of dt = 0.0010000000474974513 s",
    ),
]


@pytest.mark.parametrize(("kwargs", "error", "message"), SIMULATE_CASES)
@pytest.mark.parametrize("loop", ["auto", "python"])
def test_simulate_refuses_bad_arguments(book: cd.Scene, kwargs: dict[str, Any], error: type, message: str, loop: str) -> None:
    """The same refusal, with the same message, from either loop (an integer beyond a C long once
    ran in the Python loop and failed in the compiled one)."""
    kwargs = {"t_final": 0.01, **kwargs}
    with pytest.raises(error, match=message):
        cd.simulate(book, **kwargs, loop=loop)


ACCURACY_CASES = [  # refused before the reference run, with simulate's own messages
    ({"max_steps": "x"}, r"max_steps must be an integer >= 1 or None \(no limit\), got 'x'"),
    ({"max_steps": -5}, r"max_steps must be an integer >= 1"),
    ({"progress": "yes"}, r"progress must be True or False"),
    ({"control_dt": 3e-3, "dt": 2e-3}, r"control_dt = 0.003 s must be a whole multiple of dt = 0.002 s"),
    ({"loop": "fast"}, r"loop must be one of"),
]


@pytest.mark.parametrize(("kwargs", "message"), ACCURACY_CASES)
def test_simulate_with_accuracy_refuses_bad_arguments_before_it_runs(
    book: cd.Scene, kwargs: dict[str, Any], message: str
) -> None:
    d1, d2 = cd.scenes.book_task()
    ran = []

    def controller(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:  # counts the reference's calls
        ran.append(t)
        return cd.scenes.drives_controller(d1, d2)(t, q, v)

    kwargs = {"dt": 1e-3, **kwargs}
    with pytest.raises(cd.SimulationError, match=message):
        cd.simulate(book, 0.02, controller, "trapezoid", accuracy=1.0, **kwargs)
    assert not ran  # nothing ran first


@pytest.mark.parametrize("loop", ["auto", "python"])
def test_a_step_below_h_min_stops_with_the_trajectory_so_far(book: cd.Scene, loop: str) -> None:
    """Tolerances no step above h_min meets: a StepSizeError (a StepBudgetError) carrying the run
    up to where the step control gave up, the same in both loops."""
    d1, d2 = cd.scenes.book_task()
    method = cd.integrators.DormandPrince(rtol=1e-14, atol=1e-30, h_min=1e-4)
    with pytest.raises(cd.StepSizeError, match=r"the step fell below h_min = 0.0001 s") as info:
        cd.simulate(book, 0.05, cd.scenes.drives_controller(d1, d2), method, 1e-3, loop=loop, accuracy_check="off")
    assert isinstance(info.value, cd.StepBudgetError)
    partial = info.value.result
    assert isinstance(partial, cd.Result) and partial.t[0] == 0.0 and partial.status == "stopped"


def test_a_complex_input_is_refused_not_silently_made_real(book: cd.Scene) -> None:
    """NumPy would drop the imaginary part with only a ComplexWarning; coopdyn refuses it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(cd.SceneError, match="must be real"):
            cd.simulate(book, 0.01, v0=np.zeros(3, dtype=complex))


CONTROLLER_CASES = [
    (lambda s: ObjectImpedance(s, stiffness=2000.0), r"stiffness must be a pair \(linear \[N/m\], angular \[N·m/rad\]\)"),
    (lambda s: ObjectImpedance(s, damping=("a", 1.0)), r"damping \(linear\) \[N·s/m\] must be numeric"),
    (lambda s: ObjectImpedance(s, null_stiffness=-1.0), r"null_stiffness must be >= 0"),
    (lambda s: ObjectImpedance(s, reference=3), r"reference must be a callable"),
    (lambda s: GravityCompensationPD(s, kp=[50] * 13), r"kp must be a scalar or one value per actuated joint \(14\)"),
    (lambda s: GravityCompensationPD(s, kd=-1.0), r"kd must be >= 0 \[N·m·s/rad\]"),
    (lambda s: GravityCompensationPD(s, kp=1j), r"kp \[N·m/rad\] must be real"),
    (lambda s: GravityCompensationPD("scene"), r"scene must be a coopdyn.Scene, got str"),
    (lambda s: ComputedTorque(s, kp=np.array([[1.0]])), r"kp must be a scalar or one value per actuated joint"),
    (lambda s: ComputedTorque(s, reference="hold"), r"reference must be a callable"),
]


@pytest.mark.parametrize(("make", "message"), CONTROLLER_CASES)
def test_controllers_validate_their_arguments(pandas: cd.Scene, make: Any, message: str) -> None:
    with pytest.raises(cd.SceneError, match=message):
        make(pandas)


TASK_CASES = [
    ({"t_grip": 0}, r"t_grip must be > 0 \[s\]"),
    ({"rotation": [1, 2, 3]}, r"rotation must have shape \(3, 3\)"),
    ({"lift": 10**400}, r"lift \[m\] must be within the float range"),
    ({"squeeze": "20"}, r"squeeze \[N\] must be numeric"),
    ({"frequency": True}, r"frequency must be numeric, got True"),
    ({"cycles": -1}, r"cycles must be >= 0"),
    ({"axis": [0, 0, 0]}, r"axis must not be zero"),
]


@pytest.mark.parametrize(("kwargs", "message"), TASK_CASES)
def test_grip_lift_oscillate_validates(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(cd.SceneError, match=message):
        GripLiftOscillate(start=(0.0, 0.0, 0.5), **kwargs)


def test_book_task_refuses_an_impossible_timeline_with_a_scene_error() -> None:
    """It raised a bare ValueError, and `not A and B` let t_grip > t_lift through."""
    with pytest.raises(cd.SceneError, match=r"0 < t_grip <= t_lift .*got t_grip = 2"):
        cd.scenes.book_task(t_grip=2.0)
    with pytest.raises(cd.SceneError, match=r"t_grip must be > 0"):
        cd.scenes.book_task(t_grip=0.0)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (b'[scene]\nbuilder = "linear_book"\n\xff\xfe = 1\n', r"line 3: not UTF-8 text \(byte 0xff"),
        (b"[scene]\nx = " + b"[" * 1000 + b"]" * 1000 + b"\n", r"nested too deeply"),
        (
            b'[scene]\nbuilder = "linear_book"\nm = ' + str(10**400).encode() + b"\n[simulation]\nduration = 1.0\n",
            r"m: must be a finite",
        ),
        (b'[scene]\nbuilder = "linear_book"\n[simulation]\nduration = 1.0\ndt = 1' + b"0" * 400 + b"\n", r"dt: must be a finite"),
    ],
)
def test_scene_file_text_errors(tmp_path: Path, text: bytes, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_bytes(text)
    with pytest.raises(cd.SceneError, match=message):
        load(path)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('[task]\ntype = "grip_lift_oscillate"\nt_grip = 0\n', r"\[task\]: GripLiftOscillate: t_grip must be > 0"),
        (
            '[task]\ntype = "grip_lift_oscillate"\nrotation = [1, 2, 3]\n',
            r"\[task\]: GripLiftOscillate: rotation must have shape",
        ),
        (
            '[controller]\ntype = "object_impedance"\nstiffness = 2000.0\n',
            r"\[controller\]: ObjectImpedance: stiffness must be a pair",
        ),
        ('[controller]\ntype = "gravity_pd"\nkp = -5.0\n', r"\[controller\]: GravityCompensationPD: kp must be >= 0"),
    ],
)
def test_scene_file_controller_and_task_errors_name_the_table(tmp_path: Path, table: str, message: str) -> None:
    text = (EXAMPLES / "two_pandas.toml").read_text()
    start = text.index("[controller]")
    end = text.index("[simulation]")
    path = tmp_path / "s.toml"
    path.write_text(text[:start] + table + text[end:])
    with pytest.raises(cd.SceneFileError, match=message):
        load(path)


def test_relative_output_folders_resolve_against_the_scene_file(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "s.toml"
    path.parent.mkdir()
    path.write_text((EXAMPLES / "linear_book.toml").read_text())
    assert load(path).output["folder"] == str((tmp_path / "sub" / "out" / "linear_book").resolve())


def test_an_arm_with_every_joint_locked_runs_or_is_refused(pandas: cd.Scene) -> None:
    """A fully locked arm holds the object like a fixture (tests/test_elements.py); ObjectImpedance,
    which commands the object through joints, refuses it (it crashed the compiled loop)."""
    from coopdyn.resources import urdf_path

    arm = cd.Arm("a", str(urdf_path("slider_z.urdf")), tip_frame="tip", locked_joints=["slide"])
    obj = cd.RigidObject.box(1.0, [0.1, 0.1, 0.1], joint="prismatic")
    scene = cd.Scene([arm], obj, [cd.Interconnection("a", stiffness=np.full(6, 1e3))])
    assert np.all(np.isfinite(cd.simulate(scene, 0.01).q))
    left, right = pandas.arm_specs
    held = {f"panda_joint{i}": float(x) for i, x in enumerate(left.q0, start=1)}
    locked = left.replace(q0=None, locked_joints=held | {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0})
    scene = cd.Scene([locked, right], pandas.object, pandas.interconnection_specs, gravity=pandas.gravity)
    with pytest.raises(cd.SceneError, match=r"every joint of \['left'\] is locked"):
        ObjectImpedance(scene)


def test_a_single_sample_result_reads_the_same_forces_on_both_backends(pandas: cd.Scene) -> None:
    """The native readouts read past a writeable (1, nq) input: t_final = 0 showed 1e83 N."""
    native = cd.simulate(pandas, 0.0, backend="native")
    python = cd.simulate(pandas, 0.0, backend="python")
    assert native.t.shape == (1,)
    np.testing.assert_allclose(native.wrenches(), python.wrenches(), atol=1e-9)
    assert np.max(np.abs(native.wrenches())) < 1e-6  # unloaded at the initial state


# --- runs that cannot finish ---------------------------------------------------------------


def test_adaptive_methods_have_a_step_budget() -> None:
    """dopri5 on a very stiff interconnection crawls (its step follows the fast mode): it stops at
    max_steps with the trajectory so far, for either loop."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e10)
    for loop in ("compiled", "python"):
        with pytest.raises(cd.StepBudgetError, match=r"dopri5 took [\d,]+ steps \(max_steps = 2,000\)") as info:
            cd.simulate(scene, 1.0, integrator="dopri5", loop=loop, max_steps=2000, energy_check="off")
        res = info.value.result
        assert res.status == "stopped" and 0 < res.t[-1] < 1.0 and res.n_steps + res.n_rejected >= 2000


def test_a_trajectory_too_large_for_memory_is_refused_with_a_save_every(pandas: cd.Scene) -> None:
    with pytest.raises(
        cd.SimulationError, match=r"about 1.82 GB, more than max_memory = 1 GB. Save fewer samples \(save_every = 2"
    ):
        cd.simulate(pandas, 1000.0, dt=1e-3, max_memory=1e9)
    with pytest.raises(cd.SimulationError, match=r"more than max_steps"):
        cd.simulate(pandas, 1e5, dt=1e-3, max_memory=None)


@pytest.mark.parametrize("loop", ["python", "compiled"])
def test_the_memory_estimate_bounds_a_runs_peak(book: cd.Scene, pandas: cd.Scene, loop: str) -> None:
    """simulate's memory estimate is an upper bound of what a run allocates (tracemalloc peak)."""
    import tracemalloc

    from coopdyn.budget import BYTES_PER_SAMPLE, BYTES_PER_VALUE

    for scene in (book, pandas):
        cd.simulate(scene, 0.01, loop=loop)  # imports and caches outside the measurement
        tracemalloc.start()
        try:
            res = cd.simulate(scene, 2.0, dt=1e-3, loop=loop, energy_check="off")
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        values = 1 + scene.nq + scene.nv + scene.n_actuated
        assert peak <= len(res.t) * (values * BYTES_PER_VALUE + BYTES_PER_SAMPLE)


# --- accuracy honesty ------------------------------------------------------------------------


def _accuracy_warnings(scene: cd.Scene, **kwargs: Any) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cd.simulate(scene, 0.004, controller=GravityCompensationPD(scene), **kwargs)
    return [str(w.message) for w in caught if issubclass(w.category, cd.AccuracyWarning)]


@pytest.mark.parametrize("method", ["implicit_euler", "ros2", "trapezoid"])
def test_an_unresolved_interconnection_mode_is_named_with_the_step_that_resolves_it(method: str) -> None:
    """The warning gives the force error found against dopri5, names the mode the screen blames,
    what the method does to it and a step at which the run is trusted; at that step it is quiet."""
    import re

    scene = cd.scenes.facing_arms("panda", stiffness=1e7)
    dt = 2e-3
    (message,) = _accuracy_warnings(scene, integrator=method, dt=dt)
    assert f"{method} at dt = {dt * 1e3:g} ms gets the interconnection forces of this 0.004 s run wrong by up to" in message
    assert "checked against dopri5" in message and "Hz mode" in message
    assert "of the largest grasp force per unit energy" in message
    trusted = float(re.search(r"Use dt ≤ ([0-9.e+-]+) ms", message).group(1)) * 1e-3
    assert trusted < dt and _accuracy_warnings(scene, integrator=method, dt=trusted) == []


@pytest.mark.parametrize(
    ("method", "stiffness", "dt", "wrong"),
    [  # (the force error each run has against dopri5 at rtol 1e-10, measured once: 15–85 % / below 1 %)
        ("implicit_euler", 1e4, 1e-4, True),  # 15 %: a 28 Hz grasp mode loses 0.04 % per step, 60 % over the run
        ("implicit_euler", 1e3, 1e-3, True),  # 30 %
        ("rk4", 1e6, 1e-3, True),  # 30 %: stable, but at the edge it damps the 286 Hz mode
        ("symplectic_euler", 1e6, 1e-3, True),  # 85 %: a phase error that accumulates
        ("rk4", 1e4, 1e-3, False),
        ("trapezoid", 1e3, 1e-4, False),
    ],
)
def test_a_run_whose_forces_are_wrong_over_its_length_warns(method: str, stiffness: float, dt: float, wrong: bool) -> None:
    """One step's loss can be small and the run's total (the object-impedance task, 0.5 s)."""
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance

    scene = cd.scenes.facing_arms("panda", stiffness=stiffness)
    controller = ObjectImpedance(scene, GripLiftOscillate(start=cd.scenes.object_start(scene), squeeze=20.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cd.simulate(scene, 0.5, controller=controller, integrator=method, dt=dt, energy_check="off")
    assert any(issubclass(w.category, cd.AccuracyWarning) for w in caught) == wrong


def _impedance_run(stiffness: float, **kwargs: Any) -> tuple[cd.Result, list[str]]:
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance

    scene = cd.scenes.facing_arms("panda", stiffness=stiffness)
    controller = ObjectImpedance(scene, GripLiftOscillate(start=cd.scenes.object_start(scene), squeeze=20.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = cd.simulate(scene, 0.5, controller=controller, energy_check="off", **kwargs)
    return res, [str(w.message) for w in caught if issubclass(w.category, cd.AccuracyWarning)]


def test_the_force_error_estimate_is_the_error_against_a_tight_reference(tmp_path: Path) -> None:
    """A run the screen cannot clear is checked against dopri5: the figure it reports is the
    force error a tight reference (rtol 1e-10) finds, to 1 %, and the warning quotes it."""
    from coopdyn.integrators import INTEGRATORS

    res, messages = _impedance_run(1e4, integrator="implicit_euler", dt=1e-3)
    ref, _ = _impedance_run(1e4, integrator=INTEGRATORS["dopri5"](rtol=1e-10, atol=1e-12), dt=1e-3, max_steps=None)
    error = float(np.max(np.linalg.norm(res.wrenches()[..., :3] - ref.wrenches()[..., :3], axis=-1)))
    assert res.force_error_estimate == pytest.approx(error, rel=0.01)
    (message,) = messages
    assert f"wrong by up to {res.force_error_estimate:.4g} N" in message
    assert cd.Result.load(res.save(tmp_path / "r.npz")).force_error_estimate == res.force_error_estimate


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_an_error_controlled_explicit_pair_is_not_judged(method: str) -> None:
    """Its steps are chosen for its error, and being explicit it cannot step over a mode: no
    screen, no second run, even on stiff grasps at a loose tolerance."""
    from coopdyn.integrators import INTEGRATORS

    res, messages = _impedance_run(1e5, integrator=INTEGRATORS[method](rtol=1e-3, atol=1e-6), dt=1e-2)
    assert res.force_error_estimate is None and messages == []


def test_the_accuracy_check_can_be_limited_to_the_screen_or_turned_off() -> None:
    res, messages = _impedance_run(1e5, integrator="implicit_euler", dt=2e-3, accuracy_check="screen")
    (message,) = messages
    assert res.force_error_estimate is None and "not checked against a reference run: accuracy_check='screen'" in message
    res, messages = _impedance_run(1e5, integrator="implicit_euler", dt=2e-3, accuracy_check="off")
    assert res.force_error_estimate is None and messages == []
    with pytest.raises(cd.SimulationError, match=r"accuracy_check must be one of \['auto', 'screen', 'off'\], got 'yes'"):
        _impedance_run(1e5, integrator="implicit_euler", dt=2e-3, accuracy_check="yes")


def test_the_trapezoid_ringing_on_a_stiff_overdamped_mode_is_reported() -> None:
    """The trapezoid keeps a stiff non-oscillating mode's amplitude, flipping its sign each step
    (R(−∞) = −1): with D = 0.002·K at k = 1e7 the grasp modes are overdamped, and at 5 ms the
    run's forces are off by ~40 %. The screen names a non-oscillating mode."""
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance

    scene = cd.scenes.facing_arms("panda", stiffness=1e7, damping=0.002)
    controller = ObjectImpedance(scene, GripLiftOscillate(start=cd.scenes.object_start(scene), squeeze=20.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cd.simulate(scene, 0.5, controller=controller, integrator="trapezoid", dt=5e-3, energy_check="off")
    (message,) = [str(w.message) for w in caught if issubclass(w.category, cd.AccuracyWarning)]
    assert "non-oscillating mode (time constant" in message


def test_resolved_modes_stay_quiet(pandas: cd.Scene) -> None:
    assert _accuracy_warnings(pandas, integrator="trapezoid", dt=1e-3) == []
    assert _accuracy_warnings(pandas, integrator="rk4", dt=1e-3) == []  # explicit: stability is its check


def test_advise_reports_accuracy_next_to_stability() -> None:
    scene = cd.scenes.facing_arms("panda", stiffness=1e6)
    advice = cd.advise(scene, controller=GravityCompensationPD(scene), dt=2e-3)
    assert advice.max_resolved_dt == pytest.approx(1.0 / advice.oscillation.rate)
    assert advice.oscillation.frequency == pytest.approx(286.1, abs=0.5)
    assert "does not resolve the 286.1 Hz mode" in advice.recommendation
    assert "accuracy: the fastest oscillatory mode (286.1 Hz" in str(advice)


# --- interrupts and faults ----------------------------------------------------------------------


def _interrupt_after(seconds: float) -> threading.Timer:
    timer = threading.Timer(seconds, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    return timer


@pytest.mark.parametrize("loop", ["python", "compiled"])
def test_ctrl_c_at_random_moments_always_gives_a_consistent_result(book: cd.Scene, loop: str) -> None:
    """SIGINT at 12 random wall-clock moments: never another exception, and the partial result is
    whole (equal lengths, finite, torques filled; empty only when the message says the interrupt
    came before the first sample, e.g. while the compiled loop was being prepared)."""
    rng = np.random.default_rng(7)
    seen = 0
    for delay in rng.uniform(0.005, 0.15, 12):
        timer = None
        try:
            timer = _interrupt_after(float(delay))
            try:
                cd.simulate(book, 0.5, integrator="rk4", dt=1e-5, loop=loop, max_steps=None, energy_check="off")
            except cd.SimulationInterrupted as exc:
                res = exc.result
                n = len(res.t)
                assert res.q.shape[0] == res.v.shape[0] == res.tau.shape[0] == n
                assert n >= 1 or "before the first sample" in str(exc)
                assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.tau))
                seen += 1
            timer.join()
            time.sleep(0.02)
        except KeyboardInterrupt:  # the timer fired outside the run: not this test's subject
            if timer is not None:
                timer.join()
    assert seen >= 6


def test_a_ctrl_c_after_the_last_step_keeps_the_completed_run(book: cd.Scene) -> None:
    module = sys.modules["coopdyn.stepping"]

    original = module._Run.result
    calls = []

    def interrupted_once(self: Any, status: str = "completed") -> Any:
        if not calls:
            calls.append(status)
            raise KeyboardInterrupt
        return original(self, status)

    module._Run.result = interrupted_once  # type: ignore[method-assign]
    try:
        with pytest.raises(cd.SimulationInterrupted) as info:
            cd.simulate(book, 0.05, loop="python")
    finally:
        module._Run.result = original  # type: ignore[method-assign]
    assert info.value.result.status == "completed" and info.value.result.t[-1] == 0.05


def _result(book: cd.Scene) -> cd.Result:
    return cd.simulate(book, 0.02)


def test_outputs_replace_the_folder_whole_and_keep_the_trajectory_when_a_plot_fails(book: cd.Scene, tmp_path: Path) -> None:
    res = _result(book)
    out = tmp_path / "run"
    out.mkdir()
    (out / "plot.png").write_text("from an earlier run")

    def bad_plot(folder: Path) -> Path:
        raise RuntimeError("no display")

    done = write_outputs(out, [("trajectory", lambda f: res.save(f / "trajectory.npz"))], [("plot", bad_plot)])
    assert sorted(p.name for p in out.iterdir()) == ["trajectory.npz"]  # the old plot went with the old run
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~mask  # a folder like mkdir makes, not a private one
    assert done.problems == ("plot: RuntimeError: no display",)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging or .tmp left


def test_a_ctrl_c_while_writing_outputs_waits_for_them(book: cd.Scene, tmp_path: Path) -> None:
    """A (second) Ctrl-C during the writing cannot cut it: the folder is finished and put in
    place, then the interrupt is raised."""
    res = _result(book)

    def trajectory(folder: Path) -> Path:
        os.kill(os.getpid(), signal.SIGINT)  # arrives in the middle of the writing
        time.sleep(0.05)
        return res.save(folder / "trajectory.npz")

    with pytest.raises(KeyboardInterrupt, match="the writing was finished first"):
        write_outputs(tmp_path / "run", [("trajectory", trajectory)], [("csv", lambda f: res.save(f / "trajectory.csv"))])
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["trajectory.csv", "trajectory.npz"]


def test_a_folder_with_foreign_files_is_not_replaced(book: cd.Scene, tmp_path: Path) -> None:
    (tmp_path / "thesis.tex").write_text("mine")
    with pytest.raises(cd.OutputError, match=r"holds files coopdyn did not write \(thesis.tex\).*The trajectory was saved to"):
        write_outputs(tmp_path, [("trajectory", lambda f: _result(book).save(f / "trajectory.npz"))])
    assert (tmp_path / "thesis.tex").read_text() == "mine"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_saves_the_trajectory_elsewhere_and_says_where(book: cd.Scene, tmp_path: Path) -> None:
    res = _result(book)
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        with pytest.raises(cd.OutputError, match=r"cannot write to .*locked.*The trajectory was saved to (\S+) instead") as info:
            write_outputs(locked / "run", [("trajectory", lambda f: res.save(f / "trajectory.npz"))])
    finally:
        locked.chmod(stat.S_IRWXU)
    rescued = Path(str(info.value).split("saved to ")[1].split(" instead")[0])
    with np.load(rescued) as z:
        assert np.array_equal(z["q"], res.q)


def test_a_read_only_file_system_saves_the_trajectory_elsewhere(book: cd.Scene, tmp_path: Path, monkeypatch: Any) -> None:
    """The same as root, who may write into read-only folders: the staging folder cannot be made."""
    import tempfile

    res = _result(book)
    real_mkdtemp = tempfile.mkdtemp

    def read_only(*args: Any, **kwargs: Any) -> str:
        if Path(kwargs.get("dir") or tempfile.gettempdir()) == tmp_path:
            raise OSError(30, "Read-only file system", str(tmp_path))
        return real_mkdtemp(*args, **kwargs)

    monkeypatch.setattr(tempfile, "mkdtemp", read_only)
    with pytest.raises(cd.OutputError, match=r"Read-only file system .*The trajectory was saved to .*coopdyn-rescue-"):
        write_outputs(tmp_path / "run", [("trajectory", lambda f: res.save(f / "trajectory.npz"))])


def test_disk_full_while_writing_cleans_up_and_rescues(book: cd.Scene, tmp_path: Path, monkeypatch: Any) -> None:
    res = _result(book)
    real_savez = np.savez
    failed = []

    def full(file: Any, *args: Any, **kwargs: Any) -> None:
        if not failed:  # the first write fails (disk full), the rescue's succeeds
            failed.append(1)
            raise OSError(28, "No space left on device")
        real_savez(file, *args, **kwargs)

    monkeypatch.setattr(np, "savez", full)
    with pytest.raises(cd.OutputError, match=r"No space left on device.*The trajectory was saved to"):
        write_outputs(tmp_path / "run", [("trajectory", lambda f: res.save(f / "trajectory.npz"))])
    assert list(tmp_path.iterdir()) == []  # no half-written folder, no .tmp


CLI_WRITER = r"""
import sys, time
import coopdyn.outputs as outputs
from coopdyn.__main__ import main
real = outputs._publish
def slow(staging, target):
    print("PUBLISHING", flush=True)
    time.sleep(float(sys.argv[2]))
    real(staging, target)
outputs._publish = slow
sys.exit(main(["simulate", sys.argv[1], "--out", sys.argv[3]]))
"""


def _scene_file(tmp_path: Path, duration: float) -> Path:
    text = (EXAMPLES / "linear_book.toml").read_text()
    text = text.replace("duration = 3.0", f"duration = {duration}").replace("plot = true", "plot = false")
    path = tmp_path / "book.toml"
    path.write_text(text)
    return path


def _cli(tmp_path: Path, *args: str) -> subprocess.Popen[str]:
    script = tmp_path / "writer.py"
    script.write_text(CLI_WRITER)
    return subprocess.Popen(
        [sys.executable, str(script), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint
    )


def test_kill_9_while_the_cli_writes_leaves_the_old_run_or_the_new_never_a_mix(tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = _cli(tmp_path, str(_scene_file(tmp_path, 0.1)), "0", str(out))
    assert first.wait(120) == 0, first.stderr.read()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    second = _cli(tmp_path, str(_scene_file(tmp_path, 0.2)), "30", str(out))
    assert second.stdout.readline().strip() == "PUBLISHING"
    second.kill()
    second.wait()
    after = {p.name: p.read_bytes() for p in out.iterdir()}
    assert after == before  # the old run, whole
    assert b"duration = 0.1" in after["scene.toml"]


def test_ctrl_c_while_the_cli_writes_finishes_the_writing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = _cli(tmp_path, str(_scene_file(tmp_path, 0.2)), "1", str(out))
    assert proc.stdout.readline().strip() == "PUBLISHING"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    with np.load(out / "trajectory.npz") as z:
        assert z["t"][-1] == pytest.approx(0.2)  # the completed run is in place
    assert "Traceback" not in err


# --- property-based: controllers, tasks and simulate --------------------------------------------

junk = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=4),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.complex_numbers(max_magnitude=1e3),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=15),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
    st.just(np.array([object()])),
)


def _maybe(valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    return st.integers(0, 3).flatmap(lambda i: junk if i == 0 else valid)


SIMULATE_ARGS = {
    "t_final": _maybe(st.floats(min_value=0.0, max_value=0.02)),
    "dt": _maybe(st.sampled_from([1e-4, 1e-3, 5e-3])),
    "integrator": _maybe(st.sampled_from(["rk4", "implicit_euler", "dopri5", "exponential", "trapezoid"])),
    "save_every": _maybe(st.integers(1, 5)),
    "max_speed": _maybe(st.floats(min_value=1.0, max_value=1e4)),
    "energy_check": _maybe(st.sampled_from(["warn", "off", "raise"])),
    "loop": _maybe(st.sampled_from(["auto", "python", "compiled"])),
    "q0": _maybe(st.lists(st.floats(min_value=0.1, max_value=0.3), min_size=3, max_size=3)),
    "controller": _maybe(
        st.sampled_from(
            [
                None,
                _zero,
                lambda t, q, v: "x",
                lambda t, q, v: np.full(2, np.nan),
                lambda t, q, v: np.zeros(3),
                lambda t, q, v: None,
            ]
        )
    ),
}


def _check_simulate(book: cd.Scene, kwargs: dict[str, Any]) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = cd.simulate(book, **kwargs)
        except cd.CoopdynError:
            return
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.v))


FUZZ = {"deadline": None, "database": None, "suppress_health_check": [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]}


@settings(max_examples=300, derandomize=True, **FUZZ)
@given(kwargs=st.fixed_dictionaries({}, optional=SIMULATE_ARGS))
def test_simulate_gives_a_result_or_a_coopdyn_error(book: cd.Scene, kwargs: dict[str, Any]) -> None:
    _check_simulate(book, {"t_final": 0.01, **kwargs})


TASK_ARGS = {
    name: _maybe(st.floats(min_value=0.01, max_value=2.0))
    for name in ("squeeze", "t_grip", "lift", "t_lift", "lift_duration", "amplitude", "frequency", "cycles", "t_osc")
}
TASK_ARGS["axis"] = _maybe(st.lists(st.floats(min_value=-1, max_value=1), min_size=3, max_size=3))
TASK_ARGS["rotation"] = _maybe(st.just(np.eye(3)))
CONTROLLER_ARGS = {
    "stiffness": _maybe(st.tuples(st.floats(0, 5e3), st.floats(0, 200))),
    "damping": _maybe(st.tuples(st.floats(0, 200), st.lists(st.floats(0, 10), min_size=3, max_size=3))),
    "joint_damping": _maybe(st.floats(0, 10)),
    "null_stiffness": _maybe(st.floats(0, 50)),
}


@settings(max_examples=150, derandomize=True, **FUZZ)
@given(task=st.fixed_dictionaries({}, optional=TASK_ARGS), ctrl=st.fixed_dictionaries({}, optional=CONTROLLER_ARGS))
def test_object_impedance_and_its_task_give_a_result_or_a_coopdyn_error(
    pandas: cd.Scene, task: dict[str, Any], ctrl: dict[str, Any]
) -> None:
    try:
        controller = ObjectImpedance(pandas, GripLiftOscillate(start=object_start(pandas), **task), **ctrl)
        res = cd.simulate(pandas, 0.005, controller=controller, integrator="implicit_euler", energy_check="off")
    except cd.CoopdynError:
        return
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.tau))


@settings(max_examples=150, derandomize=True, **FUZZ)
@given(kp=junk | st.floats(0, 100), kd=junk | st.floats(0, 10), which=st.sampled_from([GravityCompensationPD, ComputedTorque]))
def test_joint_controllers_give_a_result_or_a_coopdyn_error(pandas: cd.Scene, kp: Any, kd: Any, which: type) -> None:
    try:
        res = cd.simulate(pandas, 0.005, controller=which(pandas, kp=kp, kd=kd), integrator="implicit_euler", energy_check="off")
    except cd.CoopdynError:
        return
    assert np.all(np.isfinite(res.q))


# --- the viewer's server --------------------------------------------------------------------------


def _listening(port: int) -> list[str]:
    """Local addresses (hex, as in /proc/net/tcp*) listening on ``port``."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not os.path.exists(table):
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hexport = local.rsplit(":", 1)
            if state == "0A" and int(hexport, 16) == port:
                found.append(address)
    return found


VIEWER = r"""
import logging, sys
logging.basicConfig(level=logging.INFO, stream=sys.stderr)
import coopdyn as cd
from coopdyn.viz.viewer import view
res = cd.simulate(cd.scenes.linear_book(), 0.05)
view(res, fps=5)
"""


@pytest.mark.skipif(not os.path.exists("/proc/net/tcp"), reason="reads /proc/net/tcp")
def test_the_viewer_serves_on_loopback_only_and_stops_with_sigterm(tmp_path: Path) -> None:
    pytest.importorskip("meshcat")
    script = tmp_path / "viewer.py"
    script.write_text(VIEWER)
    proc = subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint
    )
    try:
        deadline = time.monotonic() + 60
        url = None
        while url is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            if "meshcat viewer at" in line:
                url = line.split("meshcat viewer at ")[1].split()[0]
            elif not line and proc.poll() is not None:
                break
        assert url is not None, proc.stderr.read()
        port = int(url.split(":")[2].split("/")[0])
        addresses = _listening(port)
        assert addresses and all(a in ("0100007F", "0000000000000000FFFF00000100007F") for a in addresses), addresses
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
        deadline = time.monotonic() + 10
        while _listening(port) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert _listening(port) == []  # the server went with the viewer
    finally:
        if proc.poll() is None:
            proc.kill()


# --- streaming to disk --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("loop", "integrator"), [("compiled", "rk4"), ("python", "rk4"), ("compiled", "dopri5"), ("python", "dopri5")]
)
def test_a_streamed_run_equals_the_run_in_memory(book: cd.Scene, tmp_path: Path, loop: str, integrator: str) -> None:
    """3001 samples (more than one batch of 1024 and several compiled chunks) go to .npy files."""
    controller = cd.scenes.drives_controller(*cd.scenes.book_task())
    kwargs = {"controller": controller, "integrator": integrator, "dt": 1e-3, "loop": loop}
    memory = cd.simulate(book, 3.0, **kwargs)
    streamed = cd.simulate(book, 3.0, stream_to=tmp_path / "run", **kwargs)
    assert isinstance(streamed.q, np.memmap) and len(streamed.t) == len(memory.t) == 3001
    for name in ("t", "q", "v", "tau"):
        np.testing.assert_array_equal(getattr(streamed, name), getattr(memory, name))
        assert np.load(tmp_path / "run" / f"{name}.npy").shape == getattr(memory, name).shape
    np.testing.assert_array_equal(streamed.wrench(0), memory.wrench(0))


def test_a_streamed_run_that_stops_early_leaves_files_of_what_it_made(book: cd.Scene, tmp_path: Path) -> None:
    drives = cd.scenes.drives_controller(*cd.scenes.book_task())

    def controller(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.array([1e9, -1e9]) if t > 1.5 else drives(t, q, v)  # it blows up after 1.5 s

    with pytest.raises(cd.DivergenceError) as info:
        cd.simulate(book, 3.0, controller=controller, integrator="rk4", dt=1e-3, stream_to=tmp_path / "run")
    partial = info.value.result
    assert 1.4 < partial.t[-1] < 3.0 and len(partial.t) > 1024  # more than one batch went to disk
    np.testing.assert_array_equal(np.load(tmp_path / "run" / "t.npy"), partial.t)


def test_streaming_refuses_a_folder_in_use(book: cd.Scene, tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(cd.SimulationError, match=r"must be a new or empty folder"):
        cd.simulate(book, 0.01, stream_to=tmp_path)


# --- package:// meshes -----------------------------------------------------------------------------

STL = """solid t
facet normal 0 0 1
outer loop
vertex 0 0 0
vertex 0.05 0 0
vertex 0 0.05 0
endloop
endfacet
endsolid t
"""


def test_package_meshes_resolve_only_against_the_given_package_dirs(tmp_path: Path) -> None:
    """A URDF at pkgs/mypkg/urdf/ naming package://mypkg/... is not resolved by walking up its
    parent folders (which could reach anything on the disk), only through package_dirs."""
    from coopdyn.model.arm import load_arm
    from coopdyn.resources import urdf_path

    pkg = tmp_path / "pkgs" / "mypkg"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    (pkg / "meshes" / "plate.stl").write_text(STL)
    text = (
        urdf_path("slider_z.urdf")
        .read_text()
        .replace(
            '<geometry><box size="0.04 0.04 0.01"/></geometry>',
            '<geometry><mesh filename="package://mypkg/meshes/plate.stl"/></geometry>',
        )
    )
    urdf = pkg / "urdf" / "robot.urdf"
    urdf.write_text(text)
    with pytest.raises(cd.ModelLoadError, match="could not load the visual geometry"):
        load_arm(cd.Arm("a", urdf, tip_frame="tip"), meshes="visual")
    loaded = load_arm(cd.Arm("a", urdf, tip_frame="tip", package_dirs=[tmp_path / "pkgs"]), meshes="visual")
    assert loaded.visual is not None and loaded.visual.ngeoms == 1


# --- the 10 000-case fuzz run (slow) ----------------------------------------------------------------
# With `-m slow`, not derandomized (a new sample every run): 3 000 simulate calls, 2 000 object
# impedance runs, 1 000 joint-controller runs here, and tests/test_robustness.py's scene builder
# (2 000) and scene files (2 000).


@pytest.mark.slow
@settings(max_examples=3000, derandomize=False, **FUZZ)
@given(kwargs=st.fixed_dictionaries({}, optional=SIMULATE_ARGS))
def test_simulate_fuzz_thousands(book: cd.Scene, kwargs: dict[str, Any]) -> None:
    _check_simulate(book, {"t_final": 0.01, **kwargs})


@pytest.mark.slow
@settings(max_examples=2000, derandomize=False, **FUZZ)
@given(task=st.fixed_dictionaries({}, optional=TASK_ARGS), ctrl=st.fixed_dictionaries({}, optional=CONTROLLER_ARGS))
def test_object_impedance_fuzz_thousands(pandas: cd.Scene, task: dict[str, Any], ctrl: dict[str, Any]) -> None:
    test_object_impedance_and_its_task_give_a_result_or_a_coopdyn_error.hypothesis.inner_test(pandas, task, ctrl)


@pytest.mark.slow
@settings(max_examples=1000, derandomize=False, **FUZZ)
@given(kp=junk | st.floats(0, 100), kd=junk | st.floats(0, 10), which=st.sampled_from([GravityCompensationPD, ComputedTorque]))
def test_joint_controllers_fuzz_thousands(pandas: cd.Scene, kp: Any, kd: Any, which: type) -> None:
    test_joint_controllers_give_a_result_or_a_coopdyn_error.hypothesis.inner_test(pandas, kp, kd, which)


def test_sigint_at_random_moments_of_a_cli_run_saves_what_it_had(tmp_path: Path) -> None:
    """`coopdyn simulate` in a subprocess, SIGINT at random moments once coopdyn is imported
    (loading the scene, stepping, writing): exit code 130 (or 0 if it had finished), never a
    traceback, and the output folder holds one whole run — the partial trajectory with its
    diagnosis, or the finished one."""
    scene = _scene_file(tmp_path, 200.0)
    scene.write_text(
        scene.read_text().replace('integrator = "exponential"', 'integrator = "rk4"').replace("dt = 1e-3", "dt = 1e-4")
    )
    rng = np.random.default_rng(11)
    starter = "import sys, coopdyn.__main__ as m; print('READY', flush=True); sys.exit(m.main(sys.argv[1:]))"
    for k, delay in enumerate(rng.uniform(0.0, 4.0, 4)):
        out = tmp_path / f"out{k}"
        proc = subprocess.Popen(
            [sys.executable, "-c", starter, "simulate", str(scene), "--out", str(out)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=default_sigint,
        )
        assert proc.stdout is not None and proc.stdout.readline().strip() == "READY"
        time.sleep(float(delay))
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode in (0, 130), err
        assert "Traceback" not in err
        if out.exists():
            names = {p.name for p in out.iterdir()}
            assert "trajectory.npz" in names and ("diagnosis.txt" in names or "scene.toml" in names)
            with np.load(out / "trajectory.npz") as z:
                assert z["q"].shape[0] == z["t"].shape[0] >= 1
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(f".out{k}.")]  # no staging left


# --- found in review ---------------------------------------------------------------------------


def test_a_folder_with_foreign_files_is_refused_before_the_run(tmp_path: Path) -> None:
    """The check comes first: no simulation is thrown away at output time."""
    from coopdyn.io.scenefile import run

    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(cd.OutputError, match="holds files coopdyn did not write"):
        run(load(_scene_file(tmp_path, 0.1)), folder=out, progress=False)


def test_stale_cleanup_only_removes_what_a_dead_run_left(book: cd.Scene, tmp_path: Path) -> None:
    res = _result(book)
    keep = [tmp_path / ".out.old-backup", tmp_path / ".run1.old-1-2", tmp_path / ".out.writing-notes"]
    for p in keep:
        p.mkdir()
    dead = tmp_path / ".out.old-999999999-5"  # no such process
    dead.mkdir()
    write_outputs(tmp_path / "out", [("trajectory", lambda f: res.save(f / "trajectory.npz"))])
    assert all(p.is_dir() for p in keep) and not dead.exists()
    write_outputs(tmp_path / "run[12]", [("trajectory", lambda f: res.save(f / "trajectory.npz"))])
    assert (tmp_path / ".run1.old-1-2").is_dir()  # a glob pattern in the name matches nothing else


def test_outputs_refuse_the_working_folder(book: cd.Scene, tmp_path: Path, monkeypatch: Any) -> None:
    monkeypatch.chdir(tmp_path)
    for folder in (".", tmp_path.parent):
        with pytest.raises(cd.OutputError, match="is the working folder or holds it"):
            write_outputs(folder, [("trajectory", lambda f: _result(book).save(f / "trajectory.npz"))])
    assert Path.cwd() == tmp_path


def test_a_streamed_run_stopped_by_any_error_leaves_cut_files(book: cd.Scene, tmp_path: Path) -> None:
    def controller(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        if t > 0.4:
            raise RuntimeError("sensor lost")
        return np.zeros(2)

    with pytest.raises(cd.ControllerError, match="sensor lost"):
        cd.simulate(book, 0.5, controller=controller, integrator="rk4", dt=1e-4, stream_to=tmp_path / "run", loop="python")
    t = np.load(tmp_path / "run" / "t.npy")
    assert 0.39 < t[-1] <= 0.4 and np.all(np.diff(t) > 0)  # cut where it stopped, no padding


def test_a_user_a_stable_integrator_without_a_stability_function_still_runs(book: cd.Scene) -> None:
    from coopdyn.integrators import LinearlyImplicitEuler

    class Mine(LinearlyImplicitEuler):
        name = "mine"

        def stability_function(self, z: np.ndarray) -> np.ndarray:
            raise NotImplementedError("mine has no scalar stability function")

    assert cd.simulate(book, 0.01, integrator=Mine(), dt=1e-2).status == "completed"


@pytest.mark.parametrize("loop", ["compiled", "python"])
def test_the_step_budget_is_exact(pandas: cd.Scene, loop: str) -> None:
    with pytest.raises(cd.StepBudgetError) as info:
        cd.simulate(pandas, 1.0, dt=0.1, integrator="dopri5", loop=loop, max_steps=101, energy_check="off")
    res = info.value.result
    assert 101 <= res.n_steps + res.n_rejected <= 102


def test_an_ignored_sigint_stays_ignored() -> None:
    from coopdyn._signals import interrupts_deferred

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with interrupts_deferred():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_gains_that_raise_or_come_as_one_array(pandas: cd.Scene) -> None:
    class Broken:
        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            return np.zeros(pandas.n_actuated)

        def gains(self) -> np.ndarray:
            raise RuntimeError("not tuned")

    with pytest.raises(cd.ControllerError, match=r"gains\(\) raised RuntimeError: not tuned"):
        cd.simulate(pandas, 0.01, controller=Broken())

    class Stacked(Broken):
        def gains(self) -> np.ndarray:
            return np.vstack([np.full(pandas.n_actuated, 50.0), np.full(pandas.n_actuated, 5.0)])

    assert cd.simulate(pandas, 0.01, controller=Stacked(), integrator="implicit_euler").status == "completed"


@pytest.mark.parametrize(("bad", "gain"), [(np.nan, "Kp"), (np.inf, "Kd"), (-np.inf, "Kp"), (1e200, None)])
def test_gains_that_are_not_finite_are_named(pandas: cd.Scene, bad: float, gain: str | None) -> None:
    """A NaN or infinite gain is named; a huge finite one (its squares overflow the quick check)
    is a gain like any other, which the step matrix then judges; no numpy warning on the way."""
    from coopdyn.closed_loop import _checked_gains

    n = pandas.n_actuated
    kp, kd = np.full(n, 50.0), np.full(n, 5.0)
    (kd if gain == "Kd" else kp)[3] = bad
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        if gain is None:
            assert _checked_gains((kp, kd), n)[0][3] == bad
        else:
            with pytest.raises(cd.ControllerError, match=rf"gains\(\) {gain} \[.*\] must be finite"):
                _checked_gains((kp, kd), n)


def test_the_viewer_refuses_ipv6_hosts_up_front() -> None:
    from coopdyn.viz.meshcat_server import check_host

    with pytest.raises(cd.ViewerError, match="IPv4 addresses or host names only"):
        check_host("::1")
    assert check_host("127.0.0.1") == "127.0.0.1"


def test_exact_numbers_are_accepted() -> None:
    from decimal import Decimal
    from fractions import Fraction

    task = GripLiftOscillate(start=(0.0, 0.0, 0.5), squeeze=Fraction(41, 2), lift=Decimal("0.1"))
    assert task(10.0).squeeze == pytest.approx(20.5)


def test_a_calm_run_of_an_unstable_loop_is_called_what_it_is() -> None:
    """The message logic: a reference that diverged, or whose forces grow to dwarf the run's,
    says the closed loop is unstable when resolved and the calm is the integrator's; a
    reference that is merely larger (an oscillation the run damped away, not growing) does not
    claim instability."""
    from coopdyn import accuracy
    from coopdyn.closed_loop import System
    from coopdyn.control import GravityCompensationPD as PD
    from coopdyn.dynamics import Dynamics
    from coopdyn.integrators import AdaptiveROS2, get_integrator

    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    s = accuracy.screen(System(Dynamics(scene), PD(scene)), scene.q0, scene.v0 + 0.3, get_integrator("implicit_euler"), 5e-3, 1.0)
    ref = AdaptiveROS2(rtol=1e-4, atol=1e-7)
    diverged = accuracy.checked_message(s, 50.0, 60.0, ref, stopped=("ros2_adaptive diverged", 0.4, True), own_peak=5.0)
    assert diverged is not None and "first 0.4 s" in diverged and "reference, which resolves the modes, diverged" in diverged
    assert "most likely unstable" in diverged
    grew = accuracy.checked_message(s, 50.0, 60.0, ref, own_peak=5.0, growth=8.0)
    assert grew is not None and "forces growing to 60 N where this run's stay below 5 N" in grew
    damped = accuracy.checked_message(s, 50.0, 60.0, ref, own_peak=5.0, growth=1.0)
    assert damped is not None and "unstable" not in damped


@pytest.mark.slow
def test_the_old_flexible_beam_setting_is_flagged_as_an_unstable_loop() -> None:
    """The flexible-beam example's former setting — gains 500 N/m, 30 N·s/m fed back at the strip's
    middle node — under implicit Euler at 1 ms: a calm 5 N run whose resolved reference grows to
    ~90 N before its step budget runs out. The warning says the loop is unstable when resolved
    (it used to pass silently), with the growing mode of its exact linearisation."""
    from coopdyn.scenes import held_beam, object_start

    scene = held_beam()
    task = GripLiftOscillate(start=object_start(scene), squeeze=5.0, amplitude=0.02, frequency=1.5, axis=(0.0, 0.0, 1.0))
    ctrl = ObjectImpedance(scene, task, stiffness=(500.0, 10.0), damping=(30.0, 0.5), measure="object")
    said = r"most likely unstable once its fast modes are resolved(.|\n)*Hz mode growing at"
    with pytest.warns(cd.AccuracyWarning, match=said):
        res = cd.simulate(scene, 5.0, controller=ctrl, integrator="implicit_euler", dt=1e-3, save_every=10)
    assert np.abs(res.wrenches()[..., :3]).max() < 10.0  # (the calm the integrator drew)


@pytest.mark.parametrize("loop", ["compiled", "python"])
@pytest.mark.parametrize("wrapped", [False, True], ids=["built-in", "python-callable"])
def test_a_trial_stage_that_flings_the_grasps_together_is_a_rejected_attempt(loop: str, wrapped: bool) -> None:
    """dop853's first 10 ms trial step on grasps of 1e7 N/m drives a stage so far that the grasp
    points meet (no squeeze direction): the attempt is rejected and the step shrinks, as for a
    non-finite error — in both loops, with the built-in controller and with a user's Python
    callable that calls it; before, its SceneError stopped the run at t = 0."""
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.integrators import INTEGRATORS

    scene = cd.scenes.facing_arms("panda", stiffness=1e7, damping=0.002)
    impedance = ObjectImpedance(scene, GripLiftOscillate(start=cd.scenes.object_start(scene), squeeze=20.0))
    controller = (lambda t, q, v: impedance(t, q, v)) if wrapped else impedance
    integrator = INTEGRATORS["dop853"](rtol=1e-3, atol=1e-6)
    res = cd.simulate(scene, 0.01, controller=controller, integrator=integrator, dt=0.01, loop=loop, accuracy_check="off")
    assert res.loop == loop and res.n_rejected >= 1 and np.all(np.isfinite(res.q))


def test_coinciding_grasp_points_are_a_grasp_geometry_error_and_a_scene_error() -> None:
    """The error the adaptive loops take for a rejected attempt is its own class, still a SceneError
    for whoever caught that before."""
    from coopdyn.errors import GraspGeometryError
    from coopdyn.grasp import squeeze_directions

    with pytest.raises(GraspGeometryError, match="grasp points coincide with their centroid") as info:
        squeeze_directions(np.zeros((2, 3)))
    assert isinstance(info.value, cd.SceneError)
