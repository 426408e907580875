"""Sweep throughput on this machine: simulations per minute, serial vs local processes vs a
local Dask cluster, on the same sweep (examples/sweep_gains.py's grid: two Pandas, the
grip / lift / oscillate / hold task, 5 s per run with the trapezoid at 1 ms).

Rounds are interleaved (serial, processes, Dask; the order rotates each round) and the table
gives the median wall time per sweep and runs per minute; the local process pool is started by
each sweep (what a user pays), the Dask cluster once (its start-up is reported apart). Every
sweep's table is checked equal to the serial one (all columns but the timing ones).

    .venv/bin/python benchmarks/sweep_throughput.py [--rounds 3] [--workers 2] [--duration 5]
        [--out out/bench]   (writes sweep_throughput.csv and sweep_throughput.png)
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "examples"))

from sweep_gains import GAIN, STIFFNESS, make_case

import coopdyn as cd
from coopdyn.sweeps.cases import TIMING


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds per run")
    parser.add_argument("--out", default="out/bench")
    args = parser.parse_args()
    from distributed import Client, LocalCluster

    grid = {"stiffness": STIFFNESS, "gain": GAIN}
    n = len(STIFFNESS) * len(GAIN)
    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
    client = Client(cluster)
    startup = time.perf_counter() - t0
    engines = {"serial": "serial", f"processes ({args.workers})": "processes", f"Dask local cluster ({args.workers})": client}
    walls: dict[str, list[float]] = {name: [] for name in engines}
    reference = None
    skip = list(TIMING)  # what a rerun does not reproduce
    try:
        for r in range(args.rounds):
            names = list(engines)
            names = names[r % len(names) :] + names[: r % len(names)]
            for name in names:
                t = time.perf_counter()
                table = cd.sweep(
                    make_case,
                    grid,
                    duration=args.duration,
                    integrator="trapezoid",
                    dt=1e-3,
                    executor=engines[name],
                    workers=args.workers if engines[name] == "processes" else None,
                    progress=False,
                )
                walls[name].append(time.perf_counter() - t)
                same = table.drop(columns=skip)
                if reference is None:
                    reference = same
                elif not same.equals(reference):
                    raise SystemExit(f"{name}: the table differs from the first sweep's")
    finally:
        client.close()
        cluster.close()
    rows = []
    print(f"{n} runs of {args.duration:g} s per sweep, {args.rounds} interleaved rounds; Dask cluster start-up {startup:.1f} s")
    print(f"{'executor':<28} {'median wall [s]':>16} {'runs per minute':>16} {'vs serial':>10}")
    base = statistics.median(walls["serial"])
    for name, w in walls.items():
        m = statistics.median(w)
        rows.append((name, m, n / m * 60, base / m))
        print(f"{name:<28} {m:>16.2f} {n / m * 60:>16.0f} {base / m:>9.2f}×")
    print("every table equal to the first, bit for bit (timing columns aside)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "sweep_throughput.csv", "w") as f:
        f.write("executor,median_wall_s,runs_per_minute,speedup_vs_serial\n")
        f.writelines(f"{a},{b:.3f},{c:.1f},{d:.3f}\n" for a, b, c, d in rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 2.8), constrained_layout=True)
    ax.barh([r[0] for r in rows], [r[2] for r in rows], color=["#888888", "#1f77b4", "#ff7f0e"])
    for i, r in enumerate(rows):
        ax.text(r[2], i, f" {r[2]:.0f} ({r[3]:.2f}×)", va="center")
    ax.set_xlabel("simulations per minute (median)")
    ax.set_title(f"Sweep throughput: {n} runs × {args.duration:g} s, two Pandas, trapezoid 1 ms", fontsize=10)
    ax.invert_yaxis()
    ax.set_xlim(0, max(r[2] for r in rows) * 1.3)
    fig.savefig(out / "sweep_throughput.png", dpi=120)
    print(f"wrote {out / 'sweep_throughput.csv'}, {out / 'sweep_throughput.png'}")


if __name__ == "__main__":
    main()
