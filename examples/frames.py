"""The frames and sign conventions of coopdyn's outputs, drawn on the demo's scene.

Two Pandas squeeze a 2 kg box and lift it; at t = 1 s the figure shows (side view: world y
right, z up, x out of the page; the world frame is described, 0.7 m below) the object frame,
the tool (T) and grasp (G) frames, and the force each grasp puts on the object as
``Result.wrench`` gives it: [N] in world axes at the grasp point. Prints the figures it draws
(docs/physics.md, "Frames and sign conventions").

    python examples/frames.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import object_start
from coopdyn.viz.plotting import save_figure

T_SHOWN = 1.0  # [s]: squeezed and lifted (squeeze from 0.5 s, lift from 1 s)
DT = 1e-3  # [s]
STIFFNESS = 1e4  # interconnection stiffness [N/m] (the demo's)
DAMPING = 0.002  # interconnection damping / stiffness [s]
SQUEEZE = 20.0  # commanded internal force [N]
OUT = "out/frames.png"
AXIS = 0.04  # drawn length of a frame axis [m]
NEWTON = 0.004  # drawn length of 1 N [m]


def main(out: str = OUT, t_shown: float = T_SHOWN, dt: float = DT) -> dict[str, np.ndarray]:
    """Simulate, print the wrenches and squeezes at ``t_shown`` [s], draw the figure; return
    {"wrench": (2, 6) [N, N·m], "squeeze": (2,) [N], "grasp": (2, 3) [m]}."""
    import matplotlib.pyplot as plt

    scene = cd.scenes.facing_arms("panda", stiffness=STIFFNESS, damping=DAMPING)
    task = GripLiftOscillate(start=object_start(scene), squeeze=SQUEEZE)
    res = cd.simulate(scene, t_shown, controller=ObjectImpedance(scene, task), integrator="trapezoid", dt=dt)
    k = len(res.t) - 1
    model, data = scene.model, scene.model.createData()
    pin.framesForwardKinematics(model, data, res.q[k])
    wrench = res.wrenches()[k]  # (links, 6): on the object, world axes, about the grasp point
    squeeze = res.squeeze()[k]
    grasp = res.grasp_points()[k]
    print(f"t = {res.t[k]:g} s, {res.integrator} at dt = {dt:g} s")
    for i, lk in enumerate(scene.links):
        f, m = wrench[i, :3], wrench[i, 3:]
        print(
            f"  {lk.name:>5}: force on the object {np.array2string(f, precision=3)} N, moment {np.array2string(m, precision=3)} "
            f"N·m (world axes, about the grasp at {np.array2string(grasp[i], precision=3)} m); squeeze {squeeze[i]:+.3f} N"
        )
    print(f"  sum of forces {np.array2string(wrench[:, :3].sum(axis=0), precision=3)} N; weight {scene.object.mass * 9.81:.3f} N")

    fig, ax = plt.subplots(figsize=(8.0, 5.6), constrained_layout=True)
    side = np.array([1, 2])  # world (y, z): the view along −x

    def frame(M: pin.SE3, name: str, color: str, dy: float, dz: float) -> None:
        o = M.translation[side]
        for axis, label in ((0, "x"), (1, "y"), (2, "z")):
            d = M.rotation[side, axis]
            if np.linalg.norm(d) > 0.2:  # (an axis along world x points out of the page)
                ax.annotate("", o + AXIS * d, o, arrowprops={"arrowstyle": "->", "color": color, "lw": 1.5})
                beside = np.array([-d[1], d[0]]) / np.linalg.norm(d)  # (labels beside the tips: frames sit close)
                ax.text(*(o + AXIS * d + 0.012 * beside), label, color=color, fontsize=8, ha="center", va="center")
        ax.text(o[0] + dy, o[1] + dz, name, color=color, fontsize=9, ha="center", va="center")

    box = data.oMf[scene.object_frame]
    half = np.array(scene.object.size)[side] / 2
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]) * half
    outline = np.array([box.translation[side] + box.rotation[np.ix_(side, side)] @ c for c in corners])
    ax.fill(outline[:, 0], outline[:, 1], color="#c9b38f", alpha=0.6, lw=1.2, ec="#8a6d3b")
    frame(box, "object frame", "#444444", 0.0, -0.045)
    for i, lk in enumerate(scene.links):
        sign = -1.0 if grasp[i, 1] < box.translation[1] else 1.0  # left of the box or right
        apart = np.linalg.norm(data.oMf[lk.grasp_frame].translation - data.oMf[lk.tip_frame].translation)
        frame(data.oMf[lk.tip_frame], f"T ({lk.name} tool)\nG {apart * 1e3:.1f} mm from it", "#1f77b4", sign * 0.12, -0.06)
        head = data.oMf[lk.grasp_frame].translation[side]
        f = wrench[i, [1, 2]]
        ax.annotate("", head, head - NEWTON * f, arrowprops={"arrowstyle": "-|>", "color": "#d62728", "lw": 2.2})
        ax.text(head[0] + sign * 0.2, head[1] + 0.11,
                f"{lk.name}: force on the object\n(fy, fz) = ({f[0]:.1f}, {f[1]:.1f}) N\n"
                f"squeeze {squeeze[i]:+.1f} N\n(+ = compression)",
                color="#d62728", fontsize=8, ha="center", va="bottom")  # fmt: skip
    ax.text(0.0, box.translation[2] - 0.24,
            f"world frame: origin on the floor {box.translation[2]:.2f} m below the box's centre; "
            "z up, y right, x out of the page",
            fontsize=8, ha="center", va="top")  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlim(box.translation[1] - 0.42, box.translation[1] + 0.42)
    ax.set_ylim(box.translation[2] - 0.28, box.translation[2] + 0.3)
    ax.set_xlabel("world y [m]")
    ax.set_ylabel("world z [m]")
    ax.set_title(
        f"Frames and signs at t = {res.t[k]:g} s ({SQUEEZE:g} N of squeeze commanded). Result.wrench: the force on the object in "
        "world axes at the grasp point,\nmoments about it. Arrows end at the grasp they act on "
        f"({NEWTON * 1e3:g} mm per N). The box's q: position and quaternion in the world; v: in its body axes.",
        fontsize=8,
    )
    save_figure(fig, out)
    plt.close(fig)
    print(f"wrote {Path(out)}")
    return {"wrench": wrench, "squeeze": squeeze, "grasp": grasp}


if __name__ == "__main__":
    main(*sys.argv[1:2])
