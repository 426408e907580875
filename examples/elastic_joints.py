"""The demo's task on rigid and on elastic joints: two Pandas grip, lift and oscillate the box.

Every joint gets K = 1e4 N·m/rad, B = 0.5 kg·m² reflected, D = 5 N·m·s/rad (assumed values of the
order of a lightweight arm's harmonic drives, not a Panda identification). Prints both runs'
figures; writes elastic_joints.png and .html (the elastic run; its blue ghost arms are the motor
angles, the deflections magnified as its legend says).  Run: python examples/elastic_joints.py [OUT_FOLDER]
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.metrics import run_metrics
from coopdyn.scenes import object_start
from coopdyn.viz.plotting import save_figure

STIFFNESS = 1e4  # interconnection stiffness [N/m] (the demo's)
DAMPING = 0.002  # interconnection damping / stiffness [s]
SQUEEZE = 20.0  # commanded internal force [N]
JOINTS = cd.JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0)  # [N·m/rad], [kg·m²], [N·m·s/rad]
T_FINAL = 5.0  # [s]
DT = 1e-3  # [s], the trapezoid (the demo's)
SHOWN = 3  # the left arm's joint whose link and motor angles are drawn: panda_joint4


def scenes() -> tuple[cd.Scene, cd.Scene]:
    """(rigid joints, elastic joints): the demo's scene and the same with JOINTS on both arms."""
    rigid = cd.scenes.facing_arms("panda", stiffness=STIFFNESS, damping=DAMPING)
    arms = [arm.replace(elasticity=JOINTS) for arm in rigid.arm_specs]
    return rigid, cd.Scene(arms, rigid.object, rigid.interconnection_specs)


def run(scene: cd.Scene, t_final: float = T_FINAL, dt: float = DT) -> tuple[cd.Result, dict[str, Any]]:
    """The demo's task on ``scene``: the run and its figures (tracking error [m], squeeze [N])."""
    task = _task(scene)
    res = cd.simulate(scene, t_final, ObjectImpedance(scene, task), "trapezoid", dt=dt, save_every=max(1, round(0.005 / dt)))
    return res, run_metrics(res, task)[0]


def main(out: str = "out/elastic_joints", t_final: float = T_FINAL, dt: float = DT, html: bool = True) -> dict[str, Any]:
    """Run both, print and draw them; return {"rigid": (Result, figures), "elastic": ...}."""
    import matplotlib.pyplot as plt

    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    runs = dict(zip(("rigid", "elastic"), (run(s, t_final, dt) for s in scenes()), strict=True))
    for name, (res, figures) in runs.items():
        print(
            f"{name:>7} joints: tracking error max {figures['tracking_error_max_m'] * 1e3:.2f} mm, "
            f"rms {figures['tracking_error_rms_m'] * 1e3:.2f} mm; squeeze at the end {figures['internal_force_end_N']:.3f} N; "
            f"cpu {res.cpu_time:.2f} s"
        )
    elastic = runs["elastic"][0]
    deflection = elastic.joint_deflection()
    print(f"largest joint deflection θ − q: {np.abs(deflection).max() * 1e3:.2f} mrad")

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True, sharex=True)
    arm, k = elastic.scene.arms[0], SHOWN
    name = arm.joint_names[k].split("/")[-1]
    ax = axes[0, 0]
    ax.plot(elastic.t, elastic.q[:, arm.q_index[k]], label="link q")
    ax.plot(elastic.t, elastic.q[:, arm.motor_q_index[list(arm.elastic).index(k)]], "--", label="motor θ")
    rigid = runs["rigid"][0]
    ax.plot(rigid.t, rigid.q[:, rigid.scene.arms[0].q_index[k]], ":", color="0.4", label="rigid joints: q")
    ax.set(title=f"left arm, {name}: link and motor angle", ylabel="angle [rad]")
    ax.legend(loc="best", fontsize=8)
    ax = axes[0, 1]
    left = deflection[:, : arm.elastic.size]  # (the left arm's springs come first)
    for j in range(left.shape[1]):
        ax.plot(elastic.t, 1e3 * left[:, j], lw=1, label=arm.joint_names[arm.elastic[j]].split("/")[-1])
    low, high = 1e3 * left.min(), 1e3 * left.max()
    ax.set(title="left arm: deflection θ − q of each joint", ylabel="[mrad]", ylim=(low, high + 0.45 * (high - low)))
    ax.legend(loc="upper center", fontsize=7, ncol=4)
    for name, (res, _) in runs.items():
        axes[1, 0].plot(res.t, res.squeeze().mean(axis=1), label=f"{name} joints")
        axes[1, 1].plot(res.t, 1e3 * res.tracking_error(_task(res.scene)), label=f"{name} joints")
    axes[1, 0].axhline(SQUEEZE, color="0.6", lw=0.8, ls="--")
    axes[1, 0].set(title="squeeze on the box (mean of the two grasps)", ylabel="[N]", xlabel="t [s]")
    axes[1, 1].set(title="object tracking error", ylabel="[mm]", xlabel="t [s]")
    for ax in axes[1]:
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(
        f"Two Pandas grip, lift and oscillate a 2 kg box: rigid joints vs elastic (K = {JOINTS.stiffness:g} N·m/rad, "
        f"B = {JOINTS.motor_inertia:g} kg·m²); trapezoid, dt = {dt * 1e3:g} ms"
    )
    save_figure(fig, folder / "elastic_joints.png")
    plt.close(fig)
    if html:
        from coopdyn.viz.viewer import export_html

        export_html(elastic, folder / "elastic_joints.html")
    print(f"wrote {folder / 'elastic_joints.png'}" + (f" and {folder / 'elastic_joints.html'}" if html else ""))
    return runs


def _task(scene: cd.Scene) -> GripLiftOscillate:
    """The demo's task on ``scene``."""
    return GripLiftOscillate(start=object_start(scene), squeeze=SQUEEZE)


if __name__ == "__main__":
    main(*sys.argv[1:2])
