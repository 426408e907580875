"""Does an exponential Rosenbrock step win on stiff interconnections? A measurement, not a method.

The issue's candidate for k = 1e6 N/m (where no step-based method holds 10 N at steps ≥ 0.5 ms):
exponential Rosenbrock–Euler, ``y⁺ = y ⊕ h φ₁(hJ) F(y)``, exact on the linearised dynamics
``J = [[0, I], [−M⁻¹K̃, −M⁻¹D̃]]`` (the interconnections' Gauss–Newton K̃, D̃ plus the controller's
PD gains — the Jacobian coopdyn's implicit methods use), with φ₁ from one ``expm`` of the
augmented matrix ``[[hJ, hF], [0, 0]]``. Prototype in Python through the public Integrator API,
on the benchmark's Panda case (1 s, undamped interconnections, gravity compensation + PD,
perturbed start), force error against the benchmark's reference.

    .venv/bin/python benchmarks/exponential_rosenbrock.py
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import scipy.linalg

import coopdyn as cd
from coopdyn.bench.cases import OUTPUT_INTERVAL, _forces, panda_case
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
    print("exponential Rosenbrock-Euler on the Panda case, 1 s; force error [N], CPU per step [µs] (Python prototype)")
    for k in (1e4, 1e6):
        case = panda_case(k, 1.0)
        for dt in (5e-3, 2.5e-3, 1.25e-3, 6.25e-4, 3.125e-4):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", cd.EnergyBalanceWarning)
                    res = cd.simulate(
                        case.scene,
                        case.t_final,
                        controller=case.controller,
                        integrator=ExponentialRosenbrockEuler(),
                        dt=dt,
                        save_every=round(OUTPUT_INTERVAL / dt),
                        v0=case.v0,
                    )
            except cd.DivergenceError:
                print(f"  k = {k:.0e} N/m  dt = {dt * 1e3:g} ms: diverged")
                continue
            error = float(np.max(np.linalg.norm(_forces(res) - case.reference(res)[1], axis=2)))
            print(f"  k = {k:.0e} N/m  dt = {dt * 1e3:g} ms: {error:9.3g} N   {res.cpu_time / res.n_steps * 1e6:6.0f} µs/step")


if __name__ == "__main__":
    main()
