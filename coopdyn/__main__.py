"""Command line: ``coopdyn <command>`` (also ``python -m coopdyn``)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import logging
import os
import re
import sys
import time
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._signals import sigterm_as_interrupt
from .errors import CoopdynError, SimulationError, SimulationInterrupted, SweepError


def _book(args: argparse.Namespace) -> int:
    from . import scenes
    from .problems.linear_book import BookParameters, linear_book_exact
    from .simulate import simulate
    from .viz.plotting import book_figure

    params = BookParameters()
    scene = scenes.linear_book()
    d1, d2 = scenes.book_task(params)
    res = simulate(
        scene, args.t_final, controller=scenes.drives_controller(d1, d2), integrator=args.integrator, dt=args.dt, progress=True
    )
    exact = linear_book_exact(res.t, d1, d2, params)
    Y = scenes.book_positions(res.q, scene)
    dY = float(np.max(np.abs(Y - exact.Y)))
    dF = float(max(np.max(np.abs(res.wrench(0)[:, 2] - exact.Fc1)), np.max(np.abs(res.wrench(1)[:, 2] - exact.Fc2))))
    out = Path(args.out)
    png = out / "book_figure11.png"
    book_figure(res, exact, png)
    print(f"linear book system, {res.integrator} at dt = {res.dt:g} s over {args.t_final:g} s")
    per_second = res.cpu_time / max(args.t_final, 1e-300)
    print(f"  CPU {res.cpu_time:.3f} s ({per_second:.3f} CPU s per simulated s), {res.n_rhs} RHS evaluations")
    print(f"  vs exact solution: max |ΔY| = {dY:.3e} m, max |ΔFc| = {dF:.3e} N")
    print(f"  final Y1, Y2, Y3 = {Y[-1, 0]:.5f}, {Y[-1, 1]:.5f}, {Y[-1, 2]:.5f} m")
    print(f"  wrote {png}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from .demo import format_summary, run_demo

    print(format_summary(run_demo(args.out, t_final=args.t_final, dt=args.dt, integrator=args.integrator, html=not args.no_html)))
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from .io.scenefile import load, run

    print(run(load(args.scene_file), folder=args.out, max_steps=args.max_steps or None))
    return 0


def _view(args: argparse.Namespace) -> int:
    from .io.scenefile import load, load_result, open_result
    from .viz.viewer import export_html, view

    if args.result is not None:  # a scene file and a trajectory of its scene, named apart
        result = load_result(load(args.path), args.result)
    else:
        result = open_result(args.path).result
    if args.html is not None:  # an empty path is refused, not taken for "no --html"
        path = export_html(result, args.html, fps=args.fps, meshes=args.meshes or "collision")
        print(f"wrote {path} ({path.stat().st_size / 1e6:.3g} MB)")
        return 0
    view(result, fps=args.fps, loops=args.loops, host=args.host, meshes=args.meshes or "visual")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from .io.scenefile import open_result
    from .viz.plotting import result_figure

    saved = open_result(args.path, task=True)
    out = Path(args.out) if args.out else saved.path.with_name("plot.png")
    result_figure(saved.result, saved.task, out)
    print(f"wrote {out}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from .bench import run_benchmarks, run_peer_comparison

    if not args.peers:
        if args.tables or args.stiffness:
            raise SimulationError("bench: --tables and --stiffness select the peer comparison's runs; give --peers too")
        print(run_benchmarks(args.out, quick=args.quick)["report"])
        return 0
    print(run_peer_comparison(args.out, quick=args.quick, tables=args.tables, stiffnesses=args.stiffness)["report"])
    return 0


#: the keyword argument an error suggests to a Python caller, and the option the command line has instead
_MAX_STEPS = (
    re.compile(r"pass max_steps=None( \(or a larger number\))?", re.IGNORECASE),
    "give --max-steps 0 (no limit) or a larger number",
)


def _sweep(args: argparse.Namespace) -> int:
    from .sweeps import load_spec, rerun, run_spec
    from .sweeps.cases import RESERVED
    from .sweeps.table import TABLE_NAME

    if args.rerun:
        table, run = args.rerun
        try:
            number = int(run)
        except ValueError:
            raise SweepError(f"--rerun TABLE RUN: RUN is a run number, got {run!r}") from None
        report = rerun(table, number, make_case=args.case, metrics=args.metrics, trust=args.trust)
        return _print_rerun(report)
    for flag, value in (("--case", args.case), ("--metrics", args.metrics), ("--trust", args.trust or None)):
        if value is not None:
            raise SweepError(f"{flag} goes with --rerun TABLE RUN (it names the code that reruns a Python sweep's row)")
    if args.spec is None:
        raise SweepError("give a sweep spec (a scene file with a [sweep] table), or --rerun TABLE RUN")
    for flag, value in (("--workers", args.workers), ("--chunk-size", args.chunk_size)):
        if value is not None and value < 1:  # named as typed here; the library names its arguments
            raise SweepError(f"{flag} N needs N >= 1, got {value}")
    spec = load_spec(args.spec)
    if args.out is not None:
        from ._validate import path as as_path

        spec = dataclasses.replace(spec, folder=as_path(args.out, "--out DIR", SweepError).resolve())
    with _executor(args) as executor:
        table = run_spec(spec, executor=executor, workers=args.workers, chunk_size=args.chunk_size, resume=args.resume)
    meta = table.attrs["coopdyn.sweep"]
    counts = table["status"].value_counts()
    wall = meta["wall_s"]
    print(
        f"{len(table)} runs on {meta['executor']} in {wall:.1f} s wall "
        f"({len(table) / max(wall, 1e-9) * 60:.0f} runs per minute): "
        + ", ".join(f"{n} {status}" for status, n in counts.items())
    )
    done = table[table["status"] == "completed"]
    skip = {*RESERVED, *meta["params"]}  # the metrics' ranges, not the bookkeeping's
    for name in table.columns:
        if name not in skip and len(done) and table[name].dtype.kind == "f":
            col = done[name]
            print(f"  {name}: min {col.min():.4g}, median {col.median():.4g}, max {col.max():.4g}")
    others = table[table["status"] != "completed"]
    for _, row in others.head(10).iterrows():
        values = ", ".join(f"{k} = {row[k]}" for k in meta["params"])
        print(f"  run {row['run']} ({values}): {row['status']}: {row['message']}")
    if len(others) > 10:
        print(f"  … and {len(others) - 10} more runs that did not complete (status and message in the table)")
    print(f"  wrote {spec.folder / TABLE_NAME}")
    missing = [v for v in (spec.heatmap or {}).get("values", []) if v not in table.columns or not table[v].notna().any()]
    if spec.heatmap and missing:
        print(f"  no heat map: no completed run has {', '.join(missing)}")
    elif spec.heatmap:
        from .viz.plotting import sweep_heatmap

        png = spec.folder / "heatmap.png"
        h = spec.heatmap
        sweep_heatmap(
            table, h["x"], h["y"], h["values"], png, title=spec.path.name, xlabel=h.get("xlabel"), ylabel=h.get("ylabel"),
            limits=h.get("limits"),
        )  # fmt: skip
        print(f"  wrote {png}")
    print(f"  `coopdyn sweep --rerun {spec.folder / TABLE_NAME} RUN` runs a row again and compares it bit for bit")
    return 0


def _print_rerun(report: Any) -> int:
    width = max(len(c) for c, _, _ in report.compared)
    for column, stored, new in report.compared:
        mark = "  " if column not in report.differences else "≠ "
        print(f"{mark}{column:<{width}}  {_cell(stored):<24}  {_cell(new)}")
    if report.other_versions:
        print(f"versions differ from the row's: {', '.join(report.other_versions)}")
    if report.identical:
        print(
            f"run {report.run}: identical bit for bit in all {len(report.compared)} columns "
            "(cpu_s, wall_s, worker and trajectory not compared)"
        )
        return 0
    print(f"run {report.run}: {len(report.differences)} column(s) differ: {', '.join(report.differences)}")
    return 1


def _cell(value: Any) -> str:
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, float):
        return repr(value)
    text = str(value)
    return text if len(text) <= 60 else text[:57] + "..."


@contextlib.contextmanager
def _executor(args: argparse.Namespace) -> Iterator[Any]:
    """The executor the options choose; a Dask client (and a local cluster) closed on the way out."""
    options = {"workers": "--workers", "serial": "--serial", "scheduler": "--scheduler", "local_cluster": "--local-cluster"}
    chosen = [flag for attr, flag in options.items() if getattr(args, attr) not in (None, False)]
    if len(chosen) > 1:  # --workers sizes the local processes, which the other three replace
        raise SweepError(f"choose one of --workers, --serial, --scheduler, --local-cluster (got {' and '.join(chosen)})")
    if args.serial:
        yield "serial"
        return
    if args.scheduler is None and args.local_cluster is None:
        yield None
        return
    from ._optional import require

    distributed = require("distributed", "running a sweep on Dask (--scheduler, --local-cluster)", "coopdyn[dask]")
    with contextlib.ExitStack() as stack:
        if args.local_cluster is not None:
            if args.local_cluster < 1:
                raise SweepError(f"--local-cluster N needs N >= 1 workers, got {args.local_cluster}")
            cluster = stack.enter_context(
                distributed.LocalCluster(
                    n_workers=args.local_cluster, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
                )
            )
            client = stack.enter_context(distributed.Client(cluster))
        else:
            try:
                client = stack.enter_context(distributed.Client(args.scheduler, timeout="20s"))
            except (OSError, TimeoutError) as exc:
                raise SweepError(f"cannot reach the Dask scheduler at {args.scheduler}: {exc}") from exc
        yield client


def _cli_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int, line: str | None = None) -> str:
    """A warning as the command line prints it: what happened, without a line of coopdyn's source."""
    del filename, lineno, line
    return f"coopdyn: warning ({category.__name__}): {message}\n"


def _cli_message(exc: BaseException) -> str:
    """The error's message in command-line terms: where the trajectory was saved (not the Python
    attribute ``.result``: its ``detail``), command-line options instead of keyword arguments."""
    text = _MAX_STEPS[0].sub(_MAX_STEPS[1], getattr(exc, "detail", str(exc))).rstrip(".")
    if not text.endswith(("?", "!")):  # (a question keeps its own mark: no "?.")
        text += "."
    saved = [Path(p) for p in getattr(exc, "saved", ())]
    if saved:
        folder = saved[0].parent
        text += f"\nThe run so far was saved to {folder}/ ({', '.join(p.name for p in saved)}); `coopdyn view {folder}` plays it."
    return text


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    from . import __version__
    from .bench import PEER_TABLES
    from .integrators import INTEGRATORS

    methods = sorted(INTEGRATORS)
    parser = argparse.ArgumentParser(
        prog="coopdyn",
        description="Multi-arm cooperating robots holding one object through elastic interconnections.",
        epilog=(
            "`coopdyn COMMAND --help` describes a command. Exit codes: 0 done, 2 an error, 130 interrupted (Ctrl-C, SIGTERM, "
            "SIGHUP: what was done so far is saved)."
        ),
    )
    parser.add_argument("--version", action="version", version=f"coopdyn {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, summary: str, description: str) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=summary, description=description)

    def integrator_option(p: argparse.ArgumentParser, default: str) -> None:
        p.add_argument(
            "--integrator",
            default=default,
            choices=methods,
            metavar="NAME",
            help=f"one of {', '.join(methods)} (default: {default})",
        )

    demo = command(
        "demo",
        "two Pandas grip, lift and oscillate a box (the main job)",
        "Two Franka Pandas grip a 2 kg box through 1e4 N/m interconnections, lift it 10 cm, oscillate it sideways and "
        "hold it. Prints the tracking error, internal force and real-time factor; writes trajectory.npz/.csv, demo.png "
        "and demo.html (an animation that plays offline in a browser) to the output folder.",
    )
    demo.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    demo.add_argument("--t-final", type=float, default=5.0, help="duration [s] (default: 5)")
    demo.add_argument("--dt", type=float, default=1e-3, help="time step [s] (default: 1e-3)")
    integrator_option(demo, "trapezoid")
    demo.add_argument("--no-html", action="store_true", help="skip the HTML animation")
    demo.set_defaults(func=_demo)
    simulate = command(
        "simulate",
        "run a scene file (see examples/scenes/*.toml)",
        "Run the scene, controller, task and integrator a TOML scene file describes (format: docs/scene-files.md) and "
        "write its outputs (trajectory, plot, animation, a copy of the file) to its [output] folder.",
    )
    simulate.add_argument("scene_file", help="a .toml scene file")
    simulate.add_argument("--out", default=None, help="output folder (default: the file's [output] folder)")
    simulate.add_argument("--max-steps", type=int, default=2 * 10**6, help="refuse longer runs (default: 2000000; 0: no limit)")
    simulate.set_defaults(func=_simulate)
    view = command(
        "view",
        "play a saved result in meshcat (live, or as an HTML file)",
        "Play a saved result in a live meshcat viewer in the browser, or write it as a standalone HTML animation. "
        "PATH is a result file (trajectory.npz), an output folder holding one (from `coopdyn simulate` or "
        "`coopdyn demo`), or a scene file (the result in its [output] folder).",
    )
    view.add_argument("path", metavar="PATH", help="trajectory.npz, an output folder, or a .toml scene file")
    view.add_argument("--result", default=None, help="with a scene file: the trajectory .npz to play (default: its output's)")
    view.add_argument("--loops", type=int, default=None, help="play this many times (default: until Ctrl-C)")
    view.add_argument("--html", default=None, help="write a standalone HTML animation to this path instead")
    view.add_argument("--fps", type=float, default=30.0, help="frames per second of the animation (default: 30)")
    view.add_argument(
        "--meshes",
        choices=("visual", "collision"),
        default=None,
        help="the URDF geometry to draw (default: visual live, collision in --html: smaller files)",
    )
    view.add_argument(
        "--host",
        default="127.0.0.1",
        help="address the viewer serves on (default 127.0.0.1: this machine only; others are warned about)",
    )
    view.set_defaults(func=_view)
    plot = command(
        "plot",
        "plot a saved result (PNG)",
        "Draw the motion and the forces of a saved result: PATH as for `coopdyn view`. With a scene file (or the copy "
        "beside the result) the task's reference is drawn too.",
    )
    plot.add_argument("path", metavar="PATH", help="trajectory.npz, an output folder, or a .toml scene file")
    plot.add_argument("--out", default=None, help="the PNG to write (default: plot.png beside the result)")
    plot.set_defaults(func=_plot)
    book = command(
        "book",
        "the book's linear cooperative system vs its exact solution (Figure 11)",
        "Simulate the book's linear 1-DOF cooperative system (two drives, two springs, one object) and compare it with "
        "its exact solution; writes the book's Figure 11 with the deviation.",
    )
    book.add_argument("--out", default="out", help="output folder (default: out)")
    book.add_argument("--dt", type=float, default=5e-4, help="time step [s] (default: 5e-4)")
    book.add_argument("--t-final", type=float, default=3.0, help="duration [s] (default: 3)")
    integrator_option(book, "rk4")
    book.set_defaults(func=_book)
    bench = command(
        "bench",
        "work–precision and stability benchmarks (tables, CSV, PNG)",
        "CPU time against accuracy for every integrator on the book system and the Panda scene, and where each method "
        "loses stability; --peers compares with MuJoCo (and Drake and Exudyn when installed) in the same run.",
    )
    bench.add_argument("--out", default="out/bench", help="output folder (default: out/bench)")
    bench.add_argument("--quick", action="store_true", help="few points, short runs, one repetition (CI)")
    bench.add_argument(
        "--peers",
        action="store_true",
        help="instead: coopdyn vs MuJoCo, Drake and Exudyn on the Panda scenes, interleaved (needs mujoco; others if installed)",
    )
    bench.add_argument(
        "--tables",
        nargs="+",
        choices=PEER_TABLES,
        metavar="TABLE",
        help=f"with --peers, only these tables: {', '.join(PEER_TABLES)} (default: all)",
    )
    bench.add_argument(
        "--stiffness",
        nargs="+",
        type=float,
        metavar="K",
        help="with --peers, these interconnection stiffnesses [N/m] instead of each table's (the one-Panda case at the first)",
    )
    bench.set_defaults(func=_bench)
    sweep = command(
        "sweep",
        "run a parameter sweep (a scene file with a [sweep] table) into a table",
        "Run every combination of the values a scene file's [sweep] table lists (grid, random draws per seed), on local "
        "processes (default: every core) or a Dask cluster, into OUT/table.parquet: one row per run with its parameters, "
        "status (a diverging, failing or crashing run is a row, not an error), metrics, settings and versions "
        "(format: docs/sweeps.md). --rerun runs one row again and compares it bit for bit.",
    )
    sweep.add_argument("spec", nargs="?", metavar="SPEC", help="a .toml scene file with a [sweep] table")
    sweep.add_argument("--out", metavar="DIR", default=None, help="output folder (default: the spec's [sweep] folder)")
    sweep.add_argument("--workers", metavar="N", type=int, default=None, help="local processes (default: every core)")
    sweep.add_argument("--serial", action="store_true", help="run in this process, one after the other")
    sweep.add_argument(
        "--scheduler", metavar="ADDRESS", default=None, help="run on the Dask cluster at ADDRESS (needs coopdyn[dask])"
    )
    sweep.add_argument(
        "--local-cluster", metavar="N", type=int, default=None, help="start a local Dask cluster of N workers and run on it"
    )
    sweep.add_argument("--chunk-size", metavar="N", type=int, default=None, help="runs per task (default: automatic, up to 64)")
    sweep.add_argument(
        "--resume",
        action="store_true",
        help="finish the sweep that was writing to the folder when it stopped (killed, interrupted): its finished runs are kept",
    )
    sweep.add_argument("--rerun", nargs=2, metavar=("TABLE", "RUN"), default=None, help="run row RUN of TABLE again and compare")
    sweep.add_argument(
        "--case",
        metavar="WHERE",
        default=None,
        help="with --rerun of a Python sweep: its make_case, as MODULE:FUNCTION or FILE.py:FUNCTION (imports/runs that code)",
    )
    sweep.add_argument("--metrics", metavar="WHERE", default=None, help="with --rerun: the sweep's metrics function, as --case")
    sweep.add_argument(
        "--trust",
        action="store_true",
        help="with --rerun: load make_case and metrics from where the table records them (runs code the table names)",
    )
    sweep.set_defaults(func=_sweep)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    t0 = time.perf_counter()
    formatwarning = warnings.formatwarning
    warnings.formatwarning = _cli_warning  # printed warnings speak CLI (restored below: main() is also called in-process)
    try:
        with sigterm_as_interrupt():  # a killed job, a closed terminal: as Ctrl-C (a partial run or table is saved)
            code = int(args.func(args))
        print(f"done in {time.perf_counter() - t0:.1f} s")
    except BrokenPipeError:  # the reader went away (`coopdyn … | head`): nothing more to say, to anyone
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # (Python flushes stdout at exit)
        return 0
    except CoopdynError as exc:
        print(f"coopdyn: error: {_cli_message(exc)}\n(exit code 2)", file=sys.stderr)
        return 2
    except SimulationInterrupted as exc:
        print(f"coopdyn: {_cli_message(exc)}\n(exit code 130)", file=sys.stderr)
        return 130
    except KeyboardInterrupt as exc:
        print(f"coopdyn: interrupted{f' ({exc})' if str(exc) else ''}", file=sys.stderr)
        return 130
    finally:
        warnings.formatwarning = formatwarning
    return code


if __name__ == "__main__":
    raise SystemExit(main())
