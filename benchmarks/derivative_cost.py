"""What exact step and trajectory sensitivities cost, against the finite differences a user would
take instead (MuJoCo offers only those: ``mjd_transitionFD``; its identification toolbox perturbs
one rollout per parameter).

1. **One step**: two Pandas holding the demo's box (k = 1e4 N/m, damped grasps), a random loaded
   state, rk4 at 1 ms. Timed interleaved in one process, BLAS on one thread, medians of
   ``--rounds`` rounds: a compiled rk4 step (its share of a 0.1 s run), the full ∂x⁺/∂(x, u)
   exact (``Sensitivity.step`` on the compiled kernel), and central differences of compiled
   one-step rollouts (2·(2nv + nu) of them, one ``cd.rollout`` call, one thread) with their
   error against the exact derivative. Then the same for implicit Euler and the trapezoid on
   grasps of 1e6 N/m (the kernel's twin of their derivative).
2. **A trajectory's Jacobian** (examples/gauss_newton_lift.py's, with respect to 280 torques):
   chained exact step sensitivities against forward differences of compiled rollouts.
3. **Identification** (examples/identify_stiffness.py's experiment, 2 s at 1 kHz, closed loop):
   ``cd.identify`` with exact sensitivities and with finite-difference Jacobians (compiled
   closed-loop runs), for 4 and 8 parameters: CPU time, runs and how far the estimates differ.

    .venv/bin/python benchmarks/derivative_cost.py [--rounds 7]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.control import TorqueSequence

H = 1e-3  # [s]


def _example(name: str) -> Any:
    """The module examples/<name>.py (its functions and constants)."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).parent.parent / "examples" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def step_table(rounds: int, method: str = "rk4", stiffness: float = 1e4, label: str = "1.") -> None:
    scene = cd.scenes.facing_arms("panda", stiffness=stiffness, damping=0.002)
    rng = np.random.default_rng(0)
    model, nv, na = scene.model, scene.nv, scene.n_actuated
    q = pin.integrate(model, scene.q0, 0.05 * rng.normal(size=nv))
    v, tau = 0.3 * rng.normal(size=nv), 5.0 * rng.normal(size=na)
    sens = cd.Sensitivity(scene, method)
    exact = sens.step(q, v, tau, H)
    D = np.hstack([exact.dx_dx, exact.dx_du])
    sim = cd.Simulator(scene, TorqueSequence(scene, tau[None], 0.1), method, H)

    def differences(eps: float) -> np.ndarray:
        """[∂x⁺/∂x, ∂x⁺/∂u] by central differences of one batch of compiled one-step rollouts."""
        starts_q, starts_v, torques = [], [], []
        for k in range(2 * nv + na):
            for sign in (1.0, -1.0):
                e = np.zeros(2 * nv + na)
                e[k] = sign * eps
                starts_q.append(pin.integrate(model, q, e[:nv]))
                starts_v.append(v + e[nv : 2 * nv])
                torques.append((tau + e[2 * nv :])[None])
        run = cd.rollout(
            scene, np.array(torques), period=H, q0=np.array(starts_q), v0=np.array(starts_v), integrator=method, threads=1
        )
        x = np.array(
            [
                np.concatenate([pin.difference(model, exact.q, a), b - exact.v])
                for a, b in zip(run.q[:, 1], run.v[:, 1], strict=True)
            ]
        )
        return ((x[0::2] - x[1::2]) / (2.0 * eps)).T

    scale = np.max(np.abs(D))
    errors = {eps: float(np.max(np.abs(differences(eps) - D)) / scale) for eps in (1e-4, 1e-5, 1e-6, 1e-7)}
    best = min(errors, key=errors.__getitem__)
    one = f"one {method} step (a 0.1 s compiled run / 100)"
    where = "compiled" if sens.native is not None else "in Python"
    work: dict[str, Callable[[], object]] = {
        one: lambda: sim.run(0.1, q, v),
        f"exact ∂x⁺/∂(x, u): Sensitivity.step ({where})": lambda: sens.step(q, v, tau, H),
        "the dynamics' exact derivatives, once: Dynamics.derivatives": lambda: sens.dynamics.derivatives(q, v, tau),
        f"central differences: {2 * (2 * nv + na)} one-step rollouts": lambda: differences(best),
    }
    per_call = {one: 100}
    times: dict[str, list[float]] = {name: [] for name in work}
    with single_threaded_blas():
        for f in work.values():
            f()
        for _ in range(rounds):
            for name, f in work.items():
                n = 20
                t0 = time.perf_counter()
                for _ in range(n):
                    f()
                times[name].append((time.perf_counter() - t0) / n / per_call.get(name, 1))
    step = statistics.median(times[one])
    print(
        f"{label} One step, two Pandas (nv = {nv}, nu = {na}), grasps of {stiffness:g} N/m, {method} at {H * 1e3:g} ms: "
        f"median of {rounds} interleaved rounds"
    )
    for name, t in times.items():
        print(f"  {name:60s} {statistics.median(t) * 1e6:9.1f} µs   {statistics.median(t) / step:7.1f} steps")
    print(f"  (central differences at one compiled step each, without the rollouts' overhead: {2 * (2 * nv + na)} steps)")
    print(
        f"  central differences' best error against the exact derivative: {errors[best]:.1e} of its largest entry (ε = {best:g})"
    )
    print("    at each step tried: " + ", ".join(f"ε = {h:g}: {e:.1e}" for h, e in errors.items()))


def identification_table() -> None:
    ex = _example("identify_stiffness")
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.scenes import object_start

    nominal = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    controller = ObjectImpedance(nominal, GripLiftOscillate(start=object_start(nominal), squeeze=20.0))
    data = ex.experiment(nominal, controller)
    four = list(ex.HIDDEN)
    eight = [*four, "left.d_linear", "right.d_linear", "left.d_angular", "right.d_angular"]
    print(
        f"\n3. Identification: examples/identify_stiffness.py's experiment ({len(data.joints) - 1} samples at 1 kHz, closed loop)"
    )
    print(f"  {'parameters':>10} {'Jacobian':>20} {'CPU [s]':>8} {'runs':>5} {'Jacobians':>9}   largest |Δ estimate| / σ")
    for names in (four, eight):
        fits = {j: cd.identify(nominal, data, names, jacobian=j, controller=controller) for j in ("exact", "finite-differences")}
        worst = max(abs(fits["finite-differences"].estimate[k] - fits["exact"].estimate[k]) / fits["exact"].std[k] for k in names)
        for j, fit in fits.items():
            apart = f"{worst:.1e}" if j != "exact" else "-"
            print(f"  {len(names):>10} {j:>20} {fit.cpu_time:>8.2f} {fit.evaluations:>5} {fit.jacobians:>9}   {apart}")


def trajectory_table() -> None:
    """examples/gauss_newton_lift.py's Jacobian ∂x_N/∂U (20 periods × 14 torques): chained exact
    step sensitivities against forward differences (one batch of 280 compiled rollouts)."""
    ex = _example("gauss_newton_lift")
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    nu, N = scene.n_actuated, ex.N
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    U = np.tile(g, (N, 1)) + np.random.default_rng(1).normal(scale=0.5, size=(N, nu))
    sens = cd.Sensitivity(scene)
    t0 = time.process_time()
    J = ex.rollout_with_jacobian(sens, scene, U)[2]
    exact_cpu = time.process_time() - t0
    eps = 1e-4
    batch = np.repeat(U[None], N * nu + 1, axis=0)
    for j in range(N * nu):
        batch[j + 1].flat[j] += eps
    with single_threaded_blas():
        t0 = time.process_time()
        run = cd.rollout(scene, batch, period=ex.PERIOD, dt=ex.DT, integrator="rk4", threads=1)
        fd_cpu = time.process_time() - t0
    end = run.q[:, -1]
    x = np.array(
        [
            np.concatenate([pin.difference(scene.model, end[0], a), b - run.v[0, -1]])
            for a, b in zip(end[1:], run.v[1:, -1], strict=True)
        ]
    )
    error = np.max(np.abs(x.T / eps - J)) / np.max(np.abs(J))
    steps = N * round(ex.PERIOD / ex.DT)
    print(f"\n2. A trajectory's Jacobian ∂x_N/∂U ({N} periods × {nu} torques, {steps} rk4 steps; gauss_newton_lift.py)")
    print(f"  {'exact, chained from Sensitivity.transitions':48s} {exact_cpu:8.3f} s CPU")
    print(f"  {f'forward differences, {N * nu + 1} compiled rollouts':48s} {fd_cpu:8.3f} s CPU")
    print(f"    (their error against the exact Jacobian: {error:.1e} of its largest entry)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7, help="interleaved rounds of the step table (default 7)")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} at the start")
    step_table(args.rounds)
    step_table(args.rounds, "implicit_euler", 1e6, "\n1b.")
    step_table(args.rounds, "trapezoid", 1e6, "\n1c.")
    trajectory_table()
    identification_table()
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
