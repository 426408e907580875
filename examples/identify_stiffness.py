"""Identify the stiffness of two grasps from a grip–lift–oscillate run with sensor noise.

The "robot": the demo's two Pandas and box, but its grasps are not the nominal 1e4 N/m and
1e2 N·m/rad — they are HIDDEN below. It runs the demo's task for 2 s under the demo's controller
(built on the nominal scene, sampled at 1 kHz), simulated at a resolving step (rk4, 0.25 ms).
Its sensors, read at 1 kHz: joint encoders (σ 1e-4 rad) and a force–torque sensor at each grasp
(σ 0.2 N, 0.02 N·m). ``cd.identify`` fits the four stiffnesses to them from the nominal values —
the model runs the same closed loop at 1 ms, with exact sensitivities — and reports each estimate
with its standard deviation; the same fit with finite-difference Jacobians is timed beside it.
Writes identify_stiffness.png: a grasp force and a grasp moment as measured, as the nominal model
predicts them and as the fitted one does, over the grip's first 0.6 s (where the grasps ring).
Run: python examples/identify_stiffness.py [OUT_FOLDER]
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import object_start

HIDDEN = {"left.k_linear": 1.25e4, "right.k_linear": 0.85e4, "left.k_angular": 80.0, "right.k_angular": 120.0}
NOISE = (1e-4, 0.2, 0.02)  # encoders [rad], force [N], moment [N·m] (σ)
PERIOD = 1e-3  # sensors and controller [s]
T_FINAL = 2.0  # [s]


def experiment(nominal: cd.Scene, controller: Any, seed: int = 7, t_final: float = T_FINAL) -> cd.Measurements:
    """The hidden robot's run under the controller, read by noisy sensors every PERIOD."""
    robot = cd.with_parameters(nominal, HIDDEN)
    run = cd.simulate(robot, t_final, controller, "rk4", dt=PERIOD / 4, control_dt=PERIOD, save_every=4, accuracy_check="off")
    perfect = cd.Measurements.from_result(run, joint_noise=NOISE[0], force_noise=NOISE[1], torque_noise=NOISE[2])
    rng = np.random.default_rng(seed)
    wrench = perfect.wrench + np.concatenate([s * rng.normal(size=(len(run.t), 2, 3)) for s in NOISE[1:]], axis=2)
    return dataclasses.replace(perfect, joints=perfect.joints + NOISE[0] * rng.normal(size=perfect.joints.shape), wrench=wrench)


def main(out: str = "out/identify_stiffness", t_final: float = T_FINAL, plot: bool = True) -> dict[str, Any]:
    """Run the experiment and both fits; print and draw them; return {"exact", "finite-differences": Identification}."""
    nominal = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    controller = ObjectImpedance(nominal, GripLiftOscillate(start=object_start(nominal), squeeze=20.0))
    data = experiment(nominal, controller, t_final=t_final)
    fits = {
        j: cd.identify(nominal, data, list(HIDDEN), jacobian=j, controller=controller) for j in ("exact", "finite-differences")
    }
    print(fits["exact"].summary())
    print(f"{'':22} {'hidden':>12} {'estimate':>12} {'(estimate − hidden)/σ':>22}")
    for name, value in HIDDEN.items():
        fit = fits["exact"]
        print(f"{name:<22} {value:>12.6g} {fit.estimate[name]:>12.6g} {(fit.estimate[name] - value) / fit.std[name]:>22.2f}")
    fd = fits["finite-differences"]
    worst = max(abs(fd.estimate[k] - fits["exact"].estimate[k]) / fits["exact"].std[k] for k in HIDDEN)
    print(
        f"finite-difference Jacobians: {fd.cpu_time:.2f} s CPU ({fd.evaluations} runs) against {fits['exact'].cpu_time:.2f} s "
        f"({fits['exact'].evaluations} runs with sensitivities); the estimates differ by at most {worst:.1e} σ"
    )
    if plot:
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
        _figure(nominal, controller, data, fits["exact"], folder / "identify_stiffness.png")
    return fits


def _figure(nominal: cd.Scene, controller: Any, data: cd.Measurements, fit: cd.Identification, path: Path) -> None:
    import matplotlib.pyplot as plt

    n = len(data.joints) - 1
    t = np.arange(n + 1) * data.period
    model = {
        label: cd.trajectory_sensitivity(s, n, data.period, controller=controller)
        for label, s in (("nominal", nominal), ("fitted", fit.scene))
    }
    assert data.wrench is not None
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for ax, (link, axis, unit) in zip(axes, ((0, 2, "N"), (1, 4, "N·m")), strict=True):
        name = nominal.links[link].name
        label = ["fx", "fy", "fz", "mx", "my", "mz"][axis]
        ax.plot(t, data.wrench[:, link, axis], ".", ms=1.5, color="0.6", label="measured (noisy sensor)")
        ax.plot(t, model["nominal"].wrench[:, link, axis], color="tab:red", lw=1.2, label="nominal model")
        ax.plot(t, model["fitted"].wrench[:, link, axis], color="tab:blue", lw=1.2, label="fitted model")
        ax.set_ylabel(f"{name} grasp {label} [{unit}]\n(grasp frame axes)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].set_title(f"Grasp wrench before and after the fit (the first 0.6 s of the {t[-1]:.1f} s record)")
    axes[-1].set_xlabel("t [s]")
    shown = t <= min(0.6, t[-1])
    axes[-1].set_xlim(0.0, t[shown][-1])
    for ax, (link, axis) in zip(axes, ((0, 2), (1, 4)), strict=True):  # (the y range of what is shown)
        y = data.wrench[shown, link, axis]
        pad = 0.08 * (y.max() - y.min())
        ax.set_ylim(y.min() - pad, y.max() + pad)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


if __name__ == "__main__":
    main(*sys.argv[1:2])
