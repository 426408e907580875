"""Elastic interconnections: an SE(3) spring–damper between an arm tip frame T and an object
grasp frame G (DESIGN §2).

With ``T_M_G = oMT⁻¹ · oMG`` (pose of G in T) the deformation is ``e = log6(T_M_G)``
([linear; angular], [m; rad]), the elastic energy ``U = ½ eᵀ K e`` and, with the relative twist
``ξ = V_G − Ad(T_M_G⁻¹) V_T`` (both LOCAL), ``ė = Jlog6(T_M_G) ξ``. The wrench on the object at G,
in G, is ``G_f_G = −Jlog6ᵀ (K e + D ė)`` — the exact gradient of U plus the damping — and the
reaction on the arm at T, in T, is ``T_f_T = −T_M_G · G_f_G``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from .body import axis_vector


def diagonal(linear: float | Sequence[float], angular: float | Sequence[float]) -> np.ndarray:
    """A 6x6 diagonal stiffness or damping: ``linear`` [N/m or N·s/m] (scalar or x, y, z) and
    ``angular`` [N·m/rad or N·m·s/rad] (scalar or about x, y, z)."""
    lin = np.broadcast_to(_validate.finite_array(linear, "linear"), (3,))
    ang = np.broadcast_to(_validate.finite_array(angular, "angular"), (3,))
    return np.diag(np.concatenate([lin, ang]))


def axial(value: float, axis: str | Sequence[float] = "z") -> np.ndarray:
    """A 1-D spring (or damper) of ``value`` [N/m or N·s/m] along ``axis`` of the tip frame."""
    u = axis_vector(axis, "axis")
    out = np.zeros((6, 6))
    out[:3, :3] = float(_validate.finite_array(value, "value", ())) * np.outer(u, u)
    return out


@dataclass(frozen=True, eq=False)
class Interconnection:
    """An elastic link from the tip of ``arm`` to a grasp frame on the object.

    Attributes:
        arm: name of the arm whose tip frame is T.
        stiffness: K, a 6x6 symmetric positive semi-definite matrix or a 6-vector diagonal,
            order [x, y, z, rx, ry, rz] in the tip frame's axes, [N/m] and [N·m/rad] blocks.
        damping: D, same shape, [N·s/m] and [N·m·s/rad] blocks. Default: none.
        grasp: pose of the grasp frame G in the object frame; the interconnection is unloaded
            when T and G coincide. Default: the tip pose at the initial configuration.
    """

    arm: str
    stiffness: Any
    damping: Any = None
    grasp: Any = None

    def matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """The validated (K, D)."""
        what = f"interconnection to arm {self.arm!r}"
        K = _validate.spd6(self.stiffness, f"{what}: stiffness", "N/m, N·m/rad")
        D = np.zeros((6, 6)) if self.damping is None else _validate.spd6(self.damping, f"{what}: damping", "N·s/m, N·m·s/rad")
        if not np.any(K) and not np.any(D):
            raise SceneError(f"{what}: stiffness and damping are both zero; the arm would not touch the object")
        return K, D


class SpringState(NamedTuple):
    """What an interconnection computes at one instant (all LOCAL frame quantities)."""

    e: np.ndarray  #: deformation log6(T_M_G), (6,) [m, rad]
    e_dot: np.ndarray  #: its rate, (6,) [m/s, rad/s]
    G_f_G: np.ndarray  #: wrench on the object at G, in G, (6,) [N, N·m]
    T_f_T: np.ndarray  #: wrench on the arm at T, in T, (6,) [N, N·m]
    T_M_G: pin.SE3  #: pose of G in T
    J_log: np.ndarray  #: Jlog6(T_M_G), (6, 6)


def spring(oMT: pin.SE3, oMG: pin.SE3, T_v_T: np.ndarray, G_v_G: np.ndarray, K: np.ndarray, D: np.ndarray) -> SpringState:
    """Evaluate the SE(3) spring–damper law for frame poses and LOCAL twists (6,) [m/s, rad/s]."""
    T_M_G = oMT.actInv(oMG)
    e = pin.log6(T_M_G).vector
    J_log = pin.Jlog6(T_M_G)
    xi = G_v_G - T_M_G.toActionMatrixInverse() @ T_v_T
    e_dot = J_log @ xi
    G_f_G = -J_log.T @ (K @ e + D @ e_dot)
    T_f_T = -(T_M_G.toDualActionMatrix() @ G_f_G)
    return SpringState(e, e_dot, G_f_G, T_f_T, T_M_G, J_log)
