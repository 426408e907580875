"""The measurements: work–precision sweeps, stability sweeps, per-call and whole-run timings."""

from __future__ import annotations

import contextlib
import math
import statistics
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from typing import Any

import numpy as np

from ..closed_loop import System
from ..control import GravityCompensationPD
from ..dynamics import Dynamics
from ..dynamics.backend import native_available
from ..errors import DivergenceError, EnergyBalanceWarning
from ..integrators import INTEGRATORS, Integrator, LinearlyImplicitEuler, get_integrator
from ..problems.facing_arms import facing_arms
from ..problems.linear_book import book_positions, linear_book_exact
from ..result import Result
from ..simulate import simulate
from ..stability import advise
from .cases import OUTPUT_INTERVAL, Case, Row, _forces
from .stability import measure_stable_dt


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """BLAS (OpenBLAS, under numpy and scipy) on one thread while benchmarks run (threadpoolctl).

    Every matrix a benchmark multiplies or factorises is small (a scene's nv, or the linear case's
    exponential blocks), where a BLAS thread pool gains nothing; and an idle OpenBLAS worker keeps
    spinning for a while after each call, CPU time that ``time.process_time`` charges to whichever
    run comes next, at random.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


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


def run_point(case: Case, integrator: Integrator, dt: float) -> tuple[Result, bool]:
    """One run of ``case`` at step ``dt`` saved on the output grid: the result and whether the
    energy monitor warned (errors such as DivergenceError propagate)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", EnergyBalanceWarning)
        res = simulate(
            case.scene,
            case.t_final,
            controller=case.controller,
            integrator=integrator,
            dt=dt,
            save_every=max(1, round(OUTPUT_INTERVAL / dt)),
            v0=case.v0,
            accuracy_check="off",  # the benchmark measures the error itself
        )
    return res, any(issubclass(w.category, EnergyBalanceWarning) for w in caught)


def errors_against(res: Result, positions: np.ndarray, forces: np.ndarray) -> tuple[float, float]:
    """Largest object-position error [m] and interconnection-force error [N] of ``res`` against
    reference positions (n, 3) and forces (n, links, 3) on its output grid."""
    return (
        float(np.max(np.linalg.norm(res.object_position() - positions, axis=1))),
        float(np.max(np.linalg.norm(_forces(res) - forces, axis=2))),
    )


def _measure(case: Case, method: str, label: str, dt: float, rtol: float, repeats: int) -> Row:
    cpu: list[float] = []
    res = None
    flagged = False
    for _ in range(repeats):
        try:
            res, warned = run_point(case, _make(method, rtol), dt)
            flagged = flagged or warned
        except DivergenceError:
            return diverged_row(case, method, label, dt, rtol, energy_flag=True)
        cpu.append(res.cpu_time)
        if res.cpu_time > 2.0:  # slow points: fewer repeats (the median of what ran)
            break
    assert res is not None
    pos, forces = case.reference(res)
    pos_err, force_err = errors_against(res, pos, forces)
    if case.name == "linear":  # the object's position along the book's axis
        pos_err = float(np.max(np.abs(book_positions(res.q, res.scene)[:, 1] - pos[:, 2])))
    return measured_row(case, method, label, dt, rtol, res, pos_err, force_err, cpu, flagged)


def measured_row(
    case: Case, method: str, label: str, dt: float, rtol: float, res: Any, pos_err: float, force_err: float,
    cpu: list[float], energy_flag: bool,
) -> Row:  # fmt: skip
    """The chart point of a run that finished: its errors, median CPU per simulated second, counters."""
    cost = statistics.median(cpu) / case.t_final
    return Row(case.name, method, label, dt, rtol, pos_err, force_err, cost, res.n_rhs, res.n_factor, True, energy_flag)


def diverged_row(case: Case, method: str, label: str, dt: float, rtol: float, energy_flag: bool) -> Row:
    """The chart point of a run that diverged (infinite errors, no cost)."""
    return Row(case.name, method, label, dt, rtol, math.inf, math.inf, math.nan, 0, 0, False, energy_flag)


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
        scene = facing_arms("panda", stiffness=k)
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
                    simulate(scene, 0.5, controller=ctrl, integrator=m, dt=dt, v0=v0, energy_check="raise", accuracy_check="off")
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
    scene = facing_arms("panda", stiffness=1e4)
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


def _implicit_cost(stiffnesses: Sequence[float], t_final: float) -> dict[tuple[str, float, int], tuple[float, bool]]:
    """CPU s per simulated s of implicit_euler at dt = 1 ms on the Panda scene (PD 50/5, energy
    monitor on), with the Jacobian evaluated every step and every 10 steps, per backend (the
    backends alternate run by run); median of 5. Keys: (backend, k, jacobian_every)."""
    out = {}
    for k in stiffnesses:
        scene = facing_arms("panda", stiffness=k)
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
                            accuracy_check="off",
                        )
                        cpu[name].append(res.cpu_time / t_final)
                        ok[name] = bool(np.max(np.abs(res.v)) < 10.0)
                    except DivergenceError:
                        ok[name] = False
            for name, x in cpu.items():
                out[(name, k, every)] = (statistics.median(x) if x else math.nan, ok[name])
    return out
