"""Does the exact Jacobian make the implicit methods more accurate? (issue 27, item 3)

The linearly implicit methods factor ``S = M + γh (D̃ + Kd) + (γh)² (K̃ + Kp)`` with the
Gauss–Newton stiffness ``K̃ = Σ Jrᵀ S_K Jr`` and damping ``D̃`` — no geometric stiffness, no
∂M/∂q, no Coriolis derivative. With :func:`coopdyn.linearize`'s derivatives the exact ones are
``K̃ = −M ∂q̈/∂q`` and ``D̃ = −M ∂q̈/∂v`` (S is then not symmetric: LU instead of Cholesky). This
script runs both on the benchmark's perturbed two-Panda scene (``coopdyn bench``'s protocol: 0.2 s,
undamped grasps, joint PD 50/5 + gravity compensation, random start), in the Python loop for
both (the exact Jacobian has no compiled twin), interleaved, and prints per method and step:

* the largest force error against Dormand–Prince at rtol 1e-11 [N], for each Jacobian;
* whether the energy-balance monitor warned, for each;
* how much more energy the run holds than a resolved run (Dormand–Prince at rtol 1e-10) on the
  same grid, ``max(E − E_ref)`` [J] — what the monitor's warning is about;
* the median CPU time of ``--repeats`` runs [s], for each.

    .venv/bin/python benchmarks/exact_jacobian.py [--stiffness 1e6] [--repeats 3]

The exact variant (``coopdyn/bench/exact_jacobian.py``) is for measurements only: it does not win
(docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import os
import statistics
import warnings

import numpy as np

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.bench.cases import OUTPUT_INTERVAL, panda_case
from coopdyn.bench.exact_jacobian import jacobian
from coopdyn.bench.measure import errors_against
from coopdyn.errors import DivergenceError, EnergyBalanceWarning
from coopdyn.integrators import INTEGRATORS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--stiffness", type=float, default=1e6, help="interconnection stiffness [N/m]")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per point (median)")
    args = parser.parse_args()
    single_threaded_blas()
    case = panda_case(args.stiffness)
    grid = OUTPUT_INTERVAL  # the benchmark's output grid (10 ms)
    dyn = cd.Dynamics(case.scene, "python")

    def energies(res: cd.Result) -> np.ndarray:
        return np.array([dyn.energy(q, v).total for q, v in zip(res.q, res.v, strict=True)])

    ref = cd.simulate(
        case.scene,
        case.t_final,
        controller=case.controller,
        integrator=INTEGRATORS["dopri5"](rtol=1e-10, atol=1e-12),  # type: ignore[call-arg]
        dt=grid,
        v0=case.v0,
        accuracy_check="off",
        energy_check="off",
    )
    E_ref = energies(ref)
    print(f"{case.name}: {case.t_final} s, perturbed start, Python loop for both Jacobians; load average {os.getloadavg()}")
    print("| method | dt | force error [N] GN / exact | monitor warned GN / exact | max(E − E_ref) [J] GN / exact ", end="")
    print("| CPU [s] GN / exact |")
    print("|---|---|---|---|---|---|")
    for method in ("trapezoid", "generalized_alpha", "implicit_euler"):
        for dt in (1e-3, 2.5e-3, 5e-3):
            out: dict[str, tuple[float, bool, float, list[float]]] = {}
            for _ in range(args.repeats):
                for kind in ("gn", "exact"):  # interleaved
                    with jacobian(kind), warnings.catch_warnings(record=True) as caught:
                        warnings.simplefilter("always", EnergyBalanceWarning)
                        try:
                            res = cd.simulate(
                                case.scene,
                                case.t_final,
                                controller=case.controller,
                                integrator=method,
                                dt=dt,
                                save_every=max(1, round(grid / dt)),
                                v0=case.v0,
                                backend="python",
                                accuracy_check="off",
                            )
                        except DivergenceError:
                            out[kind] = (np.inf, True, np.inf, [np.nan])
                            continue
                    warned = any(issubclass(w.category, EnergyBalanceWarning) for w in caught)
                    force_error = errors_against(res, *case.reference(res))[1]
                    kept = float(np.max(energies(res) - E_ref))
                    cpu = out[kind][3] if kind in out else []
                    out[kind] = (force_error, warned, kept, [*cpu, res.cpu_time])
            gn, ex = out["gn"], out["exact"]
            print(
                f"| {method} | {dt * 1e3:g} ms | {gn[0]:.6g} / {ex[0]:.6g} "
                f"| {'yes' if gn[1] else 'no'} / {'yes' if ex[1] else 'no'} "
                f"| {gn[2]:.3g} / {ex[2]:.3g} | {statistics.median(gn[3]):.3f} / {statistics.median(ex[3]):.3f} |",
                flush=True,
            )
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
