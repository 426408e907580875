"""A sweep loses no finished run however its process stops (kill -9, SIGTERM, SIGHUP, two
Ctrl-C): its journal keeps every row, its workers die with it, and ``--resume`` completes a table
equal, bit for bit, to the table of a run never interrupted."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

import coopdyn as cd
from coopdyn.__main__ import main
from coopdyn.sweeps import load
from coopdyn.sweeps.cases import TIMING

SPEC = """
[scene]
builder = "linear_book"

[controller]
type = "book_drives"

[simulation]
duration = 1.0
integrator = "rk4"
dt = 1e-4

[sweep]
folder = "out"

[sweep.grid]
"scene.c_p" = [{values}]
"""


def spec_file(tmp_path: Path, n: int) -> Path:
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.format(values=", ".join(f"{1e4 * (1 + i / n):.6g}" for i in range(n))))
    return spec


def journal_rows(folder: Path) -> list[dict[str, object]]:
    path = folder / "table.journal"
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text().split("\n")[1:]:
        try:
            rows.append(json.loads(line))
        except ValueError:
            continue
    return rows


def reproducible(table: pd.DataFrame) -> pd.DataFrame:
    return table.drop(columns=[*TIMING, "trajectory"]).reset_index(drop=True)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie waiting for its (dead) parent's reaper is not running
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def start_and_stop(spec: Path, how: signal.Signals, after: int) -> tuple[subprocess.Popen[str], list[int]]:
    """Start ``coopdyn sweep`` on two workers, send ``how`` to it once ``after`` rows are done.
    Its temporary files go beside the spec: a process killed with -9 cannot remove them itself."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "coopdyn", "sweep", str(spec), "--workers", "2", "--chunk-size", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "TMPDIR": str(spec.parent)},
    )
    deadline = time.monotonic() + 180
    while len(journal_rows(spec.parent / "out")) < after and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()[1][-2000:]
    workers = [int(str(p.name)) for p in Path("/proc").iterdir() if p.name.isdigit() and _parent(int(p.name)) == proc.pid]
    proc.send_signal(how)
    return proc, workers


def _parent(pid: int) -> int | None:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[1])
    except (OSError, ValueError, IndexError):
        return None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc; workers die with their parent on Linux")
@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM, signal.SIGHUP])
def test_a_stopped_sweep_resumes_to_the_uninterrupted_table(tmp_path: Path, how: signal.Signals) -> None:
    n = 40
    spec = spec_file(tmp_path, n)
    proc, workers = start_and_stop(spec, how, after=4)
    _, err = proc.communicate(timeout=60)
    out = tmp_path / "out"
    if how == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL
    else:  # as Ctrl-C: the table so far is written, the others "not run"
        assert proc.returncode == 130, err[-2000:]
        assert "interrupted after" in err and "--resume" in err
        assert (load(out)["status"] == "not run").any()
    deadline = time.monotonic() + 10
    while any(alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert workers and not any(alive(w) for w in workers)  # the workers died with their parent
    finished = {r["run"] for r in journal_rows(out)}
    assert 4 <= len(finished) < n
    assert main(["sweep", str(spec), "--resume", "--serial"]) == 0
    resumed = load(out)
    assert not (out / "table.journal").exists()
    assert resumed.attrs["coopdyn.sweep"]["resumed_rows"] == len(finished)
    whole = tmp_path / "whole"
    whole.mkdir()
    spec_file(whole, n)
    assert main(["sweep", str(whole / "spec.toml"), "--serial"]) == 0
    pd.testing.assert_frame_equal(reproducible(resumed), reproducible(load(whole / "out")), check_exact=True)


def test_resume_refuses_another_sweep_and_a_finished_one(tmp_path: Path) -> None:
    def case(k: float) -> cd.Scene:
        return cd.scenes.linear_book()

    cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)
    with pytest.raises(cd.SweepError, match="nothing to resume"):
        cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False, resume=True)
    (tmp_path / "table.journal").write_text('{"journal": "coopdyn.sweep-journal/1", "key": "another"}\n')
    with pytest.raises(cd.SweepError, match="journal of another sweep"):
        cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False, resume=True)
    with pytest.raises(cd.SweepError, match="give out=the folder"):
        cd.sweep(case, {"k": [1.0]}, duration=0.01, executor="serial", progress=False, resume=True)


def test_no_user_file_is_removed(tmp_path: Path) -> None:
    """A folder coopdyn writes to is refused when it holds a file coopdyn did not write, in
    ``trajectories/`` too; the user's file stays."""

    def case(k: float) -> cd.Scene:
        return cd.scenes.linear_book()

    thesis = tmp_path / "trajectories" / "thesis.tex"
    thesis.parent.mkdir()
    thesis.write_text("three years of work")
    with pytest.raises(cd.OutputError, match=r"holds files coopdyn did not write \(trajectories/thesis.tex\)"):
        cd.sweep(case, {"k": [1.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)
    with pytest.raises(cd.OutputError, match=r"trajectories/thesis\.tex"):
        cd.outputs.write_outputs(tmp_path, [("note", lambda folder: (folder / "diagnosis.txt").write_text("x"))])
    assert thesis.read_text() == "three years of work"
    thesis.unlink()
    cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path, trajectories=True, progress=False)
    assert sorted(p.name for p in (tmp_path / "trajectories").iterdir()) == ["run-000000.npz", "run-000001.npz"]
    cd.sweep(case, {"k": [1.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)  # replaces its own files
    assert not (tmp_path / "trajectories").exists() and len(load(tmp_path)) == 1


def test_a_table_that_cannot_be_written_is_rescued(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pyarrow.parquet as pq

    def case(k: float) -> cd.Scene:
        return cd.scenes.linear_book()

    real = pq.write_table

    def disk_full(table: object, where: object, **kwargs: object) -> None:
        if Path(str(where)).parent == tmp_path / "out":
            raise OSError(28, "No space left on device")
        real(table, where, **kwargs)

    monkeypatch.setattr(pq, "write_table", disk_full)
    with pytest.raises(cd.SweepError, match=r"No space left on device.*The table was saved to .*coopdyn-rescue-") as info:
        cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path / "out", progress=False)
    rescued = Path(str(info.value).split("saved to ")[1].split(" instead")[0])
    assert list(load(rescued)["status"]) == ["completed", "completed"] and len(info.value.table) == 2
    assert len(journal_rows(tmp_path / "out")) == 2  # and the journal still holds both rows


def _sweep_in_a_pool_worker(_: int) -> list[str]:
    import warnings

    def case(k: float) -> cd.Scene:
        return cd.scenes.linear_book()

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, progress=False)
    return [*table["status"], *(str(w.message) for w in caught)]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: the test's functions reach the pool's worker")
def test_a_sweep_inside_a_daemonic_process_runs_serially() -> None:
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        out = pool.map(_sweep_in_a_pool_worker, [0])[0]
    assert out[:2] == ["completed", "completed"]
    assert "daemonic process" in out[2] and "executor='serial'" in out[2]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_FSIZE and posix_fallocate")
def test_a_stream_that_does_not_fit_is_refused_with_an_error_not_a_crash(tmp_path: Path) -> None:
    """Streaming reserves its disk space up front: a limit it cannot fit ends in an OutputError
    (not a SIGBUS later), and no half-made files are left."""
    script = tmp_path / "stream.py"
    script.write_text(
        "import resource, signal, sys\n"
        "import coopdyn as cd\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))\n"
        "try:\n"
        f"    cd.simulate(cd.scenes.linear_book(), 10.0, integrator='rk4', dt=1e-4, stream_to={str(tmp_path / 's')!r})\n"
        "except cd.OutputError as exc:\n"
        "    print('refused:', exc)\n"
    )
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "cannot stream to" in run.stdout and "File too large" in run.stdout
    assert not list((tmp_path / "s").glob("*.npy"))


@pytest.fixture
def small_disk(tmp_path: Path) -> object:
    """A 1 MB file system of its own (tmpfs; needs root, as CI has)."""
    where = tmp_path / "disk"
    where.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(where)]).returncode:
        pytest.skip("needs permission to mount a small tmpfs")
    yield where
    subprocess.run(["umount", "-l", str(where)], check=False)


def test_a_disk_filling_up_during_a_streamed_run_cannot_kill_it(small_disk: Path) -> None:
    """Another program fills the disk while a run streams to it: the run's space was reserved,
    it finishes with every sample (a memory-mapped file without the reservation dies by SIGBUS)."""
    script = small_disk.parent / "fill.py"
    script.write_text(
        "import numpy as np, coopdyn as cd\n"
        "drives = cd.scenes.drives_controller(*cd.scenes.book_task())\n"
        "filled = []\n"
        "def controller(t, q, v):\n"
        "    if t > 1.0 and not filled:\n"
        "        filled.append(1)\n"
        f"        with open({str(small_disk / 'filler')!r}, 'wb', buffering=0) as f:\n"
        "            try:\n"
        "                while True: f.write(b'x' * 4096)\n"
        "            except OSError as exc: print('disk full:', exc.strerror)\n"
        "    return drives(t, q, v)\n"
        f"res = cd.simulate(cd.scenes.linear_book(), 3.0, controller=controller, integrator='rk4', dt=1e-3, "
        f"stream_to={str(small_disk / 'run')!r})\n"
        "print('samples', len(res.t), float(res.t[-1]))\n"
    )
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, (run.returncode, run.stderr[-2000:])
    assert "disk full: No space left on device" in run.stdout and "samples 3001 3.0" in run.stdout


def test_a_journal_line_cut_by_a_kill_is_dropped_before_appending(tmp_path: Path) -> None:
    from coopdyn.sweeps.journal import Journal, finished_rows

    journal = Journal(tmp_path, "k", append=False)
    journal.add([{"run": 0, "status": "completed"}])
    journal.close(remove=False)
    with open(tmp_path / "table.journal", "a") as f:
        f.write('{"run": 1, "status": "compl')  # the kill came mid-line
    journal = Journal(tmp_path, "k", append=True)
    journal.add([{"run": 2, "status": "completed"}])
    journal.close(remove=False)
    assert sorted(finished_rows(tmp_path, "k")) == [0, 2]


def test_a_journal_that_cannot_be_written_does_not_stop_the_sweep(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from coopdyn.sweeps import journal

    def case(k: float) -> cd.Scene:
        return cd.scenes.linear_book()

    class FullDisk:
        def write(self, text: str) -> int:
            raise OSError(28, "No space left on device")

        def close(self) -> None:
            pass

    real = journal.Journal._write
    calls = []

    def full(self: journal.Journal, records: list[dict[str, object]]) -> None:
        calls.append(len(records))
        if len(calls) > 1:  # the header went in; then the disk is full
            self._file = FullDisk()  # type: ignore[assignment]
        real(self, records)

    monkeypatch.setattr(journal.Journal, "_write", full)
    with pytest.warns(RuntimeWarning, match="journal .* cannot be written .*No space left"):
        table = cd.sweep(case, {"k": [1.0, 2.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)
    assert list(table["status"]) == ["completed", "completed"] and len(load(tmp_path)) == 2


def test_temporary_files_a_kill_left_do_not_block_the_folder(tmp_path: Path) -> None:
    def case(k: float) -> cd.Scene:
        return cd.scenes.linear_book()

    (tmp_path / "trajectories").mkdir()
    (tmp_path / "trajectories" / ".run-000009.npz.tmp").write_text("half")
    (tmp_path / ".table.parquet.tmp").write_text("half")
    cd.sweep(case, {"k": [1.0]}, duration=0.01, executor="serial", out=tmp_path, progress=False)
    assert not (tmp_path / ".table.parquet.tmp").exists() and not (tmp_path / "trajectories").exists()
