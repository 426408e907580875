"""Cost of ``Result.wrench`` (and the other readouts) on a 10 000-sample two-Panda trajectory.

Times, side by side in one process and interleaved run by run, the readouts of this checkout on
both backends and, with ``--baseline DIR``, those of another coopdyn source tree (e.g. an older
commit checked out with ``git worktree add DIR <commit>``), loaded under another package name.
Prints medians and ratios.

    .venv/bin/python benchmarks/readout_cost.py --baseline /tmp/base
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio  # noqa: F401  (loads the libraries a copied kernel links against)

import coopdyn as cd

N_SAMPLES = 10_000


def _load_baseline(tree: Path, kernel: Path | None) -> Any:
    """Import ``tree/coopdyn`` as the package ``coopdyn_baseline``, with ``kernel`` (that tree's
    own compiled ``_native*.so``) if given; without it the old tree runs on its Python path
    (this install's kernel has another interface)."""
    root = Path(tempfile.mkdtemp())
    shutil.copytree(tree / "coopdyn", root / "coopdyn_baseline")
    if kernel is not None:
        shutil.copy(kernel, root / "coopdyn_baseline")
    sys.path.insert(0, str(root))
    return importlib.import_module("coopdyn_baseline")


def _trajectory(pkg: Any, scene: Any) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) of 10 000 samples: a short implicit-Euler run of ``pkg`` on ``scene``, tiled."""
    rng = np.random.default_rng(0)
    res = pkg.simulate(scene, 0.05, integrator="implicit_euler", dt=1e-3, v0=rng.normal(size=scene.nv) * 0.3)
    reps = N_SAMPLES // len(res.t) + 1
    q = np.tile(res.q, (reps, 1))[:N_SAMPLES]
    v = np.tile(res.v, (reps, 1))[:N_SAMPLES]
    return q, v


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", type=Path, default=None, help="another coopdyn source tree to compare with")
    parser.add_argument("--baseline-kernel", type=Path, default=None, help="that tree's compiled kernel (_native*.so)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    variants: dict[str, Any] = {}
    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    q, v = _trajectory(cd, scene)
    tau = np.zeros((N_SAMPLES, scene.n_actuated))
    for backend in ("native", "python"):

        def make(backend: str = backend) -> Any:
            return cd.Result(scene, np.arange(N_SAMPLES) * 1e-3, q, v, tau, "implicit_euler", 1e-3, 0, 0.0, backend=backend)

        variants[f"this checkout, {backend}"] = make
    if args.baseline is not None:
        old = _load_baseline(args.baseline, args.baseline_kernel)
        old_scene = old.scenes.facing_arms("panda", stiffness=1e4)
        np.testing.assert_array_equal(old_scene.q0, scene.q0)

        def make_old() -> Any:
            return old.Result(old_scene, np.arange(N_SAMPLES) * 1e-3, q, v, tau, "implicit_euler", 1e-3, 0, 0.0)

        variants["baseline"] = make_old
        ref = make_old().wrench(0)
        for name, make in variants.items():
            err = float(np.max(np.abs(make().wrench(0) - ref)))
            print(f"{name:<28} max |wrench(0) − baseline| = {err:.2e} N")

    readouts = {
        "wrench(0)": lambda r: r.wrench(0),
        "wrench(0..1) + arm_wrench + energy()": lambda r: (r.wrench(0), r.wrench(1), r.arm_wrench(0), r.energy()),
    }
    for label, call in readouts.items():
        times: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(args.repeats):
            for name, make in variants.items():  # interleaved: one run of each per round
                res = make()
                t0 = time.perf_counter()
                call(res)
                times[name].append(time.perf_counter() - t0)
        print(f"\n{label} on a fresh {N_SAMPLES}-sample two-Panda result [s, median of {args.repeats}]")
        base = statistics.median(times["baseline"]) if "baseline" in times else None
        for name, x in times.items():
            med = statistics.median(x)
            ratio = f"   {med / base:.3f}× baseline" if base else ""
            print(f"  {name:<28} {med:8.4f}{ratio}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
