"""Cost of saving a long run: ``Result.save`` as ``.npz`` and as ``.csv``, side by side.

The demo's scene and task (two Pandas, trapezoid at 1 ms) simulated for ``--seconds`` with
every step saved; then each format written ``--repeats`` times, interleaved, medians printed
with the load average. The interconnection wrenches both files hold are computed once before
the timing (a ``Result`` keeps its readouts).

    .venv/bin/python benchmarks/save_cost.py [--seconds 120] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import object_start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=120.0, help="simulated time [s] (default 120)")
    parser.add_argument("--repeats", type=int, default=5, help="saves of each format (default 5)")
    args = parser.parse_args()
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    task = GripLiftOscillate(start=object_start(scene), squeeze=20.0)
    t0 = time.perf_counter()
    res = cd.simulate(scene, args.seconds, controller=ObjectImpedance(scene, task), integrator="trapezoid", dt=1e-3)
    simulated = time.perf_counter() - t0
    t0 = time.perf_counter()
    res.wrenches()
    readouts = time.perf_counter() - t0
    times: dict[str, list[float]] = {".npz": [], ".csv": []}
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(args.repeats):
            for suffix, spent in times.items():
                t0 = time.perf_counter()
                res.save(Path(folder) / f"run{suffix}")
                spent.append(time.perf_counter() - t0)
        sizes = {s: (Path(folder) / f"run{s}").stat().st_size for s in times}
    load = os.getloadavg()[0]
    print(f"{len(res.t):,} samples × {res.q.shape[1] + res.v.shape[1] + res.tau.shape[1] + 1} values + wrenches")
    print(f"simulate {simulated:.2f} s wall; readouts (once, shared) {readouts:.2f} s; load average {load:.2f}")
    for suffix, spent in times.items():
        print(f"  {suffix}: median {statistics.median(spent):.2f} s over {args.repeats} saves, {sizes[suffix] / 1e6:.0f} MB")
    ratio = statistics.median(times[".csv"]) / statistics.median(times[".npz"])
    print(f"  csv / npz: {ratio:.1f}×")


if __name__ == "__main__":
    main()
