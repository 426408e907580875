"""The fixed cost of a run: what one call costs beyond its steps, which decides sweeps over many
short runs, model-predictive control and identification.

Two Pandas holding a box (k = 1e4 N/m), GravityCompensationPD, one step of 1 ms, the call
repeated; all variants interleaved call by call in one process (medians of ``--rounds`` rounds
of ``--calls`` calls each), BLAS on one thread:

* ``simulate``, as a user calls it (the accuracy screen on, ``accuracy_check="auto"``);
* ``simulate`` with ``accuracy_check="off"`` and ``energy_check="off"``;
* ``Simulator.run`` (set up once, then one run per call);
* MuJoCo with the same law and controller as compiled callbacks (``coopdyn.mujoco``): reset,
  set the state, one ``mj_step``, read the state back — what a MuJoCo user's run costs.

Prints wall time per call [µs] for rk4 and the trapezoid (whose fixed cost includes its first
factorisation), with the load average.

    .venv/bin/python benchmarks/fixed_cost.py [--calls 200] [--rounds 7]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import coopdyn as cd
from coopdyn.bench import single_threaded_blas
from coopdyn.control import GravityCompensationPD


def _variants(method: str) -> dict[str, Callable[[], object]]:
    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    pd = GravityCompensationPD(scene)
    sim = cd.Simulator(scene, pd, method, 1e-3)
    off = dict(accuracy_check="off", energy_check="off")
    variants: dict[str, Callable[[], object]] = {
        "simulate": lambda: cd.simulate(scene, 1e-3, controller=pd, integrator=method, dt=1e-3),
        "simulate, checks off": lambda: cd.simulate(scene, 1e-3, controller=pd, integrator=method, dt=1e-3, **off),  # type: ignore[arg-type]
        "Simulator.run": lambda: sim.run(1e-3),
    }
    try:
        import mujoco

        from coopdyn.mujoco import Callbacks, mjcf
    except ImportError:
        return variants
    model = mujoco.MjModel.from_xml_string(mjcf(scene, "RK4" if method == "rk4" else "implicitfast", 1e-3))
    data = mujoco.MjData(model)
    callbacks = Callbacks(scene, model, pd)

    def mujoco_run() -> object:
        mujoco.mj_resetData(model, data)
        callbacks.set_state(data, scene.q0, scene.v0)
        mujoco.mj_step(model, data)
        return callbacks.state(data)

    variants["MuJoCo (compiled callbacks)"] = mujoco_run
    variants["_callbacks"] = callbacks.__enter__  # (installed for the whole measurement)
    return variants


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=200, help="calls per round (default 200)")
    parser.add_argument("--rounds", type=int, default=7, help="interleaved rounds (default 7)")
    args = parser.parse_args()
    print(f"wall time per call [µs], median of {args.rounds} interleaved rounds of {args.calls} calls")
    with single_threaded_blas():
        for method in ("rk4", "trapezoid"):
            variants = _variants(method)
            enter = variants.pop("_callbacks", None)
            if enter is not None:
                enter()
            times: dict[str, list[float]] = {k: [] for k in variants}
            for run in variants.values():  # warm up
                run()
            for _ in range(args.rounds):
                for name, run in variants.items():
                    t0 = time.perf_counter()
                    for _ in range(args.calls):
                        run()
                    times[name].append((time.perf_counter() - t0) / args.calls)
            if enter is not None:
                enter.__self__.__exit__(None, None, None)  # type: ignore[attr-defined]
            cells = "  ".join(f"{name}: {statistics.median(t) * 1e6:7.1f}" for name, t in times.items())
            print(f"{method:10s} {cells}")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
