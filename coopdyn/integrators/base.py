"""The integrator contract: :class:`Problem` (what a method may ask of the closed loop it
advances) and :class:`Integrator` (configuration + a step function).

A new method subclasses :class:`Integrator` (fixed step: implement ``step``) or
:class:`AdaptiveIntegrator` (implement ``attempt``), gives itself a ``name`` and an ``order``,
and, for :func:`coopdyn.advise`, a scalar ``stability_function`` R(z) (or overrides
``spectral_radius``). Integrator objects hold settings only; everything that evolves is passed
in and returned. Per-run scratch (a reused factorisation, a discretisation, the last stage of a
first-same-as-last pair) is the method's own: :meth:`Integrator.workspace` makes it at the start
of a run and ``simulate`` hands it to every step as ``ws``; without it (``ws=None``) a step
computes everything afresh.

States are ``(q, v)`` on the configuration Lie group. Multi-stage methods build their stages in
a local chart ``q = q₀ ⊕ δ`` around the step's start, where ``δ̇ = dIntegrate(q₀, δ)⁻¹ v``
(docs/physics.md): the method then keeps its classical order on SE(3) free-flyers, which naive
stages ``q₀ ⊕ h Σ aᵢⱼ vⱼ`` do not.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np

from .._spec import MethodSpec


class Problem(Protocol):
    """The closed loop as integrators see it (:class:`coopdyn.closed_loop.System` implements it).

    States are (q (nq,), v (nv,)); evaluations count themselves (``n_rhs``, ``n_jac``,
    ``n_factor``).
    """

    nv: int  #: size of v
    n_actuated: int  #: size of the controller output
    neutral: np.ndarray  #: the neutral configuration (nq,)
    n_rhs: int
    n_jac: int
    n_factor: int
    #: the current step's start took a new controller sample (``control_dt``): the closed loop
    #: changed there, and a right-hand side evaluated at the last step's end (first same as
    #: last) no longer holds, nor does generalized-α's algorithmic acceleration (carried on, it
    #: costs the method its second order: both restart there as at t = 0)
    new_sample: bool

    @property
    def q0(self) -> np.ndarray:
        """The scene's initial configuration (nq,)."""
        ...

    @property
    def has_object_wrench(self) -> bool:
        """Whether an external object wrench is applied."""
        ...

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """q̈ (nv,) of the closed loop at (t, q, v)."""
        ...

    def torque(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The controller output (n_actuated,) at (t, q, v)."""
        ...

    def free_acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """q̈ (nv,) for given torques, no controller (not counted)."""
        ...

    def nonlinearity(self) -> str | None:
        """Why the dynamics are not linear, or None."""
        ...

    def implicit_terms(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(f = M q̈, M, K̃, D̃) at (t, q, v)."""
        ...

    def factor(self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, gh2: float | None = None) -> None:
        """Factorise M + γh D̃ + (γh)² K̃ (controller gains added; ``gh2`` in place of (γh)²
        when given); StepMatrixError if not SPD."""
        ...

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k_q, k_v) with the last factorisation, given M f_v: S k_v = M f_v − γh K_g f_q,
        k_q = f_q + γh k_v — that is (I − γhJ) k = (f_q, f_v) when gh2 = (γh)²."""
        ...

    def implicit_euler_velocity(self, t: float, q: np.ndarray, v: np.ndarray, h: float) -> np.ndarray:
        """v⁺ of one linearly implicit Euler step (one kinematics pass, one factorisation)."""
        ...

    def integrate(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """q ⊕ dq."""
        ...

    def difference(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """q1 ⊖ q0 (nv,)."""
        ...

    def chart_velocity(self, q0: np.ndarray, delta: np.ndarray, v: np.ndarray) -> np.ndarray:
        """δ̇ = dIntegrate(q₀, δ)⁻¹ v."""
        ...


class Integrator(ABC):
    """A one-step method for (q, v) on the configuration Lie group."""

    name: ClassVar[str]
    order: ClassVar[int]
    adaptive: ClassVar[bool] = False
    #: True when a step is the exact flow of the model (nothing to monitor for instability).
    exact_discretisation: ClassVar[bool] = False
    #: True when the method is unconditionally stable on the linearised problem.
    a_stable: ClassVar[bool] = False
    #: True when ``coopdyn.advise`` reports on it by default (a method with a stability function
    #: of its own: not a variant that shares another's, not a scipy wrapper)
    advised: ClassVar[bool] = True

    @abstractmethod
    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Advance from (t, q, v) by ``h`` [s]; return the new (q, v). ``ws``: this method's
        workspace for the run (:meth:`workspace`), or None."""

    def compiled_spec(self) -> MethodSpec | None:
        """What the compiled step loop needs to run this method, or None (the Python loop runs it).

        Only the built-in classes define it; :func:`coopdyn.simulate` uses it only when the
        method's own class defines it, so a subclass that changes a step runs in Python."""
        return None

    def workspace(self, system: Problem) -> Any:
        """Per-run scratch of this method (None: it needs none); passed to every step as ``ws``."""
        return None

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


def relative_tolerance(rtol: Any) -> float:
    """``rtol`` as a float: finite, above 0 and below 1 (a fraction of each coordinate's size; at 1
    or more an error as large as the solution itself passes, and nothing is controlled)."""
    from .._validate import positive
    from ..errors import SimulationError

    x = positive(rtol, "rtol", "1", SimulationError)
    if x >= 1.0:
        raise SimulationError(f"rtol is a fraction of each coordinate's size and must be below 1 (e.g. 1e-6), got {x:g}")
    return x


#: [m, rad, m/s, rad/s] the smallest absolute tolerance: below it no double resolves an error
#: (and scipy's LSODA, asked for 1e-200, spins without end)
MIN_ATOL = 1e-30


def absolute_tolerance(atol: Any) -> float:
    """``atol`` as a float: finite and at least :data:`MIN_ATOL`."""
    from .._validate import positive
    from ..errors import SimulationError

    x = positive(atol, "atol", "m, rad, m/s, rad/s", SimulationError)
    if x < MIN_ATOL:
        raise SimulationError(f"atol must be at least {MIN_ATOL:g} [m, rad, m/s, rad/s] (no double resolves less), got {x:g}")
    return x


class Tolerances:
    """``rtol`` and ``atol``, checked whenever they are set (at construction or after)."""

    @property
    def rtol(self) -> float:
        """Relative tolerance (0 < rtol < 1)."""
        return self._rtol

    @rtol.setter
    def rtol(self, value: float) -> None:
        self._rtol = relative_tolerance(value)

    @property
    def atol(self) -> float:
        """Absolute tolerance [m, rad, m/s, rad/s]."""
        return self._atol

    @atol.setter
    def atol(self, value: float) -> None:
        self._atol = absolute_tolerance(value)


class AdaptiveIntegrator(Tolerances, Integrator):
    """A method with an embedded error estimate; ``simulate`` controls its step.

    Args:
        rtol: relative tolerance, a fraction of each coordinate's size (0 < rtol < 1).
        atol: absolute tolerance [m, rad, m/s, rad/s], at least :data:`MIN_ATOL`.
        h_min: smallest step before the run is declared failed [s].

    The three may be changed on the instance (``method.rtol = 1e-8``); each is checked as it is set.
    """

    adaptive = True
    #: order of the error estimate + 1 is the exponent of the step-size controller
    error_order: ClassVar[int]

    def __init__(self, rtol: float = 1e-6, atol: float = 1e-9, h_min: float = 1e-12) -> None:
        self.rtol = rtol
        self.atol = atol
        self.h_min = h_min

    @property
    def h_min(self) -> float:
        """Smallest step before the run is declared failed [s]."""
        return self._h_min

    @h_min.setter
    def h_min(self, value: float) -> None:
        from .._validate import positive
        from ..errors import SimulationError

        self._h_min = positive(value, "h_min", "s", SimulationError)

    @abstractmethod
    def attempt(self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None) -> Attempt:
        """Try a step of ``h`` [s] from (t, q, v)."""

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """A step of exactly ``h`` without error control."""
        out = self.attempt(system, t, q, v, h, ws)
        return out.q, out.v

    def error_norm(
        self, system: Problem, e_delta: np.ndarray, e_v: np.ndarray, q0: np.ndarray, v0: np.ndarray, v1: np.ndarray
    ) -> float:
        """RMS of the embedded error scaled by ``atol + rtol·|y|`` (positions: ``q₀ ⊖ neutral``
        in the tangent space; velocities: the larger of start and end)."""
        sc_d = self.atol + self.rtol * np.abs(system.difference(system.neutral, q0))
        sc_v = self.atol + self.rtol * np.maximum(np.abs(v0), np.abs(v1))
        return float(np.sqrt((np.sum((e_delta / sc_d) ** 2) + np.sum((e_v / sc_v) ** 2)) / (2 * e_v.size)))

    def next_step(self, h: float, error: float) -> float:
        """Step-size controller: ``h·min(5, max(0.2, 0.9·err^(-1/(p+1))))`` (the loop takes at most ``h``
        for the step after an accepted one that followed a rejection)."""
        if error == 0.0:
            return 5.0 * h
        return h * min(5.0, max(0.2, 0.9 * error ** (-1.0 / (self.error_order + 1))))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(rtol={self.rtol:g}, atol={self.atol:g})"
