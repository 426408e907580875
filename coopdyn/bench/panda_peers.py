"""coopdyn against MuJoCo, Drake and Exudyn on the Panda scenes (``coopdyn bench --peers``),
interleaved in one process (Drake and Exudyn when installed).

For each stiffness: the benchmark's Panda case (two Pandas + 2 kg box, undamped
interconnections, gravity compensation + PD 50/5, perturbed start; reference Dormand–Prince at
rtol 1e-11), built in MuJoCo from coopdyn's own model (:mod:`.mujoco_scene`) after checking that
the accelerations agree at random states. Every run — coopdyn's methods over steps and
tolerances, MuJoCo's ``implicitfast`` and ``RK4`` over steps, Drake's discrete plant over steps
and its RK3 over accuracies, Exudyn's RK44 and generalized-α over steps — is timed in rounds: round r runs
every point once, so machine noise hits all simulators alike; the CPU time is the median over
rounds. Errors are each run's largest interconnection-force error on the 10 ms output grid,
against the same reference (MuJoCo's trajectory is read back into coopdyn's coordinates and its
forces are evaluated by the same law; Drake's likewise; Exudyn's against Exudyn's own reference,
since its spring law differs).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..errors import CoopdynError, SimulationError
from ..integrators import INTEGRATORS, Integrator, Trapezoid
from ..result import Result
from .cases import OUTPUT_INTERVAL, Case, Row, _forces, panda_case
from .drake_scene import drake_available
from .measure import _bar, _make, diverged_row, errors_against, measured_row, run_point

PEERS = ("mujoco", "exudyn", "drake")


def exudyn_available() -> bool:
    """True when ``import exudyn`` works."""
    try:
        import exudyn  # type: ignore[import-not-found,unused-ignore]  # noqa: F401
    except ImportError:
        return False
    return True


#: force-error levels of the comparison table [N]
LEVELS = (10.0, 0.1, 1e-3, 1e-6)
#: coopdyn methods in the comparison (fixed steps, or tolerances for the adaptive one)
METHODS = ("implicit_euler", "trapezoid", "trapezoid rho_inf=0.7", "generalized_alpha", "ros2", "rk4", "dopri5", "dop853")
#: settings of a method other than its default, by label (ρ∞ = 0.7: picked on this benchmark, at
#: k = 1e4 and 5 ms, from 1, 0.9, 0.7, 0.5, 0 — a user's choice, shown beside the default)
VARIANTS: dict[str, Callable[[], Integrator]] = {"trapezoid rho_inf=0.7": lambda: Trapezoid(rho_inf=0.7)}
MUJOCO = ("implicitfast", "RK4")
#: the label suffix of the MuJoCo rows whose law and controller are Python callbacks (the
#: unlabelled MuJoCo rows run them as compiled C callbacks: the fair peer)
PYTHON_CALLBACKS = " (Python callbacks)"
#: Exudyn's solvers in the comparison (when ``import exudyn`` works)
EXUDYN = ("RK44", "GeneralizedAlpha")
#: Drake's ways of running the scene (when ``import pydrake`` works): its discrete plant over
#: steps, and a continuous plant with its default error-controlled integrator over accuracies
DRAKE = ("discrete", "runge_kutta3")


def _steps(quick: bool) -> list[float]:
    n = 4 if quick else 8
    return [5e-3 / 2**k for k in range(n)]


def _rtols(quick: bool) -> list[float]:
    return [1e-4, 1e-7, 1e-10] if quick else [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]


def _coopdyn_point(
    case: Case, method: str, dt: float, rtol: float, flags: set[int], i: int
) -> Callable[[], tuple[float, Result | None]]:
    def run() -> tuple[float, Result | None]:
        integrator = VARIANTS[method]() if method in VARIANTS else _make(method, rtol)
        try:
            res, warned = run_point(case, integrator, dt)
        except CoopdynError:  # diverged, or refused (step matrix, step control): a failed point
            return math.nan, None
        if warned:
            flags.add(i)  # the energy monitor flagged it: never a "cheapest run"
        return res.cpu_time, res

    return run


def _peer_result(
    case: Case, run: tuple[np.ndarray, np.ndarray, np.ndarray, float], method: str, dt: float, n_steps: int
) -> tuple[float, Result | None]:
    """A peer's run (t, Q, V in Pinocchio's convention, CPU seconds) as a point: its CPU time and
    result, or (nan, None) when it stopped early or ran away (a diverged point)."""
    t, Q, V, cpu = run
    if t.size != round(case.t_final / OUTPUT_INTERVAL) + 1 or not (np.all(np.isfinite(Q)) and np.all(np.abs(V) < 1e4)):
        return math.nan, None
    tau = np.zeros((t.size, case.scene.n_actuated))  # the peers' torques are not read back
    return cpu, Result(case.scene, t, Q, V, tau, method, dt, n_steps, cpu)


def _mujoco_point(case: Case, integrator: str, dt: float, compiled: bool = True) -> Callable[[], tuple[float, Result | None]]:
    from .mujoco_scene import MujocoScene

    peer = MujocoScene(case.scene, case.controller, integrator, dt, compiled=compiled)
    label = f"mujoco {integrator}" + ("" if compiled else PYTHON_CALLBACKS)

    def run() -> tuple[float, Result | None]:
        save_every = max(1, round(OUTPUT_INTERVAL / dt))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                t, Q, V, cpu, n_steps = peer.run(case.scene.q0, case.v0, case.t_final, save_every)
            except CoopdynError:  # the controller met a runaway state (e.g. grasps collapsed): a failed point
                return math.nan, None
        return _peer_result(case, (t, Q, V, cpu), label, dt, n_steps * (4 if integrator == "RK4" else 1))

    return run


def _drake_accuracies(quick: bool) -> list[float]:
    return [1e-2, 1e-4, 1e-6] if quick else [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7]


def _drake_point(case: Case, integrator: str, setting: float) -> Callable[[], tuple[float, Result | None]]:
    """A Drake run: the discrete plant at step ``setting`` [s], or a continuous plant with
    ``integrator`` at target accuracy ``setting``."""
    from .drake_scene import DrakeScene

    discrete = integrator == "discrete"
    peer = DrakeScene(case.scene, case.controller, time_step=setting if discrete else 0.0)

    def run() -> tuple[float, Result | None]:
        try:
            t, Q, V, cpu, n_steps = peer.run(
                case.scene.q0, case.v0, case.t_final, OUTPUT_INTERVAL, None if discrete else integrator, setting
            )
        except (CoopdynError, RuntimeError):  # the controller at a runaway state, or Drake's integrator gave up
            return math.nan, None
        return _peer_result(case, (t, Q, V, cpu), f"drake {integrator}", setting if discrete else OUTPUT_INTERVAL, n_steps)

    return run


def _exudyn_point(case: Case, peer: Any, solver: str, dt: float) -> Callable[[], tuple[float, Result | None]]:
    """An Exudyn run; its errors are against Exudyn's own reference (its spring law is not coopdyn's)."""

    def run() -> tuple[float, Result | None]:
        try:
            run = peer.run(case.scene.q0, case.v0, case.t_final, dt, solver)
        except Exception:  # Exudyn's solver gave up (its own error types)
            return math.nan, None
        return _peer_result(case, run, f"exudyn {solver}", dt, round(case.t_final / dt))

    return run


def _exudyn_reference(case: Case, peer: Any) -> tuple[np.ndarray, np.ndarray]:
    """Exudyn's own tight solution, its RK44 at dt = 10 µs (it agrees with 20 and 40 µs to ~2e-11 in
    the coordinates; Exudyn's DOPRI5 at rtol 1e-10 stays 3e-5 away, so it is not the reference):
    object positions and forces on the grid."""
    t, Q, V, _ = peer.run(case.scene.q0, case.v0, case.t_final, 1e-5, "RK44")
    res = Result(case.scene, t, Q, V, np.zeros((t.size, case.scene.n_actuated)), "exudyn RK44", 1e-5, 0, 0.0)
    return res.object_position(), _forces(res)


def _exudyn_takes(case: Case) -> bool:
    """Whether the Exudyn peer can run the case: it models the joint PD + gravity compensation
    in Exudyn's own kinematic tree (its PD vector), not the object impedance of the task."""
    from ..control import GravityCompensationPD

    rigid = not case.scene.joint_springs.size  # (nor elastic joints)
    return rigid and (case.controller is None or isinstance(case.controller, GravityCompensationPD))


def _check(checks: dict[str, float], case: Case, peer: str, difference: float) -> None:
    """Record a peer's acceleration check; refuse to time a model that is not coopdyn's scene."""
    checks[f"{case.name} ({peer})"] = difference
    if difference > 1e-9:
        raise SimulationError(
            f"{peer}'s accelerations differ from coopdyn's by {difference:.1e} (relative) on {case.name}: "
            f"the {peer} model is not coopdyn's scene, nothing was timed"
        )


def compare(
    stiffnesses: Sequence[float] = (1e4, 1e6),
    *,
    t_final: float = 1.0,
    quick: bool = False,
    rounds: int = 5,
    progress: bool = True,
    chain: bool = True,
    task: bool = False,
    joints: Any = None,
) -> dict[str, Any]:
    """Run the comparison on two Pandas at each stiffness and (``chain``) one Panda at the first
    (the perturbed benchmark: undamped, kicked by a random start), or with ``task`` on the demo's
    task at each stiffness (:func:`.cases.task_case`: damped, grip–lift–oscillate; with ``joints``,
    a :class:`coopdyn.JointElasticity`, on arms with elastic joints — MuJoCo only); returns
    ``rows`` (:class:`Row`, the peers' methods named ``"mujoco …"``, ``"drake …"``,
    ``"exudyn …"``) and ``checks`` (``"scene (MuJoCo)"`` / ``"scene (Drake)"`` → largest
    relative difference between that peer's accelerations and coopdyn's)."""
    from .cases import task_case
    from .mujoco_scene import MujocoScene

    if task:
        cases = [task_case(k, t_final, joints=joints) for k in stiffnesses]
    else:
        cases = [panda_case(k, t_final) for k in stiffnesses]
        if chain:  # one Panda: a 7-link revolute chain holding the box by one spring
            cases.append(panda_case(stiffnesses[0], t_final, n_arms=1))
    checks: dict[str, float] = {}
    references: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # Exudyn's own, per scene
    plan: list[tuple[Case, str, str, float, float, Callable[[], tuple[float, Result | None]]]] = []
    flags: set[int] = set()
    for case in cases:
        _check(checks, case, "MuJoCo", MujocoScene(case.scene, case.controller, "RK4", 1e-3).check())
        if not task:
            _check(checks, case, "MuJoCo, Python callbacks", MujocoScene(case.scene, case.controller, "RK4", 1e-3, False).check())
        h = OUTPUT_INTERVAL
        for m in METHODS:
            if m not in VARIANTS and INTEGRATORS[m].adaptive:
                for r in _rtols(quick):
                    plan.append((case, m, f"rtol={r:g}", h, r, _coopdyn_point(case, m, h, r, flags, len(plan))))
            else:
                for dt in _steps(quick):
                    plan.append((case, m, f"dt={dt:g}", dt, math.nan, _coopdyn_point(case, m, dt, math.nan, flags, len(plan))))
        for mj in MUJOCO:
            plan += [(case, f"mujoco {mj}", f"dt={dt:g}", dt, math.nan, _mujoco_point(case, mj, dt)) for dt in _steps(quick)]
            if not task:  # (the labelled Python-callback row: on the perturbed benchmark, where it was the peer)
                plan += [
                    (case, f"mujoco {mj}{PYTHON_CALLBACKS}", f"dt={dt:g}", dt, math.nan, _mujoco_point(case, mj, dt, False))
                    for dt in _steps(quick)
                ]
        if drake_available() and not case.scene.joint_springs.size:  # (the Drake peer has no elastic joints)
            from .drake_scene import DrakeScene

            _check(checks, case, "Drake", DrakeScene(case.scene, case.controller).check())
            for dk in DRAKE:
                if dk == "discrete":
                    plan += [
                        (case, f"drake {dk}", f"dt={dt:g}", dt, math.nan, _drake_point(case, dk, dt)) for dt in _steps(quick)
                    ]
                else:
                    plan += [
                        (case, f"drake {dk}", f"accuracy={a:g}", OUTPUT_INTERVAL, a, _drake_point(case, dk, a))
                        for a in _drake_accuracies(quick)
                    ]
        if exudyn_available() and _exudyn_takes(case):
            from .exudyn_scene import ExudynScene

            peer = ExudynScene(case.scene, case.controller)
            references[case.name] = _exudyn_reference(case, peer)
            plan += [
                (case, f"exudyn {ex}", f"dt={dt:g}", dt, math.nan, _exudyn_point(case, peer, ex, dt))
                for ex in EXUDYN
                for dt in _steps(quick)
            ]
    load_before = os.getloadavg()[0]  # (the machine's load, reported beside the figures)
    cpu: dict[int, list[float]] = {i: [] for i in range(len(plan))}
    results: dict[int, Result | None] = {}
    with _bar(len(plan) * rounds, "coopdyn vs peers", progress) as bar:
        for _ in range(rounds):
            for i, (case, method, label, _, _, run) in enumerate(plan):
                if i in results and (results[i] is None or sum(cpu[i]) > 10.0):  # diverged, or slow enough
                    bar.update(1)
                    continue
                seconds, res = run()
                cpu[i].append(seconds)
                results.setdefault(i, res)
                bar.set_postfix_str(f"{case.name} {method} {label}")
                bar.update(1)
    rows = []
    for i, (case, method, label, dt, rtol, _) in enumerate(plan):
        res = results[i]
        if res is None:
            rows.append(diverged_row(case, method, label, dt, rtol, energy_flag=False))
            continue
        reference = references[case.name] if method.startswith("exudyn") else case.reference(res)  # Exudyn: its own
        pos_err, force_err = errors_against(res, *reference)
        # an energy-flagged run is not counted as reaching a level (_best_to_reach)
        rows.append(measured_row(case, method, label, dt, rtol, res, pos_err, force_err, cpu[i], i in flags))
    load = (load_before, os.getloadavg()[0])
    return {"rows": rows, "checks": checks, "rounds": rounds, "t_final": t_final, "task": task, "load": load}


def _fair(method: str) -> bool:
    """A MuJoCo row with the law and controller compiled (the fair peer)."""
    return method.startswith("mujoco") and not method.endswith(PYTHON_CALLBACKS)


def format_comparison(result: dict[str, Any]) -> str:
    """For each scene and force-error level: coopdyn's cheapest run that reaches it, MuJoCo's
    with the law and controller compiled (the fair peer) and the ratio; then the best of the
    peers that call the law from Python (MuJoCo's Python callbacks, Drake, Exudyn) and that ratio."""
    from .report import _best_to_reach

    rows: list[Row] = result["rows"]
    present = [name for name in ("Drake", "Exudyn") if any(r.method.startswith(name.lower()) for r in rows)]
    installed = {"Drake": drake_available(), "Exudyn": exudyn_available()}
    missing = [name for name, yes in installed.items() if not yes]
    slow = ", ".join(["MuJoCo", *present]) + (f"; {' and '.join(missing)} not installed" if missing else "")
    if installed["Exudyn"] and "Exudyn" not in present:
        slow += "; Exudyn's peer takes only the joint PD, not the task's object impedance"
    what = (
        "the demo's task (grip, lift, oscillate; damped, D = 0.002 s·K; ObjectImpedance)"
        if result.get("task")
        else "the perturbed start (undamped, random initial velocities; joint PD + gravity compensation)"
    )
    lines = [
        f"{what}: coopdyn vs MuJoCo with coopdyn's law and controller as compiled C callbacks (the fair peer), and vs "
        f"peers calling them from Python ({slow}); {result['t_final']:g} s, CPU median of {result['rounds']} interleaved "
        f"rounds; load average {result['load'][0]:.2f} before the rounds, {result['load'][1]:.2f} after",
        "accelerations checked first, largest relative difference: "
        + ", ".join(f"{name}: {err:.1e}" for name, err in result["checks"].items()),
    ]
    head = (
        f"{'scene':<16} {'level [N]':>9}  {'coopdyn: cheapest run':<34} {'MuJoCo, compiled callbacks':<30} {'ratio':>6}  "
        f"{'best peer with Python callbacks':<52} {'ratio':>6}"
    )
    lines += [head, "-" * len(head)]
    for scene in dict.fromkeys(r.scene for r in rows):
        mine = [r for r in rows if r.scene == scene and not r.method.startswith(PEERS)]
        fair = [r for r in rows if r.scene == scene and _fair(r.method)]
        python = [r for r in rows if r.scene == scene and r.method.startswith(PEERS) and not _fair(r.method)]
        for level in LEVELS:
            a, b, c = _best_to_reach(mine, level), _best_to_reach(fair, level), _best_to_reach(python, level)

            def cell(r: Row | None) -> str:
                return f"{r.method} {r.setting} {r.cpu_per_sim_s * 1e3:.1f} ms" if r else "not reached"

            def ratio(x: Row | None, y: Row | None) -> str:
                return f"{x.cpu_per_sim_s / y.cpu_per_sim_s:.2f}" if x and y else "—"

            lines.append(f"{scene:<16} {level:>9g}  {cell(a):<34} {cell(b):<30} {ratio(a, b):>6}  {cell(c):<52} {ratio(a, c):>6}")
    lines.append("(ms: CPU per simulated second; ratio: coopdyn / that peer, below 1 means coopdyn is cheaper;")
    lines.append(" Exudyn's errors are against its own reference: its spring law differs from coopdyn's at second order)")
    return "\n".join(lines)
