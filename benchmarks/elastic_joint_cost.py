"""Cost per step of elastic joints: the demo's scene (two Pandas + 2 kg box, k = 1e4 N/m) with
rigid joints and with every joint elastic (K = 1e4 N·m/rad, B = 0.5 kg·m², D = 5 N·m·s/rad:
nv 20 → 34), ObjectImpedance holding the box, in the compiled loop.

CPU per accepted step of a whole ``simulate`` run (energy monitor on, one sample per 10 ms),
the two scenes interleaved run by run in one process, medians of ``--repeats``; the ratio is
elastic / rigid. Prints the load average beside the table.

    .venv/bin/python benchmarks/elastic_joint_cost.py [--repeats 5] [--seconds 1]
"""

from __future__ import annotations

import argparse
import os
import statistics

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.cooperative import ObjectImpedance

METHODS = ("symplectic_euler", "rk4", "implicit_euler", "ros2", "trapezoid", "generalized_alpha", "dopri5")
JOINTS = cd.JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time per run [s]")
    args = parser.parse_args()
    rigid = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    elastic = cd.Scene([a.replace(elasticity=JOINTS) for a in rigid.arm_specs], rigid.object, rigid.interconnection_specs)
    scenes = {"rigid": rigid, "elastic": elastic}
    controllers = {name: ObjectImpedance(scene) for name, scene in scenes.items()}
    times: dict[tuple[str, str], list[float]] = {}
    load = [os.getloadavg()[0]]
    with single_threaded_blas():
        for _ in range(args.repeats):
            for method in METHODS:
                dt = 2.5e-4 if method == "symplectic_euler" else 5e-4 if method == "rk4" else 1e-3
                for name, scene in scenes.items():
                    res = cd.simulate(
                        scene,
                        args.seconds,
                        controller=controllers[name],
                        integrator=method,
                        dt=dt,
                        save_every=round(0.01 / dt),
                        loop="compiled",
                        accuracy_check="off",  # timing only: no reference runs
                    )
                    times.setdefault((method, name), []).append(res.cpu_time / res.n_steps)
            load.append(os.getloadavg()[0])
    print(
        f"CPU per step [µs], compiled loop, median of {args.repeats} interleaved runs of {args.seconds:g} s; the demo's scene "
        f"(nv {rigid.nv}) and with elastic joints (nv {elastic.nv}); load average {min(load):.2f}–{max(load):.2f}"
    )
    print(f"{'method':18s} {'rigid':>9s} {'elastic':>9s} {'elastic/rigid':>14s}")
    for method in METHODS:
        r, e = (statistics.median(times[method, name]) * 1e6 for name in scenes)
        print(f"{method:18s} {r:9.2f} {e:9.2f} {e / r:14.2f}")


if __name__ == "__main__":
    main()
