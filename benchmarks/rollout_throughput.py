"""Throughput of coopdyn.rollout: B open-loop trajectories of the demo's scene (two Pandas, 2 kg
box, k = 1e4 N/m; gravity compensation plus random torques, one row per 10 ms), implicit Euler
at 1 ms, on 1 thread and on every core, interleaved round by round, medians of wall time.

    .venv/bin/python benchmarks/rollout_throughput.py [--batch 16] [--seconds 0.5] [--rounds 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import pinocchio as pin

import coopdyn as cd
from coopdyn.bench import single_threaded_blas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=0.5, help="simulated time per trajectory [s]")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    period, N = 0.01, round(args.seconds / 0.01)
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    U = g + np.random.default_rng(0).normal(scale=2.0, size=(args.batch, N, scene.n_actuated))
    cores = os.cpu_count() or 1
    wall: dict[int, list[float]] = {1: [], cores: []}
    load = [os.getloadavg()[0]]
    with single_threaded_blas():
        cd.rollout(scene, U[:2], period=period, dt=1e-3, threads=1)  # (warm: the URDF caches, the first kernel)
        for _ in range(args.rounds):
            for threads in wall:
                t0 = time.perf_counter()
                out = cd.rollout(scene, U, period=period, dt=1e-3, threads=threads)
                wall[threads].append(time.perf_counter() - t0)
                assert out.status.count("done") == args.batch
            load.append(os.getloadavg()[0])
    w1, wn = statistics.median(wall[1]), statistics.median(wall[cores])
    steps = args.batch * N * 10
    print(
        f"{args.batch} rollouts of {args.seconds:g} s (implicit Euler, 1 ms: {steps} steps), median of {args.rounds} interleaved "
        f"rounds; load average {min(load):.2f}–{max(load):.2f}"
    )
    print(f"{'threads':>8} {'wall [s]':>9} {'steps/s':>10}")
    print(f"{1:>8} {w1:9.3f} {steps / w1:10.0f}")
    print(f"{cores:>8} {wn:9.3f} {steps / wn:10.0f}")
    print(f"throughput on {cores} threads / on 1: {w1 / wn:.2f}")


if __name__ == "__main__":
    main()
