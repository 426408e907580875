"""``coopdyn.rollout``: many open-loop trajectories of one scene in threads, as arrays.

Each trajectory plays its own torque sequence (:class:`coopdyn.control.TorqueSequence`) from its
own start state through :class:`coopdyn.Simulator`'s compiled loop, which releases the GIL while
it steps: the threads run on every core (the anchor: ``mujoco.rollout``). What model-predictive
control, trajectory optimisation and identification by finite differences ask of a simulator.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _validate
from .budget import MAX_STEPS, step_count
from .control.joint import TorqueSequence
from .errors import CoopdynError, SimulationError
from .model.scene import Scene
from .simulator import Simulator

__all__ = ["Rollouts", "rollout"]


@dataclass(frozen=True)
class Rollouts:
    """B trajectories sampled at n instants (one per control period, the start included)."""

    t: np.ndarray  #: (n,) [s]
    q: np.ndarray  #: (B, n, nq) configurations; NaN after a trajectory failed
    v: np.ndarray  #: (B, n, nv) velocities [rad/s, m/s]
    status: tuple[str, ...]  #: (B,) "done", or what stopped that trajectory (the error's message)


def rollout(
    scene: Scene,
    torques: Any,
    *,
    period: float,
    dt: float | None = None,
    q0: Any = None,
    v0: Any = None,
    integrator: Any = "implicit_euler",
    threads: int | None = None,
    max_speed: float = 1e4,
) -> Rollouts:
    """Simulate B trajectories, trajectory b playing ``torques[b]`` (N, n_actuated) [N·m or N],
    each row held for ``period`` [s] (N·period in all), from ``q0[b]``, ``v0[b]``.

    Args:
        scene: the scene.
        torques: (B, N, n_actuated) [N·m or N]; an elastic joint's torque acts on its motor.
        period: the control period [s]; the samples are taken at its multiples.
        dt: the integrator's step [s], a divisor of ``period``; default ``period``.
        q0, v0: (nq,) / (nv,) for all, or (B, nq) / (B, nv); default the scene's start.
        integrator: a method name or instance (a compiled one runs the threads in parallel).
        threads: worker threads (default: the machine's cores); 1 runs them in this thread.
        max_speed: [rad/s or m/s] beyond which a trajectory counts as diverged.

    Returns:
        :class:`Rollouts`; a trajectory that diverges or fails keeps its samples up to the last
        one reached, NaN after, and its error's message in ``status`` — the others are unaffected.

    Raises:
        SimulationError, SceneError: a bad argument, or what stops every trajectory alike before
            its first sample (a method the scene does not take, a shared start that is no state,
            more than :data:`coopdyn.budget.MAX_STEPS` steps a trajectory).
    """
    if not isinstance(scene, Scene):
        raise SimulationError(f"rollout: scene must be a coopdyn.Scene, got {type(scene).__name__}")
    U = _validate.finite_array(torques, "rollout: torques [N·m or N]", error=SimulationError)
    na = scene.n_actuated
    if U.ndim != 3 or U.shape[0] < 1 or U.shape[1] < 1 or U.shape[2] != na:
        raise SimulationError(f"rollout: torques must be (B, N, {na}): B trajectories of N periods, got shape {U.shape}")
    B, N = U.shape[:2]
    period = _validate.positive(period, "rollout: period", "s", SimulationError)
    dt = period if dt is None else _validate.positive(dt, "rollout: dt", "s", SimulationError)
    per = round(period / dt)
    if per < 1 or abs(per * dt - period) > 1e-9 * period:
        raise SimulationError(f"rollout: dt = {dt:g} s must divide the period {period:g} s")
    starts = [_states(q0, scene.q0, scene.nq, B, "q0"), _states(v0, scene.v0, scene.nv, B, "v0")]
    if threads is None:
        threads = os.cpu_count() or 1
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise SimulationError(f"rollout: threads must be a positive integer, got {threads!r}")
    t_final = N * period
    if step_count(t_final, dt) > MAX_STEPS:
        raise SimulationError(
            f"rollout: {N} periods of {period:g} s at dt = {dt:g} s are {step_count(t_final, dt):,} steps a trajectory, more "
            f"than {MAX_STEPS:,}: take a larger dt or fewer periods"
        )
    if all(np.ndim(x) <= 1 for x in (q0, v0)):  # (a shared start that is no state stops every trajectory alike)
        scene.check_state(starts[0][0], starts[1][0])
    Q = np.full((B, N + 1, scene.nq), np.nan)
    V = np.full((B, N + 1, scene.nv), np.nan)
    status = ["done"] * B
    local = threading.local()

    def one(b: int) -> None:
        if not hasattr(local, "simulator"):  # one simulator (its kernel, its loop) per thread
            local.sequence = TorqueSequence(scene, U[b], period)
            local.simulator = Simulator(  # (sampled once per period: every stage of its steps sees that row)
                scene, local.sequence, integrator, dt, save_every=per, max_speed=max_speed, control_dt=period
            )
        local.sequence.torques = U[b]
        try:
            res = local.simulator.run(t_final, starts[0][b], starts[1][b])
        except CoopdynError as exc:
            status[b] = str(exc)
            res = getattr(exc, "result", None)
            if res is None:
                return
        n = len(res.t)
        Q[b, :n], V[b, :n] = res.q, res.v

    if threads == 1 or B == 1:
        for b in range(B):
            one(b)
    else:
        with ThreadPoolExecutor(min(threads, B)) as pool:
            list(pool.map(one, range(B)))
    if all(x != "done" for x in status) and np.isnan(Q[:, 0, 0]).all() and len(set(status)) == 1:
        raise SimulationError(f"rollout: {status[0]}")  # (stopped before any sample, all alike: the setup's error)
    return Rollouts(np.arange(N + 1) * period, Q, V, tuple(status))


def _states(value: Any, default: np.ndarray, n: int, B: int, name: str) -> np.ndarray:
    """(B, n) start states from None, one state (n,) or one per trajectory (B, n)."""
    if value is None:
        return np.broadcast_to(default, (B, n))
    x = _validate.finite_array(value, f"rollout: {name}", error=SimulationError)
    if x.shape == (n,):
        return np.broadcast_to(x, (B, n))
    if x.shape != (B, n):
        raise SimulationError(f"rollout: {name} must be ({n},) or ({B}, {n}), got shape {x.shape}")
    return x
