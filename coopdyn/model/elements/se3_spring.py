"""The SE(3) spring–damper: full 6×6 stiffness and damping on the SE(3) logarithm.

With ``e = log6(T_M_G)`` ([linear; angular] [m, rad]) the elastic energy is ``U = ½ eᵀ K e``;
``ė = Jlog6(T_M_G) ξ`` and the wrench on the object at G, in G axes, is
``G_f_G = −Jlog6ᵀ (K e + D ė)`` — the exact gradient of U (no Euler angles, no gimbal lock)
plus the damping. ``S_K = Jlog6ᵀ K Jlog6`` and ``S_D = Jlog6ᵀ D Jlog6`` are the Gauss–Newton
terms (the force-proportional geometric stiffness is left out); :meth:`SE3Spring.tangent` gives
the exact derivatives, geometric stiffness included, by complex-step differentiation of
``Jlog6(e)`` (exact to round-off: no difference is taken). K and D are in the tip frame's
axes, order [x, y, z, rx, ry, rz], blocks [N/m, N·m/rad] and [N·s/m, N·m·s/rad]. C++ twin:
``src/native/elements/se3_spring.hpp``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ... import _validate
from ...errors import SceneError
from .base import Element, ElementEval, SpringDamper
from .lie import jlog6, jlog6_of_log, jlog6_of_logs, log6

#: complex step [m, rad]: far below round-off, so the derivative carries no truncation error
COMPLEX_STEP = 1e-30


class SE3Spring(SpringDamper):
    """A 6-DOF spring–damper between T and G (see the module docstring).

    Args:
        stiffness: K, a symmetric positive semi-definite 6×6 matrix or a 6-vector diagonal.
        damping: D, the same shape; default none.
        name: what messages call it.
    """

    kind: ClassVar[str] = "se3"
    rigid: ClassVar[str | None] = "rigid"
    deformation_size: ClassVar[int] = 6
    linear: ClassVar[bool] = True  # log6 of a pure translation is the translation
    exact_tangent: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A subclass that changes :meth:`evaluate` without its own :meth:`gradient` or
        :meth:`tangent` gets the base class's central differences, not this law's exact tangent;
        one that changes :meth:`evaluate` or :meth:`gradient` without its own :meth:`hessian` or
        :meth:`matrix_tangent`, the base class's :meth:`~Element.matrix_tangent`."""
        super().__init_subclass__(**kwargs)
        if "evaluate" in cls.__dict__ and not ({"gradient", "tangent"} & cls.__dict__.keys()):
            cls.exact_tangent = False
            cls.tangent = Element.tangent  # type: ignore[method-assign]
        own = cls.__dict__.keys()
        if ({"evaluate", "gradient"} & own) and not ({"hessian", "matrix_tangent"} & own):  # its S_K may not be Jᵀ·hessian·J
            cls.matrix_tangent = Element.matrix_tangent  # type: ignore[method-assign]

    def __init__(self, stiffness: Any, damping: Any = None, name: str = "interconnection") -> None:
        K = _validate.spd6(stiffness, f"{name}: stiffness", "N/m, N·m/rad")
        D = np.zeros((6, 6)) if damping is None else _validate.spd6(damping, f"{name}: damping", "N·s/m, N·m·s/rad")
        self._keep(K, D, name)

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        e, theta = log6(T_M_G)
        J = jlog6(T_M_G, e, theta)
        w = self.K @ e
        power = 0.0
        if self._damped:
            e_dot = J @ xi
            D_e_dot = self.D @ e_dot
            power = float(e_dot @ D_e_dot)
            w = w + D_e_dot
        S_K = S_D = None
        if jacobians:
            S_K = J.T @ self.K @ J
            S_D = J.T @ self.D @ J
        return ElementEval(0.5 * float(e @ self.K @ e), e, -(J.T @ w), power, S_K, S_D, theta)

    def gradient(self, e: np.ndarray) -> np.ndarray:
        """∂U/∂e (6,) at the logarithm e; analytic in e (a complex e is allowed)."""
        return self.K @ e

    def hessian(self, e: np.ndarray) -> np.ndarray:
        """∂²U/∂e² (6, 6) at the logarithm e; analytic in e (a complex e is passed). The law's
        Gauss–Newton stiffness must be ``S_K = Jlog6ᵀ·hessian(e)·Jlog6`` (:meth:`matrix_tangent`
        checks it)."""
        return np.asarray(self.K)

    def matrix_tangent(self, T_M_G: pin.SE3, xi: np.ndarray, w_K: np.ndarray, w_D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact derivatives of ``S_K w_K + S_D w_D = Jlog6ᵀ (hessian(e) Jlog6 w_K + D Jlog6 w_D)``
        (see :meth:`Element.matrix_tangent`): along ``e + i·h·Jlog6 δ`` by complex step; they do
        not depend on ξ.

        Raises:
            SceneError: the law's S_K (from :meth:`evaluate`) is not ``Jlog6ᵀ·hessian(e)·Jlog6``
                (a subclass whose ``hessian`` does not match its own stiffness)."""
        e, theta = log6(T_M_G)
        J = jlog6(T_M_G, e, theta)
        S_K = self.evaluate(T_M_G, xi, True).S_K
        assert S_K is not None
        if not np.allclose(S_K, J.T @ self.hessian(e) @ J, rtol=1e-9, atol=1e-12 * max(1.0, float(np.max(np.abs(S_K))))):
            raise SceneError(
                f"{type(self).__name__}: its Gauss–Newton stiffness S_K is not Jlog6ᵀ·hessian(e)·Jlog6, so the "
                "exact derivative of an implicit step cannot be taken from its hessian; make hessian(e) the Hessian of "
                "its energy in e (as S_K), or define matrix_tangent"
            )
        E = e + (1j * COMPLEX_STEP) * J.T  # row k: e + i·h·Jlog6[:, k]
        J_c = jlog6_of_logs(E)  # (6, 6, 6): Jlog6 at each row, in one pass
        w = np.stack([self.hessian(E[k]) @ (J_c[k] @ w_K) for k in range(6)])
        if self._damped:
            w = w + (J_c @ w_D) @ self.D.T
        return np.einsum("kji,kj->ik", J_c, w).imag / COMPLEX_STEP, np.zeros((6, 6))

    def tangent(self, T_M_G: pin.SE3, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact ``(∂G_f_G/∂δ, ∂G_f_G/∂ξ)`` (see :meth:`Element.tangent`): ``G_f_G =
        −Jlog6(e)ᵀ (∂U/∂e + D Jlog6(e) ξ)`` is differentiated along ``e + i·h·Jlog6 δ``
        (``e(T_M_G·exp6(δ)) = e + Jlog6 δ + O(δ²)``) by complex step."""
        e, theta = log6(T_M_G)
        J = jlog6(T_M_G, e, theta)
        F_d = np.empty((6, 6))
        for k in range(6):
            e_c = e + (1j * COMPLEX_STEP) * J[:, k]
            J_c = jlog6_of_log(e_c)
            w = self.gradient(e_c)
            if self._damped:
                w = w + self.D @ (J_c @ xi)
            F_d[:, k] = -(J_c.T @ w).imag / COMPLEX_STEP
        return F_d, -(J.T @ self.D @ J)
