"""simulate(..., accuracy=N): the step chosen for the force error a user asks, checked against a
reference it did not use, and the requests it cannot serve refused with the reason."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.errors import SimulationError
from coopdyn.integrators import DormandPrince
from coopdyn.scenes import object_start

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


@pytest.fixture(scope="module")
def demo() -> tuple[cd.Scene, ObjectImpedance]:
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    return scene, ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0))


def test_the_step_is_halved_until_the_forces_are_within_the_accuracy(
    demo: tuple[cd.Scene, ObjectImpedance], capsys: pytest.CaptureFixture[str]
) -> None:
    """The demo's first second under the trapezoid from 5 ms: each request gets the largest step
    of 5 ms / 2^k whose forces are within it of a dopri5 run at rtol 1e-11 (independent of the
    rtol 1e-9 reference simulate used), and the error falls at the method's order (÷4 per halving)."""
    scene, controller = demo
    truth = cd.simulate(
        scene, 1.0, controller=controller, integrator=DormandPrince(rtol=1e-11, atol=1e-14), dt=5e-3,
        accuracy_check="off", energy_check="off",
    )  # fmt: skip
    chosen = {}
    for tolerance in (1.0, 0.1, 0.01):
        res = cd.simulate(scene, 1.0, controller=controller, integrator="trapezoid", dt=5e-3, accuracy=tolerance, progress=True)
        error = float(np.max(np.linalg.norm(res.wrenches()[..., :3] - truth.wrenches()[..., :3], axis=-1)))
        assert res.force_error_estimate is not None and res.force_error_estimate <= tolerance
        assert error <= tolerance and error == pytest.approx(res.force_error_estimate, rel=1e-3)
        assert res.cpu_time > 0.0  # (the whole search's)
        assert len(res.t) == len(truth.t)  # (the saved grid kept while the step halves)
        chosen[tolerance] = res.dt
    assert chosen[1.0] > chosen[0.1] > chosen[0.01] and all(5e-3 / dt in (2, 4, 8, 16, 32) for dt in chosen.values())
    # the largest such step: the one before it misses (second order: 4× the error)
    coarser = cd.simulate(
        scene, 1.0, controller=controller, integrator="trapezoid", dt=2 * chosen[0.1], save_every=round(5e-3 / (2 * chosen[0.1])),
        accuracy_check="off", energy_check="off",
    )  # fmt: skip
    assert np.max(np.linalg.norm(coarser.wrenches()[..., :3] - truth.wrenches()[..., :3], axis=-1)) > 0.1
    tried = [float(line.split("off by ")[1].split()[0]) for line in capsys.readouterr().err.splitlines() if "off by" in line]
    assert tried[-4] / tried[-3] == pytest.approx(4.0, rel=0.2) and tried[-2] / tried[-1] == pytest.approx(4.0, rel=0.2)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "0.1"])
def test_an_accuracy_that_is_not_a_positive_force_is_refused(demo: tuple[cd.Scene, ObjectImpedance], bad: object) -> None:
    scene, controller = demo
    with pytest.raises(SimulationError, match=r"accuracy \(the force error the run may have\) must be"):
        cd.simulate(scene, 0.1, controller=controller, accuracy=bad)  # type: ignore[arg-type]


def test_what_accuracy_cannot_serve_is_refused_with_the_reason(demo: tuple[cd.Scene, ObjectImpedance], tmp_path: Path) -> None:
    """Adaptive and exact methods, streaming, an accuracy below what the reference resolves, and
    one that the halvings do not reach (first-order implicit Euler) are refused, each saying why."""
    scene, controller = demo
    with pytest.raises(SimulationError, match="dopri5 controls its error itself"):
        cd.simulate(scene, 0.1, controller=controller, integrator="dopri5", accuracy=0.1)
    with pytest.raises(SimulationError, match="exponential is exact"):
        cd.simulate(cd.scenes.linear_book(), 0.1, integrator="exponential", accuracy=0.1)
    with pytest.raises(SimulationError, match="cannot stream"):
        cd.simulate(scene, 0.1, controller=controller, accuracy=0.1, stream_to=str(tmp_path))
    with pytest.raises(SimulationError, match=r"accuracy = 1e-09 N is below what the reference resolves"):
        cd.simulate(scene, 0.05, controller=controller, accuracy=1e-9)
    with pytest.raises(
        SimulationError, match=r"implicit_euler did not reach a force error of 1e-05 N down to dt = 3\.90625e-05 s \(off by"
    ):
        cd.simulate(scene, 0.05, controller=controller, integrator="implicit_euler", dt=1e-2, accuracy=1e-5)
    with pytest.raises(SimulationError, match=r"more than max_steps = 40 steps"):
        cd.simulate(scene, 0.05, controller=controller, integrator="rk4", dt=1e-2, accuracy=1e-5, max_steps=40)


def test_an_unstable_closed_loop_is_named_not_blamed_on_the_step() -> None:
    """Undamped grasps under ObjectImpedance: a 28 Hz mode grows ×e every 44 ms, to ~1e4 N in
    2 s. No step reaches 0.1 N of a reference that grows so; the refusal says the loop is
    unstable instead of asking for a smaller step."""
    scene = cd.scenes.facing_arms("panda")
    controller = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0))
    with pytest.raises(
        SimulationError, match=r"the reference's forces grow [0-9.e+]+× over the run: the closed loop itself may be unstable"
    ):
        cd.simulate(scene, 2.0, controller=controller, integrator="trapezoid", dt=5e-3, accuracy=0.1)


def test_a_try_past_the_stability_limit_is_a_miss_and_its_warnings_stay_unsaid(
    demo: tuple[cd.Scene, ObjectImpedance], capsys: pytest.CaptureFixture[str]
) -> None:
    """rk4 from 10 ms diverges (its limit here is ~1.7 ms): those tries count as misses, their
    energy warnings are not shown, and the step found is the first that resolves the forces;
    the step before it does not (the largest step of the sequence is returned)."""
    import warnings

    scene, controller = demo
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = cd.simulate(scene, 0.3, controller=controller, integrator="rk4", dt=1e-2, accuracy=0.05, progress=True)
    printed = capsys.readouterr().err
    assert "rk4 at dt = 0.01 s diverges" in printed
    assert res.dt < 2e-3 and res.force_error_estimate is not None and res.force_error_estimate <= 0.05
    truth = cd.simulate(
        scene, 0.3, controller=controller, integrator=DormandPrince(rtol=1e-11, atol=1e-14), dt=1e-2,
        accuracy_check="off", energy_check="off",
    )  # fmt: skip
    try:  # (the step before: it diverges, or misses)
        coarser = cd.simulate(
            scene, 0.3, controller=controller, integrator="rk4", dt=2 * res.dt, save_every=round(5e-3 / res.dt),
            accuracy_check="off", energy_check="off",
        )  # fmt: skip
        assert np.max(np.linalg.norm(coarser.wrenches()[..., :3] - truth.wrenches()[..., :3], axis=-1)) > 0.05
    except cd.DivergenceError:
        pass


def test_a_scene_file_asks_for_its_accuracy(tmp_path: Path) -> None:
    """[simulation] accuracy: coopdyn simulate halves the file's dt until the forces are within
    it and says the step it took; with an adaptive method, or in a sweep, it is refused."""
    from coopdyn.io.scenefile import SceneFileError, load, run
    from coopdyn.sweeps.spec import load_spec

    text = (EXAMPLES / "two_pandas.toml").read_text()
    text = text.replace("duration = 5.0", "duration = 1.0").replace("dt = 1e-3", "dt = 5e-3\naccuracy = 0.1")
    path = tmp_path / "accurate.toml"
    path.write_text(text)
    report = run(load(path), folder=tmp_path / "out", progress=False)
    assert report.result.dt == 1.25e-3 and report.result.force_error_estimate <= 0.1
    assert "trapezoid at dt = 0.00125 s (chosen for a force error <= 0.1 N:" in report.summary[0]
    path.write_text(text.replace('integrator = "trapezoid"', 'integrator = "dopri5"'))
    with pytest.raises(SceneFileError, match=r"\[simulation\] accuracy: chooses a fixed-step method's step; dopri5"):
        load(path)
    path.write_text(text + '\n[sweep]\nfolder = "out"\n[sweep.grid]\n"scene.stiffness" = [1e4, 2e4]\n')
    with pytest.raises(cd.SweepError, match="accuracy is not taken by sweeps yet"):
        load_spec(path)


def test_auto_chooses_the_method_too(demo: tuple[cd.Scene, ObjectImpedance], capsys: pytest.CaptureFixture[str]) -> None:
    """integrator="auto": the trapezoid, rk4 and implicit Euler from dt, halving, and dopri5 at
    tighter and tighter rtol; the run returned is within the accuracy of a dopri5 run at rtol 1e-11
    it did not use, it is named (dopri5 with its rtol), and it is the cheapest of the runs that
    met it (the progress line lists them with their CPU time)."""
    scene, controller = demo
    truth = cd.simulate(
        scene, 0.5, controller=controller, integrator=DormandPrince(rtol=1e-11, atol=1e-14), dt=5e-3,
        accuracy_check="off", energy_check="off",
    )  # fmt: skip
    for tolerance in (1.0, 1e-6):
        res = cd.simulate(scene, 0.5, controller=controller, integrator="auto", dt=5e-3, accuracy=tolerance, progress=True)
        error = float(np.max(np.linalg.norm(res.wrenches()[..., :3] - truth.wrenches()[..., :3], axis=-1)))
        assert res.force_error_estimate is not None and error <= tolerance
        line = next(x for x in capsys.readouterr().err.splitlines() if "chose" in x)
        costs = {
            part.rsplit(": ", 1)[0]: float(part.rsplit(": ", 1)[1].split()[0])
            for part in line.split("meets it (")[1].rstrip(")").split(", ")
        }
        name = res.integrator if res.integrator.startswith("dopri5") else f"{res.integrator} at dt = {res.dt:g} s"
        assert costs[name] == min(costs.values()), line
        if tolerance == 1e-6:  # (no fixed step the halvings reach costs less here: rk4 needs 0.3 ms)
            assert res.integrator.startswith("dopri5 (rtol ")
        else:
            assert res.integrator in ("trapezoid", "rk4", "implicit_euler")
    with pytest.raises(SimulationError, match=r'integrator="auto" chooses the method for a force accuracy: give accuracy='):
        cd.simulate(scene, 0.1, controller=controller, integrator="auto")
    with pytest.raises(SimulationError, match=r"unknown integrator 'AUTO'; valid: .+, or \"auto\" \(the method chosen"):
        cd.simulate(scene, 0.1, controller=controller, integrator="AUTO", accuracy=0.1)
    with pytest.raises(SimulationError, match=r"no method reached a force error of 1e-05 N \(trapezoid down to dt = "):
        cd.simulate(scene, 0.05, controller=controller, integrator="auto", dt=1e-2, accuracy=1e-5, max_steps=40)


def test_a_scene_file_asks_for_auto_with_an_accuracy(tmp_path: Path) -> None:
    """``integrator = "auto"`` in a scene file chooses the method with ``accuracy``, and the
    summary names what it chose; without an accuracy it is refused at its line."""
    from coopdyn.io.scenefile import SceneFileError, load, run

    text = (EXAMPLES / "two_pandas.toml").read_text()
    text = text.replace("duration = 5.0", "duration = 0.5").replace('integrator = "trapezoid"', 'integrator = "auto"')
    path = tmp_path / "auto.toml"
    path.write_text(text)
    with pytest.raises(SceneFileError, match=r"\[simulation\] integrator: 'auto' chooses the method for a force accuracy"):
        load(path)
    path.write_text(text.replace("dt = 1e-3", "dt = 5e-3\naccuracy = 1.0"))
    report = run(load(path), folder=tmp_path / "out", progress=False)
    assert report.result.force_error_estimate <= 1.0
    assert f"with {report.result.integrator} at dt = " in report.summary[0] or "with dopri5 (rtol " in report.summary[0]
    assert "(chosen for a force error <= 1 N:" in report.summary[0]


def test_a_scene_file_without_an_integrator_is_accurate_by_default(tmp_path: Path) -> None:
    """No integrator named: `coopdyn simulate` chooses the method and step for a force error of
    0.1 N (DEFAULT_ACCURACY) halving from dt = 1 ms, and the run is within it of a dopri5 run at
    rtol 1e-11 it did not use; a sweep of the same file runs its cases with rk4 at 1 ms instead
    (no search per case), and refuses an accuracy written; an integrator named keeps its own
    step; a controller period and max_steps work with the search as with a named method."""
    from coopdyn.io.scenefile import DEFAULT_ACCURACY, load, run
    from coopdyn.sweeps.spec import Settings, SpecJob, load_spec

    text = (EXAMPLES / "two_pandas.toml").read_text()
    lines = [ln for ln in text.splitlines() if not ln.startswith(("integrator", "dt ", "dt=", "save_every"))]
    text = "\n".join(lines).replace("duration = 5.0", "duration = 0.5") + "\n"
    path = tmp_path / "plain.toml"
    path.write_text(text)
    loaded = load(path)
    assert (loaded.integrator, loaded.accuracy, loaded.dt, DEFAULT_ACCURACY) == ("auto", 0.1, 1e-3, 0.1)
    report = run(loaded, folder=tmp_path / "out", progress=False)
    truth = cd.simulate(
        loaded.scene, 0.5, controller=loaded.controller, integrator=DormandPrince(rtol=1e-11, atol=1e-14), dt=1e-2,
        accuracy_check="off", energy_check="off",
    )  # fmt: skip
    error = float(np.max(np.linalg.norm(report.result.wrenches()[..., :3] - truth.wrenches()[..., :3], axis=-1)))
    assert error <= 0.1 and "(chosen for a force error <= 0.1 N:" in report.summary[0]
    path.write_text(text + '\n[sweep]\nfolder = "out"\n[sweep.grid]\n"scene.stiffness" = [1e4, 2e4]\n')
    spec = load_spec(path)
    case = SpecJob(spec.text, str(path), Settings()).case(spec.items[0])
    assert (case.integrator, case.dt, case.save_every) == ("rk4", 1e-3, 10)
    named = load(EXAMPLES / "two_pandas.toml")
    assert (named.integrator, named.accuracy) == ("trapezoid", None)
    path.write_text(text + '\n[sweep]\nfolder = "out"\n[sweep.grid]\n"scene.stiffness" = [1e4, 2e4]\n')
    path.write_text(path.read_text().replace("duration = 0.5", "duration = 0.5\naccuracy = 0.01"))
    with pytest.raises(cd.SweepError, match="accuracy is not taken by sweeps yet"):
        load_spec(path)
    # a controller's period (1 kHz) works as with a named method: whole steps of 1 ms, halved
    path.write_text(text.replace("duration = 0.5", "duration = 0.2\ncontrol_dt = 1e-3"))
    loaded = load(path)
    assert run(loaded, folder=tmp_path / "held", progress=False).result.force_error_estimate <= 0.1


def test_what_auto_cannot_do_within_max_steps_says_so(demo: tuple[cd.Scene, ObjectImpedance]) -> None:
    """When max_steps is what stops the search, each method says how, and the message points to
    max_steps, not to a smaller step: even the first step asked for takes too many (39), or there
    is room for the samples but not for the steps (45)."""
    scene, controller = demo
    said = {
        39: (
            "trapezoid at dt = 0.01 s already takes more than max_steps = 39 steps",
            "dopri5 at its samples, 0.01 s apart, already takes more than max_steps = 39 steps",
        ),
        45: (
            "trapezoid down to dt = 0.01 s (a smaller step would take more than max_steps = 45 steps)",
            "dopri5 down to rtol 1e-08 (at rtol 0.001 it ran out of its step budget (max_steps = 45))",
        ),
    }
    for max_steps, parts in said.items():
        with pytest.raises(SimulationError) as info:
            cd.simulate(scene, 0.4, controller=controller, integrator="auto", dt=1e-2, accuracy=1e-6, max_steps=max_steps)
        message = str(info.value)
        assert all(part in message for part in parts), message
        assert message.endswith(": give a larger max_steps, or a looser accuracy")
