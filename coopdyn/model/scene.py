"""A scene: arms, the object and interconnections merged into one Pinocchio model.

The scene is the static model (never mutated after construction); states ``(q, v)`` are passed
around explicitly and Pinocchio ``Data`` lives in :class:`coopdyn.dynamics.Dynamics`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError, SceneWarning, did_you_mean
from .arm import Arm, LoadedArm, load_arm
from .elastic_joints import add_motor, continuous, motors_at_links, turned
from .elements import Element
from .elements.joint_spring import JointSprings
from .interconnection import Interconnection
from .objects import SceneObject


@dataclass(frozen=True, eq=False)
class ArmInfo:
    """Where an arm sits in the merged model."""

    name: str
    joint_names: tuple[str, ...]  #: prefixed names of its joints, in order
    q_index: np.ndarray  #: its coordinates in the scene ``q``, (nq_arm,)
    v_index: np.ndarray  #: its coordinates in the scene ``v`` (and torque vector), (nv_arm,)
    tip_frame: int  #: frame id of the tip T
    damping: np.ndarray  #: viscous joint damping, (nv_arm,) [N·m·s/rad or N·s/m]
    #: (nv_arm,) where its torques act: a rigid joint's own v index, an elastic joint's motor's
    drive_index: np.ndarray
    #: (m,) its elastic joints (with a motor), as offsets into ``v_index`` (empty: rigid joints only)
    elastic: np.ndarray
    motor_q_index: np.ndarray  #: (m,) each motor's first q index in the scene
    motor_v_index: np.ndarray  #: (m,) each motor's v index in the scene
    motor_damping: np.ndarray  #: (m,) the motors' viscous friction d_m [N·m·s/rad or N·s/m]


@dataclass(frozen=True, eq=False)
class Link:
    """A compiled interconnection: the frames it joins and its element."""

    name: str  #: what readouts and messages call it
    arm: int | None  #: index of the arm in ``scene.arms``; ``None`` for a world fixture
    tip_frame: int  #: T (an arm's tool frame, or a fixture frame on the world)
    grasp_frame: int  #: G (on the object)
    element: Element  #: the law (validated, immutable)
    native: str | None  #: name of the element's C++ twin, or None (the kernel calls its Python evaluate)


STATE_LIMIT = 1e6  #: |q|, |v| beyond this [m, rad, m/s, rad/s] is refused (energies would overflow)


#: the pinocchio.Data a run holds at once (the scene's, the dynamics', the kernel's, a compiled controller's)
DATA_ALIVE = 3


def data_bytes(nv: int) -> float:
    """[bytes] one pinocchio.Data of a model with ``nv`` velocities: its four nv×nv×nv
    second-order derivative tensors (32·nv³) dominate beyond nv ≈ 100."""
    return 32.0 * nv**3 + 400.0 * nv**2


def available_memory() -> float | None:
    """[bytes] memory this machine can still give (Linux's MemAvailable); None where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


MEMORY_SHARE = 0.5  #: the part of the available memory a scene's Pinocchio data may take


def check_memory(nv: int, obj: SceneObject, links_nv: int | None = None) -> None:
    """Refuse, before anything big is allocated, a model whose Pinocchio data would not fit
    (``links_nv``: the links' model's, whose Data the compiled kernel holds too when the scene
    has elastic joints' motors)."""
    need = DATA_ALIVE * data_bytes(nv) + (data_bytes(links_nv) if links_nv is not None else 0.0)
    available = available_memory()
    if available is None:
        return
    have = MEMORY_SHARE * available
    if need <= have:
        return
    fits = next((n for n in range(nv, 0, -1) if DATA_ALIVE * data_bytes(n) <= have), 0)
    hint = obj.memory_hint(nv, fits)
    raise SceneError(
        f"this scene has nv = {nv} velocities: a run holds {DATA_ALIVE} Pinocchio Data of {data_bytes(nv) / 1e9:.3g} GB each "
        f"(four nv×nv×nv tensors), {need / 1e9:.3g} GB in all, more than {MEMORY_SHARE:.0%} of the {available / 1e9:.3g} GB "
        "this machine has available (the run, its results and the machine need the rest). "
        f"At most nv = {fits} fits{hint}"
    )


class Scene:
    """Arms + one rigid object + elastic interconnections, as one Pinocchio model.

    A scene is immutable once built (its attributes cannot be reassigned and its arrays are
    read-only; treat ``model`` as read-only too), and it keeps what it loaded, so each URDF is
    parsed once. States ``(q, v)`` are passed around explicitly; ``pin.Data`` lives in
    :class:`coopdyn.Dynamics`.

    Args:
        arms: the arms (possibly none: an object held by fixtures only); names must be unique.
        obj: the held object: a :class:`~coopdyn.model.body.RigidObject`, an elastic
            :class:`~coopdyn.model.beam.Beam`, or any :class:`~coopdyn.model.objects.SceneObject`.
        interconnections: at least one; each names an arm (an arm may have several) or
            ``None`` for a world fixture.
        gravity: gravity acceleration in the world, (3,) [m/s²].

    Attributes:
        model: the merged ``pin.Model`` (arms in order, then the object's root joint — a beam's
            nodes —, then the elastic joints' motors, if any).
        link_model: ``model`` without the motors (the same as ``model`` for rigid joints): its
            joints, frames and coordinates are the head of ``model``'s.
        arms: one :class:`ArmInfo` per arm. ``links``: one :class:`Link` per interconnection.
        elements: the links, then the object's own elements (a :class:`~coopdyn.model.beam.Beam`'s
            beam elements; none for a rigid object): everything the dynamics evaluate.
        constraints: indices of the links that are rigid grasps (:func:`coopdyn.rigid_limit`).
        arm_specs, interconnection_specs, object: the descriptions the scene was built from.
        loaded_arms: the arms as loaded (:class:`coopdyn.model.arm.LoadedArm`), for display.
        q0, v0: the initial state, (nq,) and (nv,).
        actuated: indices in ``v`` where the arms' torques act, one per arm joint in scene order —
            the joint itself, or for an elastic joint its motor; a controller returns one
            torque/force per entry [N·m or N].
        arm_joints: indices in ``v`` of all arm joints (link side), in scene order.
        joint_springs: the elastic joints' transmissions
            (:class:`~coopdyn.model.elements.joint_spring.JointSprings`; empty for rigid arms).
        actuated_index: the same as a slice when the indices are contiguous (cheaper to index
            with on hot paths), else ``actuated``.
        object_joint: joint id of the object (a beam's reference node); ``object_q``/``object_v``
            its coordinates (all of a beam's nodes).
    """

    model: pin.Model
    link_model: pin.Model
    arms: tuple[ArmInfo, ...]
    links: tuple[Link, ...]
    elements: tuple[Link, ...]
    constraints: tuple[int, ...]
    arm_specs: tuple[Arm, ...]
    interconnection_specs: tuple[Interconnection, ...]
    loaded_arms: tuple[LoadedArm, ...]
    object: SceneObject
    object_joint: int
    object_frame: int
    object_q: np.ndarray
    object_v: np.ndarray
    actuated: np.ndarray
    arm_joints: np.ndarray
    joint_springs: JointSprings
    actuated_index: slice | np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    gravity: np.ndarray

    def __init__(
        self,
        arms: Sequence[Arm],
        obj: SceneObject,
        interconnections: Sequence[Interconnection],
        gravity: Any = (0.0, 0.0, -9.81),
    ) -> None:
        if isinstance(arms, Arm):
            arms = [arms]
        if isinstance(interconnections, Interconnection):
            interconnections = [interconnections]
        for what, value in (("arms", arms), ("interconnections", interconnections)):
            if isinstance(value, str | bytes) or not isinstance(value, Sequence):
                raise SceneError(f"{what} must be a list, got {type(value).__name__}")
        for a in arms:
            if not isinstance(a, Arm):
                raise SceneError(f"arms must be coopdyn.Arm instances, got {type(a).__name__}")
        names = [a.name for a in arms]
        if not all(isinstance(n, str) and n for n in names):
            raise SceneError(f"arm names must be non-empty strings, got {names!r}")
        if len(set(names)) != len(names):
            raise SceneError(f"arm names must be unique, got {names}")
        if not isinstance(obj, SceneObject):
            raise SceneError(
                f"obj must be a coopdyn object (coopdyn.RigidObject, coopdyn.Beam or a SceneObject), got {type(obj).__name__}"
            )
        if not isinstance(obj.name, str) or not obj.name:
            raise SceneError(f"the object's name must be a non-empty string, got {obj.name!r}")
        if obj.name == "universe" or any(obj.name == n or obj.name.startswith(f"{n}/") for n in names):
            raise SceneError(
                f"the object's name {obj.name!r} is taken (by the world frame 'universe' or an arm's frames); rename the object"
            )
        obj.check()
        if len(interconnections) == 0:
            raise SceneError("a scene needs at least one interconnection (arm tip or world fixture ↔ object)")

        loaded = [load_arm(a) for a in arms]
        model = pin.Model()
        model.name = "coopdyn_scene"
        for la in loaded:
            model = pin.appendModel(model, la.model, 0, la.base)
        model.gravity = pin.Motion(np.concatenate([_validate.finite_array(gravity, "gravity", (3,)), np.zeros(3)]))
        _add_armature(model, loaded)

        placed = obj.add_to(model)
        obj_joint, node_joints, q_obj = placed.reference, list(placed.joints), placed.q0

        arm_infos = tuple(_arm_info(model, la, None) for la in loaded)  # (the motors come last: below)
        q0 = np.concatenate([la.q0 for la in loaded] + [q_obj])
        motor_count = _motor_count(loaded)
        check_memory(model.nv + motor_count, obj, model.nv if motor_count else None)
        data = pin.Data(model)  # (createData() copies it once more: twice the peak)
        pin.framesForwardKinematics(model, data, q0)
        o_frame = model.getFrameId(obj.name)
        world_M_object = pin.SE3(data.oMf[o_frame])

        links = []
        # (name, the arm whose tool frame placed the grasp — None when given —, its world position at the start)
        grasp_points: list[tuple[str, str | None, np.ndarray]] = []
        for k, ic in enumerate(interconnections):
            if not isinstance(ic, Interconnection):
                raise SceneError(f"interconnections[{k}] must be a coopdyn.Interconnection, got {type(ic).__name__}")
            if ic.arm is not None and (not isinstance(ic.arm, str) or ic.arm not in names):
                hint = did_you_mean(ic.arm, names) if isinstance(ic.arm, str) else ""
                raise SceneError(
                    f"interconnections[{k}] names arm {ic.arm!r}, which is not in the scene.{hint} "
                    f"Arms: {names} (or arm=None for a world fixture)"
                )
            name = ic.name if ic.name is not None else (ic.arm or "fixture")
            if not isinstance(name, str) or not name:
                raise SceneError(f"interconnections[{k}].name must be a non-empty string, got {name!r}")
            element_type = ic.element_type()
            law = ic.law(f"interconnections[{k}] ({name})")
            if ic.grasp is not None:
                o_M_G = _validate.se3(ic.grasp, f"interconnections[{k}].grasp")
            elif ic.arm is not None:
                o_M_G = world_M_object.actInv(data.oMf[arm_infos[names.index(ic.arm)].tip_frame])
            else:
                o_M_G = pin.SE3.Identity()
            if ic.arm is not None:
                i_arm: int | None = names.index(ic.arm)
                tip = arm_infos[names.index(ic.arm)].tip_frame
                if ic.fixture is not None:
                    raise SceneError(
                        f"interconnections[{k}]: fixture is for arm=None (a world fixture); this one names arm {ic.arm!r}"
                    )
            else:
                i_arm = None
                w_M_T = (
                    world_M_object * o_M_G if ic.fixture is None else _validate.se3(ic.fixture, f"interconnections[{k}].fixture")
                )
                tip = model.addFrame(pin.Frame(f"world/fixture{k}", 0, w_M_T, pin.FrameType.OP_FRAME))
            g_joint, o_M_G = obj.grasp_joint(placed, o_M_G)
            g_id = model.addFrame(pin.Frame(f"{obj.name}/grasp{k}_{name}", g_joint, o_M_G, pin.FrameType.OP_FRAME))
            grasp_points.append((name, None if ic.grasp is not None else ic.arm, (data.oMi[g_joint] * o_M_G).translation))
            links.append(Link(name, i_arm, int(tip), int(g_id), law, element_type.native))
        _warn_far_grasps(obj, model, data, grasp_points)
        link_names = [lk.name for lk in links]
        if len(set(link_names)) != len(link_names):  # an arm with several links: number them
            links = [dataclasses.replace(lk, name=f"{lk.name}{k}") for k, lk in enumerate(links)]

        internal = [
            Link(il.name, None, il.tip_frame, il.grasp_frame, il.element, il.native) for il in obj.internal_links(model, placed)
        ]
        j_first, j_last = model.joints[node_joints[0]], model.joints[node_joints[-1]]
        # The elastic joints' motors come after every other joint and frame: the model without them
        # (`link_model`) reads the head of q and v and has the same joint and frame ids.
        link_model = model.copy()
        motors = _add_motors(model, loaded)
        arm_infos = tuple(_arm_info(model, la, motors) for la in loaded)
        springs = _joint_springs(model, arm_infos, loaded)
        q_motors = np.concatenate([model.joints[j].nq * [0.0] for _, j in motors] + [np.zeros(0)])
        q0 = _motors_at_rest(model, np.concatenate([q0, q_motors]), springs)
        actuated = np.concatenate([a.drive_index for a in arm_infos] + [np.zeros(0, dtype=int)]).astype(int)
        first, n = int(actuated[0]) if actuated.size else 0, actuated.size
        contiguous = n > 0 and np.array_equal(actuated, np.arange(first, first + n))
        set_ = object.__setattr__
        set_(self, "model", model)
        set_(self, "link_model", link_model)
        set_(self, "arms", arm_infos)
        set_(self, "links", tuple(links))
        set_(self, "arm_specs", tuple(arms))
        set_(self, "interconnection_specs", tuple(interconnections))
        set_(self, "loaded_arms", tuple(loaded))
        set_(self, "object", obj)
        set_(self, "object_joint", int(obj_joint))
        set_(self, "object_frame", int(o_frame))
        set_(self, "elements", tuple(links) + tuple(internal))
        set_(self, "constraints", tuple(i for i, lk in enumerate(links) if lk.element.constraint is not None))
        set_(self, "object_q", _frozen(np.arange(j_first.idx_q, j_last.idx_q + j_last.nq)))
        set_(self, "object_v", _frozen(np.arange(j_first.idx_v, j_last.idx_v + j_last.nv)))
        set_(self, "actuated", _frozen(actuated))
        set_(self, "arm_joints", _frozen(np.concatenate([a.v_index for a in arm_infos] + [np.zeros(0, dtype=int)]).astype(int)))
        set_(self, "joint_springs", springs)
        set_(self, "actuated_index", slice(first, first + n) if contiguous else self.actuated)
        set_(self, "q0", _frozen(q0))
        set_(self, "v0", _frozen(np.zeros(model.nv)))
        set_(self, "gravity", _frozen(np.array(model.gravity.linear)))

    def __setattr__(self, name: str, value: Any) -> None:
        raise SceneError(f"a Scene is immutable: build a new one instead of setting {name!r}")

    def __delattr__(self, name: str) -> None:
        raise SceneError(f"a Scene is immutable: cannot delete {name!r}")

    def __reduce__(self) -> Any:
        return (_rebuilt, (self.__dict__,))

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
        if isinstance(arm, bool) or not isinstance(arm, int | np.integer):
            raise SceneError(f"an arm is given by name or index, got {arm!r}")
        if not 0 <= int(arm) < len(self.arms):
            raise SceneError(f"arm index {arm} out of range: the scene has {len(self.arms)} arms")
        return int(arm)

    def coordinates(self) -> tuple[list[str], list[str]]:
        """Names of the entries of ``q`` and ``v``, each with its unit: a revolute joint's
        ``"left/panda_joint1 [rad]"`` and ``"… [rad/s]"``, a free flyer's ``"object.x [m]"`` …
        ``"object.qw [1]"`` (quaternion) and ``"object.vx [m/s; body axes]"`` …
        ``"object.wz [rad/s; body axes]"`` (a free flyer's velocities are in the body's own axes,
        as Pinocchio's ``v``: the names say so)."""
        q_names: list[str] = []
        v_names: list[str] = []
        for i in range(1, self.model.njoints):
            name, joint = self.model.names[i], self.model.joints[i]
            if name.endswith(MOTOR_SUFFIX):  # a motor's θ is in its link joint's units (docs/physics.md)
                joint = self.model.joints[self.model.getJointId(name.removesuffix(MOTOR_SUFFIX))]
            qs, vs = _JOINT_COORDINATES.get(joint.shortname(), (None, None))
            if qs is None or vs is None or len(qs) != joint.nq or len(vs) != joint.nv:
                qs = [(f"[{k}]", "") for k in range(joint.nq)]
                vs = [(f"[{k}]", "") for k in range(joint.nv)]
            q_names += [f"{name}{s} [{u}]" if u else f"{name}{s}" for s, u in qs]
            v_names += [f"{name}{s} [{u}]" if u else f"{name}{s}" for s, u in vs]
        return q_names, v_names

    def check_state(self, q: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
        """Validated copies of a state: shapes, finiteness and normalised quaternions."""
        if (
            type(q) is np.ndarray
            and type(v) is np.ndarray
            and q.dtype == v.dtype == np.float64
            and q.shape == (self.nq,)
            and v.shape == (self.nv,)
            and (not q.size or np.abs(q).max() <= STATE_LIMIT)  # (False for a NaN: the checks below name it)
            and (not v.size or np.abs(v).max() <= STATE_LIMIT)
            and pin.isNormalized(self.model, q, 1e-9)
        ):
            return q.copy(), v.copy()  # the common case, in a few µs less (coopdyn.Simulator's runs)
        q = _validate.finite_array(q, "q (a configuration)", (self.nq,)).copy()
        v = _validate.finite_array(v, "v (a velocity)", (self.nv,)).copy()
        for name, x, unit in (("q", q, "m or rad"), ("v", v, "m/s or rad/s")):
            if x.size and np.max(np.abs(x)) > STATE_LIMIT:
                raise SceneError(f"{name} has an entry of {np.max(np.abs(x)):.3g} [{unit}]; a state is within ±{STATE_LIMIT:g}")
        if not pin.isNormalized(self.model, q, 1e-9):
            raise SceneError("q is not a valid configuration (a quaternion is not of unit norm); use pin.normalize")
        return q, v

    def nonlinearity(self) -> str | None:
        """Why the scene's dynamics are not linear (``None`` when they are: every joint, arms and
        object, prismatic — a constant mass matrix, no Coriolis terms, translations only)."""
        bad = [  # (a motor is a rotor on the world, a fixed axis: a constant inertia, linear like a slider)
            f"{self.model.names[i]} ({j.shortname()})"
            for i, j in enumerate(self.model.joints)
            if i and j.shortname() not in _PRISMATIC and not self.model.names[i].endswith(MOTOR_SUFFIX)
        ]
        if bad:
            listed = ", ".join(bad[:3]) + (f" and {len(bad) - 3} more" if len(bad) > 3 else "")
            what = "the mass matrix or the kinematics configuration-dependent"
            return f"{len(bad)} joints that are not prismatic make {what}: {listed}"
        if any(not lk.element.linear for lk in self.links):
            return "an interconnection element is not linear in the relative translation"
        return None

    def __repr__(self) -> str:
        arms = ", ".join(a.name for a in self.arms)
        obj = f"{self.object.name!r} ({self.object.joint_label})"
        return f"Scene(arms=[{arms}], object={obj}, links={len(self.links)}, nq={self.nq}, nv={self.nv})"


def _warn_far_grasps(
    obj: SceneObject, model: pin.Model, data: pin.Data, grasps: list[tuple[str, str | None, np.ndarray]]
) -> None:
    """Warn (SceneWarning) about each grasp point farther from the object's bounds than the
    object's size (the largest edge of their bounding box), at the start: a grasp defaults to
    the arm's tool frame, so an arm placed away from the object holds it through a long lever
    without a word (a UR5 and a Kinova 0.60 and 0.93 m from a 0.15 m box ran silently)."""
    shapes = obj.bounds(model)
    if not shapes or all(model.joints[s.joint].shortname() in _PRISMATIC for s in shapes):
        return  # (no size said; or an object that only translates: where a force acts does not matter)
    boxes = [(data.oMi[s.joint] * s.placement, np.asarray(s.size, dtype=float) / 2) for s in shapes]
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    corners = np.concatenate([signs * half @ M.rotation.T + M.translation for M, half in boxes])
    size = float(np.ptp(corners, axis=0).max())
    for name, arm, p in grasps:
        gap = min(float(np.linalg.norm(np.maximum(np.abs(M.actInv(p)) - half, 0.0))) for M, half in boxes)
        if gap > size:
            fix = (
                f"the tool frame of arm {arm!r} starts there and the grasp defaults to it: place the arm at the object "
                "(its q0, cd.place_arm, or tool_pose in a scene file) or give the grasp"
                if arm is not None
                else "its grasp is given there: give a grasp on the object"
            )
            warnings.warn(
                f"interconnection {name!r} grasps the object {gap * 1e3:.0f} mm from it, more than its size "
                f"({size * 1e3:.0f} mm): {fix}",
                SceneWarning,
                stacklevel=3,
            )


_REVOLUTE = ([("", "rad")], [("", "rad/s")])
_PRISMATIC_1 = ([("", "m")], [("", "m/s")])
_QUATERNION = [(".qx", "1"), (".qy", "1"), (".qz", "1"), (".qw", "1")]
_ANGULAR = [(".wx", "rad/s; body axes"), (".wy", "rad/s; body axes"), (".wz", "rad/s; body axes")]  # (Pinocchio's v)
#: per Pinocchio joint type: (suffix, unit) of each q entry and of each v entry
_JOINT_COORDINATES: dict[str, tuple[list[tuple[str, str]], list[tuple[str, str]]]] = {
    **{f"JointModel{k}": _REVOLUTE for k in ("RX", "RY", "RZ", "RevoluteUnaligned")},
    **{f"JointModel{k}": _PRISMATIC_1 for k in ("PX", "PY", "PZ", "PrismaticUnaligned")},
    **{
        f"JointModel{k}": ([(".cos", "1"), (".sin", "1")], [("", "rad/s")])
        for k in ("RUBX", "RUBY", "RUBZ", "RevoluteUnboundedUnaligned")
    },
    "JointModelFreeFlyer": (
        [(".x", "m"), (".y", "m"), (".z", "m"), *_QUATERNION],
        [(".vx", "m/s; body axes"), (".vy", "m/s; body axes"), (".vz", "m/s; body axes"), *_ANGULAR],
    ),
    "JointModelPlanar": (
        [(".x", "m"), (".y", "m"), (".cos", "1"), (".sin", "1")],
        [(".vx", "m/s; body axes"), (".vy", "m/s; body axes"), (".wz", "rad/s")],
    ),
    "JointModelSpherical": (_QUATERNION, _ANGULAR),
}

#: Pinocchio joints along which the dynamics stay linear.
_PRISMATIC = {"JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"}


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _rebuilt(state: dict[str, Any]) -> Scene:
    """Unpickle a scene: its state restored without running the builder (no URDF is read)."""
    scene = Scene.__new__(Scene)
    scene.__dict__.update(state)
    return scene


MOTOR_SUFFIX = ".motor"  #: an elastic joint's motor is the joint ``"<arm>/<joint>.motor"``


def _motor_count(loaded: Sequence[LoadedArm]) -> int:
    """How many motors the arms have (their elastic joints of finite stiffness)."""
    return sum(int(np.isfinite(la.elasticity.stiffness).sum()) for la in loaded if la.elasticity is not None)


def _add_motors(model: pin.Model, loaded: Sequence[LoadedArm]) -> list[tuple[str, int]]:
    """A motor joint per elastic joint, arm after arm, after every other joint and frame (in
    place); returns (link joint name, motor joint id) of each."""
    motors = []
    for la in loaded:
        if la.elasticity is None:
            continue
        el = la.elasticity
        for jid, inertia, K in zip(el.joint_ids, el.inertia, el.stiffness, strict=True):
            if math.isinf(K):
                continue  # a rigid transmission: the motor inertia is the joint's armature (_add_armature)
            name = la.model.names[int(jid)]
            link = model.joints[model.getJointId(name)]
            motors.append((name, add_motor(model, name + MOTOR_SUFFIX, float(inertia), bool(continuous(link)))))
    return motors


def _add_armature(model: pin.Model, loaded: Sequence[LoadedArm]) -> None:
    """Each joint with an infinitely stiff transmission carries its motor's inertia as armature
    (in place): the K → ∞ limit of the elastic joint."""
    for la in loaded:
        el = la.elasticity
        if el is None:
            continue
        rigid = np.isinf(el.stiffness)
        for jid, inertia in zip(el.joint_ids[rigid], el.inertia[rigid], strict=True):
            joint = model.joints[model.getJointId(la.model.names[int(jid)])]
            model.armature[joint.idx_v] += inertia


def _arm_info(model: pin.Model, la: LoadedArm, motors: Sequence[tuple[str, int]] | None) -> ArmInfo:
    """Where the arm sits in ``model``; ``motors`` (link joint name, motor joint id) of the
    scene's motors, None before they are added (the arm's joints then act as rigid)."""
    joint_names = tuple(la.model.names[i] for i in range(1, la.model.njoints))
    q_index: list[int] = []
    v_index: list[int] = []
    for name in joint_names:
        j = model.joints[model.getJointId(name)]
        q_index.extend(range(j.idx_q, j.idx_q + j.nq))
        v_index.extend(range(j.idx_v, j.idx_v + j.nv))
    motor_of = dict(motors or [])
    el = la.elasticity if motors is not None else None
    finite = np.zeros(0, dtype=bool) if el is None else np.isfinite(el.stiffness)
    elastic = np.zeros(0, dtype=int) if el is None else el.joints[finite]  # (v offsets within the arm)
    motor_joints = [] if el is None else [model.joints[motor_of[la.model.names[int(j)]]] for j in el.joint_ids[finite]]
    drive = np.array(v_index, dtype=int)
    drive[elastic] = [j.idx_v for j in motor_joints]
    damping = np.array(la.damping, dtype=float)
    if el is not None:  # a rigid transmission's motor friction acts on its joint
        damping[el.joints[np.isinf(el.stiffness)]] += el.motor_damping[np.isinf(el.stiffness)]
    return ArmInfo(
        name=la.spec.name,
        joint_names=joint_names,
        q_index=_frozen(np.array(q_index, dtype=int)),
        v_index=_frozen(np.array(v_index, dtype=int)),
        tip_frame=int(model.getFrameId(la.tip_frame)),
        damping=_frozen(damping),
        drive_index=_frozen(drive),
        elastic=_frozen(np.array(elastic, dtype=int)),
        motor_q_index=_frozen(np.array([j.idx_q for j in motor_joints], dtype=int)),
        motor_v_index=_frozen(np.array([j.idx_v for j in motor_joints], dtype=int)),
        motor_damping=_frozen(np.zeros(0) if el is None else el.motor_damping[np.isfinite(el.stiffness)].copy()),
    )


def _joint_springs(model: pin.Model, arms: Sequence[ArmInfo], loaded: Sequence[LoadedArm]) -> JointSprings:
    """The scene's elastic joints, arm after arm."""
    rows = []
    for info, la in zip(arms, loaded, strict=True):
        if la.elasticity is None:
            continue
        finite = np.isfinite(la.elasticity.stiffness)
        stiffness, damping = la.elasticity.stiffness[finite], la.elasticity.damping[finite]
        for offset, motor_q, motor_v, K, D in zip(
            info.elastic, info.motor_q_index, info.motor_v_index, stiffness, damping, strict=True
        ):
            link = next(model.joints[j] for j in range(1, model.njoints) if model.joints[j].idx_v == info.v_index[offset])
            rows.append((link.idx_q, link.idx_v, motor_q, motor_v, K, D, bool(continuous(link))))
    if not rows:
        return JointSprings.none()
    columns = list(zip(*rows, strict=True))
    link_q, link_v, motor_q, motor_v = (_frozen(np.array(c, dtype=int)) for c in columns[:4])
    return JointSprings(
        link_q=link_q,
        link_v=link_v,
        motor_q=motor_q,
        motor_v=motor_v,
        stiffness=_frozen(np.array(columns[4], dtype=float)),
        damping=_frozen(np.array(columns[5], dtype=float)),
        continuous=_frozen(np.array(columns[6], dtype=bool)),
    )


def _motors_at_rest(model: pin.Model, q0: np.ndarray, springs: JointSprings) -> np.ndarray:
    """``q0`` with each motor where its spring holds its link still against the arms' weight
    (θ = q + K⁻¹ g(q)): the arms start at rest under gravity, as the grasps start undeformed."""
    if not springs.size:
        return q0
    q = motors_at_links(q0, springs)
    g = pin.computeGeneralizedGravity(model, model.createData(), q)
    return turned(model, q, springs.motor_v, g[springs.link_v] / springs.stiffness)
