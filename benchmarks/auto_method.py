"""What ``simulate(..., integrator="auto", accuracy=...)`` chooses on the demo's first second.

The demo's scene (two Pandas, 2 kg box, k = 1e4 N/m, damped grasps) under its task, from dt =
5 ms, for force accuracies of 1, 0.1, 1e-3 and 1e-6 N. Prints, per accuracy, the run chosen, its
force error against the search's dopri5 reference and against an independent dopri5 at rtol
1e-11, the candidates that met it with their CPU time, and the whole search's CPU time; with
the load average. CPU times vary run to run: between runs of near-equal cost the choice can
differ, and either meets the accuracy.

    .venv/bin/python benchmarks/auto_method.py [--t-final 1.0]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.integrators import DormandPrince
from coopdyn.scenes import object_start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-final", type=float, default=1.0, help="simulated time [s] (default 1)")
    args = parser.parse_args()
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    controller = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0))
    truth = cd.simulate(
        scene, args.t_final, controller=controller, integrator=DormandPrince(rtol=1e-11, atol=1e-14), dt=5e-3,
        accuracy_check="off", energy_check="off",
    )  # fmt: skip
    print(f"the demo's task, {args.t_final:g} s from dt = 5 ms; load average {os.getloadavg()[0]:.2f}")
    heads = f"{'accuracy [N]':>12} | {'chosen':<26} | {'error [N]':>9} | {'vs rtol 1e-11':>13} | {'search CPU [s]':>14}"
    print(heads + " | runs that met it (CPU)")
    for tolerance in (1.0, 0.1, 1e-3, 1e-6):
        said = io.StringIO()
        with contextlib.redirect_stderr(said):
            res = cd.simulate(
                scene, args.t_final, controller=controller, integrator="auto", dt=5e-3, accuracy=tolerance, progress=True
            )
        line = next(x for x in said.getvalue().splitlines() if "chose" in x)
        met = line.split("meets it (")[1].rstrip(")")
        chosen = res.integrator if res.integrator.startswith("dopri5") else f"{res.integrator} at {res.dt * 1e3:g} ms"
        error = float(np.max(np.linalg.norm(res.wrenches()[..., :3] - truth.wrenches()[..., :3], axis=-1)))
        estimate = res.force_error_estimate
        print(f"{tolerance:>12g} | {chosen:<26} | {estimate:>9.3g} | {error:>13.3g} | {res.cpu_time:>14.3f} | {met}")


if __name__ == "__main__":
    main()
