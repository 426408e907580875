"""How often a run's interconnection forces are wrong, and whether `simulate` said so.

A grid of every fixed-step method (and the two adaptive ones at their defaults) × dt × grasp
stiffness k × damping (0, or D = 0.002·K) on two Pandas under the object-impedance task
(grip–lift–oscillate, squeeze 20 N), or with ``--beam`` two Pandas holding an 8-element beam
under joint PD + gravity compensation. Each run's interconnection forces are compared with
Dormand–Prince at rtol 1e-10 (checked against the trapezoid at 10 µs, printed). A run is *wrong*
when its largest force error (the magnitude of the vector difference, any interconnection, any
sample) exceeds 10 % of the reference's peak force magnitude; *silent* when it
completed without an AccuracyWarning or EnergyBalanceWarning; a *false alarm* when an
AccuracyWarning came with a right run. Diverged runs are counted apart (they say so).

    .venv/bin/python benchmarks/accuracy_grid.py [--duration 0.5] [--beam] [--max-stiffness 1e7] [--csv out/accuracy_grid.csv]
"""

from __future__ import annotations

import argparse
import csv
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import coopdyn as cd
from coopdyn.accuracy import SCREEN_LIMIT, Modes, closed_loop_modes, judge
from coopdyn.closed_loop import System
from coopdyn.control import GravityCompensationPD
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.dynamics import Dynamics
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
    """The interconnection forces on the object (n, L, 3) [N]."""
    return res.wrenches()[..., :3]


def largest(F: np.ndarray) -> float:
    """The largest force magnitude [N] of (n, L, 3)."""
    return float(np.max(np.linalg.norm(F, axis=-1)))


def run(
    scene: cd.Scene, controller: object, method: str, dt: float, duration: float
) -> tuple[str, np.ndarray | None, float | None, list[str]]:
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
            status, F, estimate = "completed", forces(res), res.force_error_estimate
        except cd.DivergenceError:
            status, F, estimate = "diverged", None, None
        except cd.StepBudgetError:
            status, F, estimate = "stopped", None, None
    return status, F, estimate, sorted({w.category.__name__ for w in caught})


def grid(duration: float, beam: bool, max_stiffness: float, log: Callable[[str], None] = print) -> list[dict[str, Any]]:
    """Every (k, β, method, dt) run of the grid, with its force error and warnings."""
    rows: list[dict[str, Any]] = []
    for k in (k for k in STIFFNESSES if k <= max_stiffness):
        for beta in DAMPING:
            scene, controller = case(k, beta, beam)
            modes = closed_loop_modes(
                System(Dynamics(scene, None), controller, None), scene.q0, np.zeros(scene.nv)
            )  # once a scene
            t0 = time.perf_counter()
            reference = INTEGRATORS["dopri5"](rtol=1e-10, atol=1e-12)
            ref = forces(cd.simulate(scene, duration, controller=controller, integrator=reference, max_steps=None))
            check = cd.simulate(
                scene,
                duration,
                controller=controller,
                integrator="trapezoid",
                dt=1e-5,
                save_every=100,
                max_steps=None,
                accuracy_check="off",
            )
            log(
                f"k = {k:g} N/m, β = {beta:g} s: reference in {time.perf_counter() - t0:.1f} s, peak force {largest(ref):.4g} N, "
                f"dopri5 vs trapezoid at 10 µs {largest(forces(check) - ref):.2g} N"
            )
            for method in (*FIXED, *ADAPTIVE):
                for dt in STEPS if method in FIXED else (1e-3,):
                    t0 = time.perf_counter()
                    status, F, estimate, warned = run(scene, controller, method, dt, duration)
                    wall = time.perf_counter() - t0
                    expected = ref[:: max(1, round(dt / 1e-3))] if method in FIXED else ref
                    error = largest(F - expected) / largest(ref) if F is not None else float("nan")
                    screened = screen_value(modes, method, dt, duration) if method in FIXED else float("nan")
                    rows.append(
                        {
                            "k": k,
                            "beta": beta,
                            "method": method,
                            "dt": dt,
                            "status": status,
                            "error": error,
                            "estimate": estimate,
                            "screen": screened,
                            "warned": warned,
                            "wall": wall,
                        }
                    )
    return rows


def screen_value(modes: Modes, method: str, dt: float, duration: float) -> float:
    """The accuracy screen's worst force-weighted mode error for this run (``coopdyn.accuracy``)."""
    worst = judge(modes, INTEGRATORS[method](), dt, duration)
    return worst[0].weighted if worst else 0.0


def verdict(rows: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The grid's runs sorted: completed ``wrong`` ones, the ``silent`` among them (no
    AccuracyWarning or EnergyBalanceWarning), ``right`` ones and the ``false`` alarms among them
    (an AccuracyWarning)."""
    done = [r for r in rows if r["status"] == "completed"]
    wrong = [r for r in done if r["error"] > WRONG]
    right = [r for r in done if r["error"] <= WRONG]
    return {
        "wrong": wrong,
        "silent": [r for r in wrong if not {"AccuracyWarning", "EnergyBalanceWarning"} & set(r["warned"])],
        "right": right,
        "false": [r for r in right if "AccuracyWarning" in r["warned"]],
    }


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
    t0 = time.perf_counter()
    rows = grid(args.duration, args.beam, args.max_stiffness, lambda line: print(line, flush=True))
    v = verdict(rows)
    checked = [r for r in rows if r["estimate"] is not None]
    print(
        f"\n{len(rows)} runs ({len(rows) - len(v['wrong']) - len(v['right'])} diverged or stopped): {len(v['wrong'])} wrong, "
        f"{len(v['silent'])} of them silent; {len(v['right'])} right, {len(v['false'])} false alarms "
        f"({len(v['false']) / max(len(v['right']), 1):.1%}); {len(checked)} checked against a reference run; "
        f"{time.perf_counter() - t0:.0f} s wall, runs alone {sum(r['wall'] for r in rows):.0f} s"
    )
    lowest = min((r["screen"] for r in v["wrong"] if r["method"] in FIXED), default=float("nan"))
    print(f"the lowest screen value among the wrong fixed-step runs: {lowest:.3g} (checked above {SCREEN_LIMIT:g})")
    for r in v["silent"]:
        print(f"  silent: {r['method']} at dt = {r['dt']:g} s, k = {r['k']:g}, β = {r['beta']:g}: error {r['error']:.0%}")
    for r in v["false"]:
        print(f"  false alarm: {r['method']} at dt = {r['dt']:g} s, k = {r['k']:g}, β = {r['beta']:g}: error {r['error']:.0%}")
    if args.csv:
        Path(args.csv).parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows({**r, "warned": " ".join(r["warned"])} for r in rows)
        print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
