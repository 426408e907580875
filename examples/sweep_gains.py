"""Tuning the two-Panda task: interconnection stiffness × object impedance gain, in one sweep.

Every pair runs the grip / lift / oscillate / hold task for 5 s; the object impedance keeps its
damping ratio (damping scaled with √gain). The sweep collects one row per run — tracking error,
peak internal force, status — into out/sweep_gains/table.parquet and draws both metrics as heat
maps (heatmap.png). A run that diverges is a grey cell that says so; so is an unstable loop.

Run:   python examples/sweep_gains.py            (local processes, every core)
       python examples/sweep_gains.py --serial   (this process)
Then:  coopdyn sweep --rerun out/sweep_gains 7 --case examples/sweep_gains.py:make_case
       (row 7 again, compared bit for bit; a table runs no code it names unless you name it)
"""

from __future__ import annotations

import math
import sys

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import object_start
from coopdyn.viz.plotting import sweep_heatmap

STIFFNESS = [3e3, 1e4, 3e4, 1e5]  #: interconnection stiffness [N/m] (rotational: 0.01 of it [N·m/rad])
GAIN = [500.0, 1000.0, 2000.0, 4000.0, 8000.0]  #: object impedance stiffness [N/m] (rotational: 1/20 of it [N·m/rad])
OUT = "out/sweep_gains"
#: sanity bounds: a run beyond either completed but is no grip (the task squeezes with 20 N and
#: moves the box ±3 cm), hatched in the heat map like a run that warned
LIMITS = {"tracking_error_max_m": 0.05, "peak_internal_force_N": 200.0}


def make_case(stiffness: float, gain: float) -> cd.Case:
    """One run: the two-Panda scene at this interconnection stiffness, the object impedance at this gain."""
    scene = cd.scenes.facing_arms("panda", stiffness=stiffness, damping=0.002)
    task = GripLiftOscillate(start=object_start(scene), squeeze=20.0)
    scale = math.sqrt(gain / 2000.0)  # the default gains (2000, 100) with damping (120, 6): the same damping ratio
    controller = ObjectImpedance(scene, task, stiffness=(gain, gain / 20), damping=(120.0 * scale, 6.0 * scale))
    return cd.Case(scene, controller)


def main(out: str = OUT, duration: float = 5.0, executor: str | None = None, stiffness=STIFFNESS, gain=GAIN, dt: float = 1e-3):
    """Run the sweep and draw the heat maps; return the table. A loop unstable from the start is an
    "unstable loop" cell (it warned, or its divergence says so): its figures would change with
    the step; every other cell's agree with a run at dt = 0.1 ms (tests/test_examples.py)."""
    table = cd.sweep(
        make_case,
        {"stiffness": stiffness, "gain": gain},
        duration=duration,
        integrator="trapezoid",  # A-stable, second order and non-dissipative: no damping hides an unstable loop
        dt=dt,
        executor=executor,
        out=out,
    )
    shown = table[["stiffness", "gain", "status", "tracking_error_max_m", "peak_internal_force_N"]]
    print(shown.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    meta = table.attrs["coopdyn.sweep"]
    print(f"{len(table)} runs on {meta['executor']} in {meta['wall_s']:.1f} s; wrote {out}/table.parquet")
    sweep_heatmap(
        table,
        "stiffness",
        "gain",
        ["tracking_error_max_m", "peak_internal_force_N"],
        f"{out}/heatmap.png",
        title=f"Two Pandas, grip / lift / oscillate / hold, {duration:g} s",
        xlabel="interconnection stiffness [N/m]",
        ylabel="object impedance stiffness [N/m]",
        limits=LIMITS,
    )
    print(f"wrote {out}/heatmap.png")
    return table


if __name__ == "__main__":
    main(executor="serial" if "--serial" in sys.argv[1:] else None)
