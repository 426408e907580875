"""Generalized-α's start transient: how much it amplifies a start velocity on stiff, overdamped
modes, where its spectral radius (at most 1) calls it stable (docs/physics.md).

On a stiff spring with a stiff damper (a beam's stiffness-proportional damping makes every fast
element mode one) the consistent start acceleration q̈(0, v0) = −M⁻¹D v0 is huge, and the method
carries it as its algorithmic acceleration, which decays only by −ρ∞ per step: a start velocity
grows hundreds of times within a few steps. :func:`coopdyn.advise` (given a step) judges it with
:func:`judge`, against the method's undamped member (ρ∞ = 1, Newmark's average acceleration,
whose figures are the trapezoid's), and says so where it is far worse.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import _validate
from .errors import SimulationError
from .integrators.implicit import _check_rho, alpha_amplification

#: generalized-α's start transient this many times its undamped member's is reported. On the
#: 16-element held strip at 1 ms (β = 1e-4 s) the ratio is ~23 at ρ∞ = 0.9; without the beam's
#: damping below 1; on the book's stiff damped system 1.2 (``benchmarks/alpha_overshoot.py``,
#: tests/test_integrators.py).
LIMIT = 10.0
STEPS = 50  #: the steps :func:`start_transient` follows (the undamped member's own growth takes tens)
PROBES = 16  #: the seeded random start velocities it tries, the worst one counting


class AlphaTransient(NamedTuple):
    """Generalized-α's start transient at a step, as :func:`judge` found it."""

    dt: float  #: the step [s]
    amplification: float  #: its largest velocity per unit of the largest start velocity (:func:`start_transient`)
    trapezoid: float  #: the same for ρ∞ = 1, the trapezoid's figure on a linear system
    rho_inf: float  #: the ρ∞ it was computed for

    def growth(self) -> str:
        """ "7,123× at dt = 1 ms": how much a start velocity grows, at which step."""
        return f"{_times(self.amplification)} at dt = {self.dt * 1e3:.4g} ms"

    def text(self) -> str:
        """What it is and what to do (the words after "generalized_alpha is stable, but")."""
        return (
            f"at ρ∞ = {self.rho_inf:g} it amplifies a start velocity up to {_times(self.amplification)} within "
            f"{STEPS} steps of {self.dt * 1e3:.4g} ms, {_times(self.amplification / self.trapezoid)} as much as the "
            "trapezoid (stiff, overdamped modes: a stiff spring with a stiff damper, as a beam's damping makes; "
            "docs/physics.md). From a moving start take the trapezoid or implicit_euler"
        )


def _times(x: float) -> str:
    return f"{x:,.0f}×" if x >= 100 else f"{x:.3g}×"


def start_transient(A: np.ndarray, h: float, rho_inf: float, v0: np.ndarray | None = None, steps: int = STEPS) -> float:
    """How much generalized-α at step ``h`` [s] and ``rho_inf`` amplifies a start velocity on the
    linear system ``x' = A x`` (A (2n, 2n): :func:`coopdyn.stability.state_matrix`): the largest
    velocity entry over its first ``steps`` steps per unit of the largest start-velocity entry,
    the worst of the start velocities ``v0`` ((n,) or (n, p) columns; default :data:`PROBES`
    seeded random ones), each from the consistent start (q, v, a) = (0, v0, q̈(0, v0))
    (:func:`coopdyn.integrators.implicit.alpha_amplification`).

    Raises:
        SimulationError: a bad A, step, ρ∞ or start velocity (a zero one has no amplification).
    """
    A = np.asarray(A, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] % 2 or not np.all(np.isfinite(A)):
        raise SimulationError(f"start_transient: A must be a finite (2n, 2n) state matrix, got shape {A.shape}")
    h, rho_inf = _validate.positive(h, "start_transient: the step h", "s", SimulationError), _check_rho(rho_inf)
    n = A.shape[0] // 2
    v0 = np.random.default_rng(0).standard_normal((n, PROBES)) if v0 is None else np.asarray(v0, dtype=float)
    v0 = v0.reshape(n, -1) if v0.ndim == 1 and v0.size == n else v0
    size = np.abs(v0).max(axis=0) if v0.ndim == 2 and v0.shape[0] == n and v0.shape[1] else np.zeros(0)
    if not size.size or not np.all(np.isfinite(size)) or not np.all(size > 0):
        raise SimulationError(f"start_transient: v0 must be non-zero finite start velocities, (n,) or (n, p) with n = {n}")
    T = alpha_amplification(A[n:, :n], A[n:, n:], h, rho_inf)
    x = np.concatenate([np.zeros_like(v0), v0, A[n:, n:] @ v0])
    worst = np.zeros(v0.shape[1])
    for _ in range(steps):
        x = T @ x
        worst = np.maximum(worst, np.abs(x[n : 2 * n]).max(axis=0))
    return float(np.max(worst / size))


def judge(A: np.ndarray, dt: float, rho_inf: float) -> AlphaTransient | None:
    """Generalized-α's start transient at ``dt`` [s] and ``rho_inf`` when it is more than
    :data:`LIMIT` times its undamped member's, else None — also when ρ∞ = 1 (it is that member)
    or when it cannot be computed (a step so long that the step matrix is singular): a diagnosis
    never turns into an error."""
    if rho_inf >= 1.0:
        return None
    try:
        with np.errstate(all="ignore"):
            own, undamped = start_transient(A, dt, rho_inf), start_transient(A, dt, 1.0)
    except (np.linalg.LinAlgError, SimulationError):
        return None
    if not (math.isfinite(own) and math.isfinite(undamped) and own > LIMIT * undamped):
        return None
    return AlphaTransient(dt, own, undamped, rho_inf)
