"""The translational (ball) spring–damper: a point grasp that transmits no moment to the object.

The deformation is the position of G's origin in T, ``p = T_M_G.translation`` (3,) [m], in the
tip frame's axes; ``U = ½ pᵀ K p`` with K and D 3×3 [N/m], [N·s/m]. Its rate is ``ṗ = R ξ_v``
(R = T_M_G.rotation, ξ_v the linear part of the relative twist), and the wrench on the object
at G, in G axes, is ``G_f_G = −[Rᵀ (K p + D ṗ); 0]``: a pure force through the grasp point.
The reaction on the arm is that force at G, so about T it carries the moment p × f.
``S_K = Aᵀ K A`` and ``S_D = Aᵀ D A`` with ``A = [R 0]`` (3, 6). With an isotropic K the arm
feels no moment either; an anisotropic K turns with the tool. C++ twin:
``src/native/elements/ball_spring.hpp``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ... import _validate
from ...errors import SceneError
from .base import Element, ElementEval, SpringDamper


def _spd3(value: Any, name: str, unit: str) -> np.ndarray:
    """A symmetric positive semi-definite 3×3 matrix from a 3×3 array, a 3-vector diagonal or a scalar."""
    arr = _validate.finite_array(value, name)
    if arr.ndim == 0:
        arr = np.eye(3) * float(arr)
    elif arr.shape == (3,):
        arr = np.diag(arr)
    if arr.shape != (3, 3):
        raise SceneError(
            f"{name} must be a scalar, a 3-vector diagonal or a 3×3 matrix [{unit}] (x, y, z), got shape {arr.shape}"
        )
    return _validate.symmetric_psd(arr, name)


class BallSpring(SpringDamper):
    """A 3-DOF translational spring–damper between T and G (see the module docstring).

    Args:
        stiffness: K [N/m], a scalar, a 3-vector diagonal or a symmetric 3×3 matrix (tip axes).
        damping: D [N·s/m], the same shapes; default none.
        name: what messages call it.
    """

    kind: ClassVar[str] = "ball"
    rigid: ClassVar[str | None] = "rigid_point"
    deformation_size: ClassVar[int] = 3
    linear: ClassVar[bool] = True  # with translations only, the deformation is the relative translation
    exact_tangent: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A subclass that changes :meth:`evaluate` without its own :meth:`tangent` or
        :meth:`matrix_tangent` gets the base class's central differences for it, not this law's
        closed forms."""
        super().__init_subclass__(**kwargs)
        own = cls.__dict__.keys()
        if "evaluate" in own and "tangent" not in own:
            cls.exact_tangent = False
            cls.tangent = Element.tangent  # type: ignore[method-assign]
        if "evaluate" in own and "matrix_tangent" not in own:
            cls.matrix_tangent = Element.matrix_tangent  # type: ignore[method-assign]

    def __init__(self, stiffness: Any, damping: Any = None, name: str = "interconnection") -> None:
        D = np.zeros((3, 3)) if damping is None else _spd3(damping, f"{name}: damping", "N·s/m")
        self._keep(_spd3(stiffness, f"{name}: stiffness", "N/m"), D, name)

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        R, p = T_M_G.rotation, T_M_G.translation
        f = self.K @ p
        power = 0.0
        if self._damped:
            p_dot = R @ xi[:3]
            D_p_dot = self.D @ p_dot
            power = float(p_dot @ D_p_dot)
            f = f + D_p_dot
        G_f_G = np.zeros(6)
        G_f_G[:3] = -(R.T @ f)
        S_K = S_D = None
        if jacobians:
            S_K, S_D = np.zeros((6, 6)), np.zeros((6, 6))
            S_K[:3, :3] = R.T @ self.K @ R
            S_D[:3, :3] = R.T @ self.D @ R
        theta = float(np.linalg.norm(pin.log3(R)))
        return ElementEval(0.5 * float(p @ self.K @ p), p.copy(), G_f_G, power, S_K, S_D, theta)

    def matrix_tangent(self, T_M_G: pin.SE3, xi: np.ndarray, w_K: np.ndarray, w_D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact derivatives of ``S_K w_K + S_D w_D = [Rᵀ K R w_K,v + Rᵀ D R w_D,v; 0]`` (see
        :meth:`Element.matrix_tangent`): R → R·exp(δ_ω^) turns ``P w`` (P = Rᵀ K R) by
        ``[P w]^ δ_ω − P [w]^ δ_ω``; nothing depends on δ_v or ξ."""
        R = T_M_G.rotation
        G_d = np.zeros((6, 6))
        for C, w in ((self.K, w_K[:3]), (self.D, w_D[:3])):
            P = R.T @ C @ R
            G_d[:3, 3:] += pin.skew(P @ w) - P @ pin.skew(w)
        return G_d, np.zeros((6, 6))

    def tangent(self, T_M_G: pin.SE3, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact ``(∂G_f_G/∂δ, ∂G_f_G/∂ξ)`` (see :meth:`Element.tangent`). With ``f = K p + D R ξ_v``
        and ``G_f_G = −Rᵀ f``, a perturbation ``T_M_G·exp6(δ)`` moves p by ``R δ_v`` and R by
        ``R δ_ω^``: ``∂/∂δ_v = −Rᵀ K R``, ``∂/∂δ_ω = [G_f_G]^ + Rᵀ D R [ξ_v]^``, ``∂/∂ξ_v = −Rᵀ D R``."""
        R, p = T_M_G.rotation, T_M_G.translation
        f = self.K @ p + (self.D @ (R @ xi[:3]) if self._damped else 0.0)
        f_G = -(R.T @ f)
        RDR = R.T @ self.D @ R
        F_d, F_x = np.zeros((6, 6)), np.zeros((6, 6))
        F_d[:3, :3] = -(R.T @ self.K @ R)
        F_d[:3, 3:] = pin.skew(f_G[:3]) + RDR @ pin.skew(xi[:3])
        F_x[:3, :3] = -RDR
        return F_d, F_x
