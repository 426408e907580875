"""The exponential integrator for scenes whose dynamics are linear.

A scene in which every joint (arms and object) is prismatic has a constant mass matrix, no
Coriolis terms, translations only (so ``log6`` is linear) and hence affine dynamics
``ẋ = F x + G τ + c`` in ``x = (q, v)`` — the book's cooperative system is one. Such a scene is
discretised once per step size by the matrix exponential; a step is then a few matrix–vector
products: exact for torques held over the step (a sampled controller, ``hold="zoh"``), and of
order p + 1 for torques interpolated by a degree-p polynomial over the step (``"foh"``: 2,
``"cubic"``: 4, the default).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg

from .._spec import ExponentialSpec
from ..errors import SimulationError
from .base import Integrator, Problem


class LinearForm(NamedTuple):
    """``ẋ = F x + G τ + c`` with x = (q, v)."""

    F: np.ndarray  #: (2nv, 2nv)
    G: np.ndarray  #: (2nv, n_actuated)
    c: np.ndarray  #: (2nv,)


def linear_form(system: Problem) -> LinearForm:
    """The affine dynamics of a linear scene, from unit perturbations of the right-hand side
    (exact up to round-off for an affine map), checked at a random state."""
    why = system.nonlinearity()
    if why is not None:
        raise SimulationError(f"the exponential integrator needs a linear scene; this one is not: {why}")
    accel, n, m = system.free_acceleration, system.nv, system.n_actuated
    q0, v0, u0 = system.q0, np.zeros(n), np.zeros(m)
    a0 = accel(q0, v0, u0)
    eye_n, eye_m = np.eye(n), np.eye(m)
    A_q = np.column_stack([accel(q0 + eye_n[i], v0, u0) - a0 for i in range(n)])
    A_v = np.column_stack([accel(q0, eye_n[i], u0) - a0 for i in range(n)])
    B = np.column_stack([accel(q0, v0, eye_m[i]) - a0 for i in range(m)])
    F = np.block([[np.zeros((n, n)), eye_n], [A_q, A_v]])
    G = np.vstack([np.zeros((n, m)), B])
    c = np.concatenate([np.zeros(n), a0 - A_q @ q0])
    rng = np.random.default_rng(0)
    dq, v, u = rng.normal(size=n) * 0.01, rng.normal(size=n), rng.normal(size=m) * 10.0
    a = accel(q0 + dq, v, u)
    if not np.allclose(a, a0 + A_q @ dq + A_v @ v + B @ u, rtol=1e-9, atol=1e-9 * (1.0 + np.max(np.abs(a)))):
        raise SimulationError("the exponential integrator needs linear dynamics; this scene's right-hand side is not affine")
    return LinearForm(F, G, c)


_ONE = np.ones(1)

#: hold name → polynomial degree of the torque over a step (p + 1 equally spaced nodes)
HOLDS = {"zoh": 0, "foh": 1, "cubic": 3}


class _Discretisations:
    """The exponential integrator's workspace: the scene's linear form and one discretisation per
    step size."""

    def __init__(self) -> None:
        self.form: LinearForm | None = None
        self.steps: dict[float, tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int]] = {}


class Exponential(Integrator):
    """Exact discretisation of a linear scene (see the module docstring).

    Over a step the torque is the polynomial of degree p through the controller's values at
    p + 1 equally spaced instants of the step (the start included), and that forced response
    is integrated exactly. For torques that depend on time only, a step's error is that of the
    interpolation: order p + 1. For state feedback the controller sees, inside a step, the
    state predicted with the torque held at its start value.

    Args:
        hold: ``"zoh"`` (p = 0: held at the start value; exact for a sampled controller),
            ``"foh"`` (p = 1, second order) or ``"cubic"`` (p = 3, fourth order; default).
    """

    name = "exponential"
    order = 4
    a_stable = True
    exact_discretisation = True

    def __init__(self, hold: str = "cubic") -> None:
        self.hold = hold

    @property
    def hold(self) -> str:
        """How the input is held over a step (one of :data:`HOLDS`)."""
        return self._hold

    @hold.setter
    def hold(self, value: str) -> None:
        if not isinstance(value, str) or value not in HOLDS:
            raise SimulationError(f"hold must be one of {sorted(HOLDS)}, got {value!r}")
        self._hold = value

    def compiled_spec(self) -> ExponentialSpec:
        return ExponentialSpec()

    def workspace(self, system: Problem) -> _Discretisations:
        return _Discretisations()

    def discretisation(
        self, system: Problem, h: float, ws: _Discretisations | None
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int]:
        """For z = (x, u₀, 1): the step ``[Φ Γ₀ γ]``, the stacked predictions of the inner
        nodes' states, ``[Γ₁ … Γ_p]`` acting on the inner nodes' torques, and p."""
        ws = _Discretisations() if ws is None else ws
        if h not in ws.steps:
            if ws.form is None:
                ws.form = linear_form(system)
            form = ws.form
            p = HOLDS[self.hold]
            nodes = np.linspace(0.0, 1.0, p + 1) if p else np.zeros(1)
            Phi, *Gammas, gamma = _polynomial_hold(form, h, nodes)
            step = np.hstack([Phi, Gammas[0], gamma[:, None]])  # acts on z = (x, u₀, 1)
            inner = [np.hstack([P, G, g[:, None]]) for P, G, g in (_polynomial_hold(form, h * s, np.zeros(1)) for s in nodes[1:])]
            predictor = np.vstack(inner) if inner else None  # states at the inner nodes, torque held at u₀
            ws.steps[h] = (step, predictor, np.hstack(Gammas[1:]) if inner else None, p)
            system.n_factor += 1
        return ws.steps[h]

    def step(
        self, system: Problem, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        if system.has_object_wrench:
            raise SimulationError("the exponential integrator does not take object_wrench (its discretisation has no such input)")
        step, predictor, inner, p = self.discretisation(system, h, ws)
        n = q.size
        u0 = system.torque(t, q, v)
        z = np.concatenate([q, v, u0, _ONE])
        x_new = step @ z
        system.n_rhs += 1
        if predictor is not None and u0.size:
            X = predictor @ z
            U = [
                system.torque(t + h * i / p, X[(i - 1) * 2 * n : (i - 1) * 2 * n + n], X[(i - 1) * 2 * n + n : i * 2 * n])
                for i in range(1, p + 1)
            ]
            x_new += inner @ np.concatenate(U)
            system.n_rhs += p
        return x_new[:n], x_new[n:]

    def stability_function(self, z: np.ndarray) -> np.ndarray:
        return np.exp(np.asarray(z, dtype=complex))

    def __repr__(self) -> str:
        return f"Exponential(hold={self.hold!r})"


def _polynomial_hold(form: LinearForm, h: float, nodes: np.ndarray) -> tuple[np.ndarray, ...]:
    """``x(h) = Φ x(0) + Σᵢ Γᵢ u(τᵢh) + γ`` when u is the polynomial through the node values.

    In normalised time τ = s/h the torque polynomial φ(τ) and its derivatives P = (φ, φ', …)
    obey P' = N P (N: block shift); one ``expm`` of [[hF, hG, 0…, hc], [0, N, 0], [0, 0, 0]]
    gives the response to P(0) = diag(k!) V⁻¹ u_nodes (V: Vandermonde of the nodes).
    """
    F, G, c = form
    nx, m = G.shape
    p = nodes.size - 1
    size = nx + (p + 1) * m + 1
    E = np.zeros((size, size))
    E[:nx, :nx] = h * F
    E[:nx, nx : nx + m] = h * G
    E[:nx, -1] = h * c
    for k in range(p):
        E[nx + k * m : nx + (k + 1) * m, nx + (k + 1) * m : nx + (k + 2) * m] = np.eye(m)
    X = scipy.linalg.expm(E)
    Psi = X[:nx, nx : nx + (p + 1) * m]
    V = np.vander(nodes, p + 1, increasing=True)  # V[i, k] = τᵢᵏ
    W = np.diag([float(math.factorial(k)) for k in range(p + 1)]) @ np.linalg.inv(V)  # P(0) per node value
    Gammas = [sum(W[k, i] * Psi[:, k * m : (k + 1) * m] for k in range(p + 1)) for i in range(p + 1)]
    return (X[:nx, :nx], *Gammas, X[:nx, -1])
