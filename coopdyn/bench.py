"""Work–precision and stability benchmarks (DESIGN §6).

``coopdyn bench`` (or :func:`run_benchmarks`) sweeps integrators × step sizes / tolerances on
named scenes, measures CPU time (median of repeated runs) and machine-independent counters,
compares with a reference of a *different* method, and writes a table (CSV) and charts (PNG).
"""

from __future__ import annotations

import csv
import math
import os
import statistics
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, fields
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from . import scenes
from .backend import native_available, resolve
from .control import GravityCompensationPD
from .dynamics import Dynamics
from .errors import DivergenceError, SimulationError
from .integrators import INTEGRATORS, Integrator, LinearlyImplicitEuler
from .monitor import EnergyBalanceWarning
from .reference import BookParameters, Drive, linear_book_exact
from .scene import Scene
from .simulate import Result, simulate
from .stability import advise, measure_stable_dt

OUTPUT_INTERVAL = 0.01  #: errors are compared on this output grid [s]


@dataclass(frozen=True)
class Case:
    """A benchmark scene with its controller and its reference trajectory."""

    name: str
    scene: Scene
    controller: Callable[[float, np.ndarray, np.ndarray], np.ndarray]
    t_final: float
    v0: np.ndarray
    reference: Callable[[Result], tuple[np.ndarray, np.ndarray]]  #: (object positions, wrench forces) on res.t
    reference_note: str
    book: tuple[BookParameters, Drive, Drive] | None = None  #: the linear case's parameters and drives (for peers)


@dataclass(frozen=True)
class Row:
    """One point of the work–precision chart."""

    scene: str
    method: str
    setting: str  #: "dt=…" or "rtol=…"
    dt: float
    rtol: float
    position_error: float  #: max |Δ object position| over the output grid [m] (inf: diverged)
    wrench_error: float  #: max |Δ interconnection force| over the output grid [N]
    cpu_per_sim_s: float  #: median CPU seconds per simulated second
    n_rhs: int
    n_factor: int
    stable: bool
    energy_flag: bool  #: the energy monitor warned


def _forces(res: Result) -> np.ndarray:
    return np.stack([res.wrench(i)[:, :3] for i in range(len(res.scene.links))], axis=1)


def linear_case(t_final: float = 3.0) -> Case:
    """The book's linear system with the grip/lift/oscillate drives; exact reference."""
    params = BookParameters()
    scene = scenes.linear_book(**asdict(params))
    d1, d2 = scenes.book_task(params)

    def reference(res: Result) -> tuple[np.ndarray, np.ndarray]:
        ex = linear_book_exact(res.t, d1, d2, params)
        forces = np.zeros((res.t.size, 2, 3))
        forces[:, 0, 2], forces[:, 1, 2] = ex.Fc1, ex.Fc2
        return np.column_stack([np.zeros_like(ex.t), np.zeros_like(ex.t), ex.Y[:, 1]]), forces

    return Case("linear", scene, scenes.drives_controller(d1, d2), t_final, scene.v0, reference, "exact (expm)", (params, d1, d2))


def panda_case(stiffness: float, t_final: float = 0.2, reference_rtol: float = 1e-11) -> Case:
    """Two Pandas holding a 2 kg box, joint PD 50/5 + gravity compensation, perturbed start;
    reference: Dormand–Prince at a tight tolerance."""
    scene = scenes.facing_arms("panda", stiffness=stiffness)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.3
    ref = simulate(
        scene,
        t_final,
        controller=ctrl,
        integrator=INTEGRATORS["dopri5"](rtol=reference_rtol, atol=reference_rtol * 1e-2),  # type: ignore[call-arg]
        dt=OUTPUT_INTERVAL,
        v0=v0,
        energy_check="off",
    )
    ref_pos, ref_forces = ref.object_position(), _forces(ref)

    def reference(res: Result) -> tuple[np.ndarray, np.ndarray]:
        if res.t.size != ref.t.size or np.max(np.abs(res.t - ref.t)) > 1e-9:
            raise SimulationError("benchmark runs must save on the reference's output grid")
        return ref_pos, ref_forces

    note = f"dopri5 rtol={reference_rtol:g}"
    return Case(f"pandas k={stiffness:.0e}", scene, ctrl, t_final, v0, reference, note)


def _settings(method: str, quick: bool, linear: bool) -> list[tuple[str, float, float]]:
    """(label, dt, rtol) points of a method's sweep."""
    if INTEGRATORS[method].adaptive:
        if method == "ros2_adaptive":  # second order: tight tolerances cost minutes
            rtols = [1e-2, 1e-3, 1e-4] if quick else [1e-2, 1e-3, 1e-4, 1e-5]
        else:
            rtols = [1e-3, 1e-5, 1e-7] if quick else [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9]
        return [(f"rtol={r:g}", OUTPUT_INTERVAL, r) for r in rtols]
    top = 1e-2 if linear else 5e-3  # steps divide the output interval
    n = 3 if quick else 7
    return [(f"dt={top / 2**k:g}", top / 2**k, math.nan) for k in range(n)]


def _make(method: str, rtol: float) -> Integrator:
    cls = INTEGRATORS[method]
    if cls.adaptive:
        return cls(rtol=rtol, atol=rtol * 1e-3)  # type: ignore[call-arg]
    return cls()


def work_precision(
    cases: Sequence[Case], methods: Sequence[str], *, quick: bool = False, repeats: int = 5, progress: bool = True
) -> list[Row]:
    """Sweep ``methods`` over ``cases``; one :class:`Row` per (case, method, setting)."""
    plan: list[tuple[Case, str, tuple[str, float, float]]] = []
    for case in cases:
        linear = case.name == "linear"
        for m in methods:
            if m == "exponential" and not linear:
                continue
            plan.extend((case, m, s) for s in _settings(m, quick, linear))
    rows = []
    with _bar(len(plan), "work–precision", progress) as bar:
        for case, m, (label, dt, rtol) in plan:
            rows.append(_measure(case, m, label, dt, rtol, repeats))
            bar.set_postfix_str(f"{case.name} {m} {label}")
            bar.update(1)
    return rows


def _measure(case: Case, method: str, label: str, dt: float, rtol: float, repeats: int) -> Row:
    save_every = max(1, round(OUTPUT_INTERVAL / dt))
    cpu: list[float] = []
    res = None
    flagged = False
    for _ in range(repeats):
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", EnergyBalanceWarning)
                res = simulate(
                    case.scene,
                    case.t_final,
                    controller=case.controller,
                    integrator=_make(method, rtol),
                    dt=dt,
                    save_every=save_every,
                    v0=case.v0,
                )
            flagged = flagged or any(issubclass(w.category, EnergyBalanceWarning) for w in caught)
        except DivergenceError:
            return Row(case.name, method, label, dt, rtol, math.inf, math.inf, math.nan, 0, 0, False, True)
        cpu.append(res.cpu_time)
        if res.cpu_time > 2.0:  # slow points: fewer repeats (the median of what ran)
            break
    assert res is not None
    pos, forces = case.reference(res)
    pos_err = (
        float(np.max(np.linalg.norm(res.object_position() - pos, axis=1)))
        if case.name != "linear"
        else float(np.max(np.abs(scenes.book_positions(res.q, res.scene)[:, 1] - pos[:, 2])))
    )
    force_err = float(np.max(np.linalg.norm(_forces(res) - forces, axis=2)))
    return Row(
        case.name,
        method,
        label,
        dt,
        rtol,
        pos_err,
        force_err,
        statistics.median(cpu) / case.t_final,
        res.n_rhs,
        res.n_factor,
        True,
        flagged,
    )


def peer_rows(case: Case, *, quick: bool = False, repeats: int = 5, progress: bool = True) -> list[Row]:
    """MuJoCo on the linear case (:func:`linear_case`'s parameters and drives; see
    :mod:`coopdyn.peers`), over the same dt grid as coopdyn's fixed-step methods; empty for other
    cases and when MuJoCo is not installed."""
    from .peers import MUJOCO_INTEGRATORS, mujoco_available, mujoco_linear_book

    if case.book is None or not mujoco_available():
        return []
    params, d1, d2 = case.book
    drives = (d1, d2)
    plan = [(m, s) for m in MUJOCO_INTEGRATORS for s in _settings("rk4", quick, True)]
    rows = []
    bar = _bar(len(plan), "MuJoCo (linear)", progress)
    for integrator, (label, dt, _) in plan:
        save_every = max(1, round(OUTPUT_INTERVAL / dt))
        cpu = []
        for _ in range(repeats):
            run = mujoco_linear_book(params, drives, case.t_final, dt, integrator, save_every)
            cpu.append(run.cpu_time)
            if run.cpu_time > 2.0:
                break
        exact = linear_book_exact(run.t, *drives, params=params)
        stable = bool(np.all(np.isfinite(run.Y)))
        F1, F2 = run.contact_forces(params)
        rows.append(
            Row(
                case.name,
                f"mujoco {integrator}",
                label,
                dt,
                math.nan,
                float(np.max(np.abs(run.Y[:, 1] - exact.Y[:, 1]))) if stable else math.inf,
                float(max(np.max(np.abs(F1 - exact.Fc1)), np.max(np.abs(F2 - exact.Fc2)))) if stable else math.inf,
                statistics.median(cpu) / case.t_final,
                run.n_steps * (4 if integrator == "RK4" else 1),
                0,
                stable,
                False,
            )
        )
        bar.set_postfix_str(f"{integrator} {label}")
        bar.update(1)
    bar.close()
    return rows


def stability_sweep(
    stiffnesses: Sequence[float],
    methods: Sequence[str] = ("symplectic_euler", "rk4"),
    *,
    progress: bool = True,
    quick: bool = False,
) -> list[dict[str, Any]]:
    """Largest stable dt vs stiffness on the Panda scene: predicted (advise) and measured
    (bisection) for explicit methods; implicit ones are run at 1, 2 and 5 ms."""
    out = []
    bar = _bar(len(stiffnesses), "stability", progress)
    for k in stiffnesses:
        scene = scenes.facing_arms("panda", stiffness=k)
        ctrl = GravityCompensationPD(scene, 50.0, 5.0)
        adv = advise(scene, controller=ctrl)
        v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.05
        for m in methods:
            predicted = adv.max_stable_dt(m)
            measured = measure_stable_dt(scene, m, controller=ctrl, guess=predicted, v0=v0, n_steps=1000 if quick else 2000)
            out.append({"k": k, "method": m, "predicted_dt": predicted, "measured_dt": measured, "omega_max": adv.omega_max})
        for m in ("implicit_euler", "ros2"):
            ok = []
            for dt in (1e-3, 2e-3, 5e-3):
                try:
                    simulate(scene, 0.5, controller=ctrl, integrator=m, dt=dt, v0=v0, energy_check="raise")
                    ok.append(dt)
                except Exception:
                    break
            out.append(
                {"k": k, "method": m, "predicted_dt": math.inf, "measured_dt": max(ok) if ok else 0.0, "omega_max": adv.omega_max}
            )
        bar.update(1)
    bar.close()
    return out


def _backends() -> list[str]:
    """The backends to time side by side: Python always, the compiled kernel when built."""
    return ["python", "native"] if native_available() else ["python"]


def rhs_timing(repeats: int = 2000) -> dict[str, dict[str, float]]:
    """Median wall time [µs] of one right-hand side, one evaluation of the stiffness terms and one
    implicit-Euler step (PD controller included) on two Pandas, per backend: 7 blocks of
    ``repeats`` calls, the backends interleaved block by block."""
    from .integrators import System, get_integrator

    scene = scenes.facing_arms("panda", stiffness=1e4)
    rng = np.random.default_rng(1)
    q, v, tau = scene.q0, rng.normal(size=scene.nv) * 0.1, np.zeros(scene.n_actuated)
    method = get_integrator("implicit_euler")
    calls: dict[str, dict[str, Callable[[], object]]] = {}
    for name in _backends():
        dyn = Dynamics(scene, backend=name)
        system = System(dyn, GravityCompensationPD(scene, 50.0, 5.0))
        calls[name] = {
            "rhs_us": partial(dyn.acceleration, q, v, tau),
            "implicit_terms_us": partial(dyn.implicit_terms, q, v, tau),
            "implicit_euler_step_us": partial(method.step, system, 0.0, q, v, 1e-3),
        }

    def block(f: Callable[[], object]) -> float:
        t0 = time.perf_counter()
        for _ in range(repeats):
            f()
        return (time.perf_counter() - t0) / repeats * 1e6

    samples: dict[str, dict[str, list[float]]] = {b: {k: [] for k in c} for b, c in calls.items()}
    for _ in range(7):
        for name, fns in calls.items():
            for key, f in fns.items():
                samples[name][key].append(block(f))
    return {b: {k: statistics.median(x) for k, x in d.items()} for b, d in samples.items()}


def _bar(total: int, desc: str, progress: bool) -> Any:
    """A progress bar (a context manager; silent when ``progress`` is false)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="run", disable=not progress)


def write_csv(rows: Sequence[Any], path: Path) -> Path:
    """Write dataclass rows or dicts as CSV, atomically."""
    dicts = [asdict(r) if hasattr(r, "__dataclass_fields__") else dict(r) for r in rows]
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(dicts[0]))
        writer.writeheader()
        writer.writerows(dicts)
    os.replace(tmp, path)
    return path


def read_csv(path: str | os.PathLike[str]) -> list[Row]:
    """Rows written by :func:`write_csv` (e.g. to re-plot a finished run)."""
    types = {f.name: f.type for f in fields(Row)}
    convert: dict[str, Callable[[str], Any]] = {"str": str, "float": float, "int": int, "bool": lambda x: x == "True"}
    with open(path, newline="") as f:
        return [Row(**{k: convert[str(types[k])](v) for k, v in d.items()}) for d in csv.DictReader(f)]


def plot_work_precision(rows: Sequence[Row], path: Path) -> Path:
    """Log–log wrench error vs CPU per simulated second, one panel per scene; × marks divergence."""
    from .plotting import _pyplot, save_figure

    plt = _pyplot()
    names = list(dict.fromkeys(r.scene for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(5 * len(names), 4.2), constrained_layout=True, squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        n_bad = 0
        for method in dict.fromkeys(r.method for r in rows if r.scene == name):
            pts = [r for r in rows if r.scene == name and r.method == method and r.stable]
            if pts:
                style = "x--" if method.startswith("mujoco") else "o-"  # peers dashed
                ax.loglog([r.cpu_per_sim_s for r in pts], [max(r.wrench_error, 1e-16) for r in pts], style, label=method, ms=4)
            bad = [r for r in rows if r.scene == name and r.method == method and not r.stable]
            for r in bad:
                n_bad += 1
                ax.annotate(
                    f"× diverged: {method} {r.setting}",
                    (0.02, 0.05 * n_bad - 0.03),
                    xycoords="axes fraction",
                    fontsize=6,
                    color="red",
                )
        ax.set_title(name)
        ax.set_xlabel("CPU s per simulated s")
        ax.set_ylabel("max interconnection force error [N]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_stability(points: Sequence[dict[str, Any]], path: Path) -> Path:
    """Largest stable dt vs stiffness per method (predicted lines, measured markers)."""
    from .plotting import _pyplot, save_figure

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2), constrained_layout=True)
    for method in dict.fromkeys(p["method"] for p in points):
        pts = [p for p in points if p["method"] == method]
        ks = [p["k"] for p in pts]
        if all(math.isinf(p["predicted_dt"]) for p in pts):
            ax.loglog(ks, [p["measured_dt"] for p in pts], "s--", label=f"{method}: stable at every dt tried (≤ 5 ms)")
            continue
        (line,) = ax.loglog(ks, [p["predicted_dt"] for p in pts], "-", label=f"{method} predicted (advise)")
        ax.loglog(ks, [p["measured_dt"] for p in pts], "o", color=line.get_color(), label=f"{method} measured (bisection)")
    ax.set_xlabel("interconnection stiffness k [N/m] (rotational 0.01·k)")
    ax.set_ylabel("largest stable dt [s]")
    ax.set_title("Two Pandas + 2 kg box, joint PD 50/5")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)


def run_benchmarks(out: str | os.PathLike[str] = "out/bench", *, quick: bool = False, progress: bool = True) -> dict[str, Any]:
    """The whole benchmark: work–precision, stability, timings; prints tables, writes files."""
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stiffnesses = [1e4, 1e5, 1e6]
    cases = [linear_case(3.0)] + [panda_case(k, 0.1 if quick else 0.2) for k in stiffnesses]
    methods = ["symplectic_euler", "rk4", "dopri5", "implicit_euler", "ros2", "ros2_adaptive", "exponential"]
    rows = work_precision(cases, methods, quick=quick, repeats=1 if quick else 5, progress=progress)
    rows += peer_rows(cases[0], quick=quick, repeats=1 if quick else 5, progress=progress)
    stab = stability_sweep(stiffnesses + ([] if quick else [1e7]), progress=progress, quick=quick)
    timing = rhs_timing(200 if quick else 2000)
    implicit_cost = _implicit_cost([1e4, 1e7] if quick else [1e4, 1e5, 1e6, 1e7], 0.2 if quick else 1.0)
    files = {
        "rows": write_csv(rows, out_dir / "work_precision.csv"),
        "stability": write_csv(stab, out_dir / "stability.csv"),
        "chart": plot_work_precision(rows, out_dir / "work_precision.png"),
        "stability_chart": plot_stability(stab, out_dir / "stability.png"),
    }
    print(f"work–precision and stability runs: {resolve()} backend")
    print(format_rows(rows))
    print()
    print(format_stability(stab))
    print()
    print(format_timing(timing))
    print()
    print(format_implicit_cost(implicit_cost))
    print()
    print(format_peers(rows))
    for name, path in files.items():
        print(f"wrote {path}  ({name})")
    return {"rows": rows, "stability": stab, "timing": timing, "implicit_cost": implicit_cost, "files": files}


def _implicit_cost(stiffnesses: Sequence[float], t_final: float) -> dict[tuple[str, float, int], tuple[float, bool]]:
    """CPU s per simulated s of implicit_euler at dt = 1 ms on the Panda scene (PD 50/5, energy
    monitor on), with the Jacobian evaluated every step and every 10 steps, per backend (the
    backends alternate run by run); median of 5. Keys: (backend, k, jacobian_every)."""
    out = {}
    for k in stiffnesses:
        scene = scenes.facing_arms("panda", stiffness=k)
        ctrl = GravityCompensationPD(scene, 50.0, 5.0)
        v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.3
        for every in (1, 10):
            cpu: dict[str, list[float]] = {b: [] for b in _backends()}
            ok = dict.fromkeys(cpu, True)
            for _ in range(5):
                for name in cpu:
                    if not ok[name]:
                        continue
                    try:
                        res = simulate(
                            scene,
                            t_final,
                            controller=ctrl,
                            integrator=LinearlyImplicitEuler(every),
                            dt=1e-3,
                            v0=v0,
                            save_every=100,
                            backend=name,
                        )
                        cpu[name].append(res.cpu_time / t_final)
                        ok[name] = bool(np.max(np.abs(res.v)) < 10.0)
                    except DivergenceError:
                        ok[name] = False
            for name, x in cpu.items():
                out[(name, k, every)] = (statistics.median(x) if x else math.nan, ok[name])
    return out


def _best_to_reach(rows: Sequence[Row], tol: float) -> Row | None:
    """The cheapest stable row with a force error ≤ tol [N]."""
    good = [r for r in rows if r.stable and r.wrench_error <= tol]
    return min(good, key=lambda r: r.cpu_per_sim_s, default=None)


def format_rows(rows: Sequence[Row]) -> str:
    """The work–precision table as text."""
    head = (
        f"{'scene':<14} {'method':<17} {'setting':<13} {'pos err [m]':>11} {'force err [N]':>13} "
        f"{'CPU s/sim s':>11} {'RHS':>8} {'fact':>6}  ok"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        ok = "yes" if r.stable else "DIVERGED"
        if r.stable and r.energy_flag:
            ok = "energy!"
        lines.append(
            f"{r.scene:<14} {r.method:<17} {r.setting:<13} {r.position_error:>11.3e} {r.wrench_error:>13.3e} "
            f"{r.cpu_per_sim_s:>11.4f} {r.n_rhs:>8d} {r.n_factor:>6d}  {ok}"
        )
    return "\n".join(lines)


def format_peers(rows: Sequence[Row]) -> str:
    """What the peers reached on the linear case, next to coopdyn's best, at 1e-6 N and 1e-5 N."""
    from .peers import mujoco_available

    lines = []
    mine = [r for r in rows if r.scene == "linear" and not r.method.startswith("mujoco")]
    peers = [r for r in rows if r.scene == "linear" and r.method.startswith("mujoco")]
    if not peers:
        lines.append("peers: MuJoCo " + ("ran on no scene" if mujoco_available() else "is not installed (pip install mujoco)"))
    for tol in (1e-5, 1e-6):
        for who, pool in (("coopdyn", mine), ("MuJoCo", peers)):
            if not pool:
                continue
            best = _best_to_reach(pool, tol)
            lines.append(
                f"linear case, least CPU for a force error ≤ {tol:g} N over 3 s, {who}: "
                + (
                    f"{best.method} {best.setting}: {best.cpu_per_sim_s * 3.0 * 1e3:.1f} ms (error {best.wrench_error:.2e} N)"
                    if best
                    else "not reached in the sweep"
                )
            )
    lines.append("peers on the Panda scenes: not run (MuJoCo needs the URDF geometry rewritten, the SE(3) spring as a callback)")
    return "\n".join(lines)


def format_timing(timing: dict[str, dict[str, float]]) -> str:
    """The per-call costs of :func:`rhs_timing`, one column per backend, with the ratio."""
    names = list(timing)
    labels = {
        "rhs_us": "right-hand side",
        "implicit_terms_us": "implicit terms (f, M, K̃, D̃)",
        "implicit_euler_step_us": "implicit_euler step (incl. PD)",
    }
    head = f"{'two Pandas, nv = 20 [µs per call]':<36}" + "".join(f"{n:>10}" for n in names)
    if len(names) == 2:
        head += f"{'ratio':>8}"
    lines = [head, "-" * len(head)]
    for key, label in labels.items():
        line = f"{label:<36}" + "".join(f"{timing[n][key]:>10.1f}" for n in names)
        if len(names) == 2:
            line += f"{timing[names[0]][key] / timing[names[1]][key]:>7.1f}×"
        lines.append(line)
    lines.append("(medians of 7 blocks, backends interleaved)")
    return "\n".join(lines)


def format_implicit_cost(cost: dict[tuple[str, float, int], tuple[float, bool]]) -> str:
    """The whole-run costs of implicit_euler at dt = 1 ms, one line per backend and setting."""
    ks = sorted({k for _, k, _ in cost})
    head = f"{'implicit_euler, dt = 1 ms [CPU s / sim s]':<44}" + "".join(f"{f'k={k:.0e}':>10}" for k in ks)
    lines = [head, "-" * len(head)]
    for name, every in dict.fromkeys((b, e) for b, _, e in cost):
        label = f"{name}, Jacobian every {'step' if every == 1 else f'{every} steps'}"
        cells = []
        for k in ks:
            value, ok = cost[(name, k, every)]
            cells.append(f"{value:>9.4f}{' ' if ok else '!'}")
        lines.append(f"{label:<44}" + "".join(cells))
    lines.append("(PD controller and energy monitor included; median of 5 runs of 1 s; ! = unstable)")
    return "\n".join(lines)


def format_stability(points: Sequence[dict[str, Any]]) -> str:
    """The stability table as text."""
    lines = [f"{'k [N/m]':>8} {'method':<17} {'ω_max [rad/s]':>13} {'predicted dt':>13} {'measured dt':>12}"]
    for p in points:
        pred = "any" if math.isinf(p["predicted_dt"]) else f"{p['predicted_dt'] * 1e3:.4g} ms"
        meas = f"{p['measured_dt'] * 1e3:.4g} ms" + (" (max tried)" if math.isinf(p["predicted_dt"]) else "")
        lines.append(f"{p['k']:>8.0e} {p['method']:<17} {p['omega_max']:>13.4g} {pred:>13} {meas:>12}")
    return "\n".join(lines)


__all__ = [
    "Case",
    "Row",
    "linear_case",
    "panda_case",
    "rhs_timing",
    "run_benchmarks",
    "stability_sweep",
    "work_precision",
]
