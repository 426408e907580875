"""Stability: predicted (linearised) and measured largest stable steps, and advice per method.

:func:`advise` linearises the scene at a state, ``x' = A x`` with
``A = [[0, I], [−M⁻¹K̃, −M⁻¹D̃]]`` (interconnections, joint damping and the controller's PD
gains), and finds for each method the largest step whose step map has spectral radius ≤ 1.
:func:`measure_stable_dt` finds the same limit by bisection on real simulations.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .closed_loop import Controller, System
from .dynamics import Dynamics
from .errors import SimulationError
from .integrators import INTEGRATORS, Integrator, get_integrator
from .integrators.implicit import GeneralizedAlpha, _check_rho
from .model.scene import Scene
from .transient import AlphaTransient, judge

#: |λ|·dt above which a step does not resolve an oscillatory mode (fewer than 2π steps per
#: period). Measured on the book's system with undamped interconnections (``.venv/bin/python
#: benchmarks/unresolved_modes.py``): from |λ|·dt ≈ 1 on, implicit Euler's and the trapezoid's
#: force errors no longer fall with dt — 153–157 N and 236–309 N on a ~290 N signal, the
#: mode's whole swing — so the warning marks where the mode is lost, not where it is accurate:
#: below it the trapezoid's error falls fast (1.4 N at |λ|·dt = 0.10, 0.16 N at 0.03) while
#: implicit Euler's stays large (45 N and 22 N there).
RESOLVE_LIMIT = 1.0

#: the methods ``advise`` reports on by default: the registry's ``advised`` ones, in its order
ADVISED = tuple(name for name, cls in INTEGRATORS.items() if cls.advised)


@dataclass(frozen=True)
class MethodAdvice:
    """What one method can do on the linearised scene."""

    name: str
    max_stable_dt: float  #: predicted largest stable step [s] (``inf``: unconditionally stable)
    applicable: bool  #: False when the method cannot run this scene (``exponential`` on a nonlinear one)
    note: str


@dataclass(frozen=True)
class Oscillation:
    """The fastest oscillatory mode of the linearised scene (a complex eigenvalue pair)."""

    rate: float  #: |λ| [1/s] (the undamped natural frequency ω_n of the mode)
    damping_ratio: float  #: −Re λ / |λ|

    @property
    def frequency(self) -> float:
        """Its damped frequency |Im λ| / 2π [Hz]."""
        return self.rate * math.sqrt(max(1.0 - self.damping_ratio**2, 0.0)) / (2.0 * math.pi)

    @property
    def max_resolved_dt(self) -> float:
        """Largest step that resolves it, :data:`RESOLVE_LIMIT` / |λ| [s]."""
        return RESOLVE_LIMIT / self.rate


#: Modes damped more than this (overshoot below 16 %) die out within a period on their own; a
#: step that does not resolve them costs a transient, not a force signal.
OSCILLATORY_DAMPING = 0.5


def fastest_oscillation(lam: np.ndarray) -> Oscillation | None:
    """Among the eigenvalues ``lam`` of a state matrix, the oscillatory pair (damping ratio below
    :data:`OSCILLATORY_DAMPING`) with the largest |λ|, if any."""
    mag = np.abs(lam)
    osc = (np.abs(lam.imag) > 1e-6 * np.maximum(mag, 1e-300)) & (-lam.real < OSCILLATORY_DAMPING * mag)
    if not np.any(osc):
        return None
    k = int(np.argmax(np.where(osc, mag, -1.0)))
    return Oscillation(float(mag[k]), 0.0 - float(lam[k].real / mag[k]))  # 0.0 −: an undamped mode prints 0, not −0


@dataclass(frozen=True)
class Advice:
    """The result of :func:`advise`."""

    omega_max: float  #: largest undamped natural frequency [rad/s]
    damping_ratio: float  #: damping ratio of the fastest eigenvalue (−Re λ / |λ|)
    lambda_max: float  #: largest |λ| of the linearised first-order system [1/s]
    linear: bool  #: whether the scene's dynamics are exactly linear
    methods: tuple[MethodAdvice, ...]
    recommendation: str
    oscillation: Oscillation | None = None  #: the fastest oscillatory mode (accuracy: see ``max_resolved_dt``)
    eigenvalues: np.ndarray | None = field(default=None, repr=False)  #: of the linearised system [1/s]
    #: generalized-α's start transient at the ``dt`` given to :func:`advise`, when it is more than
    #: :data:`coopdyn.transient.LIMIT` times the trapezoid's (:mod:`coopdyn.transient`)
    alpha_transient: AlphaTransient | None = None

    @property
    def max_resolved_dt(self) -> float:
        """Largest step [s] that resolves every oscillatory mode (``inf``: none oscillates). Above
        it, stable implicit methods (``implicit_euler``, ``ros2``, ``trapezoid``) still run but damp
        or mis-phase that mode, and the forces it carries are wrong."""
        return math.inf if self.oscillation is None else self.oscillation.max_resolved_dt

    def max_stable_dt(self, name: str) -> float:
        """Predicted largest stable step of the method ``name`` [s]."""
        for m in self.methods:
            if m.name == name:
                return m.max_stable_dt
        raise SimulationError(f"no advice for {name!r}; advised: {[m.name for m in self.methods]}")

    def limiting_mode(self, name: str) -> complex | None:
        """The eigenvalue λ [1/s] that sets the method ``name``'s largest stable step (the first
        to leave its stability region as dt grows); ``None`` when the method is stable at any step.
        For a method without a scalar stability function (symplectic Euler): the largest |λ|."""
        h = self.max_stable_dt(name)
        lam = self.eigenvalues
        if math.isinf(h) or lam is None or not lam.size:
            return None
        try:
            with np.errstate(all="ignore"):
                r = np.abs(get_integrator(name).stability_function(1.01 * h * lam))
            k = int(np.nanargmax(r))
        except (NotImplementedError, ValueError):
            k = int(np.argmax(np.abs(lam)))
        return complex(lam[k])

    def diagnosis(self, name: str, dt: float) -> str:
        """Why the method ``name`` at step ``dt`` [s] is or is not stable here: the mode that limits
        its step (|λ|, damping ratio, frequency), its limit on |λ|·dt, the largest stable dt of every
        advised method and which are stable at ``dt`` — the figures :meth:`__str__` tables."""

        def ms(h: float) -> str:
            return "any" if math.isinf(h) else f"{h * 1e3:.4g} ms"

        parts = []
        names = [m.name for m in self.methods if m.applicable]
        if name in names:
            h = self.max_stable_dt(name)
            lam = self.limiting_mode(name)
            if lam is not None:
                rate = abs(lam)
                zeta = 0.0 - lam.real / rate if rate > 0 else 1.0
                freq = abs(lam.imag) / (2 * math.pi)
                kind = f"{freq:.4g} Hz, damping ratio {zeta:.3g}" if abs(lam.imag) > 0 else "non-oscillatory"
                parts.append(
                    f"the mode that limits {name}'s step has |λ| = {rate:.4g} 1/s ({kind}); {name} is stable while "
                    f"|λ|·dt ≤ {rate * h:.3g}, i.e. dt ≤ {ms(h)}, and dt = {dt * 1e3:.4g} ms gives |λ|·dt = {rate * dt:.3g}"
                )
            elif (
                name == "generalized_alpha"
                and self.alpha_transient is not None
                and math.isclose(self.alpha_transient.dt, dt, rel_tol=1e-12)
            ):
                parts.append(f"generalized_alpha is stable at any dt here, but {self.alpha_transient.text()}")
            else:
                parts.append(
                    f"{name} is predicted stable at any dt here (the blow-up is nonlinear: a larger motion, or the controller)"
                )
        parts.append("largest stable dt: " + ", ".join(f"{m.name} {ms(m.max_stable_dt)}" for m in self.methods if m.applicable))
        stable = self.stable_at(dt)
        parts.append(f"stable at dt = {dt * 1e3:.4g} ms: {', '.join(stable) if stable else 'none of them'}")
        return "; ".join(parts)

    def stable_at(self, dt: float) -> list[str]:
        """Names of the applicable methods predicted stable at ``dt`` [s]."""
        return [m.name for m in self.methods if m.applicable and dt <= m.max_stable_dt]

    def __str__(self) -> str:
        lines = [
            f"stiffest mode: ω_max = {self.omega_max:.4g} rad/s, |λ|max = {self.lambda_max:.4g} 1/s, "
            f"damping ratio {self.damping_ratio:.3g}; dynamics {'linear' if self.linear else 'nonlinear'}",
            f"{'method':<18} {'largest stable dt':>18}  note",
        ]
        for m in self.methods:
            dt = "unconditional" if math.isinf(m.max_stable_dt) else f"{m.max_stable_dt * 1e3:.4g} ms"
            lines.append(f"{m.name:<18} {dt if m.applicable else 'n/a':>18}  {m.note}")
        if self.oscillation is not None:
            o = self.oscillation
            lines.append(
                f"accuracy: the fastest oscillatory mode ({o.frequency:.4g} Hz, |λ| = {o.rate:.4g} 1/s, damping ratio "
                f"{o.damping_ratio:.3g}) is resolved at dt ≤ {o.max_resolved_dt * 1e3:.4g} ms; above that even stable "
                "methods get the forces it carries wrong"
            )
        lines.append(self.recommendation)
        return "\n".join(lines)


def linearize(scene: Scene, q: Any = None, v: Any = None, controller: Controller | None = None) -> np.ndarray:
    """State matrix A (2nv, 2nv) of the linearised stiff dynamics at (q, v)."""
    if not isinstance(scene, Scene):
        raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
    q, v = scene.check_state(scene.q0 if q is None else q, scene.v0 if v is None else v)
    return state_matrix(*System(Dynamics(scene), controller).stiffness(q, v))


def state_matrix(M: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``A = [[0, I], [−M⁻¹K, −M⁻¹D]]`` (2n, 2n) of ``M ẍ + D ẋ + K x = 0``."""
    n = M.shape[0]
    return np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])


def predicted_stable_dt(method: Integrator, A: np.ndarray, *, h_max: float = 10.0, rel_tol: float = 1e-3) -> float:
    """Largest h with spectral radius of the step map ≤ 1 (+1e-9), by bisection; ``inf`` when
    the method is stable up to ``h_max`` [s]."""
    if method.a_stable:
        return math.inf

    def stable(h: float) -> bool:  # 1e-6: the rigid-body modes' Jordan blocks sit at 1 ± O(√ε)
        return method.spectral_radius(A, h) <= 1.0 + 1e-6

    if stable(h_max):
        return math.inf
    lo, hi = 1e-12, h_max
    while hi / lo > 1.0 + rel_tol:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def advise(
    scene: Scene,
    q: Any = None,
    v: Any = None,
    controller: Controller | None = None,
    methods: Sequence[str] = ADVISED,
    dt: float | None = None,
    *,
    rho_inf: float | None = None,
) -> Advice:
    """Linearise ``scene`` at (q, v) (default: its initial state) and advise on integrators.

    Args:
        scene: the scene. q, v: the state to linearise at.
        controller: its PD gains (``controller.gains()``) enter the linearisation when it has them.
        methods: names of the methods to report on, from :data:`ADVISED` (the methods with a
            stability function).
        dt: the step the user intends [s]; the recommendation then says which methods are stable at it
            and, when generalized_alpha is among ``methods``, whether its start transient
            (:mod:`coopdyn.transient`) is far worse than the trapezoid's there.
        rho_inf: the ρ∞ of the generalized-α that transient is judged for; default its default
            instance's (0.9).
    """
    from ._validate import _short, positive

    if dt is not None:
        dt = positive(dt, "dt", "s", SimulationError)
    if (
        isinstance(methods, str)
        or not isinstance(methods, Sequence)
        or not all(isinstance(m, str) and m in ADVISED for m in methods)
    ):
        raise SimulationError(f"methods must be a list of names from {list(ADVISED)}, got {_short(methods)}")
    A = linearize(scene, q, v, controller)
    n = scene.nv
    lam = np.linalg.eigvals(A)
    k = int(np.argmax(np.abs(lam)))
    lam_max = float(abs(lam[k]))
    zeta = 0.0 - float(lam[k].real / lam_max) if lam_max > 0 else 1.0
    M_inv_K = -A[n:, :n]
    omega_max = float(math.sqrt(max(np.max(np.linalg.eigvals(M_inv_K).real), 0.0)))
    why_nonlinear = scene.nonlinearity()
    advice = []
    for name in methods:
        method = get_integrator(name)
        if name == "exponential" and why_nonlinear is not None:
            advice.append(MethodAdvice(name, 0.0, False, "needs a linear scene (all joints prismatic)"))
            continue
        h = predicted_stable_dt(method, A)
        if name == "exponential":
            note = "exact discretisation: any dt; error only from the torque hold"
        elif math.isinf(h):
            note = f"stable at any dt (order {method.order}); accuracy sets dt (see below)"
        else:
            note = f"ω_max·dt limit = {omega_max * h:.3g}" + (
                " (adaptive: its step control finds this)" if method.adaptive else ""
            )
        advice.append(MethodAdvice(name, h, True, note))
    if why_nonlinear is None:
        rec = "linear scene: use 'exponential' (exact for a sampled controller, second order with the default first-order hold)"
    else:
        explicit = [a for a in advice if a.applicable and not math.isinf(a.max_stable_dt)]
        fastest = max(explicit, key=lambda a: a.max_stable_dt, default=None)
        rec = (
            f"explicit methods need dt below {fastest.max_stable_dt * 1e3:.3g} ms ({fastest.name}); "
            "above that use 'implicit_euler' (cheapest), or a second-order one: 'trapezoid' or 'generalized_alpha' "
            "keep the interconnections' oscillations, 'ros2' damps them"
            if fastest is not None
            else "use 'implicit_euler' or 'ros2'"
        )
    oscillation = fastest_oscillation(lam)
    transient = None
    if dt is not None:
        ok = [a.name for a in advice if a.applicable and dt <= a.max_stable_dt]
        rec += f". At dt = {dt * 1e3:.4g} ms these are stable: {ok}"
        if oscillation is not None and dt > oscillation.max_resolved_dt and why_nonlinear is not None:
            rec += (
                f"; but dt > {oscillation.max_resolved_dt * 1e3:.4g} ms does not resolve the {oscillation.frequency:.4g} Hz mode"
            )
        if "generalized_alpha" in methods:
            rho = GeneralizedAlpha().rho_inf if rho_inf is None else _check_rho(rho_inf)
            transient = judge(A, dt, rho)
        if transient is not None:
            rec += f". generalized_alpha is stable, but {transient.text()}"
            note = f"; a start velocity grows up to {transient.growth()} (see the recommendation)"
            advice = [dataclasses.replace(a, note=a.note + note) if a.name == "generalized_alpha" else a for a in advice]
    return Advice(omega_max, zeta, lam_max, why_nonlinear is None, tuple(advice), rec, oscillation, lam, transient)


__all__ = [
    "ADVISED",
    "RESOLVE_LIMIT",
    "Advice",
    "MethodAdvice",
    "Oscillation",
    "advise",
    "fastest_oscillation",
    "linearize",
    "predicted_stable_dt",
    "state_matrix",
]
