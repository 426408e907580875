"""Two Pandas lift and shake a flexible aluminium strip: which model it needs, and how it bends.

Prints ``coopdyn.advise_model`` for the two Pandas holding a rigid box and holding the strip,
then simulates the strip as an elastic object (9 nodes, 8 beam elements) under object impedance
control read at the arms' tool frames, and writes a plot of its mid-span deflection and the grasp forces, and a meshcat
animation in which the strip bends (out/flexible_beam.png, out/flexible_beam.html).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import facing_arms, held_beam, midspan_deflection, object_start

T_FINAL = 5.0  # [s]
DT = 1e-3  # [s]
INTEGRATOR = "trapezoid"  # at 1 ms within 0.088 N and 0.019 mm of 50 µs (benchmarks/flexible_beam_check.py; tested)
BANDWIDTH = 15.0  # the drives' bandwidth [Hz]
# ObjectImpedance with its default gains (2000 N/m, 120 N·s/m). For an elastic object it reads the
# strip's pose and velocity at the arms' own tool frames (measure="tips", collocated with the
# arms' motors), so the loop through the strip is passive: every mode of the linearised closed
# loop decays. Fed back at the strip's middle node instead (measure="object"), the same gains
# make a 342 Hz bending mode grow at 64 /s — and a damping integrator at 1 ms drew that as a calm
# strip. The figures: benchmarks/flexible_beam_check.py.
OUT = "out/flexible_beam"


#: the strip's mid-span deflection along a run (n,) [m] (below the chord between its ends)
deflection = midspan_deflection


def main(t_final: float = T_FINAL, out: str = OUT, html: bool = True, integrator: str = INTEGRATOR, dt: float = DT) -> cd.Result:
    for name, scene in (("rigid box", facing_arms("panda")), ("flexible strip", held_beam())):
        print(f"-- two Pandas holding a {name}")
        print(cd.advise_model(scene, bandwidth=BANDWIDTH, dt=dt))
    scene = held_beam()
    print(scene.object.report())
    task = GripLiftOscillate(start=object_start(scene), squeeze=5.0, amplitude=0.02, frequency=1.5, axis=(0.0, 0.0, 1.0))
    res = cd.simulate(
        scene,
        t_final,
        controller=ObjectImpedance(scene, task),
        integrator=integrator,
        dt=dt,
        save_every=max(1, round(1e-2 / dt)),  # 100 samples per second
    )
    sag = deflection(res)
    print(
        f"mid-span deflection: {sag.min() * 1e3:.2f} to {sag.max() * 1e3:.2f} mm; grasp force peak "
        f"{np.abs(res.wrenches()[..., :3]).max():.2f} N; tracking error max {res.tracking_error(task).max() * 1e3:.1f} mm; "
        f"CPU {res.cpu_time:.2f} s"
    )
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    axes[0].plot(res.t, sag * 1e3, color="C1")
    axes[0].set_ylabel("mid-span deflection [mm]")
    axes[0].set_title("Two Pandas lift and shake a 0.8 m aluminium strip (30 × 3 mm)")
    for i, lk in enumerate(scene.links):
        w = res.wrench(i)
        axes[1].plot(res.t, w[:, 2], label=f"{lk.name}: vertical")
        axes[1].plot(res.t, w[:, 1], "--", label=f"{lk.name}: along the strip")
    axes[1].set_ylabel("grasp force on the strip [N]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(loc="upper right", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(f"{out}.png", dpi=110)
    plt.close(fig)
    if html:
        from coopdyn.viz.viewer import export_html

        export_html(res, f"{out}.html")
    print(f"wrote {out}.png" + (f" and {out}.html" if html else ""))
    return res


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else T_FINAL)
