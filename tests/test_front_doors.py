"""Every input that once escaped a front door as another exception than a CoopdynError (or hung)
is now refused with one that says what was wrong: one test per signature of the fuzz."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.__main__ import main
from coopdyn.io import scenefile
from coopdyn.model.elements.beam import tip_stiffness
from coopdyn.statics import equilibrium

BEAM_FILE = """
[object]
type = "beam"
length = 1.0
n_elements = {n}
section = {{ shape = "rectangle", width = 0.03, height = 0.003, E = 70e9, rho = 2700.0 }}
[[interconnections]]
stiffness = 1e4
[simulation]
duration = 0.1
"""

SECTION = cd.Section(1, 1, 1, 1, 1, 1, 1)


@pytest.mark.parametrize(
    "call",
    [
        lambda: cd.Section.rectangle(1e300, 1e300, E=1.0, rho=1.0),
        lambda: cd.Section.rectangle(1e-300, 1e-300, E=1.0, rho=1.0),
        lambda: cd.Section.rectangle(5e-324, 5e-324, E=1.0, rho=1.0),
        lambda: cd.Section.circle(1e100, E=1.0, rho=1.0),
        lambda: cd.Beam(1e300, SECTION),
        lambda: cd.Beam(1.0, cd.Section(1e300, 1e300, 1e300, 1e300, 1e300, 1e300, 1e300)),
        lambda: tip_stiffness(SECTION, 5e-324),
        lambda: tip_stiffness(cd.Section(1, 1, 1, 5e-324, 1, 1, 1, shear_factor=5e-324), 1.0),
    ],
)
def test_extreme_sections_are_refused(call: object) -> None:
    with pytest.raises(cd.SceneError, match=r"not representable in floating point|must be > 0"):
        call()  # type: ignore[operator]


def test_a_beam_too_large_for_the_machine_is_refused_before_it_is_built(tmp_path: Path) -> None:
    path = tmp_path / "beam.toml"
    path.write_text(BEAM_FILE.format(n=500))
    with pytest.raises(cd.SceneError, match=r"nv = 3006 velocities: .* GB each .* At most nv = \d+ fits; this beam fits"):
        scenefile.load(path)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[object]\ntype = { a = 1 }\nmass = 1.0\nsize = [0.1, 0.1, 0.1]", "type must be one of"),
        ('[object]\ntype = "beam"\nlength = 1.0\nsection = { shape = ["rectangle"], width = 1.0 }', "shape must be one of"),
        ('[object]\ntype = "box"\nname = "universe"\nmass = 1.0\nsize = [0.1, 0.1, 0.1]', "name 'universe' is taken"),
    ],
)
def test_malformed_scene_files_are_refused_by_line(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "s.toml"
    path.write_text(text + "\n[[interconnections]]\nstiffness = 1e4\n[simulation]\nduration = 0.1\n")
    with pytest.raises(cd.SceneFileError, match=match):
        scenefile.load(path)


def test_output_paths_are_refused_by_name(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    from coopdyn.outputs import check_folder
    from coopdyn.viz.plotting import save_figure

    (tmp_path / "adir.png").mkdir()
    (tmp_path / "afile").write_text("")
    for path, match in [
        (tmp_path / "adir.png", "is a folder"),
        (tmp_path / "plot.xyz", "must end in"),
        (f"{tmp_path}/a\0b.png", "must be a path"),
        (tmp_path / "afile" / "x.png", "cannot write the figure"),
        (tmp_path / ("a" * 300 + ".png"), "too long a path"),
    ]:
        with pytest.raises(cd.OutputError, match=match):
            save_figure(plt.figure(), path)
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(cd.OutputError, match="cannot be used"):
        check_folder(loop)
    with pytest.raises(cd.OutputError, match="too long a path"):
        check_folder(tmp_path / ("d/" * 1000))


def test_bad_arguments_to_the_helpers_are_refused() -> None:
    with pytest.raises(cd.SimulationError, match=r"scene must be a coopdyn\.Scene, got str"):
        cd.advise("not a scene")  # type: ignore[arg-type]
    with pytest.raises(cd.SimulationError, match="give at most 60 s"):
        cd.advise_model(cd.scenes.linear_book(), measure=1e308)
    with pytest.raises(cd.SimulationError, match="max_iter must be at most 1000"):
        equilibrium(cd.scenes.linear_book(), max_iter=10**12)
    with pytest.raises(cd.SweepError, match=r"integers from 0 to 2\*\*63"):
        cd.sweep(lambda seed: cd.scenes.linear_book(), seeds=[2**70], duration=0.01, executor="serial", progress=False)


def test_a_pose_beyond_a_thousand_kilometres_is_refused() -> None:
    """At 1e269 m Pinocchio's inertias overflowed to NaN and the run's diagnosis was garbled."""
    from coopdyn.resources import urdf_path

    arm = cd.Arm("far", str(urdf_path("slider_z.urdf")), tip_frame="tip", base=[0.0, 0.0, 1e269])
    box = cd.RigidObject.box(1.0, (0.1,) * 3)
    with pytest.raises(cd.SceneError, match=r"far.*1e\+269 m is farther than 1e\+06 m from the origin"):
        cd.Scene([arm], box, [cd.Interconnection("far", stiffness=1e4)])


def test_equilibrium_of_the_shipped_beam_converges_to_round_off() -> None:
    from coopdyn.problems.facing_arms import held_beam

    rest = equilibrium(held_beam())
    assert rest.iterations < 20 and rest.residual < 1e-7


def test_command_line_refusals(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = cd.simulate(cd.scenes.linear_book(), 0.05, dt=1e-3)
    res.save(tmp_path / "trajectory.npz")
    for argv, match in [
        (["demo", "--dt", "0", "--out", str(tmp_path / "demo"), "--no-html"], "dt must be > 0"),
        (["demo", "--dt", "nan", "--out", str(tmp_path / "demo"), "--no-html"], "dt must be"),
        (["view", str(tmp_path), "--html", ""], "must be a path"),
        (["view", str(tmp_path), "--html", str(tmp_path / "a.html"), "--fps", "1e300"], "fps must be at most 1000"),
        (["view", "/tmp/" + "a" * 300], "too long a path"),
        (["plot", str(tmp_path), "--out", str(tmp_path / "p.xyz")], "must end in"),
        (["bench", "--tables", "task", "--out", str(tmp_path / "b")], "give --peers too"),
    ]:
        assert main(argv) == 2, argv
        assert match in capsys.readouterr().err, argv


def test_a_result_file_with_bad_counters_is_refused(tmp_path: Path) -> None:
    import json

    path = cd.simulate(cd.scenes.linear_book(), 0.01, dt=1e-3).save(tmp_path / "r.npz")
    for key, value in (("dt", -1.0), ("n_rhs", -5)):
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays["meta"]))
        meta[key] = value
        arrays["meta"] = np.array(json.dumps(meta))
        np.savez(tmp_path / "bad.npz", **arrays)
        with pytest.raises(cd.SimulationError, match=f"{key} = {value}"):
            cd.Result.load(tmp_path / "bad.npz")
    assert os.path.getsize(path) > 0


def test_figures_are_written_in_the_format_their_ending_names(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    from coopdyn.viz.plotting import save_figure

    for name, magic in (("f.pdf", b"%PDF"), ("f.svg", b"<?xml"), ("f.png", b"\x89PNG")):
        assert save_figure(plt.figure(), tmp_path / name).read_bytes().startswith(magic)
    longest = "a" * 251 + ".png"  # 255 bytes: its temporary file needs a shorter name
    assert save_figure(plt.figure(), tmp_path / longest).stat().st_size > 0


def test_paths_a_file_system_takes_are_taken_and_the_others_refused(tmp_path: Path) -> None:
    from coopdyn.outputs import check_folder

    link = tmp_path / "out"
    link.symlink_to(tmp_path / "scratch" / "not-made-yet")
    assert check_folder(link) == tmp_path / "scratch" / "not-made-yet"
    with pytest.raises(cd.OutputError, match="a path this file system can name"):
        check_folder("\ud800")
    with pytest.raises(cd.SimulationError, match="a path this file system can name"):
        cd.Result.load("\ud800.npz")


def test_a_rerun_of_code_that_cannot_be_loaded_says_so(tmp_path: Path) -> None:
    from coopdyn.sweeps import rerun

    cd.sweep(lambda k: cd.scenes.linear_book(), {"k": [1.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)
    with pytest.raises(cd.SweepError, match="cannot import nosuchmod_xyz"):
        rerun(tmp_path, 0, make_case="nosuchmod_xyz:f")
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('top level fails')\n")
    with pytest.raises(cd.SweepError, match=r"running .*broken\.py for the sweep's make_case raised RuntimeError"):
        rerun(tmp_path, 0, make_case=f"{broken}:f")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('[scene]\nbuilder = "linear_book"\n[simulation]\nduration = 0.01\n[output]\nfolder = "a\\u0000b"\n', "folder"),
        ('[[arms]]\nname = "a"\nrobot = "a\\u0000b.urdf"\ntip_frame = "t"\n', "robot"),
        (f'[[arms]]\nname = "a"\nrobot = "{"r" * 300}.urdf"\ntip_frame = "t"\n', "too long a path"),
    ],
)
def test_bad_paths_inside_scene_files_are_refused_by_line(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "s.toml"
    rest = "" if "[simulation]" in text else ARMS_REST
    path.write_text(text + rest)
    with pytest.raises(cd.SceneFileError, match=match):
        scenefile.load(path)


ARMS_REST = (
    '[object]\ntype = "box"\nmass = 1.0\nsize = [0.1, 0.1, 0.1]\n[[interconnections]]\nstiffness = 1e4\n'
    "[simulation]\nduration = 0.1\n"
)


def test_bad_sweep_folders_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = tmp_path / "spec.toml"
    body = '[scene]\nbuilder = "linear_book"\n[simulation]\nduration = 0.01\n[sweep.grid]\n"scene.m" = [20.0]\n'
    spec.write_text(body + '[sweep]\nfolder = "a\\u0000b"\n')
    assert main(["sweep", str(spec), "--serial"]) == 2
    assert "folder" in capsys.readouterr().err
    spec.write_text(body)
    assert main(["sweep", str(spec), "--serial", "--out", "a\0b"]) == 2
    assert "--out DIR must be a path" in capsys.readouterr().err


def test_a_step_longer_than_the_run_is_one_step_of_the_run() -> None:
    res = cd.simulate(cd.scenes.linear_book(), 0.01, integrator="rk4", dt=1e10)
    assert res.n_steps == 1 and res.t[-1] == pytest.approx(0.01)


def test_a_result_whose_times_do_not_increase_is_refused(tmp_path: Path) -> None:
    path = cd.simulate(cd.scenes.linear_book(), 0.01, dt=1e-3).save(tmp_path / "r.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["t"] = arrays["t"][::-1].copy()
    np.savez(path, **arrays)
    with pytest.raises(cd.SimulationError, match="must increase from sample to sample"):
        cd.Result.load(path)


def _sweep_on_my_own_pool(_: int) -> str:
    import concurrent.futures as cf
    import multiprocessing as mp

    try:
        with cf.ProcessPoolExecutor(2, mp_context=mp.get_context("fork")) as pool:
            cd.sweep(lambda: cd.scenes.linear_book(), duration=0.01, progress=False, executor=pool)
    except cd.SweepError as exc:
        return str(exc)
    return "no error"


def test_a_process_pool_of_ones_own_inside_a_daemonic_process_is_refused_by_name() -> None:
    import multiprocessing as mp

    with mp.get_context("fork").Pool(1) as pool:
        message = pool.map(_sweep_on_my_own_pool, [0])[0]
    assert "the executor cannot take the sweep's runs here" in message and "executor='serial'" in message


def _nested(depth: int) -> object:
    x: object = 1.0
    for _ in range(depth):
        x = [x]
    return x


def _slider_scene(**arm: object) -> cd.Scene:
    from coopdyn.resources import urdf_path

    spec = {"tip_frame": "tip", "q0": [0.4], **arm}
    box = cd.RigidObject.box(5.0, [0.1] * 3, pose=[0, 0, 0.45], joint="prismatic", axis="z")
    return cd.Scene(
        [cd.Arm("s", str(urdf_path("slider_z.urdf")), **spec)], box, [cd.Interconnection("s", stiffness=2e4, element="ball")]
    )


def _abstract_element() -> cd.Scene:
    from coopdyn.model.elements.base import Element
    from coopdyn.resources import urdf_path

    box = cd.RigidObject.box(5.0, [0.1] * 3, pose=[0, 0, 0.45], joint="prismatic", axis="z")
    arm = cd.Arm("s", str(urdf_path("slider_z.urdf")), tip_frame="tip", q0=[0.4])
    return cd.Scene([arm], box, [cd.Interconnection("s", stiffness=[1e4] * 3 + [100.0] * 3, element=Element)])


class _FailingHook:
    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.zeros(2)

    def compiled_spec(self, scene: cd.Scene) -> dict[str, object]:
        raise ZeroDivisionError("hook")


def _writes_its_input(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    q[0] = np.nan
    return np.zeros(2)


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [  # the second fuzz (18 400 cases): each signature it found, now refused by name
        (lambda: cd.advise(cd.scenes.linear_book(), methods=None), cd.SimulationError, "methods must be a list of names"),
        (lambda: cd.advise(cd.scenes.linear_book(), methods=["scipy"]), cd.SimulationError, "methods must be a list of names"),
        (lambda: cd.simulate(cd.scenes.linear_book(), 0.01, backend=_nested(5000)), cd.CoopdynError, r"got \[\[\[\["),
        (lambda: cd.scenes.facing_arms(_nested(5000)), cd.SceneError, "robot must be a URDF path"),
        (lambda: cd.scenes.facing_arms("x" * 5000), cd.ModelLoadError, "unknown robot 'xxx"),
        (
            lambda: cd.Beam(0.8, cd.Section.rectangle(0.03, 0.003, E=70e9, rho=2700.0), n_elements=2).zero_modes(()),
            cd.SceneError,
            "rtol",
        ),
        (lambda: cd.simulate(cd.scenes.linear_book(), 0.01, max_memory=1e-320), cd.SimulationError, "at least 1"),
        (lambda: cd.advise_model(cd.scenes.linear_book(), dt=1e-320, measure=1e-6), cd.SimulationError, "dt must be from 1e-12"),
        (
            lambda: cd.sweep(lambda: cd.scenes.linear_book(), seeds=2**63, duration=0.005, executor="serial"),
            cd.SweepError,
            "count from 1",
        ),
        (lambda: cd.measure_stable_dt(cd.scenes.linear_book(), "rk4", n_steps=10**400), cd.SimulationError, "n_steps in"),
        (
            lambda: cd.measure_stable_dt(cd.scenes.linear_book(), "rk4", rel_tol=1e-300, n_steps=50),
            cd.SimulationError,
            "rel_tol in",
        ),
        (
            lambda: cd.measure_stable_dt(cd.scenes.linear_book(), "rk4", guess=float("nan"), n_steps=50),
            cd.SimulationError,
            "finite",
        ),
        (lambda: cd.integrators.Trapezoid(rho_inf=np.timedelta64(1, "s")), cd.SimulationError, "rho_inf"),
        (lambda: cd.simulate(cd.scenes.linear_book(), 0.01, save_every=np.timedelta64(1, "s")), cd.SimulationError, "save_every"),
        (lambda: cd.Section.rectangle(0.03, 0.003, E=70e9, rho=2700.0, timoshenko=np.array([])), cd.SceneError, "True or False"),
        (_abstract_element, cd.SceneError, "not an element to build"),
        (lambda: _slider_scene(tip_frame="universe"), cd.SceneError, "the world frame"),
        (lambda: _slider_scene(package_dirs=3), cd.SceneError, "package_dirs must be a list"),
        (
            lambda: cd.simulate(cd.scenes.linear_book(), 0.002, controller=_FailingHook()),
            cd.ControllerError,
            "compiled_spec raised",
        ),
        (
            lambda: cd.simulate(
                cd.scenes.linear_book(), 0.0, controller=lambda t, q, v: np.zeros(5), integrator="dopri5", energy_check="off"
            ),
            cd.ControllerError,
            "shape",
        ),
        (
            lambda: cd.simulate(cd.scenes.linear_book(), 0.0, controller=_writes_its_input, energy_check="off"),
            cd.ControllerError,
            "read-only",
        ),
        (
            lambda: cd.cooperative.GripLiftOscillate(start=[0, 0, 0.7], amplitude=1.7976931348623157e308),
            cd.SceneError,
            "amplitude",
        ),
    ],
)
def test_what_the_second_fuzz_found_is_refused_by_name(call: Any, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        call()


@pytest.mark.parametrize("dtype", ["float16", "float32"])
def test_a_result_file_of_narrower_floats_loads_as_doubles(tmp_path: Path, dtype: str) -> None:
    path = cd.simulate(cd.rigid_limit(cd.scenes.linear_book()), 0.01).save(tmp_path / "r.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["q"] = arrays["q"].astype(dtype)
    np.savez(path, **arrays)
    res = cd.Result.load(path)
    assert res.q.dtype == np.float64 and np.all(np.isfinite(res.wrenches()))


def test_a_result_file_with_absurd_samples_is_refused(tmp_path: Path) -> None:
    """Finite but beyond any run (|v| = 1e300): the readouts' squares would be inf or NaN."""
    path = cd.simulate(cd.scenes.linear_book(), 0.01).save(tmp_path / "r.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["v"] = np.full_like(arrays["v"], -1e300)
    np.savez(path, **arrays)
    with pytest.raises(cd.SimulationError, match=r"v is not finite or beyond ±1e\+100 at 11 sample"):
        cd.Result.load(path)
