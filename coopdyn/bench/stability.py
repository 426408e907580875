"""Measured stability: the largest stable step of a fixed-step method, by bisection on real
simulations (the prediction from the linearised system is :func:`coopdyn.advise`)."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from ..closed_loop import Controller
from ..errors import LogMapWarning, SimulationError
from ..integrators import Integrator, ScipyReference, get_integrator
from ..model.scene import Scene
from ..simulate import simulate


def is_stable_at(
    scene: Scene,
    integrator: str | Integrator,
    dt: float,
    *,
    controller: Controller | None = None,
    n_steps: int = 3000,
    v0: Any = None,
    growth: float = 1e3,
) -> bool:
    """Run ``n_steps`` of ``integrator`` at ``dt`` [s]; stable when the state stays finite and the
    largest velocity stays below ``growth·(1 + max|v₀|)``."""
    from .._validate import _short, count, finite_array, integral, positive

    method = get_integrator(integrator)
    if isinstance(method, ScipyReference) or method.adaptive:
        raise SimulationError("measure the stability of fixed-step methods only")
    dt = positive(dt, "dt", "s", SimulationError)
    if not (integral(n_steps) and n_steps > 10**6):  # (beyond: the range check below names the limit)
        n_steps = count(n_steps, "n_steps", SimulationError)
    growth = positive(growth, "growth", "1", SimulationError)
    if n_steps > 10**6 or not n_steps * dt < 1e9 or not 1.0 <= growth <= 1e100:
        raise SimulationError(
            f"is_stable_at takes n_steps up to 1e6, n_steps·dt below 1e9 s and growth in [1, 1e100]; got n_steps = "
            f"{_short(n_steps)}, dt = {dt:g} s, growth = {growth:g}"
        )
    v_start = scene.v0 if v0 is None else finite_array(v0, "v0", (scene.nv,), SimulationError)
    limit = growth * (1.0 + float(np.max(np.abs(v_start))))
    try:
        with warnings.catch_warnings():  # a run that blows up on purpose may twist its springs past π
            warnings.simplefilter("ignore", LogMapWarning)
            res = simulate(
                scene,
                n_steps * dt,
                controller=controller,
                integrator=method,
                dt=dt,
                v0=v_start,
                save_every=max(1, n_steps // 50),
                max_speed=limit,
                energy_check="off",
                accuracy_check="off",  # stability only
            )
    except SimulationError:
        return False
    return bool(np.max(np.abs(res.v)) < limit)


def measure_stable_dt(
    scene: Scene,
    integrator: str | Integrator,
    *,
    controller: Controller | None = None,
    guess: float = 1e-3,
    rel_tol: float = 0.03,
    n_steps: int = 3000,
    v0: Any = None,
) -> float:
    """Largest stable step [s] of a fixed-step method on ``scene``, by bisection on simulations
    (:func:`is_stable_at`); ``guess`` is a starting bracket point [s] (1e-9 to 1 s), ``rel_tol``
    the bracket's relative width at the end (1e-6 to 1), ``n_steps`` the steps a run at each
    trial step takes (100 to 10⁶: in fewer, an instability cannot grow past the velocity bound,
    and a method stable only below a limit would be measured stable at any step)."""
    from .._validate import _short, count, integral, positive

    method = get_integrator(integrator)
    guess = positive(guess, "guess", "s", SimulationError)
    rel_tol = positive(rel_tol, "rel_tol", "1", SimulationError)
    if not (integral(n_steps) and n_steps > 10**6):  # (beyond: the range check below names the limit)
        n_steps = count(n_steps, "n_steps", SimulationError)
    if not 1e-9 <= guess <= 1.0 or not 1e-6 <= rel_tol <= 1.0 or not 100 <= n_steps <= 10**6:
        raise SimulationError(
            f"measure_stable_dt takes guess in [1e-9, 1] s, rel_tol in [1e-6, 1] and n_steps in [100, 1e6]; got guess = "
            f"{guess:g} s, rel_tol = {rel_tol:g}, n_steps = {_short(n_steps)}"
        )

    def stable(h: float) -> bool:
        return is_stable_at(scene, method, h, controller=controller, n_steps=n_steps, v0=v0)

    lo = hi = guess
    if stable(guess):
        while stable(hi * 2.0):
            hi *= 2.0
            if hi > 1.0:
                return math.inf
        lo, hi = hi, hi * 2.0
    else:
        while not stable(lo / 2.0):
            lo /= 2.0
            if lo < 1e-9:
                return 0.0
        lo, hi = lo / 2.0, lo
    while hi / lo > 1.0 + rel_tol:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo
