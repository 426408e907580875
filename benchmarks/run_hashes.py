"""A fingerprint of every built-in method × controller × loop: SHA-256 of a run's t, q, v, tau bytes.

Run before and after a change meant to move code without changing arithmetic (a refactor of the
compiled loop, a registry, a new parameter hand-over) and ``diff`` the two outputs: any changed
line names the combination whose results are no longer bit-identical. The runs: two Pandas
holding a box (k = 1e4 N/m, D = 0.002 K, perturbed start) for 0.05 s, and two Pandas holding a
4-element beam for 0.02 s, each method at its defaults (fixed steps at 1 ms), on the compiled and
the Python loops.

    .venv/bin/python benchmarks/run_hashes.py > before.txt   # then, after the change:
    .venv/bin/python benchmarks/run_hashes.py | diff before.txt -
"""

from __future__ import annotations

import hashlib
import warnings

import numpy as np

import coopdyn as cd
from coopdyn.control import ComputedTorque, GravityCompensationPD
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.integrators import INTEGRATORS
from coopdyn.scenes import object_start


def _controllers(scene: cd.Scene) -> dict[str, object]:
    return {
        "none": None,
        "gravity_pd": GravityCompensationPD(scene),
        "computed_torque": ComputedTorque(scene),
        "impedance_hold": ObjectImpedance(scene),
        "impedance_task": ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), squeeze=20.0, t_grip=0.01)),
    }


def _digest(res: cd.Result) -> str:
    h = hashlib.sha256()
    for a in (res.t, res.q, res.v, res.tau):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:16]


def main() -> None:
    box = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    beam = cd.scenes.held_beam()
    for scene_name, scene, seconds in (("box", box, 0.05), ("beam", beam, 0.02)):
        v0 = np.random.default_rng(1).normal(size=scene.nv) * 0.1
        for ctrl_name, ctrl in _controllers(scene).items():
            for method in INTEGRATORS:
                if method == "scipy":  # no compiled twin; its own tolerances
                    continue
                for loop in ("compiled", "python"):
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        try:
                            res = cd.simulate(
                                scene, seconds, controller=ctrl, integrator=method, dt=1e-3, v0=v0, loop=loop,
                                progress=False, accuracy_check="off", max_steps=None,
                            )  # fmt: skip
                            line = f"{_digest(res)} {res.status} {res.n_steps}"
                        except cd.errors.CoopdynError as exc:
                            line = f"{type(exc).__name__}"
                    print(f"{scene_name:5} {ctrl_name:16} {method:17} {loop:9} {line}", flush=True)


if __name__ == "__main__":
    main()
