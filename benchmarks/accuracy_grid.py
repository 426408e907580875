"""How often a run's interconnection forces are wrong, and whether `simulate` said so.

A grid of every fixed-step method (and the two adaptive ones at their defaults) × dt × grasp
stiffness k × damping (0, or D = 0.002·K) on two Pandas under the object-impedance task
(grip–lift–oscillate, squeeze 20 N), or with ``--beam`` two Pandas holding an 8-element beam
under joint PD + gravity compensation. Each run's interconnection forces are compared with
Dormand–Prince at rtol 1e-10 (checked against the trapezoid at 10 µs, printed). A run is *wrong*
when its largest force error exceeds 10 % of the reference's peak force; *silent* when it
completed without an AccuracyWarning or EnergyBalanceWarning; a *false alarm* when an
AccuracyWarning came with a right run. Diverged runs are counted apart (they say so).

    .venv/bin/python benchmarks/accuracy_grid.py [--duration 0.5] [--beam] [--max-stiffness 1e7] [--csv out/accuracy_grid.csv]
"""

from __future__ import annotations

import argparse
import csv
import time
import warnings
from pathlib import Path

import numpy as np

import coopdyn as cd
from coopdyn.control import GravityCompensationPD
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.integrators import INTEGRATORS
from coopdyn.problems.facing_arms import held_beam
from coopdyn.scenes import object_start

FIXED = ("implicit_euler", "ros2", "trapezoid", "generalized_alpha", "rk4", "symplectic_euler")
ADAPTIVE = ("dopri5", "ros2_adaptive")
STEPS = (1e-4, 2.5e-4, 5e-4, 1e-3, 2e-3, 5e-3)  #: [s] each divides or is a multiple of the 1 ms output grid
STIFFNESSES = (1e3, 1e4, 1e5, 1e6, 1e7)  #: [N/m]
DAMPING = (0.0, 0.002)  #: [s] D = β K
WRONG = 0.1  #: force error / peak force above which a run is wrong


def case(k: float, beta: float, beam: bool) -> tuple[cd.Scene, object]:
    if beam:
        scene = held_beam(stiffness=k, damping=beta)
        return scene, GravityCompensationPD(scene)
    scene = cd.scenes.facing_arms("panda", stiffness=k, damping=beta)
    return scene, ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0))


def forces(res: cd.Result) -> np.ndarray:
    return np.linalg.norm(res.wrenches()[..., :3], axis=-1)


def run(scene: cd.Scene, controller: object, method: str, dt: float, duration: float) -> tuple[str, np.ndarray | None, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            adaptive = method in ADAPTIVE
            res = cd.simulate(
                scene,
                duration,
                controller=controller,
                integrator=method,
                dt=1e-3 if adaptive else dt,
                save_every=1 if adaptive else max(1, round(1e-3 / dt)),
                max_steps=3 * 10**5,
            )
            status, F = "completed", forces(res)
        except cd.DivergenceError:
            status, F = "diverged", None
        except cd.StepBudgetError:
            status, F = "stopped", None
    return status, F, sorted({w.category.__name__ for w in caught})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=0.5, help="simulated time per run [s] (default 0.5)")
    parser.add_argument("--beam", action="store_true", help="two Pandas holding an 8-element beam instead of the box")
    parser.add_argument("--csv", default=None, help="write every run's row here")
    parser.add_argument(
        "--max-stiffness",
        type=float,
        default=1e7,
        help="the stiffest grasps [N/m] (default 1e7; the beam's 1e7 reference is slow)",
    )
    args = parser.parse_args()
    rows = []
    for k in (k for k in STIFFNESSES if k <= args.max_stiffness):
        for beta in DAMPING:
            scene, controller = case(k, beta, args.beam)
            t0 = time.perf_counter()
            reference = INTEGRATORS["dopri5"](rtol=1e-10, atol=1e-12)
            ref = forces(cd.simulate(scene, args.duration, controller=controller, integrator=reference, max_steps=None))
            check = cd.simulate(
                scene, args.duration, controller=controller, integrator="trapezoid", dt=1e-5, save_every=100, max_steps=None
            )
            print(
                f"k = {k:g} N/m, β = {beta:g} s: reference in {time.perf_counter() - t0:.1f} s, peak force {ref.max():.4g} N, "
                f"dopri5 vs trapezoid at 10 µs {np.abs(forces(check) - ref).max():.2g} N",
                flush=True,
            )
            for method in (*FIXED, *ADAPTIVE):
                for dt in STEPS if method in FIXED else (1e-3,):
                    status, F, warned = run(scene, controller, method, dt, args.duration)
                    expected = ref[:: max(1, round(dt / 1e-3))] if method in FIXED else ref
                    error = float(np.abs(F - expected).max()) / float(ref.max()) if F is not None else float("nan")
                    rows.append(
                        {"k": k, "beta": beta, "method": method, "dt": dt, "status": status, "error": error, "warned": warned}
                    )
    done = [r for r in rows if r["status"] == "completed"]
    wrong = [r for r in done if r["error"] > WRONG]
    silent = [r for r in wrong if not {"AccuracyWarning", "EnergyBalanceWarning"} & set(r["warned"])]
    right = [r for r in done if r["error"] <= WRONG]
    false = [r for r in right if "AccuracyWarning" in r["warned"]]
    print(
        f"\n{len(rows)} runs ({len(rows) - len(done)} diverged or stopped): {len(wrong)} wrong, {len(silent)} of them silent; "
        f"{len(right)} right, {len(false)} false alarms ({len(false) / max(len(right), 1):.1%})"
    )
    for r in silent:
        print(f"  silent: {r['method']} at dt = {r['dt']:g} s, k = {r['k']:g}, β = {r['beta']:g}: error {r['error']:.0%}")
    if args.csv:
        Path(args.csv).parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows({**r, "warned": " ".join(r["warned"])} for r in rows)
        print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
