"""The SE(3) logarithm and its Jacobian, accurate at every rotation angle.

``log6(M) = [V(θ)⁻¹ p; θ n]`` and ``Jlog6(M)`` (the inverse right Jacobian of exp6) are
Pinocchio's formulas (``pinocchio/src/spatial/log.hxx``) with one change: their scalar
coefficients

    a(θ)  = (θ/2) cot(θ/2)                         (diagonal of Jlog3, and V⁻¹)
    β(θ)  = (1 − a(θ)) / θ²
    β'(θ)/θ

are evaluated by their Taylor series below :data:`SERIES_BELOW` and in closed form above it.
The closed forms cancel catastrophically for small θ (``β'/θ`` subtracts terms of size 2/θ⁴),
and Pinocchio 4.1 switches to a two-term series only below θ ≈ 1e-5, so for θ ≈ 1e-5…1e-3 its
``Jlog6`` is off by up to ~1e-6 relative. Here both branches are accurate to a few ulps·10 at
the switch (tests/test_elements.py compares with a 50-digit finite-difference reference).
The C++ twin is ``src/native/lie.hpp``; the two agree to round-off.
"""

from __future__ import annotations

import math
from typing import Any, TypeVar

import numpy as np
import pinocchio as pin

#: Angle [rad] below which the series are used (closed forms lose < 1e-13 relative above it).
SERIES_BELOW = 0.25

# (θ/2)cot(θ/2) = Σ (−1)ⁿ B₂ₙ θ²ⁿ / (2n)!  (Bernoulli numbers)
_A = (1.0, -1.0 / 12.0, -1.0 / 720.0, -1.0 / 30240.0, -1.0 / 1209600.0, -1.0 / 47900160.0, -691.0 / 1307674368000.0)
# β = (1 − a)/θ² and β'/θ, term by term
_BETA = tuple(-c for c in _A[1:])
_BETA_DOT = tuple(2 * (k + 1) * c for k, c in enumerate(_BETA[1:]))


_Number = TypeVar("_Number", float, complex)


def _poly(coefficients: tuple[float, ...], t2: _Number) -> _Number:
    out = 0.0 * t2
    for c in reversed(coefficients):
        out = out * t2 + c
    return out


def coefficients(theta: float) -> tuple[float, float, float]:
    """(a, β, β'/θ) at the rotation angle θ [rad] (see the module docstring)."""
    t2 = theta * theta
    if theta < SERIES_BELOW:
        return _poly(_A, t2), _poly(_BETA, t2), _poly(_BETA_DOT, t2)
    st, ct = math.sin(theta), math.cos(theta)
    a = 0.5 * theta * st / (1.0 - ct)
    inv_2_2ct = 1.0 / (2.0 * (1.0 - ct))
    beta = 1.0 / t2 - st / theta * inv_2_2ct
    beta_dot = -2.0 / (t2 * t2) + (1.0 + st / theta) / t2 * inv_2_2ct
    return a, beta, beta_dot


def _skew(x: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def log6(M: pin.SE3) -> tuple[np.ndarray, float]:
    """``(e, θ)``: the SE(3) logarithm e = [V⁻¹p; w] (6,) [m, rad] and the rotation angle θ [rad]."""
    w = pin.log3(M.rotation)
    theta = float(np.sqrt(w @ w))
    a, beta, _ = coefficients(theta)
    p = M.translation
    wxp = np.array([w[1] * p[2] - w[2] * p[1], w[2] * p[0] - w[0] * p[2], w[0] * p[1] - w[1] * p[0]])
    e = np.empty(6)
    e[:3] = a * p - 0.5 * wxp + (beta * (w @ p)) * w
    e[3:] = w
    return e, theta


def jlog6(M: pin.SE3, e: np.ndarray, theta: float) -> np.ndarray:
    """Jlog6(M) (6, 6), given ``(e, θ) = log6(M)``: ė = Jlog6 ξ for the body twist ξ of M."""
    a, beta, beta_dot = coefficients(theta)
    return _jlog6(e[3:], M.translation, theta * theta, a, beta, beta_dot, float)


def _jlog6(w: np.ndarray, p: np.ndarray, t2: Any, a: Any, beta: Any, beta_dot: Any, dtype: Any) -> np.ndarray:
    """Jlog6 from the rotation's logarithm w, the translation p, θ² and the coefficients (real
    or complex: no operation conjugates)."""
    J = np.zeros((6, 6), dtype=dtype)
    A = beta * np.outer(w, w) + 0.5 * _skew(w)
    A[np.diag_indices(3)] += a
    wTp = w @ p
    v = (beta_dot * wTp) * w - (t2 * beta_dot + 2.0 * beta) * p
    C = np.outer(v, w) + beta * np.outer(w, p) + 0.5 * _skew(p)
    C[np.diag_indices(3)] += wTp * beta
    J[:3, :3] = A
    J[3:, 3:] = A
    J[:3, 3:] = C @ A
    return J


# Series of the coefficients of V(w) = I + b(θ) ŵ + c(θ) ŵ², the left Jacobian of exp3 that maps
# the logarithm's linear part to the translation: b = (1 − cos θ)/θ², c = (θ − sin θ)/θ³.
_B = tuple((-1.0) ** k / math.factorial(2 * k + 2) for k in range(9))
_C = tuple((-1.0) ** k / math.factorial(2 * k + 3) for k in range(9))


def _coefficients_t2(t2: Any) -> tuple[Any, Any, Any, Any, Any]:
    """(a, β, β'/θ, b, c) as analytic functions of t2 = θ² (real or complex: complex-step safe),
    of one θ² or of an array of them sharing one real part (a complex step's perturbations of one
    logarithm: one branch serves all)."""
    if abs(np.ravel(t2)[0].real) < SERIES_BELOW * SERIES_BELOW:
        return _poly(_A, t2), _poly(_BETA, t2), _poly(_BETA_DOT, t2), _poly(_B, t2), _poly(_C, t2)
    theta = np.sqrt(t2 + 0j) if np.iscomplexobj(t2) else np.sqrt(t2)
    st, ct = np.sin(theta), np.cos(theta)
    a = 0.5 * theta * st / (1.0 - ct)
    inv_2_2ct = 1.0 / (2.0 * (1.0 - ct))
    beta = 1.0 / t2 - st / theta * inv_2_2ct
    beta_dot = -2.0 / (t2 * t2) + (1.0 + st / theta) / t2 * inv_2_2ct
    return a, beta, beta_dot, (1.0 - ct) / t2, (theta - st) / (t2 * theta)


def jlog6_of_log(e: np.ndarray) -> np.ndarray:
    """Jlog6 (6, 6) as a function of the logarithm ``e = log6(M)`` alone (equal to
    :func:`jlog6` to round-off). Every operation is analytic in e, so a complex e gives the
    complex-step derivative of Jlog6 — how the elements' exact second derivatives are taken."""
    rho, w = e[:3], e[3:]
    t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]  # no conjugate: analytic
    a, beta, beta_dot, b, c = _coefficients_t2(t2)
    W = _skew(w)
    p = rho + b * (W @ rho) + c * (W @ (W @ rho))  # the translation of M
    return _jlog6(w, p, t2, a, beta, beta_dot, np.result_type(e, complex) if np.iscomplexobj(e) else float)


def _skews(x: np.ndarray) -> np.ndarray:
    """[x]^ of each row of x (n, 3) → (n, 3, 3) (real or complex)."""
    out = np.zeros((*x.shape[:-1], 3, 3), dtype=x.dtype)
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -x[..., 2], x[..., 1], -x[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = x[..., 2], -x[..., 1], x[..., 0]
    return out


def jlog6_of_logs(E: np.ndarray) -> np.ndarray:
    """:func:`jlog6_of_log` of every row of E (n, 6) at once → (n, 6, 6). The rows must share
    their angle's real part (a complex step's perturbations of one logarithm): one branch of the
    series serves all of them."""
    rho, w = E[:, :3], E[:, 3:]
    t2 = np.einsum("ni,ni->n", w, w)  # no conjugate: analytic
    a, beta, beta_dot, b, c = _coefficients_t2(t2)
    W = _skews(w)
    Wr = np.einsum("nij,nj->ni", W, rho)
    p = rho + b[:, None] * Wr + c[:, None] * np.einsum("nij,nj->ni", W, Wr)
    eye = np.eye(3)
    A = beta[:, None, None] * (w[:, :, None] * w[:, None, :]) + 0.5 * W + a[:, None, None] * eye
    wTp = np.einsum("ni,ni->n", w, p)
    v = (beta_dot * wTp)[:, None] * w - (t2 * beta_dot + 2.0 * beta)[:, None] * p
    C = v[:, :, None] * w[:, None, :] + beta[:, None, None] * (w[:, :, None] * p[:, None, :]) + 0.5 * _skews(p)
    C = C + (wTp * beta)[:, None, None] * eye
    J = np.zeros((E.shape[0], 6, 6), dtype=np.result_type(E, float))
    J[:, :3, :3] = A
    J[:, 3:, 3:] = A
    J[:, :3, 3:] = C @ A
    return J


def dexp_inv_rate(delta: np.ndarray, v: np.ndarray, step: float = 1e-30) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For a free-flyer's (6,) or a spherical joint's (3,) chart coordinate δ and velocity v:
    ``(r, ∂r/∂v, ∂r/∂δ)`` with ``r = dexp⁻¹(δ) v = Jlog6(exp6 δ) v`` (the chart rate; for 3
    coordinates the rotation block), the δ derivative by complex step of ``step`` (exact to
    round-off: no difference is taken)."""
    n = delta.size
    E = np.zeros((n + 1, 6), dtype=complex)
    E[:, 6 - n :] = delta
    E[np.arange(1, n + 1), np.arange(6 - n, 6)] += 1j * step
    J = jlog6_of_logs(E)[:, 6 - n :, 6 - n :] if n == 3 else jlog6_of_logs(E)
    C = J[0].real
    return C @ v, C, np.einsum("kij,j->ik", J[1:].imag, v) / step
