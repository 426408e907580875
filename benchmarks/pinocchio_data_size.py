"""Why beams do not scale: the memory and time of one ``pinocchio.Data`` against the model's nv.

A model of N free-flying bodies (what a beam of N − 1 elements adds to a scene) is built and its
``createData()`` timed; the growth of the process's resident memory (Linux ``/proc/self/statm``:
Pinocchio zeroes what it allocates, so every page is touched) is that Data's size — it sizes
its second-order derivative tensors nv × nv × nv. Prints N, nv, seconds and MB.

    .venv/bin/python benchmarks/pinocchio_data_size.py [--bodies 10 20 40]
"""

from __future__ import annotations

import argparse
import os
import time

import pinocchio as pin


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, nargs="+", default=[10, 20, 40], help="numbers of free bodies (default 10 20 40)")
    args = parser.parse_args()
    print(f"Pinocchio {pin.__version__}: createData() of N free-flying bodies")
    print(f"{'N':>5} {'nv':>6} {'time [s]':>10} {'memory [MB]':>12}")
    for n in args.bodies:
        model = pin.Model()
        for i in range(n):
            joint = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), f"node{i}")
            model.appendBodyToJoint(joint, pin.Inertia.Random(), pin.SE3.Identity())
        before = _resident()
        t0 = time.perf_counter()
        data = model.createData()
        seconds = time.perf_counter() - t0
        print(f"{n:>5} {model.nv:>6} {seconds:>10.3f} {(_resident() - before) / 1e6:>12.0f}")
        del data


def _resident() -> int:
    """The process's resident memory [bytes]."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


if __name__ == "__main__":
    main()
