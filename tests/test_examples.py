"""Every example runs (briefly, headless) and does what its docstring says."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_linear_book_example(tmp_path: Path) -> None:
    out = tmp_path / "fig.png"
    error = _load("linear_book").main(t_final=0.3, out=str(out))
    assert error < 1e-9
    assert out.stat().st_size > 10_000


def test_two_pandas_hold_example() -> None:
    forces = _load("two_pandas_hold").main(t_final=0.2)
    assert forces.shape == (2, 3)
    assert np.all(forces[:, 2] > 0.0)  # both arms push the box up


def test_cooperative_lift_example(tmp_path: Path) -> None:
    squeeze = _load("cooperative_lift").main(t_final=1.0, n_arms=3, out=str(tmp_path / "lift.png"))
    np.testing.assert_allclose(squeeze, 15.0, rtol=0.05)  # gripped (ramp over 0.5 s), lifting since 0.75 s
    assert (tmp_path / "lift.png").stat().st_size > 10_000


def test_cli_book(tmp_path: Path) -> None:
    from coopdyn.__main__ import main

    assert main(["book", "--out", str(tmp_path), "--t-final", "0.2", "--dt", "1e-3"]) == 0
    assert (tmp_path / "book_figure11.png").stat().st_size > 10_000


def test_cli_reports_coopdyn_errors(capsys: object) -> None:
    from coopdyn.__main__ import main

    assert main(["book", "--out", "unused", "--dt", "-1"]) == 2


def test_force_uncertainty_example(tmp_path: Path) -> None:
    """The squeeze follows the series-spring law within the gravity coupling (1 mm, K1 = K2: 5 N)."""
    module = _load("force_uncertainty")
    ERRORS, RATIOS = module.ERRORS, module.RATIOS
    elastic = module.main(str(tmp_path / "fu.png"))
    assert (tmp_path / "fu.png").stat().st_size > 10_000
    k = int(np.argmin(np.abs(RATIOS - 1.0)))
    assert -elastic[ERRORS[1]][k, 0, 0] == pytest.approx(5.0, rel=1e-3)


def test_flexible_beam_example_tells_the_resolved_runs_story(tmp_path: Path) -> None:
    """The strip example at its own settings (the trapezoid at 1 ms) and at a step that resolves
    every mode (50 µs: its 1.9 kHz bending modes at 10 steps per period) report the same
    figures — grasp forces within 0.2 N, mid-span deflection within 0.1 mm — over the grip,
    the lift and the start of the oscillation (2.5 s)."""
    example = _load("flexible_beam")
    mine = example.main(2.5, str(tmp_path / "beam"), html=False)
    assert mine.status == "completed" and (tmp_path / "beam.png").exists()
    resolved = example.main(2.5, str(tmp_path / "resolved"), html=False, dt=5e-5)
    force = {r: np.abs(r.wrenches()[..., :3]) for r in (mine, resolved)}
    assert np.max(np.abs(force[mine] - force[resolved])) < 0.2
    assert np.max(np.abs(example.deflection(mine) - example.deflection(resolved))) < 1e-4
    assert force[resolved].max() < 10.0  # (the strip is held, not shaken loose: ~9 N)


def test_planar_beam_example_carries_the_beam_and_leaves_it_still(tmp_path: Path) -> None:
    """Two planar 3R arms carry the strip at the example's settings (the trapezoid at 1 ms): the
    beam follows the task within 15 mm, bends by less than 6 mm while moving and is still (under
    1 µm of vibration) in its last second."""
    from coopdyn.scenes import midspan_deflection

    example = _load("planar_beam")
    mine = example.main(6.0, str(tmp_path / "planar"), html=False)
    assert mine.status == "completed" and (tmp_path / "planar.png").stat().st_size > 10_000
    reference = example.task(mine.scene)
    sag, end = midspan_deflection(mine), example.task_end(reference)
    assert mine.tracking_error(reference).max() < 0.015
    assert np.abs(sag[mine.t < end]).max() < 0.006
    assert np.ptp(sag[mine.t >= 5.0]) < 1e-6


@pytest.mark.slow
def test_the_gain_sweep_tells_the_resolved_runs_story(tmp_path: Path) -> None:
    """The sweep as shipped (the trapezoid at 1 ms) and at 0.1 ms: the same six cells are unstable
    loops — soft grasps under stiff gains: warned, or diverged saying so (at 1 ms two diverge that
    complete with kN forces at 0.1 ms) —, and every other cell's figures agree within 0.1 mm and
    0.05 N."""
    from coopdyn.viz.plotting import _unstable

    example = _load("sweep_gains")
    shipped = example.main(out=str(tmp_path / "shipped"), executor="serial")
    fine = example.main(out=str(tmp_path / "fine"), executor="serial", dt=1e-4)
    unstable = _unstable(shipped)
    assert unstable.tolist() == _unstable(fine).tolist() and unstable.sum() == 6
    stable = ~unstable
    assert (shipped["status"][stable] == "completed").all() and (fine["status"][stable] == "completed").all()
    for metric, within in (("tracking_error_max_m", 1e-4), ("peak_internal_force_N", 0.05)):
        np.testing.assert_allclose(shipped[metric][stable], fine[metric][stable], rtol=0, atol=within, err_msg=metric)


@pytest.mark.slow
def test_planar_beam_example_tells_the_resolved_runs_story(tmp_path: Path) -> None:
    """Over the grip and the lift (2 s) the example's figures at 1 ms match a run at 0.1 ms (within
    0.4 mN of 50 µs over the whole run: benchmarks/flexible_beam_check.py) within 0.05 N and 10 µm."""
    from coopdyn.scenes import midspan_deflection

    example = _load("planar_beam")
    short = example.main(2.0, str(tmp_path / "short"), html=False)
    fine = example.main(2.0, str(tmp_path / "fine"), html=False, dt=1e-4)
    assert np.abs(short.wrenches()[..., :3] - fine.wrenches()[..., :3]).max() < 0.05
    assert np.abs(midspan_deflection(short) - midspan_deflection(fine)).max() < 1e-5


def test_planar_beam_on_elastic_joints_everything_elastic(tmp_path: Path) -> None:
    """The book's fourth system (elastic grasps, strip and joints; --elastic-joints): the arms
    still carry the strip within 15 mm and leave it still (under 1 µm in the last second); the
    joints deflect by a few mrad; over the grip and the lift the example's forces, sag and
    deflections at 1 ms match a run at 0.1 ms within 0.05 N, 10 µm and 10 µrad."""
    from coopdyn.scenes import midspan_deflection

    example = _load("planar_beam")
    mine = example.main(6.0, str(tmp_path / "elastic"), html=False, elastic_joints=True)
    assert mine.scene.joint_springs.size == 6 and (tmp_path / "elastic.png").stat().st_size > 10_000
    reference = example.task(mine.scene)
    sag = midspan_deflection(mine)
    assert mine.tracking_error(reference).max() < 0.015 and np.ptp(sag[mine.t >= 5.0]) < 1e-6
    assert 1e-3 < np.abs(mine.joint_deflection()).max() < 1e-2
    short = example.main(2.0, str(tmp_path / "short"), html=False, elastic_joints=True)
    fine = example.main(2.0, str(tmp_path / "fine"), html=False, dt=1e-4, elastic_joints=True)
    assert np.abs(short.wrenches()[..., :3] - fine.wrenches()[..., :3]).max() < 0.05
    assert np.abs(midspan_deflection(short) - midspan_deflection(fine)).max() < 1e-5
    assert np.abs(short.joint_deflection() - fine.joint_deflection()).max() < 1e-5


def test_cli_messages_end_in_one_mark(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A message that ends in a question keeps its question mark alone ("…'[[arms]]'?", not "?.");
    the others end in a full stop."""
    from coopdyn.__main__ import main

    scene = tmp_path / "typo.toml"
    scene.write_text('[scene]\nbuilder = "linear_book"\n[simulation]\nduration = 0.1\n[[arm]]\nname = "left"\n')
    assert main(["simulate", str(scene)]) == 2
    assert capsys.readouterr().err.splitlines()[0].endswith("Did you mean '[[arms]]'?")
    scene.write_text('[scene]\nbuilder = "linear_book"\n[simulation]\nduration = -1\n')
    assert main(["simulate", str(scene)]) == 2
    assert capsys.readouterr().err.splitlines()[0].endswith("must be >= 0 [s], got -1.")


def test_the_hold_and_lift_examples_tell_the_resolved_runs_story(tmp_path: Path) -> None:
    """Each example's reported figures at its own step equal a run that resolves every mode:
    two Pandas hold the box (the forces on it, 1 s) within 1e-6 N of 50 µs; three lift it (the
    squeeze at the end of 2 s, implicit Euler at 1 ms) within 0.01 N of the trapezoid at 0.1 ms."""
    hold = _load("two_pandas_hold")
    np.testing.assert_allclose(hold.main(1.0), hold.main(1.0, dt=5e-5), rtol=0.0, atol=1e-6)
    lift = _load("cooperative_lift")
    mine = lift.main(t_final=2.0, out=str(tmp_path / "a.png"))
    fine = lift.main(t_final=2.0, out=str(tmp_path / "b.png"), dt=1e-4, integrator="trapezoid")
    np.testing.assert_allclose(mine, fine, rtol=0.0, atol=0.01)


def test_elastic_joints_example_tells_the_resolved_runs_story(tmp_path: Path) -> None:
    """Its printed figures at 1 ms (the trapezoid) equal those of a run at 0.1 ms, both arms'
    kinds; the elastic arms track less closely (the motors' inertia) and hold the same squeeze."""
    example = _load("elastic_joints")
    mine = example.main(str(tmp_path / "mine"), html=False)
    resolved = example.main(str(tmp_path / "resolved"), dt=1e-4, html=False)
    for kind in ("rigid", "elastic"):
        for key, tolerance in (("tracking_error_max_m", 1e-5), ("tracking_error_rms_m", 1e-5), ("internal_force_end_N", 0.01)):
            assert mine[kind][1][key] == pytest.approx(resolved[kind][1][key], abs=tolerance), (kind, key)
    assert mine["elastic"][1]["tracking_error_max_m"] > 1.2 * mine["rigid"][1]["tracking_error_max_m"]
    assert mine["elastic"][1]["internal_force_end_N"] == pytest.approx(20.0, abs=0.01)
    assert (tmp_path / "mine" / "elastic_joints.png").stat().st_size > 20_000


def test_frames_example_draws_what_the_outputs_say(tmp_path: Path) -> None:
    """The frames figure's numbers: each grasp pushes the box inward (compression: positive
    squeeze, the y components equal and opposite), and the forces carry the weight."""
    out = _load("frames").main(out=str(tmp_path / "frames.png"))
    f = out["wrench"][:, :3]
    assert out["grasp"][0, 1] < out["grasp"][1, 1]  # link 0 grasps the box's −y face
    assert np.all(out["squeeze"] > 15.0)
    assert f[0, 1] > 15.0 and f[1, 1] == pytest.approx(-f[0, 1], abs=1e-9)  # left grasp at −y pushes towards +y
    assert 19.62 < f[:, 2].sum() < 21.0  # weight 19.62 N, and the lift accelerates it up
    assert (tmp_path / "frames.png").stat().st_size > 20_000


@pytest.mark.parametrize("name", sorted(p.stem for p in (EXAMPLES / "scenes").glob("*.toml")))
def test_the_scene_file_examples_tell_the_resolved_runs_story(name: str) -> None:
    """Each examples/scenes file's reported figures (the run's metrics: tracking error, squeeze,
    peak forces) at its own method and step against the same method at a tenth of the step:
    within 0.01 N and 0.01 mm (measured: ≤ 0.5 mN, 0.4 µm)."""
    import warnings

    import coopdyn as cd
    from coopdyn.io.scenefile import load
    from coopdyn.metrics import run_metrics

    loaded = load(EXAMPLES / "scenes" / f"{name}.toml")
    figures = []
    for dt in (loaded.dt, loaded.dt / 10):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the resolved run's screen has nothing to add)
            res = cd.simulate(
                loaded.scene, loaded.duration, controller=loaded.controller, integrator=loaded.integrator, dt=dt,
                save_every=max(1, round(loaded.dt * loaded.save_every / dt)), control_dt=loaded.control_dt,
                accuracy_check="off",
            )  # fmt: skip
        figures.append(run_metrics(res, loaded.task)[0])
    mine, resolved = figures
    assert mine.keys() == resolved.keys() and len(mine) >= 3
    for key, value in mine.items():
        tolerance = 1e-5 if key.endswith("_m") else 0.01  # [m], [N]
        assert value == pytest.approx(resolved[key], abs=tolerance), key


def test_frames_example_tells_the_resolved_runs_story(tmp_path: Path) -> None:
    """The frames figure's forces at its 1 ms against 0.1 ms: within 0.01 N."""
    frames = _load("frames")
    mine = frames.main(out=str(tmp_path / "a.png"))
    resolved = frames.main(out=str(tmp_path / "b.png"), dt=1e-4)
    np.testing.assert_allclose(mine["wrench"], resolved["wrench"], atol=0.01)
    np.testing.assert_allclose(mine["squeeze"], resolved["squeeze"], atol=0.01)


def test_identify_example_recovers_the_hidden_grasps_and_its_model_step_is_resolved(tmp_path: Path) -> None:
    ex = _load("identify_stiffness")
    fits = ex.main(str(tmp_path), t_final=1.0)
    exact, fd = fits["exact"], fits["finite-differences"]
    assert (tmp_path / "identify_stiffness.png").exists()
    for name, value in ex.HIDDEN.items():
        assert abs(exact.estimate[name] - value) < 3.0 * exact.std[name], name
        assert abs(fd.estimate[name] - exact.estimate[name]) < 0.01 * exact.std[name]
    assert 0.9 < exact.residual_rms < 1.1
    # the fit's model runs at the sensors' 1 ms: at a resolving 0.25 ms it finds the same grasps
    import coopdyn as cd
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.scenes import object_start

    nominal = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    controller = ObjectImpedance(nominal, GripLiftOscillate(start=object_start(nominal), squeeze=20.0))
    fine = cd.identify(
        nominal, ex.experiment(nominal, controller, t_final=1.0), list(ex.HIDDEN), dt=2.5e-4, controller=controller
    )
    for name in ex.HIDDEN:
        assert abs(fine.estimate[name] - exact.estimate[name]) < 0.05 * exact.std[name], name


def test_gauss_newton_example_lifts_the_box_and_its_step_is_resolved(tmp_path: Path) -> None:
    out = _load("gauss_newton_lift").main(str(tmp_path))
    errors = out["errors"]
    assert errors[0] > 0.05 and errors[-1] < 5e-4  # from 68 mm off (the box falls) to under 0.5 mm [m]
    assert abs(out["resolved_error"] - errors[-1]) < 5e-5  # the same at rk4 0.25 ms (within 0.05 mm)
    assert (tmp_path / "gauss_newton_lift.png").exists()
