"""The hardening SE(3) spring: an SE(3) spring–damper whose translational stiffness grows with the
stretch, as a rubber pad, a cable or a soft finger does.

With ``e = log6(T_M_G)`` ([linear; angular] [m, rad]) and ``p = e[:3]`` its translational part,
the elastic energy is ``U = ½ eᵀ K e + ¼ κ |p|⁴``: the gradient with respect to e is
``g = K e + κ |p|² [p; 0]`` (along a line the spring force is Duffing's ``k x + κ x³``), the wrench
on the object at G, in G axes, ``G_f_G = −Jlog6ᵀ (g + D ė)``, and the Gauss–Newton stiffness
``S_K = Jlog6ᵀ (K + κ (|p|² I₃ + 2 p pᵀ) ⊕ 0₃) Jlog6`` — the exact Hessian of U in e, positive
semi-definite for κ ≥ 0. K and D as in :class:`~coopdyn.model.elements.SE3Spring`; κ ≥ 0 [N/m³].
With κ = 0 it is the SE(3) spring. C++ twin: ``src/native/elements/hardening_spring.hpp``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ... import _validate
from .base import ElementEval, Parameter
from .lie import jlog6, log6
from .se3_spring import SE3Spring


class HardeningSpring(SE3Spring):
    """An SE(3) spring–damper with a cubic translational hardening κ (see the module docstring).

    Args:
        stiffness: K, a symmetric positive semi-definite 6×6 matrix or a 6-vector diagonal
            [N/m, N·m/rad].
        damping: D, the same shape [N·s/m, N·m·s/rad]; default none.
        name: what messages call it.
        hardening: κ ≥ 0 [N/m³]: the translational force along a stretch x is k x + κ x³.
    """

    kind: ClassVar[str] = "hardening"
    linear: ClassVar[bool] = False  # the κ term is cubic in the translation
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter("hardening", "N/m³", "κ: the force along a stretch x is k x + κ x³"),
    )

    def __init__(self, stiffness: Any, damping: Any = None, name: str = "interconnection", hardening: Any = 0.0) -> None:
        super().__init__(stiffness, damping, name)
        self.hardening = _validate.non_negative(hardening, f"{name}: hardening", "N/m³")

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        e, theta = log6(T_M_G)
        J = jlog6(T_M_G, e, theta)
        p = e[:3]
        p2 = float(p @ p)
        w = self.K @ e
        w[:3] += self.hardening * p2 * p
        power = 0.0
        if self._damped:
            e_dot = J @ xi
            D_e_dot = self.D @ e_dot
            power = float(e_dot @ D_e_dot)
            w = w + D_e_dot
        S_K = S_D = None
        if jacobians:
            H = self.K.copy()
            H[:3, :3] += self.hardening * (p2 * np.eye(3) + 2.0 * np.outer(p, p))
            S_K = J.T @ H @ J
            S_D = J.T @ self.D @ J
        energy = 0.5 * float(e @ self.K @ e) + 0.25 * self.hardening * p2 * p2
        return ElementEval(energy, e, -(J.T @ w), power, S_K, S_D, theta)

    def __repr__(self) -> str:
        return f"{super().__repr__()[:-1]}, hardening {self.hardening:g} N/m³)"
