"""How the cost of a held beam grows with its elements.

For each number of elements (``--elements``, default 8 16 32 48 64), in a fresh process so that its
peak memory is its own: ``coopdyn.scenes.held_beam(n_elements=n)`` (two Pandas holding the 0.8 m
aluminium strip by its ends, GravityCompensationPD), then

* the seconds to build the scene and to set up one ``coopdyn.Simulator`` for it, and the
  process's peak resident memory [GB] by then (Pinocchio's ``Data`` holds four nv × nv × nv
  tensors: the memory grows with the cube of the elements);
* the wall time per step [ms] of implicit Euler and the trapezoid at 1 ms, with the kernel's
  sparse Cholesky factor of the step matrix and with its dense one (the rest of a step — the
  assembly, the products with M and K̃ — runs on the sparse pattern in both), interleaved run by run
  (medians of ``--rounds`` runs of ``--seconds`` each, BLAS on one thread; runs of 0.05 s
  swung a size's step by 40 % from one invocation to the next, 0.2 s by under 5 %).

Prints one row per size, the growth exponent of each column over the last three sizes (a
least-squares fit on log-log axes), the load
average, and writes a chart (``--out``).

With ``--peer``, a second table: the strip alone, held at its ends by two springs to the world
(the grasps' 1e4 N/m and 100 N·m/rad), under gravity, from rest, in coopdyn (its beam elements,
``generalized_alpha``) and in Exudyn (its geometrically exact 3-D beam on Euler-parameter nodes,
``SolveDynamic``'s generalized-α with the settings of Exudyn's own beam test models: modified
Newton, relative tolerance 1e-6, sparse solver; up to 50 Newton iterations, twice its default,
which stopped at 64 elements; ρ∞ = 0.9 in both), both at 1 ms. The physics is
checked first, per size: the static midspan sag of both (coopdyn's ``equilibrium``, Exudyn's
``SolveStatic``) [mm]. Then the wall time per step, interleaved, and Exudyn's Newton iterations
per step.

    .venv/bin/python benchmarks/beam_scale.py [--elements 8 16 32 48 64] [--rounds 9] [--seconds 0.2] [--out out/beam_scale.png]
    .venv/bin/python benchmarks/beam_scale.py --peer [--elements 8 16 32 64 128]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

METHODS = ("implicit_euler", "trapezoid")
FACTORS = ("sparse", "dense")


def measure(n_elements: int, rounds: int, seconds: float) -> dict[str, float]:
    """One size, in this process: build and set-up times [s], peak memory [GB], ms per step."""
    import coopdyn as cd
    from coopdyn.bench import single_threaded_blas
    from coopdyn.control import GravityCompensationPD

    t0 = time.perf_counter()
    scene = cd.scenes.held_beam(n_elements=n_elements)
    built = time.perf_counter()
    sims = {METHODS[0]: cd.Simulator(scene, GravityCompensationPD(scene), METHODS[0], 1e-3)}
    out: dict[str, float] = {"nv": scene.nv, "build": built - t0, "setup": time.perf_counter() - built}
    out["sparse"] = float(sims[METHODS[0]].system.dynamics._kernel.sparse_step_matrix)  # type: ignore[attr-defined]
    out["memory"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9  # (Linux: kB) the scene and one Simulator
    sims |= {m: cd.Simulator(scene, GravityCompensationPD(scene), m, 1e-3) for m in METHODS[1:]}
    times: dict[str, list[float]] = {f"{m} {f}": [] for m in METHODS for f in FACTORS}
    with single_threaded_blas():
        for sim in sims.values():
            sim.run(seconds)  # (the compiled loop built once; the runs below restart it)
        for _ in range(rounds):
            for method, sim in sims.items():
                kernel = sim.system.dynamics._kernel  # type: ignore[attr-defined]
                for factor in FACTORS:
                    kernel.sparse_step_matrix = factor == "sparse"
                    t = time.perf_counter()
                    result = sim.run(seconds)
                    times[f"{method} {factor}"].append((time.perf_counter() - t) / result.n_steps * 1e3)
                kernel.sparse_step_matrix = True
    return out | {name: statistics.median(t) for name, t in times.items()}


GRASP = (1e4, 1e4, 1e4, 1e2, 1e2, 1e2)  #: the strip's end springs [N/m, N·m/rad] (held_beam's grasps)
LENGTH = 0.8  #: [m]


def _fixture_strip(n_elements: int) -> tuple[Any, Any]:
    """The strip held by two world springs: (coopdyn scene, a function building Exudyn's twin)."""
    import pinocchio as pin

    import coopdyn as cd
    from coopdyn.problems.facing_arms import aluminium_strip

    section = aluminium_strip()
    ends = [pin.SE3(np.eye(3), np.array([x, 0.0, 0.0])) for x in (-LENGTH / 2, LENGTH / 2)]
    try:
        scene = cd.Scene(
            [], cd.Beam(LENGTH, section, n_elements), [cd.Interconnection(None, stiffness=GRASP, grasp=g) for g in ends]
        )
    except cd.SceneError as exc:  # (too large for this machine's memory: Pinocchio's Data)
        print(f"coopdyn: {exc}", file=sys.stderr)
        scene = None

    def exudyn_strip() -> tuple[object, list[int]]:
        import exudyn as exu
        from exudyn.itemInterface import (
            LoadMassProportional,
            MarkerBodyMass,
            MarkerBodyRigid,
            MarkerNodeRigid,
            NodeRigidBodyEP,
            ObjectBeamGeometricallyExact,
            ObjectGround,
            RigidBodySpringDamper,
        )

        s = section
        sc = exu.SystemContainer()
        mbs = sc.AddSystem()
        h = LENGTH / n_elements
        nodes = [
            mbs.AddNode(NodeRigidBodyEP(referenceCoordinates=[-LENGTH / 2 + i * h, 0, 0, 1, 0, 0, 0]))
            for i in range(n_elements + 1)
        ]
        data = exu.BeamSection()
        data.stiffnessMatrix = np.diag([s.E * s.A, s.G * s.A, s.G * s.A, s.G * s.J, s.E * s.Iy, s.E * s.Iz])
        data.inertia = np.diag([s.rho * (s.Iy + s.Iz), s.rho * s.Iy, s.rho * s.Iz])
        data.massPerLength = s.rho * s.A
        for i in range(n_elements):
            e = mbs.AddObject(ObjectBeamGeometricallyExact(nodeNumbers=[nodes[i], nodes[i + 1]], length=h, sectionData=data))
            mbs.AddLoad(LoadMassProportional(markerNumber=mbs.AddMarker(MarkerBodyMass(bodyNumber=e)), loadVector=[0, 0, -9.81]))
        ground = mbs.AddObject(ObjectGround())
        for node, x in ((nodes[0], -LENGTH / 2), (nodes[-1], LENGTH / 2)):
            markers = [
                mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localPosition=[x, 0, 0])),
                mbs.AddMarker(MarkerNodeRigid(nodeNumber=node)),
            ]
            mbs.AddObject(RigidBodySpringDamper(markerNumbers=markers, stiffness=np.diag(GRASP), damping=np.zeros((6, 6))))
        mbs.Assemble()
        return (sc, mbs), nodes

    return scene, exudyn_strip


def _exudyn_settings(seconds: float) -> object:
    import exudyn as exu

    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = round(seconds / 1e-3)
    settings.timeIntegration.endTime = seconds
    settings.timeIntegration.generalizedAlpha.spectralRadius = 0.9
    settings.timeIntegration.newton.useModifiedNewton = True
    settings.timeIntegration.newton.relativeTolerance = 1e-6
    # (its default of 25 Newton iterations stops the 64-element strip at 0.14 s; 50 carries it
    # through 0.2 s, as a user would raise it; from 128 elements neither converges)
    settings.timeIntegration.newton.maxIterations = 50
    settings.timeIntegration.adaptiveStep = False  # (the table is at 1 ms: a step that does not converge stops the run)
    settings.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    settings.solution.file.write = False
    settings.timeIntegration.verboseMode = 0
    settings.staticSolver.verboseMode = 0
    settings.staticSolver.numberOfLoadSteps = 5  # (as Exudyn's beam test models)
    settings.staticSolver.adaptiveStep = True
    settings.staticSolver.newton.relativeTolerance = 1e-6
    return settings


def measure_peer(n_elements: int, rounds: int, seconds: float) -> dict[str, float]:
    """The strip on world springs, coopdyn against Exudyn: static sags [mm], ms per step, Exudyn's
    Newton iterations per step (nan where its solver stops)."""
    import exudyn as exu
    import pinocchio as pin

    import coopdyn as cd
    from coopdyn.bench import single_threaded_blas
    from coopdyn.statics import equilibrium

    scene, exudyn_strip = _fixture_strip(n_elements)
    out = {"coopdyn sag": math.nan}
    sim = None
    if scene is not None:
        middle = scene.model.getFrameId(f"beam/node{n_elements // 2}")
        data = scene.model.createData()
        pin.framesForwardKinematics(scene.model, data, equilibrium(scene).q)
        out["coopdyn sag"] = -data.oMf[middle].translation[2] * 1e3
        sim = cd.Simulator(scene, None, cd.integrators.GeneralizedAlpha(rho_inf=0.9), 1e-3)
    (_, mbs), nodes = exudyn_strip()  # type: ignore[misc]
    try:
        mbs.SolveStatic(_exudyn_settings(seconds))
        out["Exudyn sag"] = -mbs.GetNodeOutput(nodes[n_elements // 2], exu.OutputVariableType.Position)[2] * 1e3
    except exu.SolverError:
        out["Exudyn sag"] = math.nan
    times: dict[str, list[float]] = {"coopdyn": [], "Exudyn": []}
    newton = []
    with single_threaded_blas():
        if sim is not None:
            sim.run(seconds)
        for _ in range(rounds):
            if sim is not None:
                t = time.perf_counter()
                result = sim.run(seconds)
                times["coopdyn"].append((time.perf_counter() - t) / result.n_steps * 1e3)
            (_, mbs), _ = exudyn_strip()  # type: ignore[misc]
            settings = _exudyn_settings(seconds)
            t = time.perf_counter()
            try:
                exu.SolveDynamic(mbs, settings)
            except exu.SolverError:
                times["Exudyn"].append(math.nan)
                continue  # (every round of a size that fails, fails)
            it = mbs.sys["dynamicSolver"].it
            times["Exudyn"].append((time.perf_counter() - t) / it.currentStepIndex * 1e3 if it.currentStepIndex else math.nan)
            newton.append(it.newtonStepsCount / max(it.currentStepIndex, 1))
    out |= {f"{k} [ms]": statistics.median(v) if v else math.nan for k, v in times.items()}
    out["Newton per step"] = statistics.median(newton) if newton else math.nan
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--elements", type=int, nargs="+", default=[8, 16, 32, 48, 64], help="beam elements (default 8 16 32 48 64)"
    )
    parser.add_argument("--rounds", type=int, default=9, help="interleaved rounds per size (default 9)")
    parser.add_argument("--seconds", type=float, default=0.2, help="simulated seconds per timed run (default 0.2)")
    parser.add_argument("--out", default="out/beam_scale.png", help="the chart (default out/beam_scale.png)")
    parser.add_argument("--peer", action="store_true", help="the strip on world springs, coopdyn against Exudyn")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # (a child process: one size, JSON out)
    args = parser.parse_args()
    if args.rounds < 1 or not args.seconds > 0:  # (not > 0: NaN too)
        parser.error("--rounds must be at least 1 and --seconds positive")
    if args.one is not None:
        print(json.dumps((measure_peer if args.peer else measure)(args.one, args.rounds, args.seconds)))
        return
    if args.peer:
        _peer_table(args)
        return
    rows = []
    columns = [f"{m} {f}" for m in METHODS for f in FACTORS]
    print("two Pandas holding the aluminium strip (coopdyn.scenes.held_beam), dt = 1 ms, GravityCompensationPD")
    print(f"wall time per step [ms]: medians of {args.rounds} interleaved runs of {args.seconds:g} s")
    head = f"{'elements':>8} {'nv':>5} {'build [s]':>9} {'set-up [s]':>10} {'memory [GB]':>11} "
    print(head + " ".join(f"{c:>24}" for c in columns))
    for n in args.elements:
        cmd = [sys.executable, __file__, "--one", str(n), "--rounds", str(args.rounds), "--seconds", str(args.seconds)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            print(f"{n:>8} failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else done.returncode}")
            continue
        row = json.loads(done.stdout.strip().splitlines()[-1]) | {"elements": n}
        rows.append(row)
        if not row["sparse"]:
            print(f"{n:>8} (the kernel keeps the dense factor for this size: both columns are the dense one)")
        print(
            f"{n:>8} {row['nv']:>5.0f} {row['build']:>9.2f} {row['setup']:>10.2f} {row['memory']:>11.2f} "
            + " ".join(f"{row[c]:>24.3f}" for c in columns)
        )
    if len(rows) >= 2:  # least squares on log-log over the last three sizes (two when there are two)
        last = rows[-3:]
        x = np.log([r["elements"] for r in last])
        slope = {c: float(np.polyfit(x, np.log([r[c] for r in last]), 1)[0]) for c in ["build", "setup", "memory", *columns]}
        span = f"{last[0]['elements']}–{last[-1]['elements']}"
        print(f"growth exponent over {span} elements: " + ", ".join(f"{c} {s:.2f}" for c, s in slope.items()))
    print(f"load average {os.getloadavg()[0]:.2f}")
    if rows:
        _chart(rows, columns, Path(args.out))


def _peer_table(args: argparse.Namespace) -> None:
    print(
        f"the strip held by two springs to the world, from rest, dt = 1 ms; "
        f"medians of {args.rounds} interleaved runs of {args.seconds:g} s"
    )
    columns = ("coopdyn sag", "Exudyn sag", "coopdyn [ms]", "Exudyn [ms]", "Newton per step")
    print(f"{'elements':>8} " + " ".join(f"{c:>16}" for c in columns) + "   (sags [mm], wall time per step [ms])")
    for n in args.elements:
        cmd = [sys.executable, __file__, "--peer", "--one", str(n), "--rounds", str(args.rounds), "--seconds", str(args.seconds)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            print(f"{n:>8} failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else done.returncode}")
            continue
        row = json.loads(done.stdout.strip().splitlines()[-1])
        note = "" if math.isfinite(row["Exudyn [ms]"]) else "   Exudyn's dynamic solver stopped (no convergence at 1 ms)"
        note += "" if math.isfinite(row["coopdyn sag"]) else "   coopdyn: too large for this machine's memory"
        print(f"{n:>8} " + " ".join(f"{row[c]:>16.4g}" for c in columns) + note)
    print(f"load average {os.getloadavg()[0]:.2f}")


def _chart(rows: list[dict[str, float]], columns: list[str], out: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["elements"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for c, style in zip(columns, ("o-", "o--", "s-", "s--"), strict=True):
        ax1.loglog(n, [r[c] for r in rows], style, label=c.replace(" ", ", ") + " factor")
    ax1.set(xlabel="beam elements", ylabel="wall time per step [ms]", title="one step at 1 ms")
    ax2.loglog(n, [r["build"] + r["setup"] for r in rows], "o-", label="build + set-up [s]")
    ax2.loglog(n, [r["memory"] for r in rows], "s-", label="peak memory [GB]")
    ax2.set(xlabel="beam elements", title="building the scene and one Simulator")
    ax2.legend(fontsize=8)
    first = rows[0]["elements"]
    for c in (columns[0],):  # a guide: what linear growth from the smallest beam would cost
        ax1.loglog(n, [rows[0][c] * k / first for k in n], ":", color="grey", label="∝ elements (linear)")
    ax1.legend(fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xticks(n)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    fig.suptitle("Two Pandas holding an aluminium strip: cost against the strip's elements (benchmarks/beam_scale.py)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
