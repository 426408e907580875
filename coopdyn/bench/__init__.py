"""Work–precision and stability benchmarks (docs/physics.md, "Work–precision protocol").

``coopdyn bench`` (or :func:`run_benchmarks`) sweeps integrators × step sizes / tolerances on
named scenes, measures CPU time (median of repeated runs) and machine-independent counters,
compares with a reference of a *different* method, and writes a table (CSV) and charts (PNG).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..dynamics.backend import resolve
from ..integrators import INTEGRATORS
from .cases import ELASTIC_JOINTS, Case, Row, linear_case, panda_case
from .measure import _implicit_cost, peer_rows, rhs_timing, single_threaded_blas, stability_sweep, work_precision
from .report import (
    format_implicit_cost,
    format_peers,
    format_rows,
    format_stability,
    format_timing,
    plot_stability,
    plot_work_precision,
    read_csv,
    write_csv,
)
from .stability import is_stable_at, measure_stable_dt


def run_peer_comparison(
    out: str | os.PathLike[str] = "out/bench", *, quick: bool = False, progress: bool = True
) -> dict[str, Any]:
    """coopdyn against MuJoCo (with coopdyn's law compiled, and with it in Python), and Drake and
    Exudyn when installed (:mod:`.panda_peers`): the perturbed benchmark on two Pandas, k = 1e4
    and 1e6 N/m, and one Panda (a 7-link chain holding the box), k = 1e4; and the demo's task,
    damped, at k = 1e4 … 1e7 N/m (``"task"``), and on arms with elastic joints at k = 1e5 N/m
    against MuJoCo (``"elastic_joints"``: the motors as hinges with armature, the transmissions as
    tendons). Writes ``peers.csv``/``peers.png``, ``task_peers.csv``/``task_peers.png`` and
    ``elastic_joints_peers.csv``/``.png`` (work–precision, every simulator on the same axes) and
    returns the measurements with ``"report"`` (``coopdyn bench --peers`` prints it).

    Raises:
        MissingDependencyError: MuJoCo is not installed (``pip install -e ".[peers]"``).
    """
    from .._optional import require
    from .panda_peers import compare, format_comparison

    require("mujoco", "the MuJoCo peer", "coopdyn[peers]")
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    rounds = 1 if quick else 5
    with single_threaded_blas():
        result = compare(t_final=0.2 if quick else 1.0, quick=quick, rounds=rounds, progress=progress)
        task = compare(
            (1e4, 1e6) if quick else (1e4, 1e5, 1e6, 1e7),
            t_final=0.4 if quick else 1.25,
            quick=quick,
            rounds=rounds,
            progress=progress,
            task=True,
        )
        elastic = compare(
            (1e5,),
            t_final=0.4 if quick else 1.25,
            quick=quick,
            rounds=rounds,
            progress=progress,
            task=True,
            joints=ELASTIC_JOINTS,
        )
    files = {
        "rows": write_csv(result["rows"], out_dir / "peers.csv"),
        "chart": plot_work_precision(result["rows"], out_dir / "peers.png"),
        "task_rows": write_csv(task["rows"], out_dir / "task_peers.csv"),
        "task_chart": plot_work_precision(task["rows"], out_dir / "task_peers.png"),
        "elastic_rows": write_csv(elastic["rows"], out_dir / "elastic_joints_peers.csv"),
        "elastic_chart": plot_work_precision(elastic["rows"], out_dir / "elastic_joints_peers.png"),
    }
    report = "\n\n".join(
        [
            format_rows(result["rows"]),
            format_comparison(result),
            format_rows(task["rows"]),
            format_comparison(task),
            format_rows(elastic["rows"]),
            format_comparison(elastic),
            "\n".join(f"wrote {path}  ({name})" for name, path in files.items()),
        ]
    )
    return {**result, "task": task, "elastic_joints": elastic, "files": files, "report": report}


def run_benchmarks(out: str | os.PathLike[str] = "out/bench", *, quick: bool = False, progress: bool = True) -> dict[str, Any]:
    """The whole benchmark: work–precision, stability, timings; writes CSV and charts and returns
    the measurements with ``"report"``, the tables as text (``coopdyn bench`` prints it)."""
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stiffnesses = [1e4, 1e5, 1e6]
    cases = [linear_case(3.0)] + [panda_case(k, 0.1 if quick else 0.2) for k in stiffnesses]
    methods = [name for name, cls in INTEGRATORS.items() if "compiled_spec" in cls.__dict__]  # the built-ins (not scipy)
    with single_threaded_blas():
        rows = work_precision(cases, methods, quick=quick, repeats=1 if quick else 5, progress=progress)
        rows += peer_rows(cases[0], quick=quick, repeats=1 if quick else 5, progress=progress)
        stab = stability_sweep(stiffnesses + ([] if quick else [1e7]), progress=progress, quick=quick)
        timing = rhs_timing(200 if quick else 2000)
        implicit_cost = _implicit_cost([1e4, 1e7] if quick else [1e4, 1e5, 1e6, 1e7], 0.2 if quick else 1.0)
    files = {
        "rows": write_csv(rows, out_dir / "work_precision.csv"),
        "stability": write_csv(stab, out_dir / "stability.csv"),
        "chart": plot_work_precision(rows, out_dir / "work_precision.png"),
        "stability_chart": plot_stability(stab, out_dir / "stability.png"),
    }
    report = "\n\n".join(
        [
            f"work–precision and stability runs: {resolve()} backend\n" + format_rows(rows),
            format_stability(stab),
            format_timing(timing),
            format_implicit_cost(implicit_cost),
            format_peers(rows),
            "\n".join(f"wrote {path}  ({name})" for name, path in files.items()),
        ]
    )
    return {"rows": rows, "stability": stab, "timing": timing, "implicit_cost": implicit_cost, "files": files, "report": report}


__all__ = [
    "Case",
    "Row",
    "is_stable_at",
    "linear_case",
    "measure_stable_dt",
    "panda_case",
    "read_csv",
    "rhs_timing",
    "run_benchmarks",
    "run_peer_comparison",
    "single_threaded_blas",
    "stability_sweep",
    "work_precision",
]
