"""N Pandas grip a box with a commanded squeeze, lift it and oscillate it (object impedance control)."""

from __future__ import annotations

import sys

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import object_start
from coopdyn.viz.plotting import cooperative_figure

N_ARMS = 3
T_FINAL = 5.0  # [s]
DT = 1e-3  # [s]
STIFFNESS = 1e4  # interconnection stiffness [N/m]; rotational 1e2 [N·m/rad]
SQUEEZE = 15.0  # commanded internal force per grasp [N]
OUT = "out/cooperative_lift.png"


def main(
    t_final: float = T_FINAL, n_arms: int = N_ARMS, out: str = OUT, dt: float = DT, integrator: str = "implicit_euler"
) -> np.ndarray:
    """Simulate, print tracking error and squeeze, plot; return the final squeeze forces [N]."""
    scene = cd.scenes.facing_arms("panda", n_arms=n_arms, stiffness=STIFFNESS, damping=0.002)
    task = GripLiftOscillate(start=object_start(scene), squeeze=SQUEEZE)
    controller = ObjectImpedance(scene, task)
    res = cd.simulate(scene, t_final, controller=controller, integrator=integrator, dt=dt, save_every=max(1, round(1e-2 / dt)))
    squeeze = res.squeeze()[-1]
    error = res.tracking_error(task).max()
    print(f"{n_arms} arms: tracking error max {error * 1e3:.2f} mm; squeeze at the end {squeeze.round(3)} N")
    cooperative_figure(res, task, out)
    print(f"wrote {out}")
    return squeeze


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
