"""What an interconnection element without a C++ twin costs, now that the kernel calls it.

Two Pandas holding a box (k = 1e4 N/m, D = 0.002 K, gravity compensation + PD 50/5, perturbed
start), trapezoid at 1 ms for ``--seconds``, three ways, interleaved run by run in one process
(medians of ``--repeats``):

* ``all compiled``: both interconnections the built-in SE(3) spring (C++ twin);
* ``one Python element``: one of them a Python-only copy of the same law (a subclass registered
  without a twin), so the kernel calls its Python ``evaluate`` each evaluation and the rest of
  the scene and the step loop stay compiled;
* ``all Python``: the whole run on the Python dynamics and loop (what such a scene got before
  elements fell back one by one).

The three runs give the same trajectory to round-off (checked here). Prints CPU per step and the
ratios, with the load average.

    .venv/bin/python benchmarks/python_element_cost.py [--seconds 1] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import warnings
from typing import ClassVar

import numpy as np

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.control import GravityCompensationPD
from coopdyn.model.elements import ELEMENTS, SE3Spring, register


class PythonSE3Spring(SE3Spring):
    """The SE(3) spring under another name, registered without a C++ twin."""

    kind: ClassVar[str] = "se3_python_only"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time per run [s] (default 1)")
    parser.add_argument("--repeats", type=int, default=5, help="runs of each variant (default 5)")
    args = parser.parse_args()
    register(PythonSE3Spring)
    try:
        base = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
        specs = list(base.interconnection_specs)
        mixed = cd.Scene(base.arm_specs, base.object, [specs[0], _python_only(specs[1])], gravity=base.gravity)
        variants = {"all compiled": (base, "native"), "one Python element": (mixed, "native"), "all Python": (mixed, "python")}
        v0 = np.random.default_rng(1).normal(size=base.nv) * 0.3
        cpu: dict[str, list[float]] = {name: [] for name in variants}
        runs: dict[str, cd.Result] = {}
        with single_threaded_blas(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for _ in range(args.repeats):
                for name, (scene, backend) in variants.items():
                    res = cd.simulate(
                        scene, args.seconds, controller=GravityCompensationPD(scene), integrator="trapezoid", dt=1e-3,
                        v0=v0, backend=backend, accuracy_check="off", save_every=10,
                    )  # fmt: skip
                    cpu[name].append(res.cpu_time / res.n_steps)
                    runs[name] = res
        ref = runs["all compiled"]
        print(f"CPU per step [µs], median of {args.repeats} interleaved runs of {args.seconds:g} s, trapezoid at 1 ms; "
              f"two Pandas + box; load average {os.getloadavg()[0]:.2f}")  # fmt: skip
        print(f"{'variant':22s} {'backend':>8s} {'loop':>9s} {'µs/step':>9s} {'× all compiled':>15s} {'max |Δq|':>10s}")
        base_cost = statistics.median(cpu["all compiled"])
        for name, res in runs.items():
            cost = statistics.median(cpu[name])
            dq = float(np.max(np.abs(res.q - ref.q)))
            print(f"{name:22s} {res.backend:>8s} {res.loop:>9s} {cost * 1e6:9.2f} {cost / base_cost:15.2f} {dq:10.1e}")
    finally:
        ELEMENTS.pop(PythonSE3Spring.kind, None)


def _python_only(ic: cd.Interconnection) -> cd.Interconnection:
    import dataclasses

    return dataclasses.replace(ic, element=PythonSE3Spring.kind)


if __name__ == "__main__":
    main()
