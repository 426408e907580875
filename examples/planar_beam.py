"""Two planar three-link arms carry a flexible beam and keep it from vibrating.

The benchmark scenario of cooperative handling of flexible objects: two 3R arms in a vertical
plane hold a 1 m aluminium strip (30 × 3 mm, bending in their plane) by its ends, grip it, lift
it 0.1 m and shake it vertically (2 cycles at 1 Hz, ±30 mm), then hold it still. The controller
is ObjectImpedance read at the arms' own tool frames (collocated: its default for an elastic
object). The script prints the largest real part of the linearised closed loop's eigenvalues
with that reading and with the same gains fed back at the beam's middle node, then simulates the
first and prints the tracking error, the mid-span deflection while moving and the vibration
left once the motion stops; it writes out/planar_beam.png (and a meshcat animation with --html).

With --elastic-joints it is the book's fourth system, everything elastic: the grasps, the strip
and the arms' joints (JOINTS: every joint gets a transmission spring and a motor, values assumed
so that the joints' lowest mode, 33 Hz, sits beside the strip's 14.6 Hz — `coopdyn.advise_model`
says so), and it also prints the largest joint deflection and plots the deflections
(out/planar_beam_elastic_joints.png).

    .venv/bin/python examples/planar_beam.py [t_final] [--html] [--elastic-joints]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import midspan_deflection, object_start, planar_arms_beam

T_FINAL = 6.0  # [s]
DT = 1e-3  # [s]
INTEGRATOR = "trapezoid"  # at 1 ms within 0.034 N and 5.6 µm of 50 µs (benchmarks/flexible_beam_check.py)
SQUEEZE = 2.0  # [N]
AMPLITUDE = 0.03  # [m], vertical
FREQUENCY = 1.0  # [Hz]
OUT = "out/planar_beam"
JOINTS = cd.JointElasticity(stiffness=2e3, motor_inertia=0.05)  # [N·m/rad], [kg·m²] reflected (assumed)


def make_scene(elastic_joints: bool = False) -> cd.Scene:
    """The two planar 3R arms and the strip; with ``elastic_joints``, every joint elastic (JOINTS)."""
    scene = planar_arms_beam()
    if not elastic_joints:
        return scene
    arms = [arm.replace(elasticity=JOINTS) for arm in scene.arm_specs]
    return cd.Scene(arms, scene.object, scene.interconnection_specs)


def task(scene: cd.Scene) -> GripLiftOscillate:
    """Grip (SQUEEZE) at 0.5 s, lift 0.1 m from 0.75 s over 1.25 s, shake ±AMPLITUDE vertically at
    FREQUENCY for 2 cycles from 2.25 s, then hold."""
    start = object_start(scene)
    return GripLiftOscillate(start=start, squeeze=SQUEEZE, amplitude=AMPLITUDE, frequency=FREQUENCY, axis=(0.0, 0.0, 1.0))


def task_end(reference: GripLiftOscillate) -> float:
    """When the task's motion ends [s]: the last oscillation cycle's end."""
    return reference.t_osc + reference.cycles / reference.frequency


def main(
    t_final: float = T_FINAL,
    out: str | None = None,
    html: bool = False,
    integrator: str = INTEGRATOR,
    dt: float = DT,
    elastic_joints: bool = False,
) -> cd.Result:
    scene = make_scene(elastic_joints)
    out = out if out is not None else OUT + ("_elastic_joints" if elastic_joints else "")
    print(scene.object.report())
    for measure in ("tips", "object"):
        lam = cd.linearize(scene, controller=ObjectImpedance(scene, measure=measure)).eigenvalues
        top = lam[np.argmax(lam.real)]
        kind = f"a {abs(top.imag) / (2 * np.pi):.1f} Hz mode" if abs(top.imag) > 0 else "a real mode"
        where = "tool frames" if measure == "tips" else "middle node"
        print(f"closed loop read at the {where}: largest Re λ = {top.real:.3g} /s ({kind})")
    reference = task(scene)
    controller = ObjectImpedance(scene, reference)
    res = cd.simulate(scene, t_final, controller=controller, integrator=integrator, dt=dt, save_every=max(1, round(1e-2 / dt)))
    sag = midspan_deflection(res)
    end = task_end(reference)
    moving = res.t < end
    still = res.t >= max(t_final - 1.0, end)
    err = res.tracking_error(reference)
    print(f"tracking error max {err.max() * 1e3:.1f} mm, rms {np.sqrt(np.mean(err**2)) * 1e3:.1f} mm")
    print(f"mid-span deflection while moving {sag[moving].min() * 1e3:.2f} to {sag[moving].max() * 1e3:.2f} mm")
    if still.any():  # (a run that ends before the task does has no still part)
        print(f"vibration left in the last second: {np.ptp(sag[still]) * 1e6:.3g} µm peak to peak")
    print(f"grasp force peak {np.abs(res.wrenches()[..., :3]).max():.2f} N")
    if elastic_joints:
        print(f"largest joint deflection θ − q: {np.abs(res.joint_deflection()).max() * 1e3:.2f} mrad")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4 if elastic_joints else 3, 1, figsize=(8, 10.5 if elastic_joints else 8), sharex=True)
    z = res.object_position()[:, 2]
    axes[0].plot(res.t, z * 1e3, label="beam middle")
    axes[0].plot(res.t, reference.positions(res.t)[:, 2] * 1e3, "k--", lw=1, label="commanded")
    axes[0].set_ylabel("height [mm]")
    axes[0].legend(loc="lower right", fontsize=8)
    arms = "Two planar 3R arms" + (" on elastic joints" if elastic_joints else "")
    axes[0].set_title(f"{arms} carry a 1 m aluminium strip (grey: the task is done, they hold it)", fontsize=10)
    axes[1].plot(res.t, sag * 1e3, color="C1")
    axes[1].set_ylabel("mid-span deflection [mm]")
    for i, lk in enumerate(scene.links):
        axes[2].plot(res.t, res.wrench(i)[:, 2], label=f"{lk.name}: vertical")
        axes[2].plot(res.t, res.wrench(i)[:, 1], "--", label=f"{lk.name}: along the beam")
    axes[2].set_ylabel("grasp force on the beam [N]")
    axes[2].legend(loc="upper right", fontsize=8)
    if elastic_joints:
        deflection, v_names = res.joint_deflection(), scene.coordinates()[1]
        per_arm = len(scene.joint_springs.link_v) // len(scene.arms)  # (every joint elastic: arm after arm)
        for j, link in enumerate(scene.joint_springs.link_v):
            left = j < per_arm
            style = {"color": f"C{j % per_arm}", "linestyle": "-" if left else (0, (4, 3)), "lw": 1.5 if left else 1.0}
            axes[3].plot(res.t, deflection[:, j] * 1e3, label=v_names[link].split(" [")[0], **style)
        axes[3].set_title("the arms are mirror images: each right joint (dashed) on its left twin", fontsize=9, loc="left")
        axes[3].set_ylabel("joint deflection θ − q [mrad]")
        axes[3].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        if res.t[-1] > end:
            ax.axvspan(end, res.t[-1], color="0.9", zorder=0)
    fig.tight_layout()
    fig.savefig(f"{out}.png", dpi=110)
    plt.close(fig)
    if html:
        from coopdyn.viz.viewer import export_html

        export_html(res, f"{out}.html")
    print(f"wrote {out}.png" + (f" and {out}.html" if html else ""))
    return res


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(float(args[0]) if args else T_FINAL, html="--html" in sys.argv, elastic_joints="--elastic-joints" in sys.argv)
