"""Steps and force error of the adaptive methods at their default tolerances, on the bench scenes.

``dopri5`` (order 5) and ``ros2_adaptive`` (order 2: its steps grow only as rtol^½) at their
defaults, and ``ros2_adaptive`` at dopri5's tolerances (rtol 1e-6, atol 1e-9: its defaults
until 2026-11-25) and ten times looser than its defaults (rtol 1e-2, atol 1e-5), on the book's
linear system and on two Pandas at k = 1e4 and 1e6 N/m (``coopdyn.bench.cases``: PD 50/5 +
gravity compensation, perturbed start), output every ``OUTPUT_INTERVAL``. Prints accepted and
rejected steps, the ratio to dopri5's steps and the largest interconnection-force error against
each case's tight reference, in newtons and as a share of the force's swing about its mean.

    .venv/bin/python benchmarks/adaptive_steps.py [--seconds 0.1]
"""

from __future__ import annotations

import argparse

import numpy as np

import coopdyn as cd
from coopdyn.bench.cases import OUTPUT_INTERVAL, linear_case, panda_case
from coopdyn.integrators import INTEGRATORS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.1, help="simulated time per run [s] (default 0.1)")
    args = parser.parse_args()
    cases = [linear_case(args.seconds), panda_case(1e4, args.seconds), panda_case(1e6, args.seconds)]
    methods = {
        "dopri5": INTEGRATORS["dopri5"](),
        "ros2_adaptive": INTEGRATORS["ros2_adaptive"](),
        "ros2_adaptive 1e-6/1e-9": INTEGRATORS["ros2_adaptive"](rtol=1e-6, atol=1e-9),
        "ros2_adaptive 1e-2/1e-5": INTEGRATORS["ros2_adaptive"](rtol=1e-2, atol=1e-5),
    }
    print(f"{'case':>16} {'method':>24} {'steps':>8} {'rejected':>8} {'× dopri5':>9} {'force error [N]':>16} {'of swing':>10}")
    for case in cases:
        base = None
        for name, method in methods.items():
            res = cd.simulate(
                case.scene,
                case.t_final,
                controller=case.controller,
                integrator=method,
                dt=OUTPUT_INTERVAL,
                v0=case.v0,
                max_steps=None,
                energy_check="off",
                accuracy_check="off",  # the force error is measured here
            )
            _, forces = case.reference(res)
            swing = float(np.max(np.linalg.norm(forces - forces.mean(axis=0), axis=-1)))  # the force signal [N]
            mine = res.wrenches()[..., :3]  # (n, L, 3) [N], as the reference's
            error = float(np.max(np.linalg.norm(mine - forces, axis=-1)))
            base = base or res.n_steps
            print(
                f"{case.name:>16} {name:>24} {res.n_steps:>8} {res.n_rejected:>8} {res.n_steps / base:>9.1f} {error:>16.3g} "
                f"{error / swing:>10.1%}"
            )


if __name__ == "__main__":
    main()
