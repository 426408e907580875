"""scipy's ``solve_ivp`` (DOP853, Radau, BDF, …) as a cross-check reference.

Each step of ``simulate`` is integrated to tolerance by scipy in the chart ``q = q₀ ⊕ δ`` of
the step's start. Slow (a Python call per evaluation and a finite-difference Jacobian for the
implicit methods), meant for references, not for production runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from ..errors import SimulationError
from .base import Integrator, Problem, Tolerances

_METHODS = ("DOP853", "RK45", "Radau", "BDF", "LSODA")


class ScipyReference(Tolerances, Integrator):
    """``solve_ivp`` over every step.

    Args:
        method: a ``solve_ivp`` method name (DOP853, RK45, Radau, BDF, LSODA).
        rtol, atol: its tolerances.
    """

    name = "scipy"
    order = 8
    advised = False  # no stability function of its own

    def __init__(self, method: str = "DOP853", rtol: float = 1e-10, atol: float = 1e-12) -> None:
        if not isinstance(method, str) or method not in _METHODS:
            raise SimulationError(f"unknown scipy method {method!r}; valid: {list(_METHODS)}")
        self.method = method
        self.rtol = rtol
        self.atol = atol

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        n = v.size

        def rhs(s: float, y: np.ndarray) -> np.ndarray:
            delta, vel = y[:n], y[n:]
            q_s = system.integrate(q, delta)
            return np.concatenate([system.chart_velocity(q, delta, vel), system.acceleration(s, q_s, vel)])

        sol = solve_ivp(rhs, (t, t + h), np.concatenate([np.zeros(n), v]), method=self.method, rtol=self.rtol, atol=self.atol)
        if not sol.success:
            raise SimulationError(f"scipy {self.method} failed at t = {t:.6g} s: {sol.message}")
        y = sol.y[:, -1]
        return system.integrate(q, y[:n]), y[n:]

    def __repr__(self) -> str:
        return f"ScipyReference(method={self.method!r}, rtol={self.rtol:g}, atol={self.atol:g})"
