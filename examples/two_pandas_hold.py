"""Two Pandas hold a 2 kg box under gravity compensation + joint PD; each arm carries half its weight."""

from __future__ import annotations

import sys

import numpy as np

import coopdyn as cd
from coopdyn.control import GravityCompensationPD

T_FINAL = 3.0  # [s]
DT = 5e-4  # [s]
STIFFNESS = 1e4  # interconnection translational stiffness [N/m]; rotational 1e-2 of it [N·m/rad]
DAMPING = 0.005  # interconnection damping / stiffness [s]
KP, KD = 200.0, 20.0  # joint PD gains [N·m/rad], [N·m·s/rad]


def main(t_final: float = T_FINAL, dt: float = DT) -> np.ndarray:
    """Simulate and print the interconnection forces on the box; return them (2, 3) [N]."""
    scene = cd.scenes.facing_arms("panda", stiffness=STIFFNESS, damping=DAMPING)
    res = cd.simulate(scene, t_final, controller=GravityCompensationPD(scene, KP, KD), dt=dt, save_every=max(1, round(0.05 / dt)))
    forces = np.array([res.wrench(i)[-1, :3] for i in range(2)])
    for arm, f in zip(scene.arms, forces, strict=True):
        print(f"{arm.name:>5}: force on the box = {np.array2string(f, precision=6)} N")
    print(f"sum = {np.array2string(forces.sum(axis=0), precision=6)} N; box weight = {scene.object.mass * 9.81:.4f} N")
    print(f"CPU {res.cpu_time:.2f} s for {t_final:g} s simulated ({res.n_rhs} RHS evaluations)")
    return forces


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
