"""How the cost of a held beam grows with its elements.

For each number of elements (``--elements``, default 8 16 32 48 64), in a fresh process so that its
peak memory is its own: ``coopdyn.scenes.held_beam(n_elements=n)`` (two Pandas holding the 0.8 m
aluminium strip by its ends, GravityCompensationPD), then

* the seconds to build the scene and to set up one ``coopdyn.Simulator`` for it, and the
  process's peak resident memory [GB] by then (Pinocchio's ``Data`` holds four nv × nv × nv
  tensors: the memory grows with the cube of the elements);
* the wall time per step [ms] of implicit Euler and the trapezoid at 1 ms, with the kernel's
  sparse Cholesky factor of the step matrix and with its dense one, interleaved run by run
  (medians of ``--rounds`` runs of ``--seconds`` each, BLAS on one thread).

Prints one row per size, the growth exponent of each column between the last two sizes, the load
average, and writes a chart (``--out``).

    .venv/bin/python benchmarks/beam_scale.py [--elements 8 16 32 48 64] [--rounds 5] [--seconds 0.05] [--out out/beam_scale.png]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

METHODS = ("implicit_euler", "trapezoid")
FACTORS = ("sparse", "dense")


def measure(n_elements: int, rounds: int, seconds: float) -> dict[str, float]:
    """One size, in this process: build and set-up times [s], peak memory [GB], ms per step."""
    import coopdyn as cd
    from coopdyn.bench import single_threaded_blas
    from coopdyn.control import GravityCompensationPD

    t0 = time.perf_counter()
    scene = cd.scenes.held_beam(n_elements=n_elements)
    built = time.perf_counter()
    sims = {METHODS[0]: cd.Simulator(scene, GravityCompensationPD(scene), METHODS[0], 1e-3)}
    out: dict[str, float] = {"nv": scene.nv, "build": built - t0, "setup": time.perf_counter() - built}
    out["memory"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9  # (Linux: kB) the scene and one Simulator
    sims |= {m: cd.Simulator(scene, GravityCompensationPD(scene), m, 1e-3) for m in METHODS[1:]}
    times: dict[str, list[float]] = {f"{m} {f}": [] for m in METHODS for f in FACTORS}
    with single_threaded_blas():
        for sim in sims.values():
            sim.run(seconds)  # (the compiled loop built once; the runs below restart it)
        for _ in range(rounds):
            for method, sim in sims.items():
                kernel = sim.system.dynamics._kernel  # type: ignore[attr-defined]
                for factor in FACTORS:
                    kernel.sparse_step_matrix = factor == "sparse"
                    t = time.perf_counter()
                    result = sim.run(seconds)
                    times[f"{method} {factor}"].append((time.perf_counter() - t) / result.n_steps * 1e3)
                kernel.sparse_step_matrix = True
        out["sparse"] = float(kernel.sparse_step_matrix)  # whether the scene has the sparse pattern at all
    return out | {name: statistics.median(t) for name, t in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--elements", type=int, nargs="+", default=[8, 16, 32, 48, 64], help="beam elements (default 8 16 32 48 64)"
    )
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds per size (default 5)")
    parser.add_argument("--seconds", type=float, default=0.05, help="simulated seconds per timed run (default 0.05)")
    parser.add_argument("--out", default="out/beam_scale.png", help="the chart (default out/beam_scale.png)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # (a child process: one size, JSON out)
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(measure(args.one, args.rounds, args.seconds)))
        return
    rows = []
    columns = [f"{m} {f}" for m in METHODS for f in FACTORS]
    print("two Pandas holding the aluminium strip (coopdyn.scenes.held_beam), dt = 1 ms, GravityCompensationPD")
    print(f"wall time per step [ms]: medians of {args.rounds} interleaved runs of {args.seconds:g} s")
    head = f"{'elements':>8} {'nv':>5} {'build [s]':>9} {'set-up [s]':>10} {'memory [GB]':>11} "
    print(head + " ".join(f"{c:>24}" for c in columns))
    for n in args.elements:
        cmd = [sys.executable, __file__, "--one", str(n), "--rounds", str(args.rounds), "--seconds", str(args.seconds)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            print(f"{n:>8} failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else done.returncode}")
            continue
        row = json.loads(done.stdout.strip().splitlines()[-1]) | {"elements": n}
        rows.append(row)
        print(
            f"{n:>8} {row['nv']:>5.0f} {row['build']:>9.2f} {row['setup']:>10.2f} {row['memory']:>11.2f} "
            + " ".join(f"{row[c]:>24.3f}" for c in columns)
        )
    if len(rows) >= 2:
        a, b = rows[-2], rows[-1]
        ratio = math.log(b["elements"] / a["elements"])
        slope = {c: math.log(b[c] / a[c]) / ratio for c in ["build", "setup", "memory", *columns]}
        print(f"growth exponent {a['elements']}→{b['elements']} elements: " + ", ".join(f"{c} {s:.2f}" for c, s in slope.items()))
    print(f"load average {os.getloadavg()[0]:.2f}")
    if rows:
        _chart(rows, columns, Path(args.out))


def _chart(rows: list[dict[str, float]], columns: list[str], out: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["elements"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for c, style in zip(columns, ("o-", "o--", "s-", "s--"), strict=True):
        ax1.loglog(n, [r[c] for r in rows], style, label=c.replace(" ", ", ") + " factor")
    ax1.set(xlabel="beam elements", ylabel="wall time per step [ms]", title="one step at 1 ms")
    ax2.loglog(n, [r["build"] + r["setup"] for r in rows], "o-", label="build + set-up [s]")
    ax2.loglog(n, [r["memory"] for r in rows], "s-", label="peak memory [GB]")
    ax2.set(xlabel="beam elements", title="building the scene and one Simulator")
    ax2.legend(fontsize=8)
    first = rows[0]["elements"]
    for c in (columns[0],):  # a guide: what linear growth from the smallest beam would cost
        ax1.loglog(n, [rows[0][c] * k / first for k in n], ":", color="grey", label="∝ elements (linear)")
    ax1.legend(fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xticks(n)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    fig.suptitle("Two Pandas holding an aluminium strip: cost against the strip's elements (benchmarks/beam_scale.py)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
