"""Does an exponential Rosenbrock step win on stiff interconnections? A measurement, not a method.

The issue's candidate for k = 1e6 N/m (where no step-based method holds 10 N at steps ≥ 0.5 ms):
exponential Rosenbrock–Euler, ``y⁺ = y ⊕ h φ₁(hJ) F(y)``, exact on the linearised dynamics
``J = [[0, I], [−M⁻¹K̃, −M⁻¹D̃]]``, with φ₁ from one ``expm`` of the augmented matrix
``[[hJ, hF], [0, 0]]``. Prototype in Python through the public Integrator API, force error against
the benchmark's reference. Three Jacobians (``--jacobian``):

* ``gauss-newton``: the interconnections' Gauss–Newton K̃, D̃ plus the controller's PD gains — the
  Jacobian coopdyn's implicit methods use;
* ``exact``: ``K̃ = −M ∂q̈/∂q``, ``D̃ = −M ∂q̈/∂v`` of the dynamics at fixed torques
  (``coopdyn/bench/exact_jacobian.py``; the Python dynamics then run), plus the PD gains;
* ``closed-loop``: the exact one plus the controller's whole ∂τ/∂(q, v)
  (:func:`coopdyn.linearize.controller_gain`, central differences of the controller): the closed
  loop's Jacobian, with which the method is second order.

    .venv/bin/python benchmarks/exponential_rosenbrock.py [--jacobian exact|closed-loop] [--free | --task]

The perturbed case (default): the Panda case (1 s, undamped interconnections, gravity
compensation + PD, perturbed start), k = 1e4 and 1e6. ``--free`` drops the controller (0.2 s,
the arms fall under gravity; reference Dormand–Prince at rtol 1e-11): the step's Jacobian is
then the system's whole Jacobian, so the method's order shows. ``--task``: the task benchmark's
case (damped grasps, ObjectImpedance, 1.25 s), k = 1e6 and 1e7. Last, what a compiled step of
5 ms and of 1.25 ms would cost at least on the stiffest case: ``expm`` of that step's augmented
matrix (scipy's compiled Padé) and the compiled exact derivatives, against one compiled step of
the trapezoid at the same dt, medians of interleaved rounds.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from typing import Any

import numpy as np
import scipy.linalg

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.bench.cases import OUTPUT_INTERVAL, Case, _forces, panda_case, task_case
from coopdyn.bench.exact_jacobian import jacobian
from coopdyn.integrators import Integrator, Problem
from coopdyn.linearize import controller_gain

#: each step size's last augmented matrix [[hJ, hF], [0, 0]] (what the cost lines time)
MATRICES: dict[float, np.ndarray] = {}


class ExponentialRosenbrockEuler(Integrator):
    """``y⁺ = y ⊕ h φ₁(hJ) F(y)`` with one of three Jacobians (see the module docstring)."""

    name = "exp_rosenbrock"
    order = 2  # with the closed loop's Jacobian; first order with any other (measured below)
    a_stable = True

    def __init__(self, closed_loop: bool = False) -> None:
        self.closed_loop = closed_loop

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        f, M, K, D = system.implicit_terms(t, q, v)
        act = system.dynamics.actuated_index  # type: ignore[attr-defined]
        K, D = K.copy(), D.copy()
        n = v.size
        if self.closed_loop:  # M q̈ = … + S τ(q, v): the controller's whole derivative
            G = controller_gain(system, t, q, v)  # type: ignore[arg-type]
            K[act, :] -= G[:, :n]
            D[act, :] -= G[:, n:]
        else:  # its PD gains only
            kp, kd = system.gains  # type: ignore[attr-defined]
            K[act, act] += kp
            D[act, act] += kd
        E = np.zeros((2 * n + 1, 2 * n + 1))
        E[:n, n : 2 * n] = h * np.eye(n)
        E[n : 2 * n, :n] = -h * np.linalg.solve(M, K)
        E[n : 2 * n, n : 2 * n] = -h * np.linalg.solve(M, D)
        E[:n, -1] = h * v
        E[n : 2 * n, -1] = h * np.linalg.solve(M, f)
        MATRICES[h] = E
        dy = scipy.linalg.expm(E)[: 2 * n, -1]  # h φ₁(hJ) F
        return system.integrate(q, dy[:n]), v + dy[n:]


def free_case(k: float, t_final: float) -> Case:
    """The Panda case without its controller; reference Dormand–Prince at rtol 1e-11."""
    case = panda_case(k, t_final)
    ref = cd.simulate(
        case.scene,
        t_final,
        integrator=cd.integrators.INTEGRATORS["dopri5"](rtol=1e-11, atol=1e-13),  # type: ignore[call-arg]
        dt=OUTPUT_INTERVAL,
        v0=case.v0,
        accuracy_check="off",
        energy_check="off",
    )

    def reference(res: cd.Result) -> tuple[np.ndarray, np.ndarray]:
        return ref.object_position(), _forces(ref)

    return Case(case.name, case.scene, None, t_final, case.v0, reference, "dopri5 rtol=1e-11")  # type: ignore[arg-type]


def run(case: Case, method: Integrator, dt: float, python: bool) -> cd.Result:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cd.EnergyBalanceWarning)
        return cd.simulate(
            case.scene,
            case.t_final,
            controller=case.controller,
            integrator=method,
            dt=dt,
            save_every=round(OUTPUT_INTERVAL / dt),
            v0=case.v0,
            backend="python" if python else None,
            accuracy_check="off",
        )


def cost_line(case: Case, E: np.ndarray, dt: float, rounds: int = 7) -> str:
    """What a compiled step of ``dt`` would cost at least — ``expm`` of that step's augmented
    matrix ``E`` plus one evaluation of the compiled exact derivatives — against one compiled
    trapezoid step of ``dt``, interleaved medians [µs] (the controller's gain, 4·nv more
    controller calls, not counted)."""
    dynamics = cd.Dynamics(case.scene, "native")
    q, v = case.scene.q0, case.v0
    tau = case.controller(0.0, q, v) if case.controller is not None else np.zeros(case.scene.n_actuated)
    expm, derivatives, step = [], [], []
    for _ in range(rounds):
        t0 = time.process_time()
        for _ in range(100):
            scipy.linalg.expm(E)
        expm.append((time.process_time() - t0) / 100)
        t0 = time.process_time()
        for _ in range(100):
            dynamics.derivatives(q, v, tau)
        derivatives.append((time.process_time() - t0) / 100)
        res = run(case, cd.integrators.INTEGRATORS["trapezoid"](), dt, python=False)
        step.append(res.cpu_time / res.n_steps)
    e, d, s = (np.median(x) * 1e6 for x in (expm, derivatives, step))
    size = f"{E.shape[0]}×{E.shape[0]}"
    return (
        f"  {case.name}, dt = {dt * 1e3:g} ms: one compiled trapezoid step {s:.1f} µs; expm of the step's {size} augmented "
        f"matrix {e:.1f} µs, the compiled exact derivatives {d:.1f} µs: a compiled step would cost at least {e + d:.0f} µs "
        f"({(e + d) / s:.1f} trapezoid steps)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--jacobian", choices=("gauss-newton", "exact", "closed-loop"), default="gauss-newton")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--free", action="store_true", help="no controller (0.2 s): the order of the method itself")
    which.add_argument("--task", action="store_true", help="the task benchmark's case (1.25 s, damped, ObjectImpedance)")
    args = parser.parse_args()
    kind = args.jacobian
    if args.task:
        label, stiffnesses = "the task case, 1.25 s, ObjectImpedance", (1e6, 1e7)
    else:
        label = "the Panda case, " + ("0.2 s, no controller" if args.free else "1 s, PD + gravity compensation")
        stiffnesses = (1e4, 1e6)
    print(f"exponential Rosenbrock-Euler on {label}, {kind} Jacobian; force error [N], CPU per step [µs] (Python prototype)")
    print(f"load average {os.getloadavg()}")
    method = ExponentialRosenbrockEuler(closed_loop=kind == "closed-loop")
    case = None
    with single_threaded_blas(), jacobian("gn" if kind == "gauss-newton" else "exact"):
        for k in stiffnesses:
            case = task_case(k) if args.task else free_case(k, 0.2) if args.free else panda_case(k, 1.0)
            MATRICES.clear()
            for dt in (1e-2, 5e-3, 2.5e-3, 1.25e-3) if args.task else (5e-3, 2.5e-3, 1.25e-3, 6.25e-4, 3.125e-4):
                try:
                    res = run(case, method, dt, python=kind != "gauss-newton")
                except cd.DivergenceError:
                    print(f"  k = {k:.0e} N/m  dt = {dt * 1e3:g} ms: diverged")
                    continue
                error = float(np.max(np.linalg.norm(_forces(res) - case.reference(res)[1], axis=2)))
                cost = res.cpu_time / res.n_steps * 1e6
                print(f"  k = {k:.0e} N/m  dt = {dt * 1e3:g} ms: {error:9.3g} N   {cost:6.0f} µs/step")
        for dt in (5e-3, 1.25e-3):  # (the last, stiffest case's matrices: expm's cost grows with the step)
            if case is not None and dt in MATRICES:
                print(cost_line(case, MATRICES[dt], dt))
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
