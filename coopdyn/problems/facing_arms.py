"""Identical arms facing each other around a box (the two-Panda demo scene and its N-arm variant)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from ..model.arm import Arm
from ..model.body import RigidObject
from ..model.elements.beam import Section
from ..model.interconnection import Interconnection, diagonal
from ..model.scene import Scene

#: Default (base separation [m], box height [m]) of :func:`facing_arms` per robot: poses
#: where the tool reaches the box horizontally within the joint limits.
PLACEMENT: dict[str | None, tuple[float, float]] = {"panda": (1.2, 0.7), "ur5": (1.0, 0.5), "kinova": (1.2, 0.6)}


MAX_ARMS = 16  #: more arms than this do not fit around a box (and would take minutes to build)


def facing_arms(
    robot: str = "panda",
    *,
    box_mass: float = 2.0,
    box_size: Any = (0.2, 0.2, 0.2),
    separation: float | None = None,
    height: float | None = None,
    stiffness: float | Sequence[float] = 1e4,
    rotational_ratio: float = 0.01,
    damping: float = 0.0,
    joint_damping: float | str = 0.0,
    gravity: Any = (0.0, 0.0, -9.81),
    n_arms: int = 2,
    tip_frame: str | None = None,
) -> Scene:
    """Identical arms facing each other around a box, gripping it with their tools.

    Two arms (the default) stand at y = ∓separation/2 (``left`` at −, ``right`` at +), looking at
    the world origin; N arms (``arm0`` … ``armN-1``) stand on the circle of diameter
    ``separation`` at angles −90° + k·360°/N. Inverse kinematics (one solution, reused by
    symmetry) puts each tool on the circle of radius size_y/2 around the box centre — for two
    arms the box faces y = ±size_y/2 — approach axis (tool z) pointing at the centre, at
    ``height`` [m]. The interconnections are unloaded at the initial state; the scene is
    symmetric (mirror for two arms, N-fold rotation otherwise).

    Args:
        robot: example-robot-data name or URDF path of both arms.
        box_mass: mass of the box [kg].
        box_size: edge lengths (x, y, z) of the box [m]; the tools touch its faces y = ±size_y/2.
        separation: distance between the arm bases [m]; default per robot (:data:`PLACEMENT`).
        height: height of the box centre [m]; default per robot.
        stiffness: translational interconnection stiffness k [N/m]: one value, or three along the
            tool frame's x, y, z (z: the approach axis); rotational = ratio·k [N·m/rad] per axis.
        rotational_ratio: rotational/translational stiffness ratio [m²/rad].
        damping: interconnection damping as a ratio of stiffness [s] (D = damping·K).
        joint_damping: viscous joint damping of both arms (see :class:`coopdyn.Arm`).
        gravity: (3,) [m/s²].
        n_arms: number of arms, ≥ 1.
        tip_frame: tool frame of the robot (default: the robot's known tool frame).
    """
    arms, box, links, _ = _facing(
        robot, box_mass, box_size, separation, height, stiffness, rotational_ratio, damping, joint_damping, n_arms, tip_frame
    )
    return Scene(arms, box, links, gravity=gravity)


def _facing(
    robot: str,
    box_mass: float,
    box_size: Any,
    separation: float | None,
    height: float | None,
    stiffness: float | Sequence[float],
    rotational_ratio: float,
    damping: float,
    joint_damping: float | str,
    n_arms: int,
    tip_frame: str | None,
) -> tuple[list[Arm], RigidObject, list[Interconnection], float]:
    """What :func:`facing_arms` builds its scene from: the arms, the box, the interconnections,
    and the height of the box's centre [m]."""
    from ..model.ik import solve_ik

    if isinstance(n_arms, bool) or not isinstance(n_arms, int) or not 1 <= n_arms <= MAX_ARMS:
        raise SceneError(f"n_arms must be an integer from 1 to {MAX_ARMS} (arms around one box), got {n_arms!r}")

    name = robot if isinstance(robot, str) and robot in PLACEMENT else None
    default_sep, default_h = PLACEMENT[name] if name else (1.2, 0.7)
    h = float(_validate.finite_array(default_h if height is None else height, "height", ()))
    box = RigidObject.box(box_mass, box_size, pose=[0.0, 0.0, h])
    half = float(np.asarray(box_size, dtype=float)[1]) / 2.0
    sep = _validate.positive(default_sep if separation is None else separation, "separation", "m")
    k_xyz = _validate.finite_array(stiffness, "stiffness [N/m]")
    if k_xyz.shape not in ((), (3,)) or not np.all(k_xyz > 0.0):
        raise SceneError(f"stiffness must be one positive value or three (x, y, z of the tool frame) [N/m], got {k_xyz.tolist()}")
    k_rot = _validate.non_negative(rotational_ratio, "rotational_ratio", "m²/rad") * k_xyz
    K = diagonal(k_xyz.tolist(), k_rot.tolist())
    D = _validate.non_negative(damping, "damping", "s") * K
    # In each base frame: tool at distance sep/2 − half ahead, approach (tool z) along base x, tool x up.
    R_tool = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    local_target = pin.SE3(R_tool, np.array([sep / 2 - half, 0.0, h]))
    names = ["left", "right"] if n_arms == 2 else [f"arm{k}" for k in range(n_arms)]
    bases = []
    for k in range(n_arms):
        angle = -np.pi / 2 + 2 * np.pi * k / n_arms  # where the base stands, seen from the box
        position = np.array([np.cos(angle), np.sin(angle), 0.0]) * sep / 2
        bases.append(pin.SE3(pin.utils.rotate("z", angle + np.pi), position))  # base x looks at the box
    template = Arm(names[0], robot, base=bases[0], tip_frame=tip_frame, joint_damping=joint_damping)
    q0 = solve_ik(template, bases[0] * local_target)
    arms = [template.replace(name=n, base=b, q0=q0) for n, b in zip(names, bases, strict=True)]
    links = [Interconnection(a.name, stiffness=K, damping=D) for a in arms]
    return arms, box, links, h


def object_start(scene: Scene) -> np.ndarray:
    """Initial world position of the scene's object frame (3,) [m] — the start of a task."""
    if not isinstance(scene, Scene):
        raise SceneError(f"object_start needs a coopdyn.Scene, got {type(scene).__name__}")
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    return data.oMf[scene.object_frame].translation.copy()


def aluminium_strip() -> Section:
    """The strips the beam scenes hold by default: 30 × 3 mm aluminium (E = 70 GPa, 2700 kg/m³),
    flat, so that laid along world y it bends in the vertical plane."""
    return Section.rectangle(0.03, 0.003, E=70e9, rho=2700.0)


def held_beam(
    robot: str = "panda",
    *,
    length: float = 0.8,
    section: Section | None = None,
    n_elements: int = 8,
    beam_damping: float = 1e-4,
    stiffness: float = 1e4,
    rotational_ratio: float = 0.01,
    damping: float = 0.0,
    gravity: Any = (0.0, 0.0, -9.81),
) -> Scene:
    """Two arms facing each other holding a flexible beam by its ends (:func:`facing_arms` with
    the box replaced by a :class:`~coopdyn.model.beam.Beam` along world y).

    Args:
        robot: as in :func:`facing_arms`; the bases stand ``length + 0.8`` m apart.
        length: beam length [m]. section: default a 30 × 3 mm aluminium strip (E = 70 GPa,
            2700 kg/m³), flat: it bends in the vertical plane (first free–free mode ≈ 24 Hz).
        n_elements: beam elements. beam_damping: stiffness-proportional β [s].
        stiffness, rotational_ratio, damping, gravity: the grasps, as in :func:`facing_arms`.
    """
    from ..model.beam import Beam

    section = aluminium_strip() if section is None else section
    length = _validate.positive(length, "length", "m")
    # the arms and grasps of facing_arms around a box of the beam's size, without building that scene
    arms, _, links, h = _facing(
        robot, 1.0, (0.03, length, 0.003), length + 0.8, None, stiffness, rotational_ratio, damping, 0.0, 2, None
    )
    beam = Beam(
        length, section, n_elements, pose=pin.SE3(pin.utils.rotate("z", np.pi / 2), np.array([0.0, 0.0, h])), damping=beam_damping
    )
    return Scene(arms, beam, links, gravity=gravity)
