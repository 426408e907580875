"""Work–precision and stability benchmarks (docs/physics.md, "Work–precision protocol").

``coopdyn bench`` (or :func:`run_benchmarks`) sweeps integrators × step sizes / tolerances on
named scenes, measures CPU time (median of repeated runs) and machine-independent counters,
compares with a reference of a *different* method, and writes a table (CSV) and charts (PNG).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .. import _validate
from ..dynamics.backend import resolve
from ..errors import SimulationError
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

#: the tables of ``coopdyn bench --peers``, in the order they run
PEER_TABLES = ("perturbed", "task", "elastic_joints")


def run_peer_comparison(
    out: str | os.PathLike[str] = "out/bench",
    *,
    quick: bool = False,
    progress: bool = True,
    tables: Sequence[str] | None = None,
    stiffnesses: Sequence[float] | None = None,
) -> dict[str, Any]:
    """coopdyn against MuJoCo (with coopdyn's law compiled, and with it in Python), and Drake and
    Exudyn when installed (:mod:`.panda_peers`): the perturbed benchmark on two Pandas, k = 1e4
    and 1e6 N/m, and one Panda (a 7-link chain holding the box), k = 1e4; and the demo's task,
    damped, at k = 1e4 … 1e7 N/m (``"task"``), and on arms with elastic joints at k = 1e5 N/m
    against MuJoCo (``"elastic_joints"``: the motors as hinges with armature, the transmissions as
    tendons). Writes ``peers.csv``/``peers.png``, ``task_peers.csv``/``task_peers.png`` and
    ``elastic_joints_peers.csv``/``.png`` (work–precision, every simulator on the same axes) and
    returns the measurements with ``"report"`` (``coopdyn bench --peers`` prints it).

    ``tables`` (of :data:`PEER_TABLES`; default all) runs only those tables and writes only their
    files; ``stiffnesses`` [N/m] replaces each selected table's (the one-Panda case of the
    perturbed table runs at the first) — one row of the comparison in minutes instead of the
    whole run's half hour.

    Raises:
        MissingDependencyError: MuJoCo is not installed (``pip install -e ".[peers]"``).
        SimulationError: an unknown table, or a stiffness that is not a positive finite number.
    """
    from .._optional import require
    from .panda_peers import compare, format_comparison

    chosen = _peer_tables(tables)
    ks = None if stiffnesses is None else _stiffnesses(stiffnesses)
    require("mujoco", "the MuJoCo peer", "coopdyn[peers]")
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    rounds = 1 if quick else 5
    # table → (its stiffnesses, compare's keywords, its files' stem, the prefix of its files' keys)
    plans: dict[str, tuple[tuple[float, ...], dict[str, Any], str, str]] = {
        "perturbed": ((1e4, 1e6), {"t_final": 0.2 if quick else 1.0}, "peers", ""),
        "task": (
            (1e4, 1e6) if quick else (1e4, 1e5, 1e6, 1e7),
            {"t_final": 0.4 if quick else 1.25, "task": True},
            "task_peers",
            "task_",
        ),
        "elastic_joints": (
            (1e5,),
            {"t_final": 0.4 if quick else 1.25, "task": True, "joints": ELASTIC_JOINTS},
            "elastic_joints_peers",
            "elastic_",
        ),
    }
    results: dict[str, dict[str, Any]] = {}
    with single_threaded_blas():
        for name in chosen:
            default, keywords, _, _ = plans[name]
            results[name] = compare(ks or default, quick=quick, rounds=rounds, progress=progress, **keywords)
    files: dict[str, Path] = {}
    for name, result in results.items():
        stem, prefix = plans[name][2:]
        files[f"{prefix}rows"] = write_csv(result["rows"], out_dir / f"{stem}.csv")
        files[f"{prefix}chart"] = plot_work_precision(result["rows"], out_dir / f"{stem}.png")
    parts = [text for result in results.values() for text in (format_rows(result["rows"]), format_comparison(result))]
    report = "\n\n".join([*parts, "\n".join(f"wrote {path}  ({name})" for name, path in files.items())])
    first = {k: v for k, v in results.get("perturbed", {}).items() if k != "task"}  # (its "task": False)
    return {**first, **{k: v for k, v in results.items() if k != "perturbed"}, "files": files, "report": report}


def _peer_tables(tables: Sequence[str] | None) -> list[str]:
    """The tables asked for, in :data:`PEER_TABLES`' order; an unknown one is refused."""
    if tables is None:
        return list(PEER_TABLES)
    if isinstance(tables, str):
        tables = [tables]
    unknown = [t for t in tables if t not in PEER_TABLES]
    if unknown or not tables:
        raise SimulationError(f"bench --peers: tables must be some of {list(PEER_TABLES)}, got {list(tables)}")
    return [t for t in PEER_TABLES if t in tables]


def _stiffnesses(values: Sequence[float]) -> tuple[float, ...]:
    """Positive finite stiffnesses [N/m], in the order given, without repeats."""
    out = []
    for k in values:
        x = _validate.positive(k, "bench --peers: stiffness", "N/m", SimulationError)
        if x not in out:
            out.append(x)
    if not out:
        raise SimulationError("bench --peers: give at least one stiffness [N/m]")
    return tuple(out)


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
    "PEER_TABLES",
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
