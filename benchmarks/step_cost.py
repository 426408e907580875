"""Cost per step of the compiled loop against the Python loop and against the kernel's own work,
on the benchmark's Panda scene (two Pandas + 2 kg box, k = 1e4 N/m undamped, gravity
compensation + PD 50/5, perturbed start).

For each method, interleaved run by run in one process (medians of ``--repeats``):
  * ``compiled`` / ``python``: CPU per accepted step of a whole ``simulate`` run (energy monitor
    on, one sample saved per 10 ms), in each loop;
  * ``kernel``: CPU per step of the kernel calls the method makes, timed from Python on a fixed
    state (each call also pays ~0.5–1 µs of binding overhead, so this overstates the kernel's
    work): implicit Euler one ``implicit_euler_velocity``; ROS2, the trapezoid and generalized-α
    one ``implicit_terms`` + ``factor`` + two ``solve`` + one ``acceleration``; the explicit
    methods one ``acceleration`` per right-hand side the compiled run made per step (RK4 four,
    Dormand–Prince its rejected attempts and shortened landing steps included). The controller is
    not in this column (the loops include it).

    .venv/bin/python benchmarks/step_cost.py [--repeats 5] [--seconds 2] [--elastic-joints]

``--elastic-joints``: the same scene with every arm joint elastic (K = 1e4 N·m/rad, B = 0.5 kg·m²,
D = 5 N·m·s/rad) under ``MotorPD`` 50/5 instead (``benchmarks/elastic_joint_cost.py`` sets the two
scenes side by side).
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.control import GravityCompensationPD, MotorPD

METHODS = ("symplectic_euler", "rk4", "implicit_euler", "ros2", "trapezoid", "generalized_alpha", "dopri5")
EXPLICIT = ("symplectic_euler", "rk4", "dopri5")


def _kernel_work(
    dyn: cd.Dynamics, method: str, q: np.ndarray, v: np.ndarray, tau: np.ndarray, n: int, rhs_per_step: float
) -> float:
    """CPU per step [s] of the kernel calls one step of ``method`` makes, at a fixed state
    (explicit methods: ``rhs_per_step`` right-hand sides)."""
    k = dyn._kernel  # type: ignore[attr-defined]
    kp, kd = np.full(tau.size, 50.0), np.full(tau.size, 5.0)
    t0 = time.process_time()
    for _ in range(n):
        if method == "implicit_euler":
            k.implicit_euler_velocity(q, v, tau, 1e-3, kp, kd, None)
        elif method in EXPLICIT:
            k.acceleration(q, v, tau, None)
        else:
            f, M, K, D = k.implicit_terms(q, v, tau, None)
            k.factor(M, K, D, 5e-4, kp, kd, 5e-4**2)
            k.solve(v, f)
            k.acceleration(q, v, tau, None)
            k.solve(v, f)
    per_call = (time.process_time() - t0) / n
    return per_call * rhs_per_step if method in EXPLICIT else per_call


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time per run [s]")
    parser.add_argument("--elastic-joints", action="store_true", help="every arm joint elastic, under MotorPD")
    args = parser.parse_args()
    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    ctrl: Any = GravityCompensationPD(scene, 50.0, 5.0)
    if args.elastic_joints:
        joints = cd.JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0)
        scene = cd.Scene([a.replace(elasticity=joints) for a in scene.arm_specs], scene.object, scene.interconnection_specs)
        ctrl = MotorPD(scene, 50.0, 5.0)
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.3
    dyn = cd.Dynamics(scene, "native")
    tau = ctrl(0.0, scene.q0, v0)
    times: dict[tuple[str, str], list[float]] = {}
    rhs_per_step: dict[str, float] = {}
    with single_threaded_blas():
        for _ in range(args.repeats):
            for method in METHODS:
                dt = 2.5e-4 if method == "symplectic_euler" else 5e-4 if method == "rk4" else 1e-3
                for loop in ("compiled", "python"):
                    res = cd.simulate(
                        scene,
                        args.seconds,
                        controller=ctrl,
                        integrator=method,
                        dt=dt,
                        v0=v0,
                        save_every=round(0.01 / dt),
                        loop=loop,
                        accuracy_check="off",  # timing only: no reference runs
                    )
                    times.setdefault((method, loop), []).append(res.cpu_time / res.n_steps)
                    if loop == "compiled":
                        rhs_per_step[method] = res.n_rhs / res.n_steps  # incl. rejected attempts and short landing steps
                work = _kernel_work(dyn, method, scene.q0, v0, tau, 2000, rhs_per_step[method])
                times.setdefault((method, "kernel"), []).append(work)
    what = "two Pandas with elastic joints + box" if args.elastic_joints else "two Pandas + box"
    print(f"CPU per step [µs], median of {args.repeats} interleaved runs of {args.seconds:g} s; {what}, k = 1e4 N/m")
    head = (
        f"{'method':18s} {'compiled':>9s} {'python':>9s} {'kernel':>9s} {'compiled/kernel':>16s} {'python/compiled':>16s}"
        f" {'RHS/step':>9s} {'compiled/RHS':>13s}"
    )
    print(head)
    for method in METHODS:
        c, p, k = (statistics.median(times[method, w]) * 1e6 for w in ("compiled", "python", "kernel"))
        n = rhs_per_step[method]
        print(f"{method:18s} {c:9.2f} {p:9.2f} {k:9.2f} {c / k:16.2f} {p / c:16.1f} {n:9.2f} {c / n:13.2f}")


if __name__ == "__main__":
    main()
