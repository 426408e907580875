"""Interconnections: which two frames an elastic element joins, and with what law.

An :class:`Interconnection` joins an arm's tool frame T — or, with ``arm=None``, a fixture frame
fixed in the world — to a grasp frame G on the object, through an element of
:mod:`coopdyn.model.elements` (``"se3"``: the 6-DOF SE(3) spring–damper, the default;
``"ball"``: a translational spring–damper, a point grasp that transmits no moment; or any
registered kind). The element computes the wrenches from the pose of G relative to T.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _validate
from ..errors import SceneError, did_you_mean
from .body import axis_vector
from .elements import Element, ElementType, lookup


def diagonal(linear: float | Sequence[float], angular: float | Sequence[float]) -> np.ndarray:
    """A 6x6 diagonal stiffness or damping: ``linear`` [N/m or N·s/m] (scalar or x, y, z) and
    ``angular`` [N·m/rad or N·m·s/rad] (scalar or about x, y, z)."""
    parts = []
    for value, name in ((linear, "linear"), (angular, "angular")):
        arr = _validate.finite_array(value, f"diagonal: {name}")
        if arr.shape not in ((), (3,)):
            raise SceneError(f"diagonal: {name} must be a scalar or 3 values (x, y, z), got shape {arr.shape}")
        parts.append(np.broadcast_to(arr, (3,)))
    return np.diag(np.concatenate(parts))


def axial(value: float, axis: str | Sequence[float] = "z") -> np.ndarray:
    """A 1-D spring (or damper) of ``value`` [N/m or N·s/m] along ``axis`` of the tip frame."""
    u = axis_vector(axis, "axis")
    out = np.zeros((6, 6))
    out[:3, :3] = float(_validate.finite_array(value, "value", ())) * np.outer(u, u)
    return out


@dataclass(frozen=True, eq=False)
class Interconnection:
    """An elastic link from the tip of ``arm`` (or a world fixture) to a grasp frame on the object.

    Attributes:
        arm: name of the arm whose tip frame is T; ``None`` attaches T to the world (a fixture).
        stiffness: K of the element, in the tip frame's axes. ``"se3"``: a 6x6 symmetric positive
            semi-definite matrix or a 6-vector diagonal, order [x, y, z, rx, ry, rz], [N/m] and
            [N·m/rad] blocks. ``"ball"``: a scalar, 3-vector diagonal or 3x3 matrix [N/m].
        damping: D, same shape as K, [N·s/m] and [N·m·s/rad]. Default: none.
        grasp: pose of the grasp frame G in the object frame (``pin.SE3``, 4x4 or translation [m]);
            the element is unloaded when T and G coincide. Default: the tip pose at the initial
            configuration (with ``arm=None``: the object frame itself).
        element: the element kind (a name in :data:`coopdyn.model.elements.ELEMENTS`, or an
            :class:`~coopdyn.model.elements.Element` subclass). Default ``"se3"``.
        fixture: with ``arm=None``, the pose of T in the world. Default: G's initial world pose
            (the element starts unloaded).
        name: what readouts and messages call it; default ``"<arm>"`` (or ``"fixture"``) plus its index.
        parameters: the element's own parameters beyond stiffness and damping, by name (e.g.
            ``{"hardening": 1e7}`` for ``element="hardening"``; the element class's ``parameters``
            lists them with their units). Default: none.
    """

    arm: str | None
    stiffness: Any
    damping: Any = None
    grasp: Any = None
    element: str | type[Element] = "se3"
    fixture: Any = None
    name: str | None = None
    parameters: Mapping[str, Any] | None = None

    def element_type(self) -> ElementType:
        """The registered element kind (Python class and C++ twin)."""
        return lookup(self.element)

    def law(self, what: str | None = None) -> Element:
        """The validated element (its parameters checked); ``what`` names it in messages."""
        label = what or f"interconnection to arm {self.arm!r}"
        cls = self.element_type().python
        given = self.parameters if self.parameters is not None else {}
        if not isinstance(given, Mapping) or not all(isinstance(k, str) for k in given):
            raise SceneError(f"{label}: parameters must be a mapping of names to values, got {_validate._short(given)}")
        known = {p.name: p for p in cls.parameters}
        for key in given:
            if key not in known:
                listed = ", ".join(f"{p.name} [{p.unit}]" for p in cls.parameters) or "none beyond stiffness and damping"
                hint = did_you_mean(key, known)
                raise SceneError(f"{label}: the {cls.kind!r} element has no parameter {key!r}.{hint} Its parameters: {listed}")
        return cls(self.stiffness, self.damping, label, **given)
