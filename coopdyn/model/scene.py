"""A scene: arms, the object and interconnections merged into one Pinocchio model.

The scene is the static model (never mutated after construction); states ``(q, v)`` are passed
around explicitly and Pinocchio ``Data`` lives in :class:`coopdyn.dynamics.Dynamics`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError, did_you_mean
from .arm import Arm, LoadedArm, load_arm
from .body import RigidObject
from .interconnection import Interconnection


@dataclass(frozen=True, eq=False)
class ArmInfo:
    """Where an arm sits in the merged model."""

    name: str
    joint_names: tuple[str, ...]  #: prefixed names of its joints, in order
    q_index: np.ndarray  #: its coordinates in the scene ``q``, (nq_arm,)
    v_index: np.ndarray  #: its coordinates in the scene ``v`` (and torque vector), (nv_arm,)
    tip_frame: int  #: frame id of the tip T
    damping: np.ndarray  #: viscous joint damping, (nv_arm,) [N·m·s/rad or N·s/m]


@dataclass(frozen=True, eq=False)
class Link:
    """A compiled interconnection: frame ids and matrices."""

    arm: int  #: index of the arm in ``scene.arms``
    tip_frame: int  #: T
    grasp_frame: int  #: G
    K: np.ndarray  #: (6, 6) stiffness in T/G axes [N/m, N·m/rad]
    D: np.ndarray  #: (6, 6) damping [N·s/m, N·m·s/rad]


class Scene:
    """Arms + one rigid object + elastic interconnections, as one Pinocchio model.

    Args:
        arms: the arms; names must be unique.
        obj: the held object.
        interconnections: at least one; each names an arm (an arm may have several).
        gravity: gravity acceleration in the world, (3,) [m/s²].

    Attributes:
        model: the merged ``pin.Model`` (arms in order, then the object's root joint).
        arms: one :class:`ArmInfo` per arm. ``links``: one :class:`Link` per interconnection.
        arm_specs, interconnection_specs, object: the descriptions the scene was built from.
        q0, v0: the initial state, (nq,) and (nv,).
        actuated: indices in ``v`` of all arm joints, in scene order; a controller returns one
            torque/force per entry [N·m or N].
        actuated_index: the same as a slice when the indices are contiguous (cheaper to index
            with on hot paths), else ``actuated``.
        object_joint: joint id of the object; ``object_q``/``object_v`` its coordinates.
    """

    def __init__(
        self,
        arms: Sequence[Arm],
        obj: RigidObject,
        interconnections: Sequence[Interconnection],
        gravity: Any = (0.0, 0.0, -9.81),
    ) -> None:
        if isinstance(arms, Arm):
            arms = [arms]
        if not arms:
            raise SceneError("a scene needs at least one arm")
        for a in arms:
            if not isinstance(a, Arm):
                raise SceneError(f"arms must be coopdyn.Arm instances, got {type(a).__name__}")
        names = [a.name for a in arms]
        if not all(isinstance(n, str) and n for n in names):
            raise SceneError(f"arm names must be non-empty strings, got {names!r}")
        if len(set(names)) != len(names):
            raise SceneError(f"arm names must be unique, got {names}")
        if not isinstance(obj, RigidObject):
            raise SceneError(f"obj must be a coopdyn.RigidObject, got {type(obj).__name__}")
        if not interconnections:
            raise SceneError("a scene needs at least one interconnection (arm tip ↔ object)")

        loaded = [load_arm(a) for a in arms]
        model = pin.Model()
        model.name = "coopdyn_scene"
        for la in loaded:
            model = pin.appendModel(model, la.model, 0, la.base)
        model.gravity = pin.Motion(np.concatenate([_validate.finite_array(gravity, "gravity", (3,)), np.zeros(3)]))

        # The object on its own root joint.
        inertia = obj.spatial_inertia()
        oMo = pin.SE3.Identity() if obj.pose is None else _validate.se3(obj.pose, "object pose")
        jmodel = obj.joint_model()
        if obj.joint == "freeflyer":
            placement, q_obj = pin.SE3.Identity(), pin.SE3ToXYZQUAT(oMo)
        else:
            placement, q_obj = oMo, _neutral(jmodel)
        obj_joint = model.addJoint(0, jmodel, placement, obj.name)
        model.appendBodyToJoint(obj_joint, inertia, pin.SE3.Identity())
        model.addBodyFrame(obj.name, obj_joint, pin.SE3.Identity(), 0)

        self.arms = tuple(_arm_info(model, la) for la in loaded)
        q0 = np.concatenate([la.q0 for la in loaded] + [q_obj])
        data = model.createData()
        pin.framesForwardKinematics(model, data, q0)

        links = []
        for k, ic in enumerate(interconnections):
            if not isinstance(ic, Interconnection):
                raise SceneError(f"interconnections[{k}] must be a coopdyn.Interconnection, got {type(ic).__name__}")
            if not isinstance(ic.arm, str) or ic.arm not in names:
                hint = did_you_mean(ic.arm, names)
                raise SceneError(f"interconnections[{k}] names arm {ic.arm!r}, which is not in the scene.{hint} Arms: {names}")
            K, D = ic.matrices()
            i_arm = names.index(ic.arm)
            tip = self.arms[i_arm].tip_frame
            if ic.grasp is None:
                o_M_G = data.oMf[model.getFrameId(obj.name)].actInv(data.oMf[tip])
            else:
                o_M_G = _validate.se3(ic.grasp, f"interconnections[{k}].grasp")
            g_id = model.addFrame(pin.Frame(f"{obj.name}/grasp{k}_{ic.arm}", obj_joint, o_M_G, pin.FrameType.OP_FRAME))
            links.append(Link(arm=i_arm, tip_frame=tip, grasp_frame=g_id, K=K, D=D))
        self.links = tuple(links)
        self.arm_specs = tuple(arms)
        self.interconnection_specs = tuple(interconnections)
        self.model = model
        self.object = obj
        self.object_joint = int(obj_joint)
        jo = model.joints[obj_joint]
        self.object_frame = int(model.getFrameId(obj.name))
        self.object_q = np.arange(jo.idx_q, jo.idx_q + jo.nq)
        self.object_v = np.arange(jo.idx_v, jo.idx_v + jo.nv)
        self.actuated = np.concatenate([a.v_index for a in self.arms])
        first, n = int(self.actuated[0]) if self.actuated.size else 0, self.actuated.size
        contiguous = n > 0 and np.array_equal(self.actuated, np.arange(first, first + n))
        self.actuated_index: slice | np.ndarray = slice(first, first + n) if contiguous else self.actuated
        self.q0 = q0
        self.v0 = np.zeros(model.nv)
        self.gravity = np.array(model.gravity.linear)

    @property
    def nq(self) -> int:
        """Size of the configuration vector."""
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        """Size of the velocity vector."""
        return int(self.model.nv)

    @property
    def n_actuated(self) -> int:
        """Number of arm joints: the length of a controller's output."""
        return int(self.actuated.size)

    def arm_index(self, arm: int | str) -> int:
        """Index of an arm given by index or name."""
        if isinstance(arm, str):
            names = [a.name for a in self.arms]
            if arm not in names:
                raise SceneError(f"no arm named {arm!r}.{did_you_mean(arm, names)} Arms: {names}")
            return names.index(arm)
        if not 0 <= int(arm) < len(self.arms):
            raise SceneError(f"arm index {arm} out of range: the scene has {len(self.arms)} arms")
        return int(arm)

    def check_state(self, q: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
        """Validated copies of a state: shapes, finiteness and normalised quaternions."""
        q = np.array(q, dtype=float)
        v = np.array(v, dtype=float)
        if q.shape != (self.nq,):
            raise SceneError(f"q must have shape ({self.nq},), got {q.shape}")
        if v.shape != (self.nv,):
            raise SceneError(f"v must have shape ({self.nv},), got {v.shape}")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise SceneError("q and v must be finite")
        if not pin.isNormalized(self.model, q, 1e-9):
            raise SceneError("q is not a valid configuration (a quaternion is not of unit norm); use pin.normalize")
        return q, v

    def __repr__(self) -> str:
        arms = ", ".join(a.name for a in self.arms)
        obj = f"{self.object.name!r} ({self.object.joint})"
        return f"Scene(arms=[{arms}], object={obj}, links={len(self.links)}, nq={self.nq}, nv={self.nv})"


def _neutral(jmodel: pin.JointModel) -> np.ndarray:
    m = pin.Model()
    m.addJoint(0, jmodel, pin.SE3.Identity(), "j")
    return pin.neutral(m)


def _arm_info(model: pin.Model, la: LoadedArm) -> ArmInfo:
    joint_names = tuple(la.model.names[i] for i in range(1, la.model.njoints))
    q_index: list[int] = []
    v_index: list[int] = []
    for name in joint_names:
        j = model.joints[model.getJointId(name)]
        q_index.extend(range(j.idx_q, j.idx_q + j.nq))
        v_index.extend(range(j.idx_v, j.idx_v + j.nv))
    return ArmInfo(
        name=la.spec.name,
        joint_names=joint_names,
        q_index=np.array(q_index),
        v_index=np.array(v_index),
        tip_frame=int(model.getFrameId(la.tip_frame)),
        damping=la.damping,
    )
