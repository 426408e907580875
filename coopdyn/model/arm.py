"""Arms: a URDF (or an example-robot-data name), a base pose, a tip frame, locked joints.

An :class:`Arm` is a description only; :func:`load_arm` turns it into a Pinocchio model whose
joint and frame names are prefixed with ``"<arm name>/"`` so that several arms, even of the
same robot, can be merged into one scene model.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import ModelLoadError, SceneError, did_you_mean
from .elastic_joints import JointElasticity, ResolvedElasticity
from .elastic_joints import resolve as resolve_elasticity

#: Tool frames of well-known example-robot-data arms, used when ``tip_frame`` is not given.
DEFAULT_TIP_FRAMES: dict[str, str] = {
    "panda": "panda_hand_tcp",
    "ur3": "tool0",
    "ur5": "tool0",
    "ur10": "tool0",
    "kinova": "j2s6s200_end_effector",
}

#: Joints locked by default for well-known arms ("model no more than a scene needs").
DEFAULT_LOCKED_JOINTS: dict[str, tuple[str, ...]] = {
    "panda": ("panda_finger_joint1", "panda_finger_joint2"),
}


@dataclass(frozen=True, eq=False)
class Arm:
    """One manipulator of the scene.

    Attributes:
        name: unique name of the arm in the scene; its joints and frames are prefixed ``name/``.
        robot: path to a URDF file, or an example-robot-data robot name (``"panda"``, ``"ur5"``).
        tip_frame: frame of the URDF where the interconnection attaches (the tool frame). Known
            robots have a default (Panda: ``panda_hand_tcp``).
        base: pose of the arm's root in the world: ``pin.SE3``, 4x4 matrix or translation [m].
        q0: initial configuration of the unlocked joints, shape (nq_arm,) [rad or m] — a
            continuous joint as its (cos θ, sin θ) pair — or, for an arm with continuous joints,
            one value per joint (nv_arm,) [rad or m], a continuous joint's angle. Default: the
            robot's reference posture (SRDF ``default``) or its neutral configuration.
        locked_joints: joints removed from the model, held at their ``q0``/reference value; a
            mapping gives the value explicitly. ``None`` uses the robot's default (Panda: fingers).
        joint_damping: viscous joint friction ``τ_f = -d q̇`` [N·m·s/rad or N·s/m]: a scalar, one
            value per unlocked joint, or ``"urdf"`` for the URDF ``<dynamics damping>`` values.
        elasticity: elastic joints (:class:`coopdyn.JointElasticity`: a motor coordinate, a motor
            inertia and a transmission spring per joint); default ``None``: rigid joints.
        mass_overrides: mapping ``joint name -> total mass [kg]`` of the body that joint carries;
            that body's spatial inertia is scaled to the new mass (centre of mass kept).
        package_dirs: folders that hold the ROS packages a URDF's ``package://NAME/...`` mesh
            paths name (each folder contains ``NAME/``), for the viewer's meshes. Searched after
            them: the folders of ``ROS_PACKAGE_PATH`` and example-robot-data's models — never
            the URDF's parent folders.
    """

    name: str
    robot: str | os.PathLike[str]
    tip_frame: str | None = None
    base: Any = None
    q0: Any = None
    locked_joints: Sequence[str] | Mapping[str, float] | None = None
    joint_damping: float | Sequence[float] | str = 0.0
    mass_overrides: Mapping[str, float] = field(default_factory=dict)
    package_dirs: Sequence[str | os.PathLike[str]] = ()
    elasticity: JointElasticity | None = None

    def replace(self, **changes: Any) -> Arm:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True, eq=False)
class LoadedArm:
    """An arm turned into a prefixed, reduced Pinocchio model (internal to scene building)."""

    spec: Arm
    model: pin.Model
    q0: np.ndarray
    tip_frame: str
    base: pin.SE3
    damping: np.ndarray
    visual: pin.GeometryModel | None = None  #: display geometry (``load_arm(..., meshes=...)``)
    elasticity: ResolvedElasticity | None = None  #: its elastic joints, if any


def _robot_name(robot: str | os.PathLike[str]) -> str | None:
    text = os.fspath(robot)
    try:
        exists = Path(text).exists()
    except (OSError, ValueError):  # a name no file system takes (too long, NUL): not a file
        exists = False
    if text.endswith(".urdf") or os.sep in text or exists:
        return None
    return text


def package_search_path(extra: Sequence[str | os.PathLike[str]] = ()) -> list[str]:
    """Where ``package://`` paths are looked up: ``extra`` (an arm's ``package_dirs``), then the
    entries of ``ROS_PACKAGE_PATH``, then example-robot-data's model folders."""
    if isinstance(extra, str | bytes) or not isinstance(extra, Sequence):
        raise SceneError(f"package_dirs must be a list of folders, got {_validate._short(extra)}")
    dirs = [os.fspath(_validate.path(p, "package_dirs entry")) for p in extra]
    dirs += [p for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    try:
        from example_robot_data.path import EXAMPLE_ROBOT_DATA_MODEL_DIR

        dirs += [str(Path(EXAMPLE_ROBOT_DATA_MODEL_DIR)), str(Path(EXAMPLE_ROBOT_DATA_MODEL_DIR).parent)]
    except ImportError:
        pass
    return [d for d in dirs if Path(d).is_dir()]


def _load_urdf(
    robot: str | os.PathLike[str], meshes: str | None = None, package_dirs: Sequence[str | os.PathLike[str]] = ()
) -> tuple[pin.Model, np.ndarray | None, pin.GeometryModel | None]:
    """Load the kinematic/inertial model, the reference posture where one exists and, with
    ``meshes`` ("visual" or "collision"), that geometry of the URDF (meshes resolved through
    its package folders)."""
    name = _robot_name(robot)
    if name is None:
        path = _validate.path(robot, "robot (a URDF path)", ModelLoadError)
        if not path.is_file():
            raise ModelLoadError(f"URDF file not found: {path}. Give an existing .urdf path or an example-robot-data name.")
        try:
            model, _ = _parsed(str(path.resolve()), _stamp(path), None)
        except Exception as exc:  # Pinocchio raises plain ValueError/RuntimeError with XML details
            raise ModelLoadError(f"could not parse URDF {path}: {exc}") from exc
        model = model.copy()
        return model, None, _geometry(model, path, package_search_path(package_dirs), meshes) if meshes else None
    try:
        from example_robot_data import robots_loader
    except ImportError as exc:  # pragma: no cover - a dependency of coopdyn
        raise ModelLoadError(
            "loading robots by name needs example-robot-data: pip install example-robot-data example-robot-data-loaders"
        ) from exc
    loader = robots_loader.ROBOTS.get(name)
    if loader is None:
        raise ModelLoadError(
            f"unknown robot {_validate._short(name)}: not a URDF path and not an example-robot-data name."
            + did_you_mean(name, robots_loader.ROBOTS)
        )
    if not loader.urdf_filename:
        raise ModelLoadError(f"example-robot-data robot {name!r} has no URDF (only SDF); give a URDF path instead")
    rel = os.path.join(loader.path, loader.urdf_subpath, loader.urdf_filename)
    root = robots_loader.getModelPath(rel)
    urdf = Path(root, rel)
    srdf = os.path.join(root, loader.path, loader.srdf_subpath, loader.srdf_filename) if loader.srdf_filename else None
    model, q_ref = _parsed(str(urdf), _stamp(urdf), srdf)
    model = model.copy()
    visual = _geometry(model, urdf, [os.path.join(root, "../..")], meshes) if meshes else None
    return model, None if q_ref is None else q_ref.copy(), visual


def _stamp(path: Path) -> tuple[int, int]:
    """(modification time [ns], size [bytes]) of a file: a changed URDF is parsed again."""
    st = path.stat()
    return st.st_mtime_ns, st.st_size


@functools.lru_cache(maxsize=64)
def _parsed(urdf: str, stamp: tuple[int, int], srdf: str | None) -> tuple[pin.Model, np.ndarray | None]:
    """The model of a URDF file and its SRDF ``default`` posture, parsed once per process and file
    version (callers copy the model before changing it)."""
    del stamp  # part of the cache key only
    model = pin.buildModelFromUrdf(urdf)
    q_ref = None
    if srdf is not None:
        pin.loadReferenceConfigurations(model, srdf, False)
        if "default" in model.referenceConfigurations:
            q_ref = np.array(model.referenceConfigurations["default"], dtype=float)
    return model, q_ref


def _geometry(model: pin.Model, path: Path, package_dirs: list[str], meshes: str) -> pin.GeometryModel:
    kinds = {"visual": pin.GeometryType.VISUAL, "collision": pin.GeometryType.COLLISION}
    if meshes not in kinds:
        raise SceneError(f"meshes must be 'visual' or 'collision', got {meshes!r}")
    text = _meshes_in_place(path, package_dirs, meshes)
    try:
        if text is None:
            return pin.buildGeomFromUrdf(model, str(path), kinds[meshes], package_dirs=package_dirs)
        return pin.buildGeomFromUrdfString(model, text, kinds[meshes], package_dirs=package_dirs)
    except Exception as exc:
        raise ModelLoadError(f"could not load the {meshes} geometry of {path}: {exc}") from exc


MESH_SUFFIXES = frozenset({".stl", ".dae", ".obj", ".ply", ".glb", ".gltf"})  #: what a mesh file may be


def _meshes_in_place(urdf: Path, package_dirs: list[str], meshes: str) -> str | None:
    """Before any mesh is read: the URDF's text without the ``meshes`` ("visual" or
    "collision") geometry whose mesh file lies outside the URDF's own folder (its package, the
    folder above, when it sits in a ROS package's ``urdf/`` folder) and the package folders, or
    has an ending no mesh has — each dropped with a warning — or None when every mesh is in
    place. A URDF received from someone else could
    otherwise have any file of this machine read, and embedded in an HTML animation."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError):
        return None  # Pinocchio's parser says what is wrong with it
    folder = urdf.resolve().parent
    package = folder.parent if folder.name in ("urdf", "robots") and folder.parent != folder.parent.parent else folder
    allowed = [package, *(Path(d).resolve() for d in package_dirs)]
    dropped = False
    for link in root.iter("link"):
        for element in list(link.findall(meshes)):
            mesh = element.find("geometry/mesh")
            name = None if mesh is None else mesh.get("filename")
            if not name:
                continue
            where = _mesh_file(name, urdf, package_dirs)
            if where is None or (where.suffix.lower() in MESH_SUFFIXES and any(where.is_relative_to(r) for r in allowed)):
                if where is not None and mesh is not None:
                    mesh.set("filename", str(where))  # absolute: the text is parsed without its folder
                continue
            warnings.warn(
                f"{urdf}: the {meshes} mesh {name} of link {link.get('name')!r} lies outside the URDF's package and the "
                "package folders, or is not a mesh file: not read (give its folder in Arm(package_dirs=...) if you trust it)",
                stacklevel=7,
            )
            link.remove(element)
            dropped = True
    return ET.tostring(root, encoding="unicode") if dropped else None


def _mesh_file(name: str, urdf: Path, package_dirs: list[str]) -> Path | None:
    """The file a URDF's mesh ``filename`` names (None: a package:// path no folder holds)."""
    if name.startswith("package://"):
        rest = name.removeprefix("package://")
        found = next((Path(d) / rest for d in package_dirs if (Path(d) / rest).is_file()), None)
        return found.resolve() if found is not None else None
    path = Path(name.removeprefix("file://"))
    return (path if path.is_absolute() else urdf.parent / path).resolve()


def _joint_id(model: pin.Model, joint: str, what: str) -> int:
    if not model.existJointName(joint):
        names = list(model.names)[1:]
        raise SceneError(f"{what}: no joint named {joint!r}.{did_you_mean(joint, names)} Joints: {names}")
    return int(model.getJointId(joint))


def load_arm(arm: Arm, meshes: str | None = None) -> LoadedArm:
    """Load, reduce, re-inertia and prefix the model of ``arm`` (and, with ``meshes`` =
    "visual" or "collision", that geometry for display)."""
    if not isinstance(arm, Arm):
        raise SceneError(f"expected a coopdyn.Arm, got {type(arm).__name__}")
    if not isinstance(arm.name, str) or not arm.name or "/" in arm.name:
        raise SceneError(f"arm name must be a non-empty string without '/', got {_validate._short(arm.name)}")
    what = f"arm {arm.name!r}"
    if not isinstance(arm.robot, str | os.PathLike) or not os.fspath(arm.robot):
        raise SceneError(f"{what}: robot must be a URDF path or an example-robot-data name, got {_validate._short(arm.robot)}")
    package_search_path(arm.package_dirs)  # (checked here: it is used only when meshes are loaded)
    if arm.tip_frame is not None and not isinstance(arm.tip_frame, str):
        raise SceneError(f"{what}: tip_frame must be a frame name (string), got {_validate._short(arm.tip_frame)}")
    locked_spec = arm.locked_joints
    if locked_spec is not None:
        names = list(locked_spec) if isinstance(locked_spec, Mapping | list | tuple) else None
        if names is None or not all(isinstance(n, str) for n in names):
            raise SceneError(
                f"{what}: locked_joints must be a list of joint names or a mapping name -> value, got {locked_spec!r}"
            )
    if not isinstance(arm.mass_overrides, Mapping) or not all(isinstance(k, str) for k in arm.mass_overrides):
        raise SceneError(f"{what}: mass_overrides must be a mapping joint name -> mass [kg], got {arm.mass_overrides!r}")
    model, q_ref, visual = _load_urdf(arm.robot, meshes, arm.package_dirs)
    if model.nq == 0:
        raise ModelLoadError(f"arm {arm.name!r}: the URDF {arm.robot} has no movable joint")
    q_full = _inside_limits(model, pin.neutral(model)) if q_ref is None else q_ref

    # Locked joints: remove them from the model, held at their value.
    robot_name = _robot_name(arm.robot)
    locked = arm.locked_joints
    if locked is None:
        locked = DEFAULT_LOCKED_JOINTS.get(robot_name or "", ())
    if isinstance(locked, str):
        raise SceneError(f"{what}: locked_joints must be a list of joint names, not a string {locked!r}")
    lock_ids = [_joint_id(model, j, f"{what}, locked_joints") for j in locked]
    repeated = sorted({j for j in locked if list(locked).count(j) > 1})
    if repeated:  # Pinocchio would refuse it with a ValueError
        raise SceneError(f"{what}: locked_joints names {repeated} more than once; name each joint once")
    if isinstance(locked, Mapping):
        q_full = q_full.copy()
        for j, jid in zip(locked, lock_ids, strict=True):
            if model.joints[jid].nq != 1:
                raise SceneError(f"{what}: locked joint {j!r} is not a 1-DOF joint; give it without a value")
            q_full[model.joints[jid].idx_q] = float(_validate.finite_array(locked[j], f"{what}, locked value of {j!r}", ()))
    full_model = model
    if lock_ids and visual is not None:
        model, visual = pin.buildReducedModel(full_model, visual, lock_ids, q_full)
    elif lock_ids:
        model = pin.buildReducedModel(full_model, lock_ids, q_full)
    q_default = _reduced_configuration(full_model, model, q_full)

    # Mass overrides (e.g. a slider of a different mass).
    for joint, mass in arm.mass_overrides.items():
        jid = _joint_id(model, joint, f"{what}, mass_overrides")
        m_new = _validate.positive(mass, f"{what}, mass_overrides[{joint!r}]", "kg")
        inertia = model.inertias[jid]
        if inertia.mass <= 0.0:
            model.inertias[jid] = pin.Inertia(m_new, np.zeros(3), np.zeros((3, 3)))
        else:
            scale = m_new / inertia.mass
            model.inertias[jid] = pin.Inertia(m_new, inertia.lever.copy(), inertia.inertia * scale)

    tip = arm.tip_frame or DEFAULT_TIP_FRAMES.get(robot_name or "")
    if tip is None:
        frames = [f.name for f in model.frames][-5:]
        raise SceneError(
            f"{what}: give tip_frame (the tool frame the interconnection attaches to); last frames of the model: {frames}"
        )
    if not model.existFrame(tip):
        names = [f.name for f in model.frames]
        raise SceneError(f"{what}: no frame named {_validate._short(tip)} in the model.{did_you_mean(tip, names)}")
    if tip == "universe":
        raise SceneError(f"{what}: tip_frame 'universe' is the world frame, not a frame of the arm")

    if arm.q0 is not None:
        q0 = _configuration(model, arm.q0, what)
    else:
        q0 = q_default
    _check_limits(model, q0, what)

    damping = _damping(arm, model, what)
    elasticity = resolve_elasticity(arm.elasticity, model, what, [str(j) for j in locked])
    base = pin.SE3.Identity() if arm.base is None else _validate.se3(arm.base, f"{what}, base")

    # Prefix joint and frame names so that several arms merge into one model.
    for i in range(1, model.njoints):
        model.names[i] = f"{arm.name}/{model.names[i]}"
    for frame in model.frames:
        frame.name = f"{arm.name}/{frame.name}"
    if visual is not None:
        for g in visual.geometryObjects:
            g.name = f"{arm.name}/{g.name}"
    return LoadedArm(
        spec=arm,
        model=model,
        q0=q0,
        tip_frame=f"{arm.name}/{tip}",
        base=base,
        damping=damping,
        visual=visual,
        elasticity=elasticity,
    )


def _configuration(model: pin.Model, value: Any, what: str) -> np.ndarray:
    """An arm's q0 (nq,): given as the configuration (nq values; a continuous joint as its
    (cos θ, sin θ) pair, normalised when rounding left it within 5 % of unit length), or — when
    the arm has continuous joints (nq > nv) — as one value per degree of freedom (nv values, a
    continuous joint's angle θ [rad]), mapped by ``pin.integrate`` from the neutral configuration."""
    shapes = [(model.nq,)] if model.nq == model.nv else [(model.nq,), (model.nv,)]
    q = _validate.finite_array(value, f"{what}, q0", None)
    if q.shape not in shapes:
        per = f"{model.nq} values (the configuration)" + (
            f" or {model.nv} (one per joint, a continuous joint's angle in rad)" if model.nq != model.nv else ""
        )
        raise SceneError(f"{what}, q0 must have {per}, got shape {q.shape}")
    if model.nq != model.nv and q.shape == (model.nv,):
        for j in range(1, model.njoints):  # a continuous joint's angle has no limits to catch degrees
            joint = model.joints[j]
            if joint.nq == 2 and joint.nv == 1:
                _validate.warn_if_degrees(q[joint.idx_v], f"{what}, q0 of the continuous joint {model.names[j]!r}", 4)
        return pin.integrate(model, pin.neutral(model), q)
    q = q.copy()
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq == 2 and joint.nv == 1:  # a continuous joint: (cos θ, sin θ)
            pair = q[joint.idx_q : joint.idx_q + 2]
            norm = float(np.hypot(*pair))
            if abs(norm - 1.0) > 0.05:  # (rounding leaves it near 1; its angle, atan2, is unchanged by normalising)
                raise SceneError(
                    f"{what}, q0: the continuous joint {model.names[j]!r} takes (cos θ, sin θ), a pair of unit length; got "
                    f"({pair[0]:.6g}, {pair[1]:.6g}), of length {norm:.6g}. Give q0 as one angle per joint ({model.nv} values "
                    "[rad]) instead"
                )
            q[joint.idx_q : joint.idx_q + 2] = pair / norm
    return q


def _inside_limits(model: pin.Model, q: np.ndarray) -> np.ndarray:
    """``q`` with every 1-DOF joint outside its finite limits moved to mid-range."""
    q = q.copy()
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for j in model.joints[1:]:
        if j.nq == 1 and j.nv == 1:
            i = j.idx_q
            if lo[i] < hi[i] and np.isfinite(lo[i]) and np.isfinite(hi[i]) and not lo[i] <= q[i] <= hi[i]:
                q[i] = 0.5 * (lo[i] + hi[i])
    return q


def _reduced_configuration(full: pin.Model, reduced: pin.Model, q_full: np.ndarray) -> np.ndarray:
    """The configuration ``q_full`` of ``full`` restricted to the joints kept in ``reduced``."""
    q = np.empty(reduced.nq)
    for jid in range(1, reduced.njoints):
        jf = full.joints[full.getJointId(reduced.names[jid])]
        jr = reduced.joints[jid]
        q[jr.idx_q : jr.idx_q + jr.nq] = q_full[jf.idx_q : jf.idx_q + jf.nq]
    return q


def _check_limits(model: pin.Model, q: np.ndarray, what: str) -> None:
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for jid in range(1, model.njoints):
        j = model.joints[jid]
        if j.nq != 1 or j.nv != 1:
            continue
        i = j.idx_q
        if lo[i] < hi[i] and not (lo[i] - 1e-9 <= q[i] <= hi[i] + 1e-9):
            read_as_degrees = np.radians(q[i])  # [rad]
            hint = (
                f" (in degrees? {q[i]:.6g}° is {read_as_degrees:.6g} rad, within them: q0 is in rad)"
                if abs(q[i]) > 2 * np.pi and lo[i] <= read_as_degrees <= hi[i] and _revolute(j)
                else ""
            )
            raise SceneError(
                f"{what}: q0 of joint {model.names[jid]!r} is {q[i]:.6g}, outside its limits [{lo[i]:.6g}, {hi[i]:.6g}]{hint}"
            )
        if _revolute(j) and not hi[i] - lo[i] <= 4 * np.pi:  # no limits (or ±1.8e308): nothing caught degrees
            _validate.warn_if_degrees(q[i], f"{what}, q0 of joint {model.names[jid]!r}", 4)


def _revolute(joint: pin.JointModel) -> bool:
    """Whether a 1-DOF joint turns (its q an angle [rad]) rather than slides."""
    return joint.shortname().startswith("JointModelR")


def _damping(arm: Arm, model: pin.Model, what: str) -> np.ndarray:
    if isinstance(arm.joint_damping, str):
        if arm.joint_damping != "urdf":
            raise SceneError(f"{what}: joint_damping must be a number, one number per joint or 'urdf', got {arm.joint_damping!r}")
        return np.array(model.damping, dtype=float)
    d = _validate.finite_array(arm.joint_damping, f"{what}, joint_damping")
    if d.ndim == 0:
        d = np.full(model.nv, float(d))
    if d.shape != (model.nv,):
        raise SceneError(
            f"{what}: joint_damping must be a scalar or have {model.nv} entries (one per unlocked joint), got shape {d.shape}"
        )
    if np.any(d < 0.0):
        raise SceneError(f"{what}: joint_damping must be >= 0 [N·m·s/rad], got {d.tolist()}")
    return d
