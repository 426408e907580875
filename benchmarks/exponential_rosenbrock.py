"""Does an exponential Rosenbrock step win on stiff interconnections? A measurement, not a method.

The issue's candidate for k = 1e6 N/m (where no step-based method holds 10 N at steps ≥ 0.5 ms):
exponential Rosenbrock–Euler, ``y⁺ = y ⊕ h φ₁(hJ) F(y)``, exact on the linearised dynamics
``J = [[0, I], [−M⁻¹K̃, −M⁻¹D̃]]`` (the interconnections' Gauss–Newton K̃, D̃ plus the controller's
PD gains — the Jacobian coopdyn's implicit methods use), with φ₁ from one ``expm`` of the
augmented matrix ``[[hJ, hF], [0, 0]]``. Prototype in Python through the public Integrator API,
on the benchmark's Panda case (1 s, undamped interconnections, gravity compensation + PD,
perturbed start), force error against the benchmark's reference.

    .venv/bin/python benchmarks/exponential_rosenbrock.py [--jacobian exact]

``--jacobian exact`` gives the step the exact ``−M ∂q̈/∂q``, ``−M ∂q̈/∂v`` in place of K̃, D̃
(``coopdyn/bench/exact_jacobian.py``; the Python dynamics then run). ``--free`` drops the
controller (0.2 s, the arms fall under gravity; reference Dormand–Prince at rtol 1e-11): the
step's Jacobian is then the system's whole Jacobian, so the method's order shows.
"""

from __future__ import annotations

import argparse
import warnings
from typing import Any

import numpy as np
import scipy.linalg

import coopdyn as cd
from coopdyn.bench.cases import OUTPUT_INTERVAL, _forces, panda_case
from coopdyn.bench.exact_jacobian import jacobian
from coopdyn.integrators import Integrator, Problem


class ExponentialRosenbrockEuler(Integrator):
    """``y⁺ = y ⊕ h φ₁(hJ) F(y)`` with coopdyn's implicit-method Jacobian (see the module docstring)."""

    name = "exp_rosenbrock"
    order = 2  # with the exact Jacobian; with K̃, D̃ only it is first order (measured below)
    a_stable = True

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        f, M, K, D = system.implicit_terms(t, q, v)
        kp, kd = system.gains  # type: ignore[attr-defined]
        act = system.dynamics.actuated_index  # type: ignore[attr-defined]
        K, D = K.copy(), D.copy()
        K[act, act] += kp
        D[act, act] += kd
        n = v.size
        E = np.zeros((2 * n + 1, 2 * n + 1))
        E[:n, n : 2 * n] = h * np.eye(n)
        E[n : 2 * n, :n] = -h * np.linalg.solve(M, K)
        E[n : 2 * n, n : 2 * n] = -h * np.linalg.solve(M, D)
        E[:n, -1] = h * v
        E[n : 2 * n, -1] = h * np.linalg.solve(M, f)
        dy = scipy.linalg.expm(E)[: 2 * n, -1]  # h φ₁(hJ) F
        return system.integrate(q, dy[:n]), v + dy[n:]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--jacobian", choices=("gauss-newton", "exact"), default="gauss-newton")
    parser.add_argument("--free", action="store_true", help="no controller (0.2 s): the order of the method itself")
    args = parser.parse_args()
    kind = args.jacobian
    t_final = 0.2 if args.free else 1.0
    print(f"exponential Rosenbrock-Euler on the Panda case, {t_final:g} s, {kind} Jacobian", end="")
    print(", no controller" if args.free else ", PD + gravity compensation", end="")
    print("; force error [N], CPU per step [µs] (Python prototype)")
    for k in (1e4, 1e6):
        case = panda_case(k, t_final)
        controller = None if args.free else case.controller
        reference = case.reference
        if args.free:
            ref = cd.simulate(
                case.scene,
                t_final,
                integrator=cd.integrators.INTEGRATORS["dopri5"](rtol=1e-11, atol=1e-13),  # type: ignore[call-arg]
                dt=OUTPUT_INTERVAL,
                v0=case.v0,
                accuracy_check="off",
                energy_check="off",
            )

            def reference(res: cd.Result, ref: cd.Result = ref) -> tuple[np.ndarray, np.ndarray]:
                return ref.object_position(), _forces(ref)

        for dt in (5e-3, 2.5e-3, 1.25e-3, 6.25e-4, 3.125e-4):
            try:
                with warnings.catch_warnings(), jacobian("exact" if kind == "exact" else "gn"):
                    warnings.simplefilter("ignore", cd.EnergyBalanceWarning)
                    res = cd.simulate(
                        case.scene,
                        case.t_final,
                        controller=controller,
                        integrator=ExponentialRosenbrockEuler(),
                        dt=dt,
                        save_every=round(OUTPUT_INTERVAL / dt),
                        v0=case.v0,
                        backend="python" if kind == "exact" else None,
                        accuracy_check="off",
                    )
            except cd.DivergenceError:
                print(f"  k = {k:.0e} N/m  dt = {dt * 1e3:g} ms: diverged")
                continue
            error = float(np.max(np.linalg.norm(_forces(res) - reference(res)[1], axis=2)))
            print(f"  k = {k:.0e} N/m  dt = {dt * 1e3:g} ms: {error:9.3g} N   {res.cpu_time / res.n_steps * 1e6:6.0f} µs/step")


if __name__ == "__main__":
    main()
