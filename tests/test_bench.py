"""The benchmark machinery on a small sweep (the full one is `coopdyn bench`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from coopdyn import bench


def test_work_precision_rows_and_outputs(tmp_path: Path) -> None:
    case = bench.linear_case(0.5)
    rows = bench.work_precision([case], ["symplectic_euler", "rk4", "exponential"], quick=True, repeats=1, progress=False)
    assert {r.method for r in rows} == {"symplectic_euler", "rk4", "exponential"}
    for method in ("symplectic_euler", "rk4"):
        errs = [r.wrench_error for r in rows if r.method == method]
        assert all(r.stable for r in rows if r.method == method)
        assert errs == sorted(errs, reverse=True)  # smaller dt, smaller error
    rk4 = [r for r in rows if r.method == "rk4"]
    assert np.log2(rk4[0].wrench_error / rk4[-1].wrench_error) / (len(rk4) - 1) > 3.0  # ~4th order per halving
    assert all(r.n_rhs > 0 and r.cpu_per_sim_s > 0 for r in rows)
    csv = bench.write_csv(rows, tmp_path / "wp.csv")
    assert csv.read_text().splitlines()[0].startswith("scene,method,setting,dt,rtol,position_error")
    again = bench.read_csv(csv)
    assert [r.setting for r in again] == [r.setting for r in rows]
    assert [r.wrench_error for r in again] == [r.wrench_error for r in rows]  # repr round-trips floats
    assert [r.stable for r in again] == [r.stable for r in rows]
    assert bench.plot_work_precision(rows, tmp_path / "wp.png").stat().st_size > 10_000
    assert "force err [N]" in bench.format_rows(rows)
    # a scene named with more after its stiffness (the peer bench's elastic-joint task) is drawn too:
    # "k=1e+05," once failed to parse and the whole 20-minute run ended in a ValueError
    elastic = [dataclasses.replace(r, scene="task k=1e+05, elastic joints") for r in rows]
    figure = bench.plot_work_precision(elastic, tmp_path / "elastic.png")
    assert figure.stat().st_size > 10_000


def test_diverging_points_are_marked_not_dropped() -> None:
    case = bench.panda_case(1e6, t_final=0.02)
    rows = bench.work_precision([case], ["symplectic_euler"], quick=True, repeats=1, progress=False)
    first = rows[0]  # dt = 5 ms, far beyond the explicit limit (~1 ms)
    assert not first.stable and math.isinf(first.wrench_error)
    assert "DIVERGED" in bench.format_rows(rows)


def test_peer_comparison_on_the_panda_scene() -> None:
    """coopdyn vs MuJoCo on the Panda scene: both simulators' runs, errors against the same
    reference (MuJoCo RK4 and coopdyn rk4 at the same small step agree with it alike), and the
    table of cheapest runs per force level."""
    import pytest

    pytest.importorskip("mujoco")
    from coopdyn.bench.panda_peers import compare, format_comparison

    result = compare((1e4,), t_final=0.05, quick=True, rounds=1, progress=False)
    rows = {(r.method, r.setting): r for r in result["rows"]}
    assert result["checks"]["pandas k=1e+04 (MuJoCo)"] < 1e-12
    mine, theirs = rows["rk4", "dt=0.000625"], rows["mujoco RK4", "dt=0.000625"]
    assert mine.stable and theirs.stable
    assert theirs.wrench_error == pytest.approx(mine.wrench_error, rel=0.05)  # the same method on the same system
    python = rows["mujoco RK4 (Python callbacks)", "dt=0.000625"]  # the labelled second row: the same run
    assert python.wrench_error == pytest.approx(theirs.wrench_error, rel=1e-6)
    assert result["checks"]["pandas k=1e+04 (MuJoCo, Python callbacks)"] < 1e-12
    table = format_comparison(result)
    assert "pandas k=1e+04" in table and "1 panda k=1e+04" in table and "MuJoCo, compiled callbacks" in table
    assert "best peer with Python callbacks" in table and "load average" in table
    assert result["checks"]["1 panda k=1e+04 (MuJoCo)"] < 1e-12  # the chain holding the box, too
    if "pandas k=1e+04 (Drake)" in result["checks"]:  # Drake installed: checked, timed and tabled
        assert max(v for k, v in result["checks"].items() if k.endswith("(Drake)")) < 1e-12
        assert {"drake discrete", "drake runge_kutta3"} <= {r.method for r in result["rows"]}
        assert "MuJoCo, Drake, Exudyn" in table or "MuJoCo, Drake" in table


def test_peer_comparison_on_elastic_joints_is_mujoco_only() -> None:
    """The task on arms with elastic joints against MuJoCo (motors as hinges with armature,
    transmissions as tendons): the accelerations checked equal, MuJoCo's RK4 at a small step
    as accurate as coopdyn's, and neither Drake nor Exudyn in the rows (they refuse elastic
    joints)."""
    import pytest

    pytest.importorskip("mujoco")
    from coopdyn.bench.cases import ELASTIC_JOINTS
    from coopdyn.bench.panda_peers import compare

    result = compare((1e5,), t_final=0.05, quick=True, rounds=1, progress=False, task=True, joints=ELASTIC_JOINTS)
    assert result["checks"]["task k=1e+05, elastic joints (MuJoCo)"] < 1e-12
    rows = {(r.method, r.setting): r for r in result["rows"]}
    mine, theirs = rows["rk4", "dt=0.000625"], rows["mujoco RK4", "dt=0.000625"]
    assert mine.stable and theirs.stable
    assert theirs.wrench_error == pytest.approx(mine.wrench_error, rel=0.05, abs=1e-9)
    assert not {r.method.split()[0] for r in result["rows"]} & {"drake", "exudyn"}


def test_single_threaded_blas_limits_then_restores() -> None:
    """Inside ``single_threaded_blas`` (what the benchmarks time under) every BLAS library numpy and
    scipy loaded runs one thread (an idle pool's spinning would be charged to the next timed run);
    the limit in force before is restored after."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from coopdyn.bench import single_threaded_blas

    def blas_threads() -> set[int]:
        return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}

    with threadpool_limits(limits=2, user_api="blas"):
        assert blas_threads() == {2}
        with single_threaded_blas():
            assert blas_threads() == {1}
        assert blas_threads() == {2}


def test_peer_comparison_runs_only_the_tables_and_stiffnesses_asked_for(tmp_path: Path, monkeypatch) -> None:
    """``coopdyn bench --peers --tables task --stiffness 1e7``: one row of the comparison — only
    that table is run, at that stiffness, and only its files are written."""
    import pytest

    pytest.importorskip("mujoco")
    from coopdyn.bench import panda_peers

    calls = []
    case = bench.linear_case(0.5)
    rows = bench.work_precision([case], ["rk4"], quick=True, repeats=1, progress=False)

    def fake_compare(stiffnesses, **keywords):  # records what would run; the rows of a tiny real sweep
        calls.append((tuple(stiffnesses), keywords.get("task", False), keywords.get("joints") is not None))
        return {"rows": rows, "checks": {}, "rounds": 1, "t_final": 0.5, "task": keywords.get("task", False), "load": (0.0, 0.0)}

    monkeypatch.setattr(panda_peers, "compare", fake_compare)
    result = bench.run_peer_comparison(tmp_path, quick=True, progress=False, tables=["task"], stiffnesses=[1e7])
    assert calls == [((1e7,), True, False)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["task_peers.csv", "task_peers.png"]
    assert set(result["files"]) == {"task_rows", "task_chart"} and "rows" not in result
    calls.clear()
    bench.run_peer_comparison(tmp_path / "all", quick=True, progress=False)
    assert calls == [((1e4, 1e6), False, False), ((1e4, 1e6), True, False), ((1e5,), True, True)]  # (quick)


@pytest.mark.parametrize(
    ("tables", "stiffnesses", "message"),
    [
        (["tasks"], None, "tables must be"),
        ([], None, "tables must be"),
        (None, [0.0], "stiffness"),
        (None, [math.nan], "stiffness"),
        (None, [], "at least one"),
    ],
)
def test_peer_comparison_refuses_unknown_tables_and_bad_stiffnesses(
    tmp_path: Path, tables: list[str] | None, stiffnesses: list[float] | None, message: str
) -> None:
    """Refused before anything runs (MuJoCo need not be installed to be told)."""
    import pytest

    from coopdyn.errors import SimulationError

    with pytest.raises(SimulationError, match=message):
        bench.run_peer_comparison(tmp_path / "no", quick=True, progress=False, tables=tables, stiffnesses=stiffnesses)
    assert not (tmp_path / "no").exists()
