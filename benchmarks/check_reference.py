"""Which reference the accuracy check can afford on a stiff scene: steps and force error.

Two Pandas holding the 8-element strip (``held_beam``, undamped grasps at k = 1e3, 1e5, 1e6
N/m, joint PD + gravity compensation) for ``--seconds``: dopri5 at rtol 1e-4 and ros2_adaptive
at the check's tolerances (``coopdyn.accuracy.STIFF_REFERENCE``) and at rtol 1e-5, each against
dopri5 at rtol 1e-8; the largest interconnection-force error relative to the peak force, the
accepted steps and the wall time (one run each; the load average printed).

    .venv/bin/python benchmarks/check_reference.py [--seconds 0.3]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

import coopdyn as cd
from coopdyn.accuracy import STIFF_REFERENCE
from coopdyn.control import GravityCompensationPD
from coopdyn.integrators import INTEGRATORS
from coopdyn.problems.facing_arms import held_beam


def forces(res: cd.Result) -> np.ndarray:
    return res.wrenches()[..., :3]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.3, help="simulated time [s] (default 0.3)")
    args = parser.parse_args()
    rtol, atol = STIFF_REFERENCE
    candidates = {
        "dopri5 rtol 1e-4": INTEGRATORS["dopri5"](rtol=1e-4, atol=1e-6),
        f"ros2_adaptive rtol {rtol:g}": INTEGRATORS["ros2_adaptive"](rtol=rtol, atol=atol),
        "ros2_adaptive rtol 1e-5": INTEGRATORS["ros2_adaptive"](rtol=1e-5, atol=1e-8),
    }
    print(f"{'k [N/m]':>8} {'method':>26} {'steps':>7} {'force error / peak':>19} {'wall [s]':>9}")
    for k in (1e3, 1e5, 1e6):
        scene = held_beam(stiffness=k)
        controller = GravityCompensationPD(scene)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            tight = INTEGRATORS["dopri5"](rtol=1e-8, atol=1e-10)
            ref = cd.simulate(scene, args.seconds, controller=controller, integrator=tight, max_steps=None, accuracy_check="off")
            print(f"{k:>8.0e} {'dopri5 rtol 1e-8':>26} {ref.n_steps:>7} {'(reference)':>19} {time.perf_counter() - t0:>9.2f}")
            F = forces(ref)
            peak = float(np.max(np.linalg.norm(F, axis=-1)))
            for name, method in candidates.items():
                t0 = time.perf_counter()
                res = cd.simulate(
                    scene, args.seconds, controller=controller, integrator=method, max_steps=None, accuracy_check="off"
                )
                wall = time.perf_counter() - t0
                error = float(np.max(np.linalg.norm(forces(res) - F, axis=-1))) / peak
                print(f"{k:>8.0e} {name:>26} {res.n_steps:>7} {error:>19.3%} {wall:>9.2f}")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
