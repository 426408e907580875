"""Ready-made scenes: the book's linear system and two Pandas holding a box."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from . import _validate
from .arm import Arm
from .body import RigidObject
from .errors import SceneError
from .interconnection import Interconnection, axial, diagonal
from .reference import BookParameters, Drive, Segment
from .resources import urdf_path
from .scene import Scene


def linear_book(**params: Any) -> Scene:
    """The book's linear cooperative system (eq. 45/46) built from URDF sliders.

    Keyword arguments: any of ``m, m1, m2`` [kg], ``c_p, c_k`` [N/m], ``d_p, d_k`` [N·s/m],
    ``s1, s3, Y10, Y20, Y30`` [m], ``g`` [m/s²]; the book's values by default
    (:class:`coopdyn.reference.BookParameters`).

    Arms ``tip1`` and ``tip2`` are 1-DOF prismatic sliders along world z (``urdf/slider_z.urdf``)
    whose joint coordinate is the tip height (Y1, Y3). The object slides along z from height Y20
    (its joint coordinate is Y2 − Y20). Interconnection 0 is the book's p (tip 1 – object),
    1 is k (object – tip 2); both are 1-D springs along z. Read Y1, Y2, Y3 with
    :func:`book_positions`; the book's Fc1, Fc2 are ``result.wrench(0)[:, 2]``, ``result.wrench(1)[:, 2]``.
    """
    p = BookParameters.from_kwargs(**params)
    slider = urdf_path("slider_z.urdf")
    arms = [
        Arm("tip1", slider, tip_frame="tip", q0=[p.Y10], mass_overrides={"slide": p.m1}),
        Arm("tip2", slider, tip_frame="tip", q0=[p.Y30], mass_overrides={"slide": p.m2}),
    ]
    obj = RigidObject(
        mass=p.m,
        inertia=np.eye(3) * 0.1,
        pose=[0.0, 0.0, p.Y20],
        joint="prismatic",
        axis="z",
        name="object",
        size=(0.08, 0.08, 0.04),
    )
    links = [
        Interconnection("tip1", stiffness=axial(p.c_p), damping=axial(p.d_p), grasp=[0.0, 0.0, -p.s1]),
        Interconnection("tip2", stiffness=axial(p.c_k), damping=axial(p.d_k), grasp=[0.0, 0.0, p.s3]),
    ]
    return Scene(arms, obj, links, gravity=[0.0, 0.0, -p.g])


def book_positions(q: np.ndarray, scene: Scene) -> np.ndarray:
    """Heights Y1, Y2, Y3 (n, 3) [m] of the linear book scene's configurations q (n, nq)."""
    q = np.atleast_2d(q)
    Y20 = float(_validate.se3(scene.object.pose, "object pose").translation[2])
    return np.stack([q[:, scene.arms[0].q_index[0]], Y20 + q[:, scene.object_q[0]], q[:, scene.arms[1].q_index[0]]], axis=1)


def book_task(
    params: BookParameters | None = None,
    *,
    squeeze: float = 100.0,
    t_grip: float = 0.5,
    lift: float = 0.1,
    t_lift: float = 1.0,
    lift_duration: float = 1.0,
    amplitude: float = 0.02,
    frequency: float = 2.0,
    t_oscillate: float = 2.0,
) -> tuple[Drive, Drive]:
    """Open-loop drives τ1, τ2 [N] that grip, lift and oscillate the object (book Fig. 11).

    * from 0: both tips carry their own weight and half the object's; the squeeze (internal
      force) ramps to ``squeeze`` [N] over ``t_grip`` [s] (τ1 up, τ2 down);
    * from ``t_lift`` [s]: an acceleration ``a(s) = A sin(2π s / T)`` over ``T = lift_duration``
      [s] raises the object by ``lift`` [m] and stops it;
    * from ``t_oscillate`` [s]: half a period of ``a(s) = ½ X ω² sin(ω s)`` brings the object to
      the velocity X ω, then ``a(s) = −X ω² sin(ω s)`` makes it oscillate with amplitude
      ``X = amplitude`` [m] at ``frequency`` [Hz] (ω = 2π·frequency).

    Each tip carries the inertial force of its own mass and half the object's. Every drive is
    continuous in time (no force jumps), so fixed-step methods keep their order.
    """
    p = params or BookParameters()
    if not 0.0 < t_grip <= t_lift and t_lift + lift_duration <= t_oscillate:
        raise ValueError("book_task needs 0 < t_grip <= t_lift and t_lift + lift_duration <= t_oscillate")
    A_lift = 2.0 * np.pi * lift / lift_duration**2
    w_lift = 2.0 * np.pi / lift_duration
    w_osc = 2.0 * np.pi * frequency
    A_osc = amplitude * w_osc**2

    def drive(mass_share: float, weight: float, sign: float) -> Drive:
        hold = weight + sign * squeeze
        segments = [
            Segment(0.0, weight, sign * squeeze / t_grip),
            Segment(t_grip, hold),
            Segment(t_lift, hold, 0.0, mass_share * A_lift, w_lift, 0.0),
            Segment(t_oscillate, hold, 0.0, 0.5 * mass_share * A_osc, w_osc, 0.0),
            Segment(t_oscillate + np.pi / w_osc, hold, 0.0, mass_share * A_osc, w_osc, np.pi),
        ]
        if t_grip == t_lift:
            del segments[1]
        if t_lift + lift_duration < t_oscillate:
            segments.insert(-2, Segment(t_lift + lift_duration, hold))
        return Drive(segments)

    share1, share2 = p.m1 + p.m / 2, p.m2 + p.m / 2
    return drive(share1, share1 * p.g, 1.0), drive(share2, share2 * p.g, -1.0)


def drives_controller(*drives: Drive) -> Callable[[float, np.ndarray, np.ndarray], np.ndarray]:
    """A controller applying open-loop drives, one per arm joint: ``τ_i = drive_i(t)``."""

    def controller(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.array([d(t) for d in drives])

    return controller


#: Default (base separation [m], box height [m]) of :func:`facing_arms` per robot: poses
#: where the tool reaches the box horizontally within the joint limits.
PLACEMENT: dict[str | None, tuple[float, float]] = {"panda": (1.2, 0.7), "ur5": (1.0, 0.5), "kinova": (1.2, 0.6)}


def facing_arms(
    robot: str = "panda",
    *,
    box_mass: float = 2.0,
    box_size: Any = (0.2, 0.2, 0.2),
    separation: float | None = None,
    height: float | None = None,
    stiffness: float = 1e4,
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
        stiffness: translational interconnection stiffness k [N/m]; rotational = ratio·k [N·m/rad].
        rotational_ratio: rotational/translational stiffness ratio [m²/rad].
        damping: interconnection damping as a ratio of stiffness [s] (D = damping·K).
        joint_damping: viscous joint damping of both arms (see :class:`coopdyn.Arm`).
        gravity: (3,) [m/s²].
        n_arms: number of arms, ≥ 1.
        tip_frame: tool frame of the robot (default: the robot's known tool frame).
    """
    from .ik import solve_ik

    if isinstance(n_arms, bool) or not isinstance(n_arms, int) or n_arms < 1:
        raise SceneError(f"n_arms must be an integer >= 1, got {n_arms!r}")

    name = robot if isinstance(robot, str) and robot in PLACEMENT else None
    default_sep, default_h = PLACEMENT[name] if name else (1.2, 0.7)
    h = float(_validate.finite_array(default_h if height is None else height, "height", ()))
    box = RigidObject.box(box_mass, box_size, pose=[0.0, 0.0, h])
    half = float(np.asarray(box_size, dtype=float)[1]) / 2.0
    sep = _validate.positive(default_sep if separation is None else separation, "separation", "m")
    K = diagonal(stiffness, rotational_ratio * stiffness)
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
    return Scene(arms, box, links, gravity=gravity)


def object_start(scene: Scene) -> np.ndarray:
    """Initial world position of the scene's object frame (3,) [m] — the start of a task."""
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    return data.oMf[scene.object_frame].translation.copy()
