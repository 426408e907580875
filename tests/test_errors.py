"""The error a user gets, and nothing lost when a long run ends badly."""

from __future__ import annotations

import os
import signal
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.__main__ import main
from coopdyn._optional import MissingDependencyError


def test_malformed_urdf(tmp_path: Path) -> None:
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/>")
    with pytest.raises(cd.ModelLoadError, match=r"could not parse URDF .*bad.urdf"):
        cd.Scene([cd.Arm("a", bad, tip_frame="a")], cd.RigidObject.box(1.0, (0.1,) * 3), [cd.Interconnection("a", np.ones(6))])


def test_missing_dependency_names_the_install(monkeypatch: pytest.MonkeyPatch, book: cd.Scene) -> None:
    from coopdyn.viz.plotting import book_figure

    res = cd.simulate(book, 0.01, dt=1e-3)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)  # as if matplotlib were not installed
    with pytest.raises(MissingDependencyError, match=r"plotting needs the package 'matplotlib': pip install matplotlib"):
        book_figure(res)


def test_nan_in_an_external_wrench(pandas: cd.Scene) -> None:
    with pytest.raises(cd.ControllerError, match=r"object_wrench\(t\) must be finite.*6 finite real numbers"):
        cd.simulate(pandas, 0.01, dt=1e-3, object_wrench=lambda t: np.full(6, np.nan))


def test_a_run_too_long_to_finish_is_refused(book: cd.Scene) -> None:
    with pytest.raises(cd.SimulationError, match=r"asks for 1e\+12 steps, more than max_steps = 2,000,000.*Enlarge dt"):
        cd.simulate(book, 1e3, dt=1e-9)


def test_ctrl_c_keeps_the_trajectory_so_far(book: cd.Scene) -> None:
    """A real SIGINT in the middle of a run: the partial trajectory comes with the interrupt."""
    sent = []

    def controller(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        if t >= 0.05 and not sent:
            sent.append(t)
            os.kill(os.getpid(), signal.SIGINT)
        return np.zeros(2)

    # the signal arrives during the step 0.049 → 0.05 s (its last stage is at 0.05 s): that step is dropped
    with pytest.raises(cd.SimulationInterrupted, match=r"interrupted at t = 0.049 s of 1 s") as info:
        cd.simulate(book, 1.0, controller=controller, dt=1e-3)
    partial = info.value.result
    assert isinstance(info.value, KeyboardInterrupt)  # still stops a script like Ctrl-C does
    assert partial.status == "interrupted" and partial.t[-1] == pytest.approx(0.049) and partial.q.shape == (50, 3)


def test_diverging_scene_file_saves_what_it_had(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene_file = tmp_path / "stiff.toml"
    scene_file.write_text(
        '[scene]\nbuilder = "linear_book"\nc_p = 2e8\nc_k = 2e8\nd_p = 0.0\nd_k = 0.0\n'
        '[simulation]\nduration = 1.0\nintegrator = "symplectic_euler"\ndt = 1e-3\n'
    )
    out = tmp_path / "out"
    with pytest.warns(cd.EnergyBalanceWarning):
        assert main(["simulate", str(scene_file), "--out", str(out)]) == 2
    assert "diverged at t =" in capsys.readouterr().err
    with np.load(out / "trajectory.npz") as z:
        assert 0 < z["t"][-1] < 1.0 and np.all(np.isfinite(z["q"]))
    diagnosis = (out / "diagnosis.txt").read_text()
    assert "DivergenceError" in diagnosis and "ω_max" in diagnosis and "implicit_euler" in diagnosis


def test_saving_is_atomic(tmp_path: Path, book: cd.Scene, monkeypatch: pytest.MonkeyPatch) -> None:
    """A write that fails half-way leaves the previous file untouched and no temporary file."""
    res = cd.simulate(book, 0.01, dt=1e-3)
    path = res.save(tmp_path / "run.npz")
    before = path.read_bytes()

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", broken)
    with pytest.raises(OSError, match="disk full"):
        res.save(path)
    assert path.read_bytes() == before
    with pytest.raises(cd.SimulationError, match=r"unknown result format '.txt': use .npz \(reloads\) or .csv"):
        res.save(tmp_path / "run.txt")
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["run.npz"]


@pytest.mark.parametrize("entry", [1e6, -1e6])
def test_a_state_at_the_bound_is_a_state(pandas: cd.Scene, entry: float) -> None:
    v = np.full(pandas.nv, entry)
    assert np.array_equal(pandas.check_state(pandas.q0, v)[1], v)


@pytest.mark.parametrize(
    ("entry", "said"),
    [
        (1.0000001e6, r"v has an entry of 1e\+06"),
        (1e300, r"v has an entry of 1e\+300"),
        (np.nan, "v .a velocity. must be finite"),
    ],
)
def test_a_state_past_the_bound_is_refused_by_name_without_a_numpy_warning(pandas: cd.Scene, entry: float, said: str) -> None:
    v = np.r_[np.zeros(pandas.nv - 1), entry]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(cd.SceneError, match=said):
            pandas.check_state(pandas.q0, v)
