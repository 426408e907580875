"""What a user's own Python controller costs, now that the compiled loop calls it back.

The same law three ways, interleaved run by run in one process (medians of ``--repeats``, BLAS on
one thread), on two Pandas holding a box (k = 1e4 N/m, D = 0.002 K, perturbed start, 1 s) and
on the book's linear system (drives, 3 s):

* ``built-in``: the built-in controller (GravityCompensationPD; the book's drives), compiled;
* ``Python, called back``: the same law as a plain Python function (what a user writes), called
  from the compiled loop at every evaluation;
* ``Python loop``: the same function with ``loop="python"`` (where such a controller ran before);
* ``Python at 1 kHz``: the Python function sampled at 1 kHz with a zero-order hold
  (``control_dt=1e-3``: one call per millisecond, as a robot's controller runs), and
  ``built-in at 1 kHz``, the built-in law sampled the same way.

Prints CPU per step and the ratios to the built-in run (called at every evaluation), with the
load average. The first three runs of each case give the same trajectory to round-off, and the
two sampled runs give the same (sampled) trajectory to round-off (checked here).

    .venv/bin/python benchmarks/python_controller_cost.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import warnings
from typing import Any

import numpy as np

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.control import GravityCompensationPD


class _UsersController:
    """The law as a user writes it: a Python class with ``__call__`` (and ``gains()``, which the
    implicit methods' step matrix uses, as the built-in's)."""

    def __init__(self, law: Any) -> None:
        self.law = law

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return self.law(t, q, v)

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        return self.law.gains() if hasattr(self.law, "gains") else (0.0, 0.0)


def _cases() -> list[tuple[str, cd.Scene, Any, dict[str, Any]]]:
    pandas = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    v0 = np.random.default_rng(1).normal(size=pandas.nv) * 0.3
    book = cd.scenes.linear_book()
    pd = GravityCompensationPD(pandas)
    drives = cd.scenes.drives_controller(*cd.scenes.book_task())
    return [
        ("two Pandas, rk4 0.5 ms", pandas, pd, {"integrator": "rk4", "dt": 5e-4, "v0": v0, "t_final": 1.0}),
        ("two Pandas, trapezoid 1 ms", pandas, pd, {"integrator": "trapezoid", "dt": 1e-3, "v0": v0, "t_final": 1.0}),
        ("book, rk4 1 ms", book, drives, {"integrator": "rk4", "dt": 1e-3, "t_final": 3.0}),
    ]


#: the table's columns, one per variant (each 17 characters wide)
HEADS = tuple(f"{h:>17s}" for h in ("built-in", "Python, called", "Python loop", "Python at 1 kHz", "built-in at 1 kHz"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs of each variant (default 5)")
    args = parser.parse_args()
    print(f"CPU per step [µs], median of {args.repeats} interleaved runs; load average {os.getloadavg()[0]:.2f}")
    print(f"{'case':28s} " + " ".join(f"{h:>17s}" for h in HEADS) + f" {'max |Δq|':>10s}")
    with single_threaded_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, scene, law, settings in _cases():
            users_controller = _UsersController(law)
            variants = {
                "built-in": (law, "auto", None),
                "called back": (users_controller, "auto", None),
                "python": (users_controller, "python", None),
                "Python 1 kHz": (users_controller, "auto", 1e-3),
                "built-in 1 kHz": (law, "auto", 1e-3),
            }
            settings = dict(settings)
            t_final = settings.pop("t_final")
            cpu: dict[str, list[float]] = {k: [] for k in variants}
            runs: dict[str, cd.Result] = {}
            for _ in range(args.repeats):
                for key, (ctrl, loop, control_dt) in variants.items():
                    res = cd.simulate(
                        scene, t_final, controller=ctrl, loop=loop, control_dt=control_dt, accuracy_check="off", progress=False,
                        **settings,
                    )  # fmt: skip
                    cpu[key].append(res.cpu_time / res.n_steps)
                    runs[key] = res
            loops = tuple(runs[k].loop for k in variants)
            assert loops == ("compiled", "compiled", "python", "compiled", "compiled"), loops
            base = statistics.median(cpu["built-in"])
            dq = max(float(np.max(np.abs(runs[k].q - runs["built-in"].q))) for k in ("called back", "python"))
            dq = max(dq, float(np.max(np.abs(runs["Python 1 kHz"].q - runs["built-in 1 kHz"].q))))
            cells = [f"{statistics.median(cpu[k]) * 1e6:7.2f} ({statistics.median(cpu[k]) / base:4.2f}×)" for k in variants]
            print(f"{name:28s} " + " ".join(f"{c:>{len(h)}s}" for c, h in zip(cells, HEADS, strict=True)) + f" {dq:10.1e}")


if __name__ == "__main__":
    main()
