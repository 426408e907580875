"""Rigid grasps: the stiffness → ∞ limit of the spring elements, as kinematic constraints.

A rigid element holds G on T exactly: ``T_M_G = I`` (:class:`RigidGrasp`, the limit of the SE(3)
spring, six constraints) or ``T_M_G.translation = 0`` (:class:`RigidPoint`, the limit of the ball
spring, three). It has no law of its own: its wrench is the constraint force that Pinocchio's
``constraintDynamics`` solves for (:mod:`coopdyn.dynamics.constrained`), so :meth:`evaluate`
puts no force on G and stores no energy. Its deformation is the *drift*, how far the integrated
state has left the constraint ([m, rad], the same measure as the spring it replaces), which
Baumgarte stabilisation drives back to zero: the constraint acceleration gets
``−Kp·drift − Kd·(drift rate)`` added, with ``stiffness`` = Kp [1/s²] and ``damping`` = Kd [1/s].
They run on the Python path only (Pinocchio's own C++ solves the constraints).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ... import _validate
from .base import Element, ElementEval
from .lie import log6

#: Default Baumgarte gains: a critically damped drift correction at ω = 50 rad/s.
BAUMGARTE_KP = 2500.0  #: [1/s²]
BAUMGARTE_KD = 100.0  #: [1/s]


class RigidGrasp(Element):
    """A rigid 6-D grasp: G welded to T (see the module docstring).

    Args:
        stiffness: the Baumgarte gain Kp [1/s²] on the drift (≥ 0); default :data:`BAUMGARTE_KP`.
        damping: the Baumgarte gain Kd [1/s] on the drift rate (≥ 0); default :data:`BAUMGARTE_KD`.
        name: what messages call it.
    """

    kind: ClassVar[str] = "rigid"
    rigid: ClassVar[str | None] = "rigid"
    deformation_size: ClassVar[int] = 6
    constraint: ClassVar[str | None] = "6D"

    def __init__(self, stiffness: Any = None, damping: Any = None, name: str = "interconnection") -> None:
        self.kp = BAUMGARTE_KP if stiffness is None else _validate.non_negative(stiffness, f"{name}: Baumgarte Kp", "1/s²")
        self.kd = BAUMGARTE_KD if damping is None else _validate.non_negative(damping, f"{name}: Baumgarte Kd", "1/s")

    def drift(self, T_M_G: pin.SE3) -> tuple[np.ndarray, float]:
        """The constraint violation ``log6(T_M_G)`` (6,) [m, rad] and its rotation angle [rad]."""
        return log6(T_M_G)

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        e, theta = self.drift(T_M_G)
        zero = np.zeros((6, 6)) if jacobians else None
        return ElementEval(0.0, e, np.zeros(6), 0.0, zero, zero, theta)

    @property
    def has_damping(self) -> bool:
        return False

    def __repr__(self) -> str:
        return f"{type(self).__name__}(Baumgarte Kp {self.kp:g} 1/s², Kd {self.kd:g} 1/s)"


class RigidPoint(RigidGrasp):
    """A rigid point grasp: G's origin held on T's, rotation free (the ball spring's limit)."""

    kind: ClassVar[str] = "rigid_point"
    rigid: ClassVar[str | None] = "rigid_point"
    deformation_size: ClassVar[int] = 3
    constraint: ClassVar[str | None] = "3D"

    def drift(self, T_M_G: pin.SE3) -> tuple[np.ndarray, float]:
        """The constraint violation, G's origin in T (3,) [m], and 0 (the rotation is free)."""
        return T_M_G.translation.copy(), 0.0
