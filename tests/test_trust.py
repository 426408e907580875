"""Files are data: a sweep table, a result or a scene file someone sends runs no code it names,
and is refused by name when it is damaged or hostile (docs/trust.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

import coopdyn as cd
from coopdyn.__main__ import main
from coopdyn.sweeps import rerun

EVIL = """
from pathlib import Path
Path({marker!r}).write_text("ran")
def make_case(**kwargs):
    Path({marker!r}).write_text("ran")
"""


def book_case(stiffness: float = 1.0) -> cd.Scene:
    return cd.scenes.linear_book()


def forged_table(tmp_path: Path, source: dict[str, object]) -> Path:
    """A real sweep's table whose recorded make_case is replaced by ``source``."""
    import pyarrow.parquet as pq

    cd.sweep(book_case, {"stiffness": [1.0]}, duration=0.01, executor="serial", out=tmp_path / "sweep", progress=False)
    path = tmp_path / "sweep" / "table.parquet"
    arrow = pq.read_table(path)
    metadata = dict(arrow.schema.metadata)
    meta = json.loads(metadata[b"coopdyn.sweep"])
    meta["source"] = {"kind": "python", **source}
    metadata[b"coopdyn.sweep"] = json.dumps(meta).encode()
    pq.write_table(arrow.replace_schema_metadata(metadata), path)
    return path


@pytest.mark.parametrize("by", ["file", "module"])
def test_a_hostile_table_runs_nothing_it_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, by: str) -> None:
    marker = tmp_path / "marker.txt"
    evil = tmp_path / "lib" / "evil_payload.py"
    evil.parent.mkdir()
    evil.write_text(EVIL.format(marker=str(marker)))
    monkeypatch.syspath_prepend(str(evil.parent))
    module = "evil_payload" if by == "module" else "__main__"
    table = forged_table(tmp_path, {"module": module, "qualname": "make_case", "file": str(evil), "name": "make_case"})
    with pytest.raises(cd.SweepError, match=r"does not import or run code it names.*--case .*evil_payload.*--trust"):
        rerun(table, 0)
    assert main(["sweep", "--rerun", str(table), "0"]) == 2
    assert not marker.exists() and "evil_payload" not in sys.modules
    # named by the user, or trusted explicitly, it runs (and here it is not a case maker at all)
    assert rerun(table, 0, trust=True).differences
    assert marker.read_text() == "ran"


def test_a_rerun_takes_the_code_the_user_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = forged_table(tmp_path, {"module": None, "qualname": None, "file": None, "name": "<lambda>"})
    here = Path(__file__).resolve()
    assert rerun(table, 0, make_case=book_case).identical
    assert rerun(table, 0, make_case=f"{here}:book_case").identical
    assert main(["sweep", "--rerun", str(table), "0", "--case", f"{here}:book_case"]) == 0
    with pytest.raises(cd.SweepError, match=r"MODULE:FUNCTION or FILE\.py:FUNCTION"):
        rerun(table, 0, make_case="book_case")
    with pytest.raises(cd.SweepError, match="no file"):
        rerun(table, 0, make_case=f"{tmp_path}/missing.py:f")
    with pytest.raises(cd.SweepError, match="defines no nothing_here"):
        rerun(table, 0, make_case=f"{here}:nothing_here")
    assert main(["sweep", "x.toml", "--trust"]) == 2
    assert "--trust goes with --rerun" in capsys.readouterr().err


def saved_result(tmp_path: Path) -> Path:
    res = cd.simulate(cd.scenes.linear_book(), 0.01, integrator="rk4", dt=1e-3)
    return res.save(tmp_path / "r.npz")


def test_a_result_bomb_is_refused_before_it_is_decompressed(tmp_path: Path) -> None:
    """A small file that would expand to gigabytes: refused from its headers."""
    import numpy as np

    path = saved_result(tmp_path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["q"] = np.zeros((2**27, 2))  # 2 GiB of zeros: a few MB compressed
    bomb = tmp_path / "bomb.npz"
    np.savez_compressed(bomb, **arrays)
    assert bomb.stat().st_size < 10e6
    with pytest.raises(cd.SimulationError, match=r"would take 2.15 GB in memory, more than the 1 GB allowed"):
        cd.Result.load(bomb, max_bytes=1e9)
    assert cd.Result.load(path).t[-1] == pytest.approx(0.01)
    for bad, match in (("x", "must be numeric"), (-1, "must be > 0"), (float("nan"), "must be finite")):
        with pytest.raises(cd.SimulationError, match=f"max_bytes {match}"):
            cd.Result.load(path, max_bytes=bad)


@pytest.mark.parametrize("key", ["t", "q", "v", "tau"])
def test_a_result_with_nan_samples_is_refused_by_name(tmp_path: Path, key: str) -> None:
    import numpy as np

    path = saved_result(tmp_path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays[key] = arrays[key].copy()
    arrays[key][3] = np.nan
    np.savez(path, **arrays)
    with pytest.raises(
        cd.SimulationError, match=rf"{key} is not finite or beyond ±1e\+100 at 1 sample\(s\), the first at index 3"
    ):
        cd.Result.load(path)


def test_a_killed_run_from_the_command_line_saves_what_it_made(tmp_path: Path) -> None:
    """SIGTERM and SIGHUP stop `coopdyn simulate` as Ctrl-C does: the partial run is written."""
    import signal
    import subprocess
    import time

    scene = tmp_path / "long.toml"
    scene.write_text(
        '[scene]\nbuilder = "linear_book"\n[controller]\ntype = "book_drives"\n'
        '[simulation]\nduration = 1000.0\nintegrator = "rk4"\ndt = 1e-5\n[output]\nfolder = "out"\nplot = false\nhtml = false\n'
    )
    for sig in (signal.SIGTERM, signal.SIGHUP):
        proc = subprocess.Popen(
            [sys.executable, "-m", "coopdyn", "simulate", str(scene), "--max-steps", "0"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        time.sleep(4.0)  # past start-up, into the run
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err[-2000:]
        assert "interrupted at t = " in err and "The run so far was saved to" in err
        res = cd.Result.load(tmp_path / "out" / "trajectory.npz")
        assert res.status == "interrupted" and 0 < res.t[-1] < 1000.0


def test_a_urdf_cannot_have_a_file_outside_its_package_read(tmp_path: Path) -> None:
    """A URDF naming a "mesh" anywhere on the disk: that file is not read, nor embedded in the
    HTML animation; a mesh inside the URDF's package is."""
    from coopdyn.model.arm import load_arm
    from coopdyn.resources import urdf_path

    secret = tmp_path / "home" / "secret.stl"
    secret.parent.mkdir()
    secret.write_text("solid SECRET-TOKEN-123\nendsolid t\n")
    pkg = tmp_path / "pkg"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    (pkg / "meshes" / "plate.stl").write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.05 0 0\nvertex 0 0.05 0\nendloop\nendfacet\nendsolid t\n"
    )
    box = '<geometry><box size="0.04 0.04 0.01"/></geometry>'
    base = urdf_path("slider_z.urdf").read_text()
    for mesh, kept in ((secret, 0), (pkg / "meshes" / "plate.stl", 1)):
        urdf = pkg / "urdf" / "robot.urdf"
        urdf.write_text(base.replace(box, f'<geometry><mesh filename="{mesh}"/></geometry>'))
        with pytest.warns(UserWarning, match="lies outside the URDF's package") if not kept else _no_warning():
            loaded = load_arm(cd.Arm("a", urdf, tip_frame="tip"), meshes="visual")
        assert loaded.visual is not None and loaded.visual.ngeoms == kept


def _no_warning() -> object:
    import contextlib
    import warnings

    @contextlib.contextmanager
    def quiet() -> object:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            yield

    return quiet()


def test_a_sweep_table_too_large_for_memory_is_refused_from_its_metadata(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from coopdyn.sweeps import load, table

    cd.sweep(book_case, {"stiffness": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)
    monkeypatch.setattr(table, "MAX_LOAD_BYTES", 10.0)
    with pytest.raises(cd.SweepError, match=r"would take .* GB in memory \(from its metadata\)"):
        load(tmp_path)
