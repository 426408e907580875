"""The fixed cost of a run: what one call costs beyond its steps, which decides sweeps over many
short runs, model-predictive control and identification.

Two Pandas holding a box (k = 1e4 N/m), GravityCompensationPD, one step of 1 ms, the call
repeated; all variants interleaved call by call in one process (medians of ``--rounds`` rounds
of ``--calls`` calls each), BLAS on one thread:

* ``simulate``, as a user calls it (the accuracy screen on, ``accuracy_check="auto"``);
* ``simulate`` with ``accuracy_check="off"`` and ``energy_check="off"``;
* both again under the demo's controller (``ObjectImpedance`` on the demo's damped grasps), whose
  checks cost more (its loop check probes its compiled twin);
* ``Simulator.run`` (set up once, then one run per call);
* MuJoCo with the same law and controller as compiled callbacks (``coopdyn.mujoco``): reset,
  set the state, one ``mj_step``, read the state back — what a MuJoCo user's run costs;
* ``Simulator.run`` and MuJoCo over 21 steps: a step's own cost is the difference / 20, and
  the fixed cost of a run is the one-step run less one step (the two simulators' steps differ:
  MuJoCo's implicitfast is not coopdyn's trapezoid).

Prints wall time per call [µs] for rk4 and the trapezoid (MuJoCo's RK4 and implicitfast; the
trapezoid factorises its step matrix at every step), with the load average. ``--parts`` also
times the pieces of a ``Simulator.run`` (rk4) one by one: its checks, the controller's settings
compared with those of the loop the last run left (``Loop.restart`` then runs it again from the
new state), and the step with its samples and the ``Result`` (a run within the loop's first chunk
that completes without a warning takes them straight from the loop).

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
from coopdyn.cooperative import ObjectImpedance


def _variants(method: str) -> dict[str, Callable[[], object]]:
    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    pd = GravityCompensationPD(scene)
    sim = cd.Simulator(scene, pd, method, 1e-3)
    sim21 = cd.Simulator(scene, pd, method, 1e-3)
    off = dict(accuracy_check="off", energy_check="off")
    demo = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    impedance = ObjectImpedance(demo)
    variants: dict[str, Callable[[], object]] = {
        "simulate": lambda: cd.simulate(scene, 1e-3, controller=pd, integrator=method, dt=1e-3),
        "simulate, checks off": lambda: cd.simulate(scene, 1e-3, controller=pd, integrator=method, dt=1e-3, **off),  # type: ignore[arg-type]
        "simulate, ObjectImpedance": lambda: cd.simulate(demo, 1e-3, controller=impedance, integrator=method, dt=1e-3),
        "simulate, ObjectImpedance, checks off": lambda: cd.simulate(
            demo,
            1e-3,
            controller=impedance,
            integrator=method,
            dt=1e-3,
            **off,  # type: ignore[arg-type]
        ),
        "Simulator.run": lambda: sim.run(1e-3),
        "Simulator.run, 21 steps": lambda: sim21.run(21e-3),
    }
    try:
        import mujoco

        from coopdyn.mujoco import Callbacks, mjcf
    except ImportError:
        return variants
    model = mujoco.MjModel.from_xml_string(mjcf(scene, "RK4" if method == "rk4" else "implicitfast", 1e-3))
    data = mujoco.MjData(model)
    callbacks = Callbacks(scene, model, pd)

    def mujoco_run(n_steps: int) -> object:
        mujoco.mj_resetData(model, data)
        callbacks.set_state(data, scene.q0, scene.v0)
        mujoco.mj_step(model, data, n_steps)
        return callbacks.state(data)

    variants["MuJoCo (compiled callbacks)"] = lambda: mujoco_run(1)
    variants["MuJoCo, 21 steps"] = lambda: mujoco_run(21)
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
            median = {name: statistics.median(t) * 1e6 for name, t in times.items()}
            print(f"{method}: " + "  ".join(f"{name} {t:.1f}" for name, t in median.items()))
            # a step's own cost from the 21-step run, and what is left of a one-step run: the fixed cost
            for name, one, many in (
                ("Simulator.run", "Simulator.run", "Simulator.run, 21 steps"),
                ("MuJoCo", "MuJoCo (compiled callbacks)", "MuJoCo, 21 steps"),
            ):
                if many in median:
                    step = (median[many] - median[one]) / 20
                    print(f"    {name:14s} per step {step:5.1f}, fixed cost (one-step run less a step) {median[one] - step:5.1f}")
    if args.parts:
        _parts(args.calls * args.rounds)
    print(f"load average {os.getloadavg()[0]:.2f}")


def _parts(n: int) -> None:
    """Simulator.run's pieces, each timed over n one-step rk4 runs (medians would hide nothing
    here: each piece is one call), as its code runs them after its first run: the loop that run
    built is restarted."""
    from coopdyn import compiled
    from coopdyn.budget import check_budget
    from coopdyn.stepping import _check_samples, _checked_duration, _Run

    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    sim = cd.Simulator(scene, GravityCompensationPD(scene), "rk4", 1e-3)
    sim.run(1e-3)  # (builds the loop the runs below restart)
    system, method, native = sim.system, sim.method, sim._loop
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
        key = sim._key(t_final, compiled.controller_settings(scene, system))
        assert compiled.same(key, sim._loop_key)
        t0 = lap("the controller's settings, compared", t0)
        native.restart(q, v)
        t0 = lap("Loop.restart", t0)
        assert sim._short(run, native, time.process_time(), sim._first_chunk(run, native)) is not None
        t0 = lap("the step, the samples and the Result", t0)
        native.restart(q, v)
        t0 = time.perf_counter()
        native.advance(compiled.FIRST_CHUNK)
        lap("(of which the step alone)", t0)
    print(f"Simulator.run's pieces, rk4, one step, mean of {n} runs [µs]:")
    for name, total in spent.items():
        print(f"  {name:45s} {total / n * 1e6:7.1f}")
    print(f"  {'total':45s} {sum(t for k, t in spent.items() if not k.startswith('(')) / n * 1e6:7.1f}")


if __name__ == "__main__":
    main()
