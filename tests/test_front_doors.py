"""Every input that once escaped a front door as another exception than a CoopdynError (or hung)
is now refused with one that says what was wrong: one test per signature of the fuzz."""

from __future__ import annotations

import os
from pathlib import Path

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
