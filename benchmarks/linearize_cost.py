"""What an exact linearisation costs, against the finite differences a user would take instead.

Two Pandas holding a box (k = 1e5 N/m, damped grasps and joints), a random loaded state. Timed
interleaved in one process, BLAS on one thread, medians of ``--rounds`` rounds:

* ``cd.linearize`` on the compiled kernel and on the Python reference (A and B, exact; each call
  sets up its dynamics), and ``Dynamics.derivatives`` on a kernel set up once;
* one acceleration on the kernel (the unit finite differences pay);
* central differences of the kernel's acceleration in tangent coordinates for ∂q̈/∂(q, v)
  (2·2nv accelerations), and their largest error against the exact A, relative to its largest
  entry, at the step that gives them their best accuracy of a few tried.

    .venv/bin/python benchmarks/linearize_cost.py [--rounds 7]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.dynamics import Dynamics


def central_differences(dyn: Dynamics, model: pin.Model, q: np.ndarray, v: np.ndarray, tau: np.ndarray, h: float) -> np.ndarray:
    """[∂q̈/∂q, ∂q̈/∂v] (nv, 2nv) by central differences of step h."""
    nv = model.nv
    out = np.empty((nv, 2 * nv))
    for k in range(nv):
        e = np.zeros(nv)
        e[k] = h
        plus, minus = pin.integrate(model, q, e), pin.integrate(model, q, -e)
        out[:, k] = (dyn.acceleration(plus, v, tau) - dyn.acceleration(minus, v, tau)) / (2 * h)
        out[:, nv + k] = (dyn.acceleration(q, v + e, tau) - dyn.acceleration(q, v - e, tau)) / (2 * h)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7, help="interleaved rounds (default 7)")
    args = parser.parse_args()
    scene = cd.scenes.facing_arms("panda", stiffness=1e5, damping=20.0, joint_damping=0.5)
    rng = np.random.default_rng(0)
    model, nv = scene.model, scene.nv
    q = pin.integrate(model, scene.q0, 0.05 * rng.normal(size=nv))
    v, tau = 0.5 * rng.normal(size=nv), rng.normal(size=scene.n_actuated)
    native = Dynamics(scene, "native")
    exact = cd.linearize(scene, q, v, tau, backend="native").A[nv:]
    scale = np.max(np.abs(exact))
    steps = (1e-4, 1e-5, 1e-6, 1e-7)
    errors = {h: np.max(np.abs(central_differences(native, model, q, v, tau, h) - exact)) / scale for h in steps}
    best = min(errors, key=errors.__getitem__)
    work: dict[str, Callable[[], object]] = {
        "linearize, kernel": lambda: cd.linearize(scene, q, v, tau, backend="native"),
        "linearize, Python": lambda: cd.linearize(scene, q, v, tau, backend="python"),
        "Dynamics.derivatives, kernel (set up once)": lambda: native.derivatives(q, v, tau),
        "one acceleration, kernel": lambda: native.acceleration(q, v, tau),
        f"central differences, kernel ({4 * nv} accelerations)": lambda: central_differences(native, model, q, v, tau, best),
    }
    calls = {name: max(1, round(0.05 / max(1e-7, _once(f)))) for name, f in work.items()}
    times: dict[str, list[float]] = {name: [] for name in work}
    with single_threaded_blas():
        for _ in range(args.rounds):
            for name, f in work.items():
                t0 = time.perf_counter()
                for _ in range(calls[name]):
                    f()
                times[name].append((time.perf_counter() - t0) / calls[name])
    print(f"two Pandas, k = 1e5 N/m, nv = {nv}: wall time per call, median of {args.rounds} interleaved rounds")
    for name, t in times.items():
        print(f"  {name:55s} {statistics.median(t) * 1e6:9.1f} µs")
    print(f"central differences' best error against the exact ∂q̈/∂(q, v): {errors[best]:.1e} of its largest entry (h = {best:g})")
    print("  at each step tried: " + ", ".join(f"h = {h:g}: {e:.1e}" for h, e in errors.items()))
    print(f"load average {os.getloadavg()[0]:.2f}")


def _once(f: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    f()
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
