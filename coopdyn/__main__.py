"""Command line: ``coopdyn <command>`` (also ``python -m coopdyn``)."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .errors import CoopdynError, SimulationInterrupted


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
    from .io.scenefile import load, load_result
    from .viz.viewer import export_html, view

    loaded = load(args.scene_file)
    result = load_result(loaded, args.result)
    if args.html:
        print(f"wrote {export_html(result, args.html)}")
        return 0
    view(result, loops=args.loops, host=args.host)
    return 0


def _bench(args: argparse.Namespace) -> int:
    from .bench import run_benchmarks, run_peer_comparison

    run = run_peer_comparison if args.peers else run_benchmarks
    print(run(args.out, quick=args.quick)["report"])
    return 0


def _print_saved(exc: BaseException) -> None:
    """The files a failed run saved (set as ``saved`` by the demo and scene-file runs)."""
    for path in getattr(exc, "saved", ()):
        print(f"  wrote {path} (what the run had)")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    parser = argparse.ArgumentParser(prog="coopdyn", description="Multi-arm cooperating robots with elastic interconnections.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="two Pandas grip, lift and oscillate a box (the main job)")
    demo.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    demo.add_argument("--t-final", type=float, default=5.0, help="duration [s] (default: 5)")
    demo.add_argument("--dt", type=float, default=1e-3, help="time step [s] (default: 1e-3)")
    demo.add_argument("--integrator", default="implicit_euler", help="integrator name (default: implicit_euler)")
    demo.add_argument("--no-html", action="store_true", help="skip the HTML animation")
    demo.set_defaults(func=_demo)
    simulate = sub.add_parser("simulate", help="run a scene file (see examples/scenes/*.toml)")
    simulate.add_argument("scene_file", help="a .toml scene file")
    simulate.add_argument("--out", default=None, help="output folder (default: the file's [output] folder)")
    simulate.add_argument("--max-steps", type=int, default=2 * 10**6, help="refuse longer runs (default: 2000000; 0: no limit)")
    simulate.set_defaults(func=_simulate)
    view = sub.add_parser("view", help="play a scene file's saved result in a live meshcat viewer")
    view.add_argument("scene_file", help="the .toml scene file the result came from")
    view.add_argument("--result", default=None, help="trajectory .npz (default: <output folder>/trajectory.npz)")
    view.add_argument("--loops", type=int, default=None, help="play this many times (default: until Ctrl-C)")
    view.add_argument("--html", default=None, help="write a standalone HTML animation to this path instead")
    view.add_argument(
        "--host",
        default="127.0.0.1",
        help="address the viewer serves on (default 127.0.0.1: this machine only; others are warned about)",
    )
    view.set_defaults(func=_view)
    book = sub.add_parser("book", help="the book's linear cooperative system vs its exact solution (Figure 11)")
    book.add_argument("--out", default="out", help="output folder (default: out)")
    book.add_argument("--dt", type=float, default=5e-4, help="time step [s] (default: 5e-4)")
    book.add_argument("--t-final", type=float, default=3.0, help="duration [s] (default: 3)")
    book.add_argument("--integrator", default="rk4", help="integrator name (default: rk4)")
    book.set_defaults(func=_book)
    bench = sub.add_parser("bench", help="work–precision and stability benchmarks (tables, CSV, PNG)")
    bench.add_argument("--out", default="out/bench", help="output folder (default: out/bench)")
    bench.add_argument("--quick", action="store_true", help="few points, short runs, one repetition (CI)")
    bench.add_argument(
        "--peers", action="store_true", help="instead: coopdyn vs MuJoCo on the Panda scene, interleaved (needs mujoco)"
    )
    bench.set_defaults(func=_bench)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    t0 = time.perf_counter()
    try:
        code = int(args.func(args))
    except CoopdynError as exc:
        _print_saved(exc)
        print(f"coopdyn: error: {exc}", file=sys.stderr)
        return 2
    except SimulationInterrupted as exc:
        _print_saved(exc)
        print(f"coopdyn: {exc}", file=sys.stderr)
        return 130
    except KeyboardInterrupt as exc:
        print(f"coopdyn: interrupted{f' ({exc})' if str(exc) else ''}", file=sys.stderr)
        return 130
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
