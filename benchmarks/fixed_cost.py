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
factorisation), with the load average. ``--parts`` also times the pieces of a ``Simulator.run``
(rk4) one by one: its checks, the plan of the compiled loop's settings, the kernel's loop object,
the step, the samples and the ``Result``.

    .venv/bin/python benchmarks/fixed_cost.py [--calls 200] [--rounds 7] [--parts]
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
    parser.add_argument("--parts", action="store_true", help="also time the pieces of Simulator.run")
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
    if args.parts:
        _parts(args.calls * args.rounds)
    print(f"load average {os.getloadavg()[0]:.2f}")


def _parts(n: int) -> None:
    """Simulator.run's pieces, each timed over n one-step rk4 runs (medians would hide nothing
    here: each piece is one call), as its code runs them."""
    from coopdyn import compiled
    from coopdyn.budget import check_budget
    from coopdyn.simulate import _check_samples, _checked_duration, _Run

    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    sim = cd.Simulator(scene, GravityCompensationPD(scene), "rk4", 1e-3)
    system, method = sim.system, sim.method
    spent: dict[str, float] = {}

    def lap(name: str, t0: float) -> float:
        t = time.perf_counter()
        spent[name] = spent.get(name, 0.0) + t - t0
        return t

    for i in range(n + 100):
        if i == 100:  # (warmed up)
            spent.clear()
        t0 = time.perf_counter()
        t_final = _checked_duration(1e-3)
        q, v = scene.check_state(scene.q0, scene.v0)
        budget = check_budget(scene, t_final, sim.dt, sim.save_every, sim.max_steps, sim.max_memory)
        _check_samples(t_final, sim.control_dt, budget)
        system.restart()
        run = _Run(scene, system, method, sim.dt, sim.save_every, t_final, sim.max_speed, (q, v))
        t0 = lap("checks, the controller's gains", t0)
        config, _ = compiled.plan(
            scene, system, method, q0=q, v0=v, dt=sim.dt, t_final=t_final, n_steps=run.n_steps,
            save_every=sim.save_every, max_speed=sim.max_speed, energy_check="off",
        )  # fmt: skip
        t0 = lap("the plan (settings from the typed specs)", t0)
        native = system.dynamics.compiled_loop(config)  # type: ignore[attr-defined]
        t0 = lap("the kernel's loop object", t0)
        native.advance(compiled.FIRST_CHUNK)
        native.take_events()
        t0 = lap("the step", t0)
        samples = compiled.samples(native, scene)
        run.t, run.q, run.v, run.tau = samples.t.tolist(), list(samples.q), list(samples.v), list(samples.tau)
        t0 = lap("the samples", t0)
        run.result()
        lap("the Result", t0)
    print(f"Simulator.run's pieces, rk4, one step, mean of {n} runs [µs]:")
    for name, total in spent.items():
        print(f"  {name:45s} {total / n * 1e6:7.1f}")
    print(f"  {'total':45s} {sum(spent.values()) / n * 1e6:7.1f}")


if __name__ == "__main__":
    main()
