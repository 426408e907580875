"""The held object: a rigid body on its own root joint (a :class:`~.objects.SceneObject`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from .fields import Field, numbers, pose_data
from .objects import Placement, SceneObject, Shape

#: Root joints an object may have, and the Pinocchio joint each one builds.
OBJECT_JOINTS = ("freeflyer", "prismatic", "planar")

_AXES = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}


def axis_vector(axis: str | Sequence[float], name: str) -> np.ndarray:
    """A unit 3-vector from ``"x"``, ``"y"``, ``"z"`` or any non-zero 3-vector."""
    if isinstance(axis, str):
        if axis not in _AXES:
            raise SceneError(f"{name} must be 'x', 'y', 'z' or a 3-vector, got {axis!r}")
        return _AXES[axis].copy()
    vec = _validate.finite_array(axis, name, (3,))
    norm = float(np.linalg.norm(vec))
    if norm == 0.0:
        raise SceneError(f"{name} must be a non-zero 3-vector")
    return vec / norm


_RIGID = {
    "mass": Field("number", "mass [kg]", True),
    "pose": Field("pose", "initial pose of the object frame in the world [m]"),
    "com": Field("vector3", "centre of mass in the object frame [m]; default the origin"),
    "joint": Field("string", f"root joint: one of {list(OBJECT_JOINTS)}; default freeflyer"),
    "axis": Field("axis", "slide axis of a prismatic object, in the object frame; default 'z'"),
    "name": Field("string", "name of the object's joint and frame; default 'object'"),
}

#: the size drawn for an object that does not say its own [m]
DEFAULT_SIZE = (0.05, 0.05, 0.05)


@dataclass(frozen=True, eq=False)
class RigidObject(SceneObject):
    """The object the arms hold.

    Attributes:
        mass: mass [kg], > 0.
        inertia: rotational inertia about the centre of mass in the object frame, (3, 3) [kg·m²];
            symmetric, positive definite, principal moments obeying the triangle inequality.
        pose: initial pose of the object frame in the world (``pin.SE3``, 4x4 or translation [m]).
        com: centre of mass in the object frame, (3,) [m].
        joint: ``"freeflyer"`` (6 DOF, default), ``"prismatic"`` (1 DOF along ``axis``) or
            ``"planar"`` (3 DOF: x, y and rotation about z of the initial object frame).
        axis: slide axis of a prismatic object, in the object frame (``"x"``/``"y"``/``"z"`` or 3-vector).
        name: name of the object's joint and body frame.
    """

    mass: float
    inertia: Any
    pose: Any = None
    com: Any = (0.0, 0.0, 0.0)
    joint: str = "freeflyer"
    axis: str | Sequence[float] = "z"
    name: str = "object"
    size: Any = None  #: edge lengths (x, y, z) [m] of a box, for visualisation (set by :meth:`box`)

    description_types: ClassVar[dict[str, dict[str, Field]]] = {
        "box": {**_RIGID, "size": Field("vector3", "edge lengths x, y, z [m] (a homogeneous box)", True)},
        "rigid": {
            **_RIGID,
            "inertia": Field(
                "matrix", "rotational inertia about the centre of mass, object axes: 3x3 or 3 principal [kg·m²]", True
            ),
            "size": Field("vector3", "edge lengths of the box drawn for it [m] (display only)"),
        },
    }

    @classmethod
    def box(cls, mass: float, size: Sequence[float], **kwargs: Any) -> RigidObject:
        """A homogeneous box of ``mass`` [kg] and edge lengths ``size`` = (x, y, z) [m]."""
        m = _validate.positive(mass, "box mass", "kg")
        s = _validate.finite_array(size, "box size", (3,))
        if np.any(s <= 0.0):
            raise SceneError(f"box size must be three positive edge lengths [m], got {s.tolist()}")
        x2, y2, z2 = s**2
        inertia = m / 12.0 * np.diag([y2 + z2, x2 + z2, x2 + y2])
        return cls(mass=m, inertia=inertia, size=tuple(float(x) for x in s), **kwargs)

    def spatial_inertia(self) -> pin.Inertia:
        """The validated spatial inertia of the body, about the object frame origin."""
        m = _validate.positive(self.mass, "object mass", "kg")
        c = _validate.finite_array(self.com, "object com", (3,))
        inertia = _validate.finite_array(self.inertia, "object inertia", (3, 3))
        if np.max(np.abs(inertia - inertia.T)) > 1e-12 * max(1.0, float(np.max(np.abs(inertia)))):
            raise SceneError("object inertia must be symmetric")
        principal = np.linalg.eigvalsh(inertia)
        if principal[0] <= 0.0:
            raise SceneError(f"object inertia must be positive definite; principal moments {principal.tolist()} [kg·m²]")
        a, b, c_ = principal
        if a + b < c_ * (1.0 - 1e-9):
            raise SceneError(
                "object inertia violates the triangle inequality (no rigid body has it): principal moments "
                f"{principal.tolist()} [kg·m²] need I1 + I2 >= I3"
            )
        return pin.Inertia(m, c, inertia)

    def joint_model(self) -> pin.JointModel:
        """The Pinocchio root joint of the object."""
        if self.joint == "freeflyer":
            return pin.JointModelFreeFlyer()
        if self.joint == "prismatic":
            return pin.JointModelPrismaticUnaligned(axis_vector(self.axis, "object axis"))
        if self.joint == "planar":
            return pin.JointModelPlanar()
        raise SceneError(f"object joint must be one of {OBJECT_JOINTS}, got {self.joint!r}")

    # -- the object protocol (objects.SceneObject) -----------------------------------------------
    @property
    def joint_label(self) -> str:
        return self.joint

    @classmethod
    def from_description(cls, type_name: str, values: dict[str, Any]) -> RigidObject:
        if "joint" in values and values["joint"] not in OBJECT_JOINTS:
            raise SceneError(f"joint must be one of {list(OBJECT_JOINTS)}, got {values['joint']!r}")
        if type_name == "box":
            box = cls.box(values.pop("mass"), values.pop("size"), **values)
            box.joint_model()  # (a prismatic box's axis)
            return box
        inertia = values["inertia"]
        if np.ndim(inertia) == 1:
            values["inertia"] = np.diag(inertia) if len(inertia) == 3 else inertia
        obj = cls(**values)
        obj.spatial_inertia()  # checked here, where the message can say so
        obj.joint_model()
        return obj

    def mass_and_com(self) -> tuple[float, np.ndarray]:
        return self.mass, np.asarray(self.com, dtype=float)

    def with_mass(self, mass: float) -> RigidObject:
        m = _validate.positive(mass, f"{self.name}: mass", "kg")
        return dataclasses.replace(self, mass=m, inertia=np.asarray(self.inertia, dtype=float) * (m / self.mass))

    def describe(self) -> dict[str, Any]:
        out = {"type": "rigid", "mass": float(self.mass), "inertia": numbers(self.inertia, "object inertia")}
        out |= {"com": numbers(self.com, "object com"), "joint": self.joint, "name": self.name}
        out["axis"] = self.axis if isinstance(self.axis, str) else numbers(self.axis, "object axis")
        if self.size is not None:
            out["size"] = numbers(self.size, "object size")
        if self.pose is not None:
            out["pose"] = pose_data(self.pose, "object pose")
        return out

    def check(self) -> None:
        if not isinstance(self.joint, str) or self.joint not in OBJECT_JOINTS:
            raise SceneError(f"object joint must be one of {OBJECT_JOINTS}, got {self.joint!r}")

    def add_to(self, model: pin.Model) -> Placement:
        """The object on its own root joint: a free flyer placed at the world origin with the pose
        in its coordinates, or a prismatic / planar joint placed at the pose."""
        inertia = self.spatial_inertia()
        oMo = pin.SE3.Identity() if self.pose is None else _validate.se3(self.pose, "object pose")
        jmodel = self.joint_model()
        if self.joint == "freeflyer":
            placement, q_obj = pin.SE3.Identity(), pin.SE3ToXYZQUAT(oMo)
        else:
            placement, q_obj = oMo, _neutral(jmodel)
        joint = model.addJoint(0, jmodel, placement, self.name)
        model.appendBodyToJoint(joint, inertia, pin.SE3.Identity())
        model.addBodyFrame(self.name, joint, pin.SE3.Identity(), 0)
        return Placement(joint, (joint,), q_obj)

    def bounds(self, model: pin.Model) -> list[Shape] | None:
        """Its box, when it has a size (without one, the box drawn is a stand-in)."""
        return None if self.size is None else self.shapes(model)

    def shapes(self, model: pin.Model) -> list[Shape]:
        size = tuple(float(x) for x in (self.size if self.size is not None else DEFAULT_SIZE))
        frame = model.getFrameId(self.name)
        return [Shape(f"{self.name}/box", model.frames[frame].parentJoint, frame, pin.SE3.Identity(), size)]  # type: ignore[arg-type]


def _neutral(jmodel: pin.JointModel) -> np.ndarray:
    """The neutral configuration of a single joint."""
    m = pin.Model()
    m.addJoint(0, jmodel, pin.SE3.Identity(), "j")
    return pin.neutral(m)
