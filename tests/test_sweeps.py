"""Sweeps: every run a row whatever it does, the same rows on every executor (serial, local
processes, a local Dask cluster) bit for bit, a row rerun bit for bit, Ctrl-C keeping the finished
rows, and the errors a user gets for a bad sweep."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import object_start
from coopdyn.sweeps import load, load_spec, rerun
from coopdyn.sweeps.cases import TIMING, expand

ROOT = Path(__file__).resolve().parent.parent
TIMING_COLUMNS = list(TIMING)


def make_case(stiffness: float = 1e4, gain: float = 2000.0, mode: str = "ok", seed: int | None = None) -> cd.Case:
    """A short two-Panda case; ``mode`` makes it raise, kill its process or diverge."""
    if mode == "raise":
        raise ValueError("this case is broken on purpose")
    if mode == "crash":
        os._exit(3)
    if mode == "segfault":
        os.kill(os.getpid(), signal.SIGSEGV)
    if seed is not None:  # Monte Carlo: the gain drawn around its nominal value
        gain *= 1.0 + 0.2 * np.random.default_rng(seed).standard_normal()
    scene = cd.scenes.facing_arms("panda", stiffness=stiffness, damping=0.002)
    task = GripLiftOscillate(start=object_start(scene), squeeze=20.0, t_grip=0.1, t_lift=0.1, lift_duration=0.2, amplitude=0.0)
    controller = ObjectImpedance(scene, task, stiffness=(gain, gain / 20))
    if mode == "diverge":  # rk4 at 5 ms: beyond its limit (1.7 ms at 1e4 N/m)
        return cd.Case(scene, controller, integrator="rk4", dt=5e-3)
    return cd.Case(scene, controller)


def peak_speed(result: cd.Result, case: cd.Case) -> dict[str, float]:
    return {"peak_speed": float(np.abs(result.v).max())}


def reproducible(table: pd.DataFrame) -> pd.DataFrame:
    return table.drop(columns=TIMING_COLUMNS)


GRID = {"stiffness": [1e4, 2e4], "gain": [1000.0, 4000.0], "mode": ["ok", "diverge", "raise"]}


def test_expand_grid_samples_and_seeds() -> None:
    items = expand({"a": [1, 2], "b": ["x", "y", "z"], "c": 7.0}, seeds=2)
    assert len(items) == 12
    assert [i.run for i in items] == list(range(12))
    assert items[0].params == {"a": 1, "b": "x", "c": 7.0} and items[0].seed == 0 and items[1].seed == 1
    assert items[2].params["b"] == "y" and items[-1].params == {"a": 2, "b": "z", "c": 7.0}  # the first name varies slowest
    samples = expand([{"a": 1}, {"a": 3}], seeds=[5])
    assert [(i.params["a"], i.seed) for i in samples] == [(1, 5), (3, 5)]
    frame = expand(pd.DataFrame({"a": [1.5, 2.5], "k": [np.float64(1e4), 2e4]}), None)
    assert frame[1].params == {"a": 2.5, "k": 2e4} and type(frame[1].params["k"]) is float
    assert expand({"pair": [[1.0, 2.0], (3, 4)]}, None)[1].params["pair"] == [3, 4]  # list-valued parameters
    assert expand(None, None)[0].params == {}


@pytest.mark.parametrize(
    ("params", "seeds", "match"),
    [
        ({"status": [1]}, None, "reserved"),
        ({"a": []}, None, "no values"),
        ("abc", None, "params must be"),
        ({"a": [object()]}, None, "a value must be a number"),
        ({"a": [1]}, 0, "seeds must be a count from 1 to 1e\\+07"),
        ({"a": [1]}, [1, -2], r"integers from 0 to 2\*\*63"),
        ({"a": [1]}, 1.5, "seeds must be a count"),
        ({"a": [1.0, "x"]}, None, r"mixes kinds of value \(number, str\)"),
        ({"a": [True, 2]}, None, r"mixes kinds of value \(bool, number\)"),
        ({"a": [10**30]}, None, "does not fit a table's 64-bit integers"),
        ({"a": range(10**4), "b": range(10**4)}, None, "a grid of 1e\\+08 combinations"),
        ({"a": [1]}, 10**12, r"seeds must be a count from 1 to 1e\+07 \(what one sweep holds\)"),
    ],
)
def test_bad_parameters_are_refused(params: object, seeds: object, match: str) -> None:
    with pytest.raises(cd.SweepError, match=match):
        expand(params, seeds)


def test_sweep_arguments_are_checked_before_anything_runs(tmp_path: Path) -> None:
    with pytest.raises(cd.SweepError, match="cannot take the parameters"):
        cd.sweep(make_case, {"stifness": [1e4]}, duration=0.1, executor="serial")
    with pytest.raises(cd.SweepError, match="seeds are passed as seed"):
        cd.sweep(lambda stiffness: None, {"stiffness": [1e4]}, seeds=2, duration=0.1, executor="serial")
    with pytest.raises(cd.SweepError, match="unknown executor"):
        cd.sweep(make_case, None, duration=0.1, executor="dask")
    with pytest.raises(cd.SweepError, match="workers must be"):
        cd.sweep(make_case, None, duration=0.1, workers=0)
    with pytest.raises(cd.SweepError, match="chunk_size"):
        cd.sweep(make_case, None, duration=0.1, chunk_size=0)
    with pytest.raises(cd.SweepError, match="duration must be a finite number"):
        cd.sweep(make_case, None, duration=float("inf"))
    with pytest.raises(cd.SweepError, match="integrator must be one of"):
        cd.sweep(make_case, None, duration=0.1, integrator="euler")
    with pytest.raises(cd.SweepError, match="give out=a folder"):
        cd.sweep(make_case, None, duration=0.1, trajectories=True)
    with pytest.raises(cd.SweepError, match="executor must be"):
        cd.sweep(make_case, None, duration=0.1, executor=42)
    with pytest.raises(cd.SweepError, match="executor must be"):
        cd.sweep(make_case, None, duration=0.1, executor=np.array(["serial", "processes"]))
    with pytest.raises(cd.SweepError, match="progress must be True or False, got 'no'"):
        cd.sweep(make_case, None, duration=0.1, progress="no")
    with pytest.raises(cd.SweepError, match="trajectories must be True or False"):
        cd.sweep(make_case, None, duration=0.1, out=tmp_path, trajectories="yes")
    for call in (lambda: load(3), lambda: load_spec(3), lambda: rerun(3, 1), lambda: load_spec("a\0b.toml")):
        with pytest.raises(cd.SweepError, match="must be a path"):
            call()
    with pytest.raises(cd.SweepError, match=r"run_spec takes a spec from coopdyn\.sweeps\.load_spec"):
        cd.sweeps.run_spec("spec.toml")
    import threading

    lock = threading.Lock()
    with pytest.raises(cd.SweepError, match="executor='serial'"):
        cd.sweep(lambda: lock and make_case(), None, duration=0.1, executor="processes", progress=False)


def test_a_sweep_with_diverging_and_raising_cases_finishes(tmp_path: Path) -> None:
    table = cd.sweep(make_case, GRID, duration=0.3, metrics=peak_speed, executor="serial", out=tmp_path, progress=False)
    assert len(table) == 12 and list(table["run"]) == list(range(12))
    by_mode = table.groupby("mode")["status"].unique()
    assert list(by_mode["ok"]) == ["completed"]
    assert list(by_mode["diverge"]) == ["diverged"]
    assert list(by_mode["raise"]) == ["failed"]
    diverged = table[table["status"] == "diverged"].iloc[0]
    assert "rk4 is stable while" in diverged["message"]  # the stability diagnosis
    assert diverged["t_reached_s"] < 0.3 and np.isnan(diverged["tracking_error_max_m"])
    failed = table[table["status"] == "failed"].iloc[0]
    assert failed["message"].startswith("ValueError: this case is broken on purpose (at test_sweeps.py:")
    ok = table[table["status"] == "completed"]
    assert (ok["t_reached_s"] == 0.3).all() and (ok["loop"] == "compiled").all()
    assert (ok["tracking_error_max_m"] < 0.05).all() and (ok["peak_speed"] > 0).all()
    assert (ok["internal_force_end_N"] > 5.0).all()  # gripped (20 N commanded since 0.1 s; the grasp mode still rings)
    assert (table["coopdyn_version"] == cd.__version__).all()
    assert set(table["integrator"].dropna()) == {"rk4"}  # the sweep's default, and the diverging cases' own
    saved = load(tmp_path)
    pd.testing.assert_frame_equal(saved, table, check_dtype=False)
    assert saved.attrs["coopdyn.sweep"]["source"]["qualname"] == "make_case"


def test_processes_and_a_users_executor_give_the_serial_rows_and_isolate_a_crash() -> None:
    grid = {**GRID, "mode": ["ok", "diverge", "raise", "crash", "segfault"]}
    serial = cd.sweep(make_case, {**grid, "mode": ["ok", "diverge", "raise"]}, duration=0.3, executor="serial", progress=False)
    local = cd.sweep(make_case, grid, duration=0.3, workers=2, chunk_size=3, progress=False)
    crashed = local[local["mode"] == "crash"]
    assert (crashed["status"] == "crashed").all() and len(crashed) == 4
    assert crashed["message"].str.contains("died \\(exit code 3\\)").all()
    segfault = local[local["mode"] == "segfault"]["message"]
    assert segfault.str.contains("SIGSEGV\\); faulthandler: File .*test_sweeps.py., line \\d+ in make_case").all()
    others = local[~local["mode"].isin(["crash", "segfault"])].drop(columns="run").reset_index(drop=True)
    expected = serial.drop(columns="run").reset_index(drop=True)
    pd.testing.assert_frame_equal(reproducible(others), reproducible(expected), check_exact=True)
    with ProcessPoolExecutor(2) as pool:  # any concurrent.futures.Executor
        theirs = cd.sweep(make_case, {**grid, "mode": ["ok", "raise"]}, duration=0.3, executor=pool, progress=False)
    assert list(theirs["status"]) == ["completed", "failed"] * 4
    ok = serial[serial["mode"] == "ok"]["tracking_error_max_m"].to_numpy()
    assert np.array_equal(theirs[theirs["mode"] == "ok"]["tracking_error_max_m"].to_numpy(), ok)


def test_a_local_dask_cluster_gives_the_serial_table_exactly() -> None:
    distributed = pytest.importorskip("distributed")
    grid = {"stiffness": [1e4, 2e4], "gain": [1000.0, 4000.0], "mode": ["ok", "raise"]}
    serial = cd.sweep(make_case, grid, seeds=2, duration=0.3, executor="serial", progress=False)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        remote = cd.sweep(make_case, grid, seeds=2, duration=0.3, executor=client, chunk_size=3, progress=False)
        pids = {int(w.split(":")[1]) for w in remote["worker"]}
    assert os.getpid() not in pids  # ran on the cluster's processes
    assert remote.attrs["coopdyn.sweep"]["executor"].startswith("Dask at tcp://127.0.0.1:")
    pd.testing.assert_frame_equal(reproducible(remote), reproducible(serial), check_exact=True)
    ok = serial[serial["status"] == "completed"]
    assert ok.groupby(["stiffness", "gain"])["tracking_error_max_m"].nunique().eq(2).all()  # the seeds differ


def test_a_row_reruns_bit_for_bit(tmp_path: Path) -> None:
    from coopdyn.__main__ import main

    table = cd.sweep(
        make_case, GRID, seeds=[4], duration=0.3, metrics=peak_speed, workers=2, out=tmp_path, trajectories=True, progress=False
    )
    for run in (0, 3, 4):  # completed, diverged, failed
        report = rerun(tmp_path / "table.parquet", run, make_case=make_case, metrics=peak_speed)
        assert report.identical, report.differences
    assert {c for c, _, _ in report.compared} >= {"tracking_error_max_m", "peak_speed", "message", "n_rhs", "seed"}
    assert main(["sweep", "--rerun", str(tmp_path), "0", "--trust"]) == 0
    here = f"{Path(__file__).resolve()}"
    assert main(["sweep", "--rerun", str(tmp_path), "0", "--case", f"{here}:make_case", "--metrics", f"{here}:peak_speed"]) == 0
    saved = cd.Result.load(tmp_path / "trajectories" / table.loc[0, "trajectory"])  # trajectories reload
    assert saved.t[-1] == 0.3 and np.isclose(float(np.abs(saved.v).max()), table.loc[0, "peak_speed"])
    import pyarrow.parquet as pq

    arrow = pq.read_table(tmp_path / "table.parquet")
    column = arrow.column("tracking_error_max_m").to_pylist()
    column[0] *= 1.0 + 1e-15
    arrow = arrow.set_column(arrow.schema.get_field_index("tracking_error_max_m"), "tracking_error_max_m", [column])
    pq.write_table(arrow, tmp_path / "table.parquet")
    report = rerun(tmp_path, 0, trust=True)
    assert report.differences == ("tracking_error_max_m",)
    assert main(["sweep", "--rerun", str(tmp_path), "0", "--trust"]) == 1
    with pytest.raises(cd.SweepError, match="not 99"):
        rerun(tmp_path, 99, trust=True)
    with pytest.raises(cd.SweepError, match="workers must be"):  # refused before the earlier sweep is touched
        cd.sweep(make_case, None, duration=0.1, workers=0, out=tmp_path)
    assert (tmp_path / "table.parquet").is_file() and (tmp_path / "trajectories").is_dir()


def test_ctrl_c_keeps_the_finished_rows(tmp_path: Path) -> None:
    calls = []

    def interrupted(stiffness: float) -> cd.Case:
        calls.append(stiffness)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return make_case(stiffness)

    with pytest.raises(cd.SweepInterrupted, match="after 2 of 4 runs") as info:
        cd.sweep(interrupted, {"stiffness": [1e4, 2e4, 3e4, 4e4]}, duration=0.2, executor="serial", out=tmp_path, progress=False)
    table = info.value.table
    assert list(table["status"]) == ["completed", "completed", "not run", "not run"]
    assert info.value.saved == tmp_path / "table.parquet"
    assert list(load(tmp_path)["status"]) == list(table["status"])


def test_ctrl_c_stops_the_worker_processes(tmp_path: Path) -> None:
    """SIGINT to a sweep on local processes (after some runs finished): it stops within seconds,
    exit code 130, and the table holds the finished runs and the others as "not run"."""
    script, done = tmp_path / "slow.py", tmp_path / "done"
    done.mkdir()
    script.write_text(
        textwrap.dedent(
            f"""
            import os, sys, time
            sys.path.insert(0, {str(ROOT / "tests")!r})
            import coopdyn as cd
            from test_sweeps import make_case

            def slow(i):
                time.sleep(0.25)
                open(os.path.join({str(done)!r}, str(i)), "w").close()
                return make_case()

            if __name__ == "__main__":
                try:
                    out = {str(tmp_path / "out")!r}
                    cd.sweep(slow, {{"i": list(range(400))}}, duration=0.05, workers=2, chunk_size=1, out=out, progress=False)
                except cd.SweepInterrupted as exc:
                    print("interrupted", exc, flush=True)
                    sys.exit(130)
            """
        )
    )
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while len(list(done.iterdir())) < 4 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    t = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err[-2000:]
    assert time.perf_counter() - t < 10
    statuses = load(tmp_path / "out")["status"].value_counts()
    assert statuses.get("completed", 0) >= 2 and statuses.get("not run", 0) > 0, statuses  # (up to 2 in flight)
    assert "interrupted after" in out


SPEC = """
[scene]
builder = "facing_arms"
robot = "panda"
stiffness = 1e4
damping = 0.002

[controller]
type = "object_impedance"

[task]
type = "grip_lift_oscillate"
t_grip = 0.1

[simulation]
duration = 0.2
integrator = "implicit_euler"
dt = 1e-3

[sweep]
folder = "out"

[sweep.grid]
"scene.stiffness" = [1e4, 1e5]
"controller.stiffness" = [[1000.0, 50.0], [2000.0, 100.0]]

[sweep.heatmap]
x = "scene.stiffness"
y = "controller.stiffness"
values = ["tracking_error_max_m", "peak_internal_force_N"]
limits = { tracking_error_max_m = 0.05 }
"""


def test_a_spec_runs_from_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from coopdyn.__main__ import main

    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    assert main(["sweep", str(spec), "--workers", "2"]) == 0
    printed = capsys.readouterr().out
    assert "4 runs on 2 local processes" in printed and "4 completed" in printed
    table = load(tmp_path / "out")
    assert list(table.columns[:4]) == ["run", "scene.stiffness", "controller.stiffness", "seed"]
    assert table["controller.stiffness"].map(list).tolist() == [[1000.0, 50.0], [2000.0, 100.0]] * 2
    assert (tmp_path / "out" / "heatmap.png").stat().st_size > 10_000
    assert rerun(tmp_path / "out", 3).identical
    assert main(["simulate", str(spec), "--out", str(tmp_path / "base")]) == 0  # a spec is a scene file: its base case
    # the same sweep by hand, through the Python API, gives the same numbers
    by_hand = cd.sweep(
        lambda k, gains: _spec_case(k, gains),
        {"k": [1e4, 1e5], "gains": [[1000.0, 50.0], [2000.0, 100.0]]},
        duration=0.2,
        integrator="implicit_euler",
        save_every=10,
        executor="serial",
        progress=False,
    )
    assert np.array_equal(by_hand["tracking_error_max_m"].to_numpy(), table["tracking_error_max_m"].to_numpy())


def _spec_case(k: float, gains: list[float]) -> cd.Case:
    scene = cd.scenes.facing_arms("panda", stiffness=k, damping=0.002)
    task = GripLiftOscillate(start=object_start(scene), t_grip=0.1)
    return cd.Case(scene, ObjectImpedance(scene, task, stiffness=tuple(gains)), task)


def test_random_draws_per_seed(tmp_path: Path) -> None:
    spec = tmp_path / "mc.toml"
    spec.write_text(
        SPEC.replace(
            '[sweep.grid]\n"scene.stiffness" = [1e4, 1e5]\n',
            '[sweep.grid]\n"scene.stiffness" = [1e4, 1e5]\n[sweep.random]\n"task.squeeze" = {uniform = [10.0, 30.0]}\n'
            '"object.mass" = {choice = [1.0]}\n',
        )
        .replace('"controller.stiffness" = [[1000.0, 50.0], [2000.0, 100.0]]\n', "")
        .replace('folder = "out"', 'folder = "out"\nseeds = 3')
        .split("[sweep.heatmap]")[0]
    )
    with pytest.raises(cd.SweepError, match="no \\[object\\] table"):
        load_spec(spec)
    spec.write_text(spec.read_text().replace('"object.mass" = {choice = [1.0]}\n', ""))
    loaded = load_spec(spec)
    draws = [(i.params["scene.stiffness"], i.seed, i.params["task.squeeze"]) for i in loaded.items]
    assert len(draws) == 6 and all(10.0 <= d[2] <= 30.0 for d in draws)
    assert [d[2] for d in draws[:3]] == [d[2] for d in draws[3:]]  # the same draws at every grid point
    assert draws[0][2] == float(np.random.default_rng(0).uniform(10.0, 30.0))
    assert load_spec(spec).items == loaded.items


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda s: s.replace("[sweep]\n", "[sweep]\nworkers = 2\n"), r"line \d+: \[sweep\] workers: unknown key"),
        (lambda s: s.replace('"scene.stiffness"', '"scene.stifness"'), "first run .* does not build.*stifness"),
        (lambda s: s.replace('"scene.stiffness"', '"scenery.stiffness"'), "a swept value is named 'table.key'"),
        (lambda s: s.replace("[sweep]\n", "[sweep]\nseeds = 2\n"), "seeds without \\[sweep.random\\]"),
        (lambda s: s.replace('"scene.stiffness" = [1e4, 1e5]', '"scene.stiffness" = 1e4'), "non-empty list"),
        (lambda s: s.replace('x = "scene.stiffness"', 'x = "k"'), "give x and y"),
        (
            lambda s: s.replace('"tracking_error_max_m", "peak', '"tracking_error_max", "peak'),
            "values \\['tracking_error_max'\\]",
        ),
        (
            lambda s: s.replace('"scene.stiffness" = [1e4, 1e5]', '"interconnections.-1.stiffness" = [1e4]'),
            "no \\[interconnections\\]",
        ),
        (lambda s: s.split("[sweep]")[0], "no \\[sweep\\] table"),
        (
            lambda s: s.replace("tracking_error_max_m = 0.05", 'tracking_error_max_m = "5 cm"'),
            r"limits must be a table metric = largest sensible value .*got \{'tracking_error_max_m': '5 cm'\}",
        ),
        (lambda s: s.replace("tracking_error_max_m = 0.05", "tracking_error = 0.05"), r"limits must be a table metric"),
        (
            lambda s: s.replace("[sweep.grid]", "[sweep.random]").replace(
                "[[1000.0, 50.0], [2000.0, 100.0]]", "{gauss = [1, 2]}"
            ),
            "seeds",
        ),
    ],
)
def test_spec_errors_name_the_problem(tmp_path: Path, edit: object, match: str) -> None:
    spec = tmp_path / "bad.toml"
    spec.write_text(edit(SPEC))  # type: ignore[operator]
    with pytest.raises(cd.CoopdynError, match=match):
        load_spec(spec)


def test_the_dask_options_name_the_install(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from coopdyn.__main__ import main

    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    assert main(["sweep", str(spec), "--local-cluster", "2"]) == 2
    assert 'pip install -e ".[dask]" in the coopdyn repository' in capsys.readouterr().err
    assert main(["sweep", str(spec), "--serial", "--local-cluster", "2"]) == 2
    capsys.readouterr()
    assert main(["sweep", str(spec), "--serial", "--workers", "2"]) == 2  # --workers sizes the local processes only
    assert (
        "choose one of --workers, --serial, --scheduler, --local-cluster (got --workers and --serial)" in capsys.readouterr().err
    )
    assert main(["sweep", str(spec), "--local-cluster", "0"]) == 2
    capsys.readouterr()
    assert main(["sweep", str(spec), "--chunk-size", "0"]) == 2
    assert "--chunk-size N needs N >= 1, got 0" in capsys.readouterr().err
    assert main(["sweep"]) == 2


def test_a_spec_on_a_local_dask_cluster_from_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    from coopdyn.__main__ import main

    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    assert main(["sweep", str(spec), "--local-cluster", "2", "--out", str(tmp_path / "dask")]) == 0
    assert "on Dask at tcp://127.0.0.1" in capsys.readouterr().out
    assert main(["sweep", str(spec), "--serial", "--out", str(tmp_path / "serial")]) == 0
    pd.testing.assert_frame_equal(
        reproducible(load(tmp_path / "dask")), reproducible(load(tmp_path / "serial")), check_exact=True
    )


def test_heatmap_labels_and_cells(tmp_path: Path) -> None:
    from coopdyn.viz.plotting import column_label, sweep_heatmap

    assert column_label("tracking_error_max_m") == ("tracking error max [mm]", 1e3)
    assert column_label("peak_internal_force_N") == ("peak internal force [N]", 1.0)
    table = pd.DataFrame(
        {
            "k": [1.0, 1.0, 2.0, 2.0],
            "g": [[1, 2], [3, 4], [1, 2], [3, 4]],
            "status": ["completed", "diverged", "completed", "completed"],
            "err_m": [0.001, np.nan, 0.002, 0.003],
        }
    )
    fig = sweep_heatmap(table, "k", "g", "err_m", tmp_path / "h.png", xlabel="k [N/m]")
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts == ["1", "2", "diverged", "3"]
    assert fig.axes[0].get_xlabel() == "k [N/m]" and fig.axes[0].get_ylabel() == "g"
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == ["(1, 2)", "(3, 4)"]
    assert (tmp_path / "h.png").stat().st_size > 5_000
    with pytest.raises(ValueError, match="no column 'x'"):
        sweep_heatmap(table, "x", "g", "err_m")


def test_heatmap_marks_completed_runs_that_warned_or_pass_a_bound(tmp_path: Path) -> None:
    """A completed run that warned (its warnings column) or whose metric passes a sanity bound is
    not an ordinary cell: it is hatched and says how many runs did; a clean cell is not."""
    from coopdyn.viz.plotting import sweep_heatmap

    table = pd.DataFrame(
        {
            "k": [1.0, 1.0, 2.0, 2.0, 2.0],
            "g": [1, 2, 1, 2, 2],
            "status": ["completed"] * 5,
            "warnings": ["", "AccuracyWarning: implicit_euler ...", "", "", "EnergyBalanceWarning: ..."],
            "tracking_error_max_m": [0.002, 0.679, 0.003, 0.004, 0.005],
        }
    )
    fig = sweep_heatmap(table, "k", "g", "tracking_error_max_m", tmp_path / "h.png", limits={"tracking_error_max_m": 0.05})
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts == ["2", "3", "679\nwarned\nbeyond bound", "4.5\n1/2 warned"]
    assert len(fig.axes[0].patches) == 2  # the two doubtful cells hatched
    assert fig.get_supxlabel() == (
        "hatched: completed runs that warned (the table's warnings column) or exceed tracking error max [mm] > 50"
    )
    clean = sweep_heatmap(table.assign(warnings=""), "k", "g", "tracking_error_max_m")
    assert not clean.axes[0].patches and not clean.get_supxlabel()
    for bad in ({"nope": 1.0}, {"tracking_error_max_m": float("nan")}, {"tracking_error_max_m": "1"}):
        with pytest.raises(cd.SweepError, match=r"no column 'nope'|limits\['tracking_error_max_m'\] must be a finite number"):
            sweep_heatmap(table, "k", "g", "tracking_error_max_m", limits=bad)  # type: ignore[arg-type]


def test_heatmap_shows_an_unstable_loop_as_such(tmp_path: Path) -> None:
    """A run whose loop was unstable from the start — completed with an UnstableLoopWarning, or
    diverged saying so — is an "unstable loop" cell, not a figure (another step would give
    another); a divergence for another reason stays "diverged"."""
    from coopdyn.accuracy import UNSTABLE_AT_START
    from coopdyn.viz.plotting import sweep_heatmap

    table = pd.DataFrame(
        {
            "k": [1.0, 2.0, 3.0, 4.0, 5.0],
            "g": [1, 1, 1, 1, 1],
            "status": ["completed", "completed", "diverged", "diverged", "failed"],
            "warnings": ["", "UnstableLoopWarning: The closed loop …", "", "", "UnstableLoopWarning: The closed loop …"],
            "message": [
                "",
                "",
                f"the simulation diverged … {UNSTABLE_AT_START}: linearised …",
                "the simulation diverged …",
                "KeyError: 'x' (at metrics.py:3 in metrics)",
            ],
            "tracking_error_max_m": [0.002, 0.357, np.nan, np.nan, np.nan],
        }
    )
    fig = sweep_heatmap(table, "k", "g", "tracking_error_max_m", tmp_path / "h.png")
    assert [t.get_text() for t in fig.axes[0].texts] == ["2", "unstable loop", "unstable loop", "diverged", "failed"]


def test_sweep_example(tmp_path: Path) -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("sweep_gains", ROOT / "examples" / "sweep_gains.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    table = module.main(out=str(tmp_path), duration=0.3, executor="serial", stiffness=[1e4], gain=[1000.0, 4000.0])
    assert list(table["status"]) == ["completed", "completed"]
    assert (tmp_path / "heatmap.png").stat().st_size > 10_000
    assert rerun(tmp_path, 1, make_case=f"{ROOT / 'examples' / 'sweep_gains.py'}:make_case").identical


def test_the_schema_knows_the_sweep_table() -> None:
    """docs/scene-file.schema.json describes [sweep] with the keys the spec reader takes, and the
    shipped spec passes it."""
    import json

    import jsonschema

    from coopdyn.io.scenefile import tomllib
    from coopdyn.io.schema import SWEEP
    from coopdyn.sweeps.spec import DISTRIBUTIONS, SWEEP_KEYS

    assert set(SWEEP["properties"]) == set(SWEEP_KEYS)
    assert set(SWEEP["properties"]["random"]["additionalProperties"]["properties"]) == set(DISTRIBUTIONS)
    schema = json.loads((ROOT / "docs" / "scene-file.schema.json").read_text())
    for path in (ROOT / "examples" / "sweeps").glob("*.toml"):
        jsonschema.validate(tomllib.loads(path.read_text()), schema)
        assert len(load_spec(path).items) > 1
    bad = tomllib.loads(SPEC.replace("[sweep]\n", "[sweep]\nworkers = 2\n"))
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_parameter_sets_must_name_the_same_parameters_and_settings_are_checked_up_front() -> None:
    """A sample without a parameter the others have would be a column with holes (and a row that
    reruns without it); bad settings are refused once instead of failing every row."""

    def make_case(**params: float) -> cd.Scene:
        raise AssertionError("never built")

    with pytest.raises(cd.SweepError, match=r"the same parameters in the same order: \['a'\] and \['a', 'b'\]"):
        cd.sweep(make_case, [{"a": 1}, {"a": 2, "b": 3}], duration=0.1)
    for kwargs, message in (
        ({"max_steps": -1}, "max_steps must be an integer >= 1"),
        ({"max_steps": "x"}, "max_steps must be an integer >= 1"),
        ({"dt": 1e-15}, "dt must be >= 1e-12"),
        ({"dt": float("nan")}, "dt"),
        ({"save_every": 0}, "save_every must be an integer >= 1"),
        ({"energy_check": "loud"}, "energy_check must be one of"),
        ({"accuracy_check": "maybe"}, r"accuracy_check must be one of \['auto', 'screen', 'off'\]"),
    ):
        with pytest.raises(cd.SweepError, match=message):
            cd.sweep(make_case, {"a": [1]}, duration=0.1, **kwargs)  # type: ignore[arg-type]


def test_a_table_parquet_cannot_store_still_reaches_the_user(tmp_path: Path) -> None:
    """Every run finished; a metric Parquet cannot store (an integer beyond 64 bits) makes saving
    fail with a SweepError that says why and carries the whole table."""
    book = cd.scenes.linear_book()
    with pytest.raises(cd.SweepError, match="cannot be stored as Parquet") as info:
        cd.sweep(
            lambda k: cd.Case(book, duration=0.01), {"k": [1, 2]}, metrics=lambda r, c: {"huge": 10**30},
            executor="serial", out=tmp_path, progress=False,
        )  # fmt: skip
    assert list(info.value.table["status"]) == ["completed", "completed"]
    assert not (tmp_path / "table.parquet").exists()


def test_a_bad_step_is_a_failed_row_saying_so() -> None:
    """dt = 0 or NaN in a case: that row fails with the check's message (not a division by zero)."""
    book = cd.scenes.linear_book()
    table = cd.sweep(
        lambda dt: cd.Case(book, duration=0.01, dt=dt), {"dt": [0.0, float("nan"), 1e-3]}, executor="serial", progress=False
    )
    assert list(table["status"]) == ["failed", "failed", "completed"]
    assert list(table["message"][:2]) == ["SweepError: dt must be > 0 [s], got 0.0", "SweepError: dt must be finite, got nan"]


def test_heatmap_refuses_what_it_cannot_draw() -> None:
    from coopdyn.viz.plotting import sweep_heatmap

    table = pd.DataFrame({"k": [1.0, 2.0], "g": [1, 1], "status": ["completed"] * 2, "m": [1.0, 2.0], "name": ["a", "b"]})
    for values, match in (([], "at least one metric"), (None, "at least one metric"), ("name", "'name' is not numeric")):
        with pytest.raises(cd.SweepError, match=match):
            sweep_heatmap(table, "k", "g", values)
    with pytest.raises(cd.SweepError, match="no rows to draw"):
        sweep_heatmap(table.iloc[:0], "k", "g", "m")
    with pytest.raises(cd.SweepError, match="takes a sweep table"):
        sweep_heatmap([1, 2], "k", "g", "m")


def test_workers_with_an_executor_of_its_own_is_refused() -> None:
    with pytest.raises(cd.SweepError, match="workers sizes the local processes"):
        cd.sweep(lambda a: cd.scenes.linear_book(), {"a": [1]}, duration=0.01, executor="serial", workers=2)


def test_a_failed_rows_message_is_the_same_on_every_executor(tmp_path: Path) -> None:
    """A script's make_case reaches local workers by value (cloudpickle names its code
    ``<dynamic-code>``): the failed row still names the script, as a serial run does, and
    the row reruns identical."""
    script = tmp_path / "study.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import json, sys
            import coopdyn as cd

            def make_case(k):
                if k > 1:
                    raise ValueError("broken on purpose")
                return cd.scenes.linear_book()

            if __name__ == "__main__":
                out = {{}}
                for name, executor in (("serial", "serial"), ("processes", None)):
                    table = cd.sweep(make_case, {{"k": [1, 2]}}, duration=0.01, executor=executor, progress=False,
                                     out={str(tmp_path)!r} + "/" + name)
                    out[name] = table["message"].tolist()
                print(json.dumps(out))
            """
        )
    )
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    import json

    messages = json.loads(run.stdout.strip().splitlines()[-1])
    assert messages["serial"] == messages["processes"] == ["", "ValueError: broken on purpose (at study.py:7 in make_case)"]
    assert rerun(tmp_path / "processes", 1, make_case=f"{script}:make_case").identical


def test_a_sweep_passes_its_accuracy_check_to_every_run(tmp_path: Path) -> None:
    """implicit Euler at 2 ms on k = 1e5 N/m under the object-impedance task: with "screen" the
    rows carry the screen's warning (no second run), with "off" none, with "auto" the checked one."""
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance

    def make_case(k: float) -> cd.Case:
        scene = cd.scenes.facing_arms("panda", stiffness=k)
        return cd.Case(scene, ObjectImpedance(scene, GripLiftOscillate(start=cd.scenes.object_start(scene), squeeze=20.0)))

    warned, estimate = {}, {}
    for check in ("auto", "screen", "off"):
        table = cd.sweep(
            make_case, {"k": [1e5]}, duration=0.5, integrator="implicit_euler", dt=2e-3, executor="serial",
            progress=False, energy_check="off", accuracy_check=check,
        )  # fmt: skip
        warned[check] = str(table["warnings"][0])
        estimate[check] = table["force_error_estimate_N"][0] if "force_error_estimate_N" in table else float("nan")
    assert "checked against dopri5" in warned["auto"] and estimate["auto"] > 0
    assert np.isnan(estimate["screen"]) and np.isnan(estimate["off"])
    assert "not checked against a reference run: accuracy_check='screen'" in warned["screen"]
    assert "AccuracyWarning" not in warned["off"]


def test_the_demo_a_scene_file_and_a_sweep_report_the_same_metrics_under_the_same_names(tmp_path: Path) -> None:
    """One set of names (coopdyn.metrics.METRICS) at every front door: the demo's summary, a
    scene file run's report and a sweep table's columns; the same run gives the same values."""
    import dataclasses

    from coopdyn.demo import run_demo
    from coopdyn.io.scenefile import load, run
    from coopdyn.metrics import METRICS

    demo = run_demo(tmp_path / "demo", t_final=0.3, html=False, progress=False)
    assert {k for k in demo if k.endswith(("_m", "_N")) and k != "commanded_internal_force_N"} <= set(METRICS)
    loaded = load(ROOT / "examples" / "scenes" / "two_pandas.toml")
    loaded = dataclasses.replace(loaded, duration=0.3)
    report = run(loaded, folder=tmp_path / "file", progress=False)
    assert set(report.metrics) <= set(METRICS) and "internal_force_end_N" in report.metrics
    table = cd.sweep(
        lambda: cd.Case(loaded.scene, controller=loaded.controller, task=loaded.task),
        {},
        duration=0.3,
        dt=loaded.dt,
        integrator=loaded.integrator,
        save_every=loaded.save_every,
        executor="serial",
        progress=False,
    )
    row = table.iloc[0]
    for name, value in report.metrics.items():
        assert row[name] == pytest.approx(value, rel=1e-12), name
