"""Force uncertainty, resolved by elasticity: the internal force of a box held at two grasps.

A 2 kg box (0.3 m long) is held at its ends by two grasps fixed in the world (arms held still),
the second one off by a grasp error e along the box. The rigid model (``coopdyn.rigid_limit``)
cannot tell how the two grasps share the load: its solver returns the least-norm distribution,
half the weight each and no squeeze, whatever the grasps. The elastic model's static answer
(``coopdyn.statics.equilibrium``) depends on the stiffness ratio K1/K2 and on e — the
series-spring law f = k1 k2 / (k1 + k2) · e. Writes out/force_uncertainty.png.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin

import coopdyn as cd
from coopdyn.statics import equilibrium

K2 = 1e4  # [N/m] the second grasp's translational stiffness; the first is ratio × K2
ERRORS = (0.5e-3, 1e-3, 2e-3)  # grasp errors e along the box [m]
RATIOS = np.logspace(-1, 1, 21)
OUT = "out/force_uncertainty.png"


def scene(ratio: float, e: float) -> cd.Scene:
    box = cd.RigidObject.box(2.0, [0.3, 0.1, 0.1], pose=[0.0, 0.0, 0.5])
    links = []
    for x, k, offset in ((-0.15, ratio * K2, 0.0), (0.15, K2, e)):
        fixture = pin.SE3(np.eye(3), np.array([x + offset, 0.0, 0.5]))
        links.append(cd.Interconnection(None, stiffness=cd.diagonal(k, 0.01 * k), grasp=[x, 0.0, 0.0], fixture=fixture))
    return cd.Scene([], box, links)


def forces(s: cd.Scene, q: np.ndarray) -> np.ndarray:
    """Both grasps' forces on the box (2, 3) [N] at rest in q (world axes)."""
    return cd.Dynamics(s).readouts(q[None], np.zeros((1, s.nv))).object_wrench[0, :, :3]


def main(out: str = OUT) -> dict[str, np.ndarray]:
    elastic = {e: np.array([forces(s, equilibrium(s, tol=1e-10).q) for s in (scene(r, e) for r in RATIOS)]) for e in ERRORS}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # rigid_limit drops the grasp error, and says so
        rigid_scene = cd.rigid_limit(scene(1.0, ERRORS[0]))
    lam = cd.Dynamics(rigid_scene).constraint_wrenches(rigid_scene.q0, np.zeros(rigid_scene.nv), np.zeros(0))  # type: ignore[attr-defined]
    rigid_squeeze, rigid_share = -lam[0, 0] + 0.0, lam[0, 2] / (lam[0, 2] + lam[1, 2])
    print(f"rigid limit (least-norm): squeeze {rigid_squeeze:.3g} N, grasp 1 carries {rigid_share:.3f} of the weight")
    print(
        f"{'K1/K2':>7}"
        + "".join(f"{'squeeze e=' + format(e * 1e3, 'g') + ' mm':>20}" for e in ERRORS)
        + f"{'series law (1 mm)':>20}"
    )
    for k, r in enumerate(RATIOS[::5]):
        law = r * K2 * K2 / (r * K2 + K2) * 1e-3
        row = "".join(f"{-elastic[e][k * 5, 0, 0]:>18.3f} N" for e in ERRORS)
        print(f"{r:>7.3g}{row}{law:>18.3f} N")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for e in ERRORS:
        axes[0].semilogx(RATIOS, -elastic[e][:, 0, 0], marker="o", ms=3, label=f"elastic, e = {e * 1e3:g} mm")
    F = elastic[ERRORS[0]][:, :, 2]  # the weight's share does not depend on e (linear springs)
    axes[1].semilogx(RATIOS, F[:, 0] / F.sum(axis=1), marker="o", ms=3, color="C3", label="elastic (every e alike)")
    axes[0].axhline(rigid_squeeze, color="k", lw=2, label="rigid limit (least-norm)")
    axes[1].axhline(rigid_share, color="k", lw=2, label="rigid limit (least-norm)")
    axes[0].set_ylabel("internal (squeeze) force [N]")
    axes[1].set_ylabel("share of the weight on grasp 1")
    for ax in axes:
        ax.set_xlabel("stiffness ratio K1 / K2")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle("A box held at two grasps: the rigid model picks one force distribution, elasticity determines it")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    print(f"wrote {out}")
    return elastic


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else OUT)
