"""The integrator contract: :class:`System` (the closed loop, with work counters) and
:class:`Integrator` (configuration + a step function).

A new method subclasses :class:`Integrator` (fixed step: implement ``step``) or
:class:`AdaptiveIntegrator` (implement ``attempt``), gives itself a ``name`` and an ``order``,
and, for :func:`coopdyn.advise`, a scalar ``stability_function`` R(z) (or overrides
``spectral_radius``). Integrator objects hold settings only; everything that evolves is passed
in and returned, and per-run scratch (factorisations, discretisations) lives in ``System.cache``.

States are ``(q, v)`` on the configuration Lie group. Multi-stage methods build their stages in
a local chart ``q = q₀ ⊕ δ`` around the step's start, where ``δ̇ = dIntegrate(q₀, δ)⁻¹ v``
(DESIGN §2): the method then keeps its classical order on SE(3) free-flyers, which naive stages
``q₀ ⊕ h Σ aᵢⱼ vⱼ`` do not.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar, NamedTuple

import numpy as np
import pinocchio as pin

from ..closed_loop import System


class Integrator(ABC):
    """A one-step method for (q, v) on the configuration Lie group."""

    name: ClassVar[str]
    order: ClassVar[int]
    adaptive: ClassVar[bool] = False
    #: True when a step is the exact flow of the model (nothing to monitor for instability).
    exact_discretisation: ClassVar[bool] = False
    #: True when the method is unconditionally stable on the linearised problem.
    a_stable: ClassVar[bool] = False

    @abstractmethod
    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance from (t, q, v) by ``h`` [s]; return the new (q, v)."""

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        """R(z) of the method on y' = λy (z = hλ), elementwise. Needed by :func:`coopdyn.advise`."""
        raise NotImplementedError(f"{self.name} has no scalar stability function")

    def spectral_radius(self, A: np.ndarray, h: float) -> float:
        """Spectral radius of one step applied to the linear system x' = A x, x = (q, v)."""
        return float(np.max(np.abs(self.stability_function(h * np.linalg.eigvals(A)))))

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class Attempt(NamedTuple):
    """One attempted adaptive step."""

    q: np.ndarray
    v: np.ndarray
    error: float  #: scaled error norm (accept when ≤ 1)


class AdaptiveIntegrator(Integrator):
    """A method with an embedded error estimate; ``simulate`` controls its step.

    Args:
        rtol: relative tolerance. atol: absolute tolerance [m, rad, m/s, rad/s].
        h_min: smallest step before the run is declared failed [s].
    """

    adaptive = True
    #: order of the error estimate + 1 is the exponent of the step-size controller
    error_order: ClassVar[int]

    def __init__(self, rtol: float = 1e-6, atol: float = 1e-9, h_min: float = 1e-12) -> None:
        from ..errors import SimulationError

        for name, value in (("rtol", rtol), ("atol", atol), ("h_min", h_min)):
            if not (np.isfinite(value) and value > 0.0):
                raise SimulationError(f"{name} must be a positive number, got {value!r}")
        self.rtol, self.atol, self.h_min = float(rtol), float(atol), float(h_min)

    @abstractmethod
    def attempt(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> Attempt:
        """Try a step of ``h`` [s] from (t, q, v)."""

    def step(self, system: System, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """A step of exactly ``h`` without error control."""
        out = self.attempt(system, t, q, v, h)
        return out.q, out.v

    def error_norm(
        self, system: System, e_delta: np.ndarray, e_v: np.ndarray, q0: np.ndarray, v0: np.ndarray, v1: np.ndarray
    ) -> float:
        """RMS of the embedded error scaled by ``atol + rtol·|y|`` (positions: ``q₀ ⊖ neutral``
        in the tangent space; velocities: the larger of start and end)."""
        neutral = system.cache.get("neutral")
        if neutral is None:
            neutral = system.cache["neutral"] = pin.neutral(system.model)
        sc_d = self.atol + self.rtol * np.abs(pin.difference(system.model, neutral, q0))
        sc_v = self.atol + self.rtol * np.maximum(np.abs(v0), np.abs(v1))
        return float(np.sqrt((np.sum((e_delta / sc_d) ** 2) + np.sum((e_v / sc_v) ** 2)) / (2 * e_v.size)))

    def next_step(self, h: float, error: float) -> float:
        """Step-size controller: ``h·min(5, max(0.2, 0.9·err^(-1/(p+1))))``."""
        if error == 0.0:
            return 5.0 * h
        return h * min(5.0, max(0.2, 0.9 * error ** (-1.0 / (self.error_order + 1))))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(rtol={self.rtol:g}, atol={self.atol:g})"
