"""Would a PI step-size controller make Dormand–Prince cheaper on stiff interconnections? A
measurement, not a method.

coopdyn's adaptive methods use the classical controller ``h⁺ = h·min(5, max(0.2, 0.9·err^(-1/5)))``
(``AdaptiveIntegrator.next_step``). Where the step is limited by stability rather than accuracy —
Dormand–Prince following the ~290 Hz spring mode of two Pandas at k = 1e6 N/m — it oscillates
about the limit and many attempts are rejected. Gustafsson's PI controller, as in Hairer's DOPRI5
(``err^(-(1/5 - 0.75β))·err_prev^β`` after an accepted step, β = 0.04; the classical shrink
after a rejected one), damps that oscillation. Prototype in Python through the public Integrator API (the Python loop), on the
benchmark's Panda case (1 s, undamped interconnections, gravity compensation + PD, perturbed
start), force error against the benchmark's reference; right-hand sides counted, not timed.

    .venv/bin/python benchmarks/pi_step_control.py
"""

from __future__ import annotations

import coopdyn as cd
from coopdyn.bench.cases import panda_case
from coopdyn.bench.measure import errors_against
from coopdyn.integrators import DormandPrince

BETA = 0.04


class PIDormandPrince(DormandPrince):
    """Dormand–Prince with Hairer's PI step-size controller (β = 0.04). The controller's memory
    lives on the instance: one instance per run."""

    def __init__(self, rtol: float) -> None:
        super().__init__(rtol=rtol)
        self.previous = 1e-4  # the last accepted step's error norm (Hairer's facold)

    def next_step(self, h: float, error: float) -> float:
        if not error <= 1.0:  # rejected (or NaN): the classical controller's shrink
            return super().next_step(h, error)
        factor = 0.9 * max(error, 1e-10) ** (-(0.2 - 0.75 * BETA)) * self.previous**BETA
        self.previous = max(error, 1e-4)
        return h * min(5.0, max(0.2, factor))


def main() -> None:
    print("Dormand–Prince, classical vs PI step control; two Pandas + box, 1 s, Python loop")
    print(
        f"{'k [N/m]':>8s} {'rtol':>7s} {'controller':>10s} {'accepted':>9s} {'rejected':>9s} {'RHS':>7s} {'force err [N]':>14s}"
    )
    for k in (1e6, 1e4):
        case = panda_case(k, t_final=1.0)
        for rtol in (1e-2, 1e-3, 1e-4, 1e-6):
            for name, method in (("classical", DormandPrince(rtol=rtol)), ("PI", PIDormandPrince(rtol))):
                res = cd.simulate(
                    case.scene, 1.0, controller=case.controller, integrator=method, dt=0.01, v0=case.v0,
                    energy_check="off", loop="python",
                )  # fmt: skip
                positions, forces = case.reference(res)
                err = errors_against(res, positions, forces)[1]
                print(f"{k:8.0e} {rtol:7.0e} {name:>10s} {res.n_steps:9d} {res.n_rejected:9d} {res.n_rhs:7d} {err:14.3g}")


if __name__ == "__main__":
    main()
