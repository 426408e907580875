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
from .lie import jlog6
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
        """The SE(3) spring's evaluation plus the hardening term's energy, wrench and stiffness."""
        ev = super().evaluate(T_M_G, xi, jacobians)
        if self.hardening == 0.0:
            return ev
        J = jlog6(T_M_G, ev.deformation, ev.theta)[:3]  # d(p)/dξ: the translational rows
        p = ev.deformation[:3]
        p2 = float(p @ p)
        G_f_G = ev.G_f_G - J.T @ (self.hardening * p2 * p)
        S_K = None
        if ev.S_K is not None:
            S_K = ev.S_K + J.T @ (self.hardening * (p2 * np.eye(3) + 2.0 * np.outer(p, p))) @ J
        return ev._replace(energy=ev.energy + 0.25 * self.hardening * p2 * p2, G_f_G=G_f_G, S_K=S_K)

    def gradient(self, e: np.ndarray) -> np.ndarray:
        """∂U/∂e = K e + κ |p|² [p; 0] (analytic in e: |p|² is pᵀp, no conjugate)."""
        p = e[:3]
        g = self.K @ e
        g[:3] += self.hardening * (p @ p) * p
        return g

    def hessian(self, e: np.ndarray) -> np.ndarray:
        """∂²U/∂e² = K + κ (|p|² I₃ + 2 p pᵀ) ⊕ 0₃ (analytic in e)."""
        p = e[:3]
        H = self.K + np.zeros((6, 6), dtype=np.result_type(e, float))
        H[:3, :3] += self.hardening * ((p @ p) * np.eye(3) + 2.0 * np.outer(p, p))
        return H

    def __repr__(self) -> str:
        return f"{super().__repr__()[:-1]}, hardening {self.hardening:g} N/m³)"
