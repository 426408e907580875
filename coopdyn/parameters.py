"""Named physical parameters of a scene — grasp stiffness and damping entries, where the grasps
sit on the object, the object's mass — and the scene with other values: what
:mod:`coopdyn.sensitivity` differentiates with respect to and :func:`coopdyn.identify` fits.

A name is ``"<interconnection>.<kind>"`` or ``"object.mass"`` (:func:`parameters` says which
kinds); :func:`with_parameters` rebuilds the scene with new values, its grasps kept where they were
but a grasp position it names.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from . import _validate
from .errors import SceneError
from .model.elements.ball_spring import BallSpring
from .model.elements.hardening_spring import HardeningSpring
from .model.elements.se3_spring import SE3Spring
from .model.scene import Scene

__all__ = ["KINDS", "Parameter", "parameters", "with_parameters"]

AXES = ("x", "y", "z", "rx", "ry", "rz")


def _kinds() -> dict[str, tuple[str, tuple[int, ...], str, str]]:
    """A parameter's kind → (the element's matrix, its diagonal indices, unit, what it is)."""
    out: dict[str, tuple[str, tuple[int, ...], str, str]] = {}
    for m, matrix, units in (("k", "stiffness", ("N/m", "N·m/rad")), ("d", "damping", ("N·s/m", "N·m·s/rad"))):
        out[f"{m}_linear"] = (matrix, (0, 1, 2), units[0], f"translational {matrix} (x, y, z alike)")
        out[f"{m}_angular"] = (matrix, (3, 4, 5), units[1], f"rotational {matrix} (rx, ry, rz alike)")
        for j, axis in enumerate(AXES):
            out[f"{m}_{axis}"] = (matrix, (j,), units[j // 3], f"{matrix} along {axis}")
    for j, axis in enumerate(AXES[:3]):
        out[f"grasp_{axis}"] = ("grasp", (j,), "m", f"the grasp frame's position along the object frame's {axis}")
    return out


#: a parameter's kind → (the element's matrix, its diagonal indices, unit, what it is)
KINDS = _kinds()
#: the element laws whose wrench is linear in K and in D (the hardening spring's κ term has no K);
#: exactly these classes: a subclass may change the law
_LINEAR_IN_KD = (SE3Spring, HardeningSpring, BallSpring)


@dataclass(frozen=True)
class Parameter:
    """A named physical parameter of a scene (see :func:`parameters`)."""

    name: str  #: e.g. ``"left.k_linear"`` or ``"object.mass"``
    value: float  #: its value in the scene [unit]
    unit: str  #: e.g. ``"N/m"``
    link: int | None  #: the interconnection's index in ``scene.links``; None for the object's mass
    kind: str  #: a key of :data:`KINDS` (``k_linear``, ``d_x``, ``grasp_z``, …) or ``mass``

    @property
    def position(self) -> bool:
        """Whether it is a grasp position [m] (any sign; the others are ≥ 0)."""
        return KINDS.get(self.kind, ("",))[0] == "grasp"


def _names_help(scene: Scene) -> str:
    links = ", ".join(f"'{lk.name}.<kind>'" for lk in scene.links)
    return f"{links} (kinds: {', '.join(KINDS)}), 'object.mass'"


def _entries(element: Any, kind: str) -> np.ndarray:
    """The sub-block of the element's K or D that the kind names."""
    matrix, idx, _, _ = KINDS[kind]
    return np.asarray(element.K if matrix == "stiffness" else element.D)[np.ix_(idx, idx)]


def parameters(scene: Scene, names: Sequence[str]) -> tuple[Parameter, ...]:
    """The scene's parameters named ``"<interconnection>.<kind>"`` or ``"object.mass"``, checked.

    A kind names diagonal entries of the element's K or D (its own axes: :class:`coopdyn.Interconnection`):
    ``k_x``, ``k_y``, ``k_z`` [N/m], ``k_rx``, ``k_ry``, ``k_rz`` [N·m/rad], and ``d_…`` alike
    [N·s/m, N·m·s/rad], one entry each; or ``k_linear``, ``k_angular``, ``d_linear``,
    ``d_angular``: one value for the three entries of a block, which must then be k·I₃ (isotropic).
    The other entries stay as they are. A ball spring has the translational ones only.
    ``grasp_x``, ``grasp_y``, ``grasp_z`` [m]: where the grasp frame G sits on a rigid object, its
    position along the object frame's axes (its orientation kept; any element law).
    ``object.mass`` [kg] is a rigid object's mass, its rotational inertia scaled with it (the same
    shape, a different density).

    Raises:
        SceneError: an unknown name, a repeated one, an element whose law is not linear in K and D
            (a beam, a user's law) for a stiffness or damping, a block that is not isotropic, or a
            grasp position on an elastic object (its grasps ride on nodes).
    """
    if not isinstance(scene, Scene):
        raise SceneError(f"parameters: scene must be a coopdyn.Scene, got {type(scene).__name__}")
    if isinstance(names, str) or not isinstance(names, Sequence) or not names:
        raise SceneError(f"parameters must be a non-empty list of names such as {_names_help(scene)}, got {names!r}")
    out = []
    links = {lk.name: i for i, lk in enumerate(scene.links)}
    for name in names:
        if not isinstance(name, str) or "." not in name:
            raise SceneError(f"parameter {name!r}: a name is '<interconnection>.<kind>' or 'object.mass': {_names_help(scene)}")
        owner, kind = name.rsplit(".", 1)  # (an interconnection's own name may hold a dot)
        if name == "object.mass":
            if scene.object.with_mass(1.0) is None:
                raise SceneError(
                    f"parameter 'object.mass': the object is a {type(scene.object).__name__}, not one body on one joint "
                    "(a RigidObject): its mass is not one parameter"
                )
            out.append(Parameter(name, float(scene.object.mass_and_com()[0]), "kg", None, "mass"))
            continue
        if owner not in links or kind not in KINDS:
            raise SceneError(f"unknown parameter {name!r}; this scene has {_names_help(scene)}")
        i = links[owner]
        element = scene.links[i].element
        if KINDS[kind][0] == "grasp":
            if scene.object.with_mass(1.0) is None:  # (not one body on one joint: the protocol's answer)
                raise SceneError(
                    f"parameter {name!r}: the object is a {type(scene.object).__name__}; a grasp position is a parameter "
                    "on a rigid object only (on an elastic one the grasp rides on its nearest node)"
                )
            out.append(Parameter(name, float(grasp_pose(scene, i).translation[KINDS[kind][1][0]]), "m", i, kind))
            continue
        if type(element) not in _LINEAR_IN_KD:  # (a subclass may change the law: not known to be linear)
            raise SceneError(
                f"parameter {name!r}: the {type(element).__name__} law is not known to be linear in its stiffness and damping; "
                "parameters are offered for the se3, ball and hardening elements"
            )
        if isinstance(element, BallSpring) and max(KINDS[kind][1]) > 2:
            raise SceneError(f"parameter {name!r}: a ball spring has no rotational stiffness or damping")
        B = _entries(element, kind)
        k = float(B[0, 0])
        if np.max(np.abs(B - k * np.eye(len(B)))) > 1e-12 * max(abs(k), 1e-300):
            raise SceneError(
                f"parameter {name!r}: the {KINDS[kind][3]} block of {owner!r} is not isotropic (k·I₃): "
                f"diagonal {np.diag(B).tolist()}; fit its entries one by one ({kind[0]}_x, {kind[0]}_y, …) instead"
            )
        out.append(Parameter(name, k, KINDS[kind][2], i, kind))
    if len({p.name for p in out}) != len(out):
        raise SceneError(f"parameters: a name is repeated in {list(names)}")
    entries: dict[tuple[int, str, int], str] = {}
    for p in out:
        if p.link is None:
            continue
        matrix, idx, _, _ = KINDS[p.kind]
        for i in idx:
            other = entries.setdefault((p.link, matrix, i), p.name)
            if other != p.name:
                raise SceneError(f"parameters: {other!r} and {p.name!r} both set entry {AXES[i]} of that {matrix}; keep one")
    return tuple(out)


def with_parameters(scene: Scene, values: Mapping[str, float]) -> Scene:
    """A new scene, equal to ``scene`` but for the named parameters' values (see :func:`parameters`).

    The grasps (but a named grasp position), the start state and everything else are kept; a grasp
    that was placed at an arm's tool (``grasp=None``) is kept where it was.
    """
    names = list(values)
    params = parameters(scene, names)
    specs = list(scene.interconnection_specs)
    obj = scene.object
    matrices: dict[int, dict[str, np.ndarray]] = {}  # link → its new K and D
    grasps: dict[int, pin.SE3] = {}  # link → its grasp frame moved on the object
    for p in params:
        if p.kind == "mass":
            changed = obj.with_mass(_validate.positive(values[p.name], "parameter 'object.mass'", "kg"))
            assert changed is not None  # (parameters() checked it)
            obj = changed
            continue
        assert p.link is not None
        element: Any = scene.links[p.link].element
        matrix, idx, _, _ = KINDS[p.kind]
        if matrix == "grasp":
            moved = grasps.setdefault(p.link, grasp_pose(scene, p.link).copy())
            position = moved.translation.copy()
            position[idx[0]] = _validate.number(values[p.name], f"parameter {p.name!r}", p.unit, SceneError)
            moved.translation = position
            continue
        value = _validate.non_negative(values[p.name], f"parameter {p.name!r}", p.unit)
        current = matrices.setdefault(p.link, {"stiffness": np.array(element.K, float), "damping": np.array(element.D, float)})
        current[matrix][np.ix_(idx, idx)] = value * np.eye(len(idx))
    for i in sorted(set(matrices) | set(grasps)):
        spec = specs[i]
        grasp = grasps.get(i, spec.grasp if spec.grasp is not None else grasp_pose(scene, i))
        new = matrices.get(i, {"stiffness": spec.stiffness, "damping": spec.damping})
        fixture = spec.fixture
        if spec.arm is None and fixture is None:  # (a fixture placed at G's start: kept there when G moves)
            fixture = _world_pose(scene, scene.links[i].tip_frame)
        specs[i] = dataclasses.replace(spec, grasp=grasp, stiffness=new["stiffness"], damping=new["damping"], fixture=fixture)
    return Scene(list(scene.arm_specs), obj, specs, scene.gravity)


def _start(scene: Scene) -> pin.Data:
    """The scene's kinematics at its start (the frames' world poses in ``oMf``)."""
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    return data


def _world_pose(scene: Scene, frame: int) -> pin.SE3:
    """A frame's world pose at the scene's start."""
    return _start(scene).oMf[frame].copy()


def grasp_pose(scene: Scene, link: int) -> pin.SE3:
    """The pose of link's grasp frame in the object frame, at the scene's start (as the scene
    placed it; on an elastic object the grasp rides on a node, the pose is the same at rest)."""
    data = _start(scene)
    return data.oMf[scene.object_frame].actInv(data.oMf[scene.links[link].grasp_frame])
