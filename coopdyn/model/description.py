"""A scene as plain data — numbers, strings, lists and tables — and back.

:func:`describe` turns any :class:`~coopdyn.model.scene.Scene` into such a description (what a
saved :class:`coopdyn.Result` carries, so that it reloads with readouts) and :func:`build` turns
one back into the scene; scene files (:mod:`coopdyn.io.scenefile`) hold the same tables:

* ``gravity`` — (3,) [m/s²];
* ``arms`` — one table per arm: the fields of :class:`~coopdyn.model.arm.Arm`;
* ``object`` — ``type = "box"`` (mass, edge lengths), ``"rigid"`` (mass, inertia) or ``"beam"``
  (:class:`~coopdyn.model.beam.Beam` with its section);
* ``interconnections`` — one table per element: the fields of
  :class:`~coopdyn.model.interconnection.Interconnection`.

:data:`ARM`, :data:`OBJECT`, :data:`SECTION` and :data:`INTERCONNECTION` list every key with
its kind of value and meaning: the checks here and the scene file's JSON Schema
(:mod:`coopdyn.io.schema`) are both made from them. A pose is a translation ``[x, y, z]`` [m],
a 4x4 homogeneous matrix, or a table ``{translation = [...], rotation = 3x3 | rpy = [r, p, y]
[rad] | quaternion = [x, y, z, w]}``. Relative file paths (a URDF, package folders) are read
against ``base`` (a scene file's folder); :func:`describe` writes absolute ones.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError, did_you_mean
from .arm import Arm, _robot_name, load_arm
from .elastic_joints import JointElasticity
from .elements import ELEMENTS, Section, lookup
from .fields import Field, numbers, pose_data
from .ik import place_arm
from .interconnection import Interconnection
from .object_types import description_types
from .objects import SceneObject
from .scene import Scene

#: kinds of value, and what each accepts (the schema's wording)
KINDS = {
    "string": "a string",
    "number": "a number",
    "integer": "an integer",
    "boolean": "true or false",
    "vector3": "3 numbers",
    "axis": "'x', 'y', 'z' or 3 numbers",
    "vector": "a list of numbers",
    "pose": "a translation [x, y, z], a 4x4 matrix or {translation, rotation | rpy | quaternion}",
    "matrix": "a number, a list of numbers (a diagonal) or a square matrix (list of rows)",
    "names": "a list of joint names, or a table joint name = value",
    "joint_damping": "a number, one number per joint, or 'urdf'",
    "masses": "a table joint name = mass",
    "parameters": "a table: parameter name = number (the element's own parameters, with their units)",
    "paths": "a list of folder paths",
    "section": "a table: shape = 'rectangle' | 'circle' with its dimensions, or the section's properties",
    "per_joint": 'a number, or one number per elastic joint (a stiffness may be inf or "inf")',
    "joint_names": "a list of joint names",
    "elasticity": "a table: stiffness, motor_inertia (required), damping, gear_ratio, motor_damping, joints",
}

GRAVITY = Field("vector3", "gravity acceleration in the world [m/s²]; default [0, 0, -9.81]")

ARM: dict[str, Field] = {
    "name": Field("string", "unique name of the arm; its joints and frames are prefixed 'name/'", True),
    "robot": Field(
        "string", "an example-robot-data name (panda, ur5, kinova, …) or a URDF path (relative to the scene file)", True
    ),
    "tip_frame": Field("string", "the tool frame the interconnection attaches to (known robots have a default)"),
    "base": Field("pose", "pose of the arm's root in the world [m]"),
    "q0": Field("vector", "initial configuration of the unlocked joints [rad or m]; default: the reference posture"),
    "tool_pose": Field(
        "pose",
        "world pose the tool frame starts at [m], reached by inverse kinematics within the joint limits (instead of q0)",
    ),
    "locked_joints": Field("names", "joints removed from the model and held at a value; default: the robot's (Panda: fingers)"),
    "joint_damping": Field("joint_damping", "viscous joint friction [N·m·s/rad or N·s/m]; default 0"),
    "mass_overrides": Field("masses", "joint name = total mass [kg] of the body the joint carries"),
    "package_dirs": Field("paths", "folders holding the ROS packages a URDF's package:// mesh paths name"),
    "elasticity": Field("elasticity", "elastic joints: a motor, a motor inertia and a spring per joint; default: rigid"),
}

#: an arm's ``elasticity`` keys (coopdyn.JointElasticity)
ELASTICITY: dict[str, Field] = {
    "stiffness": Field(
        "per_joint", "K, the transmission's spring [N·m/rad or N/m]; inf: rigid, the motor inertia as armature", True
    ),
    "motor_inertia": Field("per_joint", "the rotor's inertia [kg·m² or kg]: reflected B, or J_m with gear_ratio", True),
    "damping": Field("per_joint", "D, the transmission's damping [N·m·s/rad or N·s/m]; default 0"),
    "gear_ratio": Field("per_joint", "n: B = n² motor_inertia; default 1"),
    "motor_damping": Field("per_joint", "the motor's viscous friction [N·m·s/rad], reflected like motor_inertia; default 0"),
    "joints": Field("joint_names", "the elastic joints (URDF names); default: every unlocked joint"),
}

#: ``[object]`` keys, per ``type`` (each object class declares its own: object_types.OBJECTS)
OBJECT: dict[str, dict[str, Field]] = {name: fields for name, (_, fields) in description_types().items()}

#: a beam's ``section`` keys, per ``shape`` ("properties": the section given by its properties)
SECTION: dict[str, dict[str, Field]] = {
    "rectangle": {
        "width": Field("number", "along y [m]", True),
        "height": Field("number", "along z [m]", True),
        "E": Field("number", "Young's modulus [Pa]", True),
        "rho": Field("number", "density [kg/m³]", True),
        "nu": Field("number", "Poisson's ratio; default 0.3"),
        "timoshenko": Field("boolean", "shear deformation (Timoshenko); default false"),
    },
    "circle": {
        "diameter": Field("number", "[m]", True),
        "E": Field("number", "Young's modulus [Pa]", True),
        "rho": Field("number", "density [kg/m³]", True),
        "nu": Field("number", "Poisson's ratio; default 0.3"),
        "timoshenko": Field("boolean", "shear deformation (Timoshenko); default false"),
    },
    "properties": {
        **{k: Field("number", d, True) for k, d in (("E", "[Pa]"), ("G", "shear modulus [Pa]"), ("rho", "[kg/m³]"))},
        **{k: Field("number", d, True) for k, d in (("A", "[m²]"), ("Iy", "[m⁴]"), ("Iz", "[m⁴]"), ("J", "[m⁴]"))},
        "shear_factor": Field("number", "Timoshenko's κ; absent: Euler–Bernoulli"),
    },
}

INTERCONNECTION: dict[str, Field] = {
    "arm": Field("string", "the arm whose tip frame is T; absent: a world fixture"),
    "stiffness": Field(
        "matrix",
        "K in tip-frame axes, order x, y, z, rx, ry, rz: a number, 6 numbers (a diagonal) or 6x6 [N/m, N·m/rad]; "
        "ball: a number, 3 numbers or 3x3 [N/m]",
        True,
    ),
    "damping": Field("matrix", "D, same shape as the stiffness [N·s/m, N·m·s/rad]; default none"),
    "grasp": Field("pose", "pose of the grasp frame G in the object frame [m]; default: the tip's initial pose"),
    "element": Field("string", "the element kind; default 'se3'"),
    "fixture": Field("pose", "without arm: the pose of T in the world [m]; default: G's initial pose"),
    "name": Field("string", "what readouts and messages call it; default the arm's name"),
    "parameters": Field(
        "parameters", "the element's own parameters beyond stiffness and damping, e.g. hardening = 1e7 [N/m³]; default none"
    ),
}

TABLES = ("gravity", "arms", "object", "interconnections")


class Location(NamedTuple):
    """Where in a description a value sits: a table, the entry's index in a list of tables, a key."""

    table: str
    entry: int | None = None
    key: str | None = None

    def __str__(self) -> str:
        where = self.table + (f"[{self.entry}]" if self.entry is not None else "")
        return where + (f".{self.key}" if self.key else "")


class DescriptionError(SceneError):
    """A scene description is invalid at :attr:`location` (see :class:`Location`)."""

    def __init__(self, message: str, location: Location) -> None:
        super().__init__(f"{location}: {message}")
        self.location = location
        self.reason = message


# -- describe --------------------------------------------------------------------------------------


def describe(scene: Scene) -> dict[str, Any]:
    """The description of ``scene``: plain data that :func:`build` turns back into the same
    scene (same model, initial state and elements)."""
    if not isinstance(scene, Scene):
        raise SceneError(f"describe needs a coopdyn.Scene, got {type(scene).__name__}")
    return {
        "gravity": scene.gravity.tolist(),
        "arms": [_describe_arm(a) for a in scene.arm_specs],
        "object": scene.object.describe(),
        "interconnections": [_describe_link(ic) for ic in scene.interconnection_specs],
    }


def _matrix(value: Any, name: str) -> Any:
    """A stiffness or damping as data: a diagonal matrix as its diagonal (the same element)."""
    arr = _validate.finite_array(value, name)
    if arr.ndim == 2 and arr.shape[0] == arr.shape[1] and np.array_equal(arr, np.diag(np.diag(arr))):
        return np.diag(arr).tolist()
    return arr.tolist()


def _describe_arm(arm: Arm) -> dict[str, Any]:
    robot = os.fspath(arm.robot)
    out: dict[str, Any] = {"name": arm.name, "robot": robot if _robot_name(robot) else str(Path(robot).resolve())}
    if arm.tip_frame is not None:
        out["tip_frame"] = arm.tip_frame
    if arm.base is not None:
        out["base"] = pose_data(arm.base, f"arm {arm.name!r}: base")
    if arm.q0 is not None:
        out["q0"] = numbers(arm.q0, f"arm {arm.name!r}: q0")
    if isinstance(arm.locked_joints, Mapping):
        out["locked_joints"] = {str(k): float(v) for k, v in arm.locked_joints.items()}
    elif arm.locked_joints is not None:
        out["locked_joints"] = [str(j) for j in arm.locked_joints]
    damping = arm.joint_damping
    out["joint_damping"] = damping if isinstance(damping, str) else numbers(damping, f"arm {arm.name!r}: joint_damping")
    if arm.mass_overrides:
        out["mass_overrides"] = {str(k): float(v) for k, v in arm.mass_overrides.items()}
    if arm.package_dirs:
        out["package_dirs"] = [str(Path(p).resolve()) for p in arm.package_dirs]
    if arm.elasticity is not None:
        el, what = arm.elasticity, f"arm {arm.name!r}: elasticity"
        out["elasticity"] = {
            key: numbers(getattr(el, key), f"{what}.{key}") for key in ("motor_inertia", "damping", "gear_ratio", "motor_damping")
        }
        stiffness = np.asarray(el.stiffness, dtype=float)  # (+inf, a rigid transmission: "inf", which JSON can hold)
        finite = numbers(np.where(np.isposinf(stiffness), 1.0, stiffness), f"{what}.stiffness")
        rigid = np.isposinf(stiffness)
        if stiffness.ndim == 0:
            out["elasticity"]["stiffness"] = "inf" if rigid else finite
        else:
            out["elasticity"]["stiffness"] = ["inf" if r else x for r, x in zip(rigid, finite, strict=True)]
        if el.joints is not None:
            out["elasticity"]["joints"] = [str(j) for j in el.joints]
    return out


def _describe_link(ic: Interconnection) -> dict[str, Any]:
    what = f"interconnection {ic.name or ic.arm or 'fixture'!r}"
    kind = ic.element_type()
    out: dict[str, Any] = {}
    if ic.arm is not None:
        out["arm"] = ic.arm
    out["element"] = kind.python.kind
    try:
        out["stiffness"] = _matrix(ic.stiffness, f"{what}: stiffness")
        if ic.damping is not None:
            out["damping"] = _matrix(ic.damping, f"{what}: damping")
    except SceneError as exc:
        raise SceneError(f"{what}: its parameters are not numbers, so it cannot be described as data ({exc})") from None
    for key in ("grasp", "fixture"):
        if getattr(ic, key) is not None:
            out[key] = pose_data(getattr(ic, key), f"{what}: {key}")
    if ic.name is not None:
        out["name"] = ic.name
    values = ic.law(what).parameter_values()  # the element's own parameters, by its declared names
    if values:
        out["parameters"] = values
    return out


# -- build -----------------------------------------------------------------------------------------


def build(doc: Mapping[str, Any], base: str | os.PathLike[str] | None = None) -> Scene:
    """The scene a description (see the module docstring) describes; relative paths are read
    against ``base`` (default: the working folder).

    Raises:
        DescriptionError: a key or value is invalid; its ``location`` says where.
    """
    if not isinstance(doc, Mapping):
        raise SceneError(f"a scene description is a table (dict), got {type(doc).__name__}")
    for key in doc:
        if key not in TABLES:
            raise DescriptionError(f"unknown key; valid: {list(TABLES)}{did_you_mean(str(key), TABLES)}", Location(str(key)))
    folder = Path(base) if base is not None else Path.cwd()
    gravity = _value("vector3", doc.get("gravity", [0.0, 0.0, -9.81]), Location("gravity"))
    arms = [_build_arm(entry, folder, k) for k, entry in enumerate(_tables(doc.get("arms", []), "arms"))]
    names = [a.name for a in arms]
    for k, name in enumerate(names):
        if name in names[:k]:
            raise DescriptionError(
                f"arm names must be unique; arms[{names.index(name)}] is named {name!r} too", Location("arms", k, "name")
            )
    if "object" not in doc:
        types = ", ".join(repr(t) for t in description_types())
        raise DescriptionError(f"missing: the held object (a table with type = one of {types})", Location("object"))
    obj = _build_object(doc["object"])
    entries = _tables(doc.get("interconnections", []), "interconnections")
    if not entries:
        raise DescriptionError("at least one is needed (arm tip or world fixture ↔ object)", Location("interconnections"))
    links = [_build_link(entry, k, [a.name for a in arms]) for k, entry in enumerate(entries)]
    return Scene(arms, obj, links, gravity=gravity)


def _tables(value: Any, table: str) -> list[Mapping[str, Any]]:
    if not isinstance(value, list | tuple) or not all(isinstance(v, Mapping) for v in value):
        raise DescriptionError(f"must be a list of tables ([[{table}]] in TOML), got {_validate._short(value)}", Location(table))
    return list(value)


def _keys(
    entry: Mapping[str, Any], fields: Mapping[str, Field], where: Location, extra: tuple[str, ...] = (), prefix: str = ""
) -> None:
    """Refuse unknown and missing keys (``prefix``: a sub-table's name and a dot, in the location)."""
    for key in entry:
        if key not in fields and key not in extra:
            valid = sorted([*fields, *extra])
            message = f"unknown key; valid keys: {valid}.{did_you_mean(str(key), valid)}"
            raise DescriptionError(message, where._replace(key=f"{prefix}{key}"))
    missing = [k for k, f in fields.items() if f.required and k not in entry]
    if missing:
        raise DescriptionError(f"missing required key(s) {missing}", where)


def _values(entry: Mapping[str, Any], fields: Mapping[str, Field], where: Location, prefix: str = "") -> dict[str, Any]:
    return {k: _value(fields[k].kind, v, where._replace(key=f"{prefix}{k}")) for k, v in entry.items() if k in fields}


def _value(kind: str, value: Any, where: Location) -> Any:
    """``value`` checked as a ``kind`` and converted (arrays, poses)."""

    def bad(expected: str | None = None) -> DescriptionError:
        return DescriptionError(f"must be {expected or KINDS[kind]}, got {_validate._short(value)}", where)

    if kind == "string":
        if not isinstance(value, str) or not value:
            raise bad("a non-empty string")
        return value
    if kind == "boolean":
        if not isinstance(value, bool):
            raise bad()
        return value
    if kind == "integer":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad()
        return value
    if kind == "paths":
        if not isinstance(value, list) or not all(isinstance(p, str) and p for p in value):
            raise bad()
        return value
    if kind == "masses":
        if not isinstance(value, Mapping) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in value.values()
        ):
            raise bad()
        return dict(value)
    if kind == "parameters":
        if not isinstance(value, Mapping) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value.values()
        ):
            raise bad()
        return {str(k): float(v) for k, v in value.items()}
    if kind == "names":
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            return value
        if isinstance(value, Mapping) and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value.values()):
            return dict(value)
        raise bad()
    if kind == "axis" and isinstance(value, str):
        if value not in ("x", "y", "z"):
            raise bad()
        return value
    if kind == "joint_damping" and isinstance(value, str):
        if value != "urdf":
            raise bad()
        return value
    if kind == "section":
        return _section(value, where)
    if kind == "elasticity":
        return _elasticity(value, where)
    if kind == "per_joint":  # (JointElasticity checks the values; a stiffness may be +inf, "inf" in JSON)

        def number(v: Any) -> bool:
            return (isinstance(v, int | float) and not isinstance(v, bool)) or v == "inf"

        if isinstance(value, list) and all(number(v) for v in value):
            return [math.inf if v == "inf" else v for v in value]
        if number(value):
            return math.inf if value == "inf" else value
        raise bad()
    if kind == "joint_names":
        if isinstance(value, list) and value and all(isinstance(v, str) for v in value):
            return value
        raise bad()
    try:
        if kind == "pose":
            return _pose(value, str(where))
        arr = _validate.finite_array(value, str(where))
    except SceneError as exc:  # the check's own words, without the name it was given (the location says it)
        raise DescriptionError(str(exc).removeprefix(str(where)).lstrip(":. "), where) from None
    shapes: dict[str, list[tuple[int, ...]]] = {
        "number": [()],
        "vector3": [(3,)],
        "axis": [(3,)],
        "vector": [(arr.size,)],
        "joint_damping": [(), (arr.size,)],
    }
    if kind in shapes and arr.shape not in shapes[kind]:
        raise bad()
    if kind == "matrix" and not (arr.ndim <= 1 or (arr.ndim == 2 and arr.shape[0] == arr.shape[1])):
        raise bad()
    return float(arr) if arr.ndim == 0 else arr


def _pose(value: Any, name: str) -> pin.SE3:
    if not isinstance(value, Mapping):
        shape = _validate.finite_array(value, name).shape
        if shape not in ((3,), (4, 4)):
            raise SceneError(f"{name} must be {KINDS['pose']}, got shape {shape}")
        return _validate.se3(value, name)
    for key in value:
        if key not in ("translation", "rotation", "rpy", "quaternion"):
            raise SceneError(f"unknown key {key!r}; a pose table has translation and one of rotation, rpy, quaternion")
    given = [k for k in ("rotation", "rpy", "quaternion") if k in value]
    if len(given) > 1:
        raise SceneError(f"give one of rotation, rpy and quaternion, not {given}")
    p = _validate.finite_array(value.get("translation", [0.0, 0.0, 0.0]), f"{name}.translation", (3,))
    R = np.eye(3)
    if given == ["rpy"]:
        rpy = _validate.finite_array(value["rpy"], f"{name}.rpy [rad]", (3,))
        _validate.warn_if_degrees(rpy, f"{name}.rpy")
        R = pin.rpy.rpyToMatrix(*rpy)
    elif given == ["quaternion"]:
        x = _validate.finite_array(value["quaternion"], f"{name}.quaternion (x, y, z, w)", (4,))
        if not abs(np.linalg.norm(x) - 1.0) < 1e-6:
            raise SceneError(f"{name}.quaternion must have unit norm, got norm {np.linalg.norm(x):.6g}")
        R = pin.Quaternion(x[3], x[0], x[1], x[2]).normalized().matrix()
    elif given == ["rotation"]:
        R = _validate.finite_array(value["rotation"], f"{name}.rotation", (3, 3))
    return _validate.se3(pin.SE3(np.eye(3), p) if given == [] else _homogeneous(R, p), name)


def _homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, p
    return M


def _section(value: Any, where: Location) -> Section:
    if not isinstance(value, Mapping):
        raise DescriptionError(f"must be {KINDS['section']}, got {_validate._short(value)}", where)
    entry = dict(value)
    shape = entry.pop("shape", "properties")
    if not isinstance(shape, str) or shape not in SECTION:
        raise DescriptionError(f"shape must be one of {sorted(SECTION)}, got {shape!r}", where)
    _keys(entry, SECTION[shape], where)
    kwargs = _values(entry, SECTION[shape], where)
    try:
        if shape == "properties":
            return Section(**kwargs)
        return Section.rectangle(**kwargs) if shape == "rectangle" else Section.circle(**kwargs)
    except SceneError as exc:
        raise DescriptionError(str(exc), where) from None


def _elasticity(value: Any, where: Location) -> JointElasticity:
    if not isinstance(value, Mapping):
        raise DescriptionError(f"must be {KINDS['elasticity']}, got {_validate._short(value)}", where)
    _keys(value, ELASTICITY, where, prefix="elasticity.")
    return JointElasticity(**_values(value, ELASTICITY, where, prefix="elasticity."))


def _build_arm(entry: Mapping[str, Any], folder: Path, k: int) -> Arm:
    where = Location("arms", k)
    _keys(entry, ARM, where)
    kwargs = _values(entry, ARM, where)
    robot = kwargs["robot"]
    try:
        _validate.path(robot, "a URDF path or an example-robot-data name")
    except SceneError as exc:
        raise DescriptionError(str(exc), where._replace(key="robot")) from None
    if _robot_name(robot) is None or (folder / robot).is_file():
        kwargs["robot"] = str((folder / robot).resolve()) if not Path(robot).is_absolute() else robot
    if "package_dirs" in kwargs:
        kwargs["package_dirs"] = [str((folder / p).resolve()) for p in kwargs["package_dirs"]]
    tool_pose = kwargs.pop("tool_pose", None)
    if tool_pose is not None and "q0" in kwargs:
        raise DescriptionError("give q0 or tool_pose (placed by inverse kinematics), not both", where._replace(key="tool_pose"))
    arm = Arm(**kwargs)
    try:
        load_arm(arm)  # checked here, where a message can say which entry (URDFs are parsed once)
    except SceneError as exc:
        raise DescriptionError(str(exc), where) from None
    if tool_pose is not None:
        try:
            arm = place_arm(arm, tool_pose)
        except SceneError as exc:
            hint = f"{exc} (check the pose, the base and the tip_frame)"
            raise DescriptionError(hint, where._replace(key="tool_pose")) from None
    return arm


def _build_object(entry: Any) -> SceneObject:
    where = Location("object")
    if not isinstance(entry, Mapping):
        raise DescriptionError(f"must be a table, got {_validate._short(entry)}", where)
    kind = entry.get("type")
    types = description_types()
    if not isinstance(kind, str) or kind not in types:
        raise DescriptionError(f"type must be one of {sorted(types)}, got {kind!r}", where._replace(key="type"))
    cls, fields = types[kind]
    entry = {k: v for k, v in entry.items() if k != "type"}
    _keys(entry, fields, where)
    kwargs = _values(entry, fields, where)
    try:
        return cls.from_description(kind, kwargs)
    except SceneError as exc:
        raise DescriptionError(str(exc), where) from None


def _build_link(entry: Mapping[str, Any], k: int, arms: list[str]) -> Interconnection:
    where = Location("interconnections", k)
    _keys(entry, INTERCONNECTION, where)
    kwargs = _values(entry, INTERCONNECTION, where)
    kind = kwargs.pop("element", "se3")
    if kind not in ELEMENTS:
        raise DescriptionError(f"unknown element; registered: {sorted(ELEMENTS)}", where._replace(key="element"))
    arm = kwargs.pop("arm", None)
    if arm is not None and arm not in arms:
        raise DescriptionError(f"no arm named {arm!r}.{did_you_mean(arm, arms)} Arms: {arms}", where._replace(key="arm"))
    ic = Interconnection(arm, element=kind, **kwargs)
    try:
        lookup(kind)
        ic.law(f"the {kind} element")
    except SceneError as exc:
        raise DescriptionError(str(exc), where) from None
    return ic
