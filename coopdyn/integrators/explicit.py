"""Explicit methods: symplectic Euler, Runge–Kutta from a Butcher tableau (RK4), and adaptive
embedded pairs (Dormand–Prince 5(4)). Methods that differ only in coefficients differ only in data."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._spec import RungeKuttaSpec, SymplecticEulerSpec
from ..errors import SimulationError
from .base import AdaptiveIntegrator, Attempt, Integrator, Problem


class SymplecticEuler(Integrator):
    """Semi-implicit Euler: ``v⁺ = v + h a(q, v)``, ``q⁺ = q ⊕ h v⁺``. First order, 1 RHS/step."""

    name = "symplectic_euler"
    order = 1

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        v_new = v + h * system.acceleration(t, q, v)
        return system.integrate(q, h * v_new), v_new

    def compiled_spec(self) -> SymplecticEulerSpec:
        return SymplecticEulerSpec()

    def spectral_radius(self, A: np.ndarray, h: float) -> float:
        """The method is partitioned (no scalar R(z)): use its step matrix on x' = A x."""
        n = A.shape[0] // 2
        A_vq, A_vv = A[n:, :n], A[n:, n:]
        eye = np.eye(n)
        G = np.block([[eye + h * h * A_vq, h * (eye + h * A_vv)], [h * A_vq, eye + h * A_vv]])
        return float(np.max(np.abs(np.linalg.eigvals(G))))


@dataclass(frozen=True)
class ButcherTableau:
    """Coefficients of an explicit Runge–Kutta method (``b_hat``: embedded lower-order weights),
    checked on construction as the compiled loop checks them (src/native/methods/runge_kutta.hpp):
    explicit (row i has at most i entries), one b, c (and b_hat) per stage, consistent
    (Σⱼ aᵢⱼ = cᵢ, Σ b = 1, Σ b_hat = 1, to 1e-12)."""

    A: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]
    b_hat: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        s = len(self.A)
        if s == 0 or len(self.b) != s or len(self.c) != s or (self.b_hat is not None and len(self.b_hat) != s):
            raise SimulationError(
                f"a Butcher tableau needs one b, c (and b_hat) per row of A: {s} rows, {len(self.b)} b, {len(self.c)} c"
            )
        if any(len(row) > i for i, row in enumerate(self.A)):
            raise SimulationError("the tableau must be explicit: row i of A has at most i entries")
        sums = [math.fsum(row) for row in self.A]
        if any(abs(a - c) > 1e-12 for a, c in zip(sums, self.c, strict=True)):
            raise SimulationError(f"inconsistent tableau: the rows of A sum to {sums}, c is {list(self.c)}")
        for name, w in (("b", self.b), ("b_hat", self.b_hat)):
            if w is not None and abs(math.fsum(w) - 1.0) > 1e-12:
                raise SimulationError(f"inconsistent tableau: {name} sums to {math.fsum(w)!r}, not 1")


def combine(coefficients: Sequence[float], ks: list[np.ndarray]) -> np.ndarray:
    """Σ cᵢ kᵢ over the non-zero coefficients (vectors, or matrices of derivatives: coopdyn.sensitivity)."""
    out = np.zeros_like(ks[0])
    for c, k in zip(coefficients, ks, strict=False):
        if c:
            out += c * k
    return out


def _stages(
    tab: ButcherTableau, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, a0: np.ndarray | None = None
) -> tuple[list[np.ndarray], list[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Chart rates δ̇ᵢ and accelerations aᵢ of every stage, and (δ, q, v) of the last stage."""
    kd: list[np.ndarray] = []
    ka: list[np.ndarray] = []
    last = (np.zeros_like(v), q, v)
    for row, c in zip(tab.A, tab.c, strict=True):
        if kd:
            delta = h * combine(row, kd)
            v_s = v + h * combine(row, ka)
            q_s = system.integrate(q, delta)
            kd.append(system.chart_velocity(q, delta, v_s))
            ka.append(system.acceleration(t + c * h, q_s, v_s))
            last = (delta, q_s, v_s)
        else:
            kd.append(v)
            ka.append(system.acceleration(t, q, v) if a0 is None else a0)
    return kd, ka, last


def _tableau_spec(tab: ButcherTableau) -> RungeKuttaSpec:
    b_hat = list(tab.b_hat) if tab.b_hat is not None else None
    return RungeKuttaSpec(A=[list(row) for row in tab.A], b=list(tab.b), c=list(tab.c), b_hat=b_hat)


def _rk_stability(tab: ButcherTableau, z: np.ndarray, weights: tuple[float, ...]) -> np.ndarray:
    """R(z) = 1 + z bᵀ (I − zA)⁻¹ 1 evaluated stage by stage (explicit: A strictly lower)."""
    z = np.asarray(z, dtype=complex)
    stages: list[np.ndarray] = []
    for row in tab.A:
        y = np.ones_like(z)
        for a, k in zip(row, stages, strict=False):
            y = y + a * z * k
        stages.append(y)
    out = np.ones_like(z)
    for b, k in zip(weights, stages, strict=True):
        out = out + b * z * k
    return out


class ExplicitRungeKutta(Integrator):
    """An explicit Runge–Kutta method applied in the local chart around the step's start."""

    tableau: ClassVar[ButcherTableau]

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        tab = self.tableau
        kd, ka, _ = _stages(tab, system, t, q, v, h)
        delta = h * combine(tab.b, kd)
        return system.integrate(q, delta), v + h * combine(tab.b, ka)

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _rk_stability(self.tableau, z, self.tableau.b)


class RK4(ExplicitRungeKutta):
    """The classical fourth-order Runge–Kutta method (Lie-group correct), 4 RHS/step."""

    name = "rk4"
    order = 4
    tableau = ButcherTableau(
        A=((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)),
        b=(1 / 6, 1 / 3, 1 / 3, 1 / 6),
        c=(0.0, 0.5, 0.5, 1.0),
    )

    def compiled_spec(self) -> RungeKuttaSpec:
        return _tableau_spec(self.tableau)


class _FirstSameAsLast:
    """An embedded pair's workspace: the last stage's acceleration, reused as the next step's first
    when that step starts from the same state array ``q`` with the same controller output (no
    new ``control_dt`` sample)."""

    def __init__(self) -> None:
        self.q: np.ndarray | None = None
        self.a: np.ndarray | None = None


_DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),
)


class EmbeddedRungeKutta(AdaptiveIntegrator):
    """An adaptive explicit Runge–Kutta pair whose last stage is its solution (first same as
    last): the last row of A is b, its c is 1 and its own weight 0, so the next step starts from
    that stage's acceleration. ``b_hat`` gives the embedded solution; ``error_order`` is the
    order of the error estimate ``b − b_hat`` (the step controller's exponent is 1/(p + 1)).
    A subclass that only sets ``tableau``, ``name``, ``order`` and ``error_order`` is
    differentiated by :mod:`coopdyn.sensitivity` as its tableau.
    """

    tableau: ClassVar[ButcherTableau]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        tab = cls.__dict__.get("tableau")
        if tab is None:
            return
        if not isinstance(getattr(cls, "error_order", None), int):
            raise SimulationError(f"{cls.__name__}: an embedded pair needs its error_order, the order of b − b_hat (an int)")
        if tab.b_hat is None or tuple(tab.A[-1]) != tuple(tab.b[:-1]) or tab.b[-1] != 0.0 or tab.c[-1] != 1.0:
            raise SimulationError(
                f"{cls.__name__}: an embedded pair's last stage must be its solution (first same as last): the last row "
                "of A equal to b, its c 1 and its own weight 0, with b_hat given"
            )

    def _spec(self) -> RungeKuttaSpec:
        return dataclasses.replace(_tableau_spec(self.tableau), adaptive=True, error_order=self.error_order)

    def workspace(self, system: Problem) -> _FirstSameAsLast:
        return _FirstSameAsLast()

    def attempt(self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None) -> Attempt:
        tab = self.tableau
        a0 = ws.a if ws is not None and ws.q is q and not system.new_sample else None  # a new held torque: afresh
        kd, ka, (_, q_new, v_new) = _stages(tab, system, t, q, v, h, a0)  # the last stage is the solution
        diff = tuple(b - bh for b, bh in zip(tab.b, tab.b_hat or (), strict=True))
        err = self.error_norm(system, h * combine(diff, kd), h * combine(diff, ka), q, v, v_new)
        if ws is not None:
            ws.q, ws.a = q_new, ka[-1]
        return Attempt(q_new, v_new, err)

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return _rk_stability(self.tableau, z, self.tableau.b)


class DormandPrince(EmbeddedRungeKutta):
    """Dormand–Prince 5(4): adaptive, error-controlled, 6 RHS per step (first-same-as-last).

    Args:
        rtol, atol: tolerances of the embedded error estimate (see :class:`AdaptiveIntegrator`).
    """

    name = "dopri5"
    order = 5
    error_order = 4
    tableau = ButcherTableau(
        A=_DP_A,
        b=(35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0),
        c=(0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0),
        b_hat=(5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40),
    )

    def compiled_spec(self) -> RungeKuttaSpec:  # (in each class: only a class's own compiled_spec is run compiled)
        return self._spec()


def _dop853_tableau() -> ButcherTableau:
    """Hairer's DOP853 as a first-same-as-last pair: its 12 stages (scipy's coefficients, from
    E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*, 2nd ed.,
    §II.10), a 13th at the solution, and the embedded fifth-order solution ``b − E5``."""
    from scipy.integrate._ivp import dop853_coefficients as hairer

    n = hairer.N_STAGES
    b = tuple(float(x) for x in hairer.B)
    return ButcherTableau(
        A=(*(tuple(float(x) for x in hairer.A[i, :i]) for i in range(n)), b),
        b=(*b, 0.0),
        c=(*(float(x) for x in hairer.C[:n]), 1.0),
        b_hat=tuple(bi - float(e) for bi, e in zip((*b, 0.0), hairer.E5, strict=True)),
    )


class DormandPrince853(EmbeddedRungeKutta):
    """Dormand–Prince 8(5) (Hairer's DOP853): adaptive, eighth order, 12 RHS per step
    (first-same-as-last). For tight accuracy, where its order pays for its twice as many stages
    per step (docs/benchmarks.md: the cheapest coopdyn run at 1e-6 N on the peer benchmarks);
    where a stiff mode sets the step at a loose tolerance, they can cost more than ``dopri5``'s.

    Its step is controlled by the fifth-order estimate alone. Hairer's code (and scipy's
    ``DOP853``) blends in a third-order one, an estimate never larger, so at the same ``rtol``
    their steps are longer and their error larger than this method's.

    Args:
        rtol, atol: tolerances of the embedded error estimate (see :class:`AdaptiveIntegrator`).
    """

    name = "dop853"
    order = 8
    error_order = 5
    tableau = _dop853_tableau()

    def compiled_spec(self) -> RungeKuttaSpec:  # (its own: see DormandPrince)
        return self._spec()
