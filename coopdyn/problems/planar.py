"""Two planar three-link arms carrying a flexible beam: the benchmark scenario of cooperative
handling of flexible objects (two 3R arms in a vertical plane, the beam's ends in their hands,
moved along a trajectory while its vibration is suppressed)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from ..model.arm import Arm
from ..model.elements import Section
from ..model.interconnection import Interconnection, diagonal
from ..model.scene import Scene
from ..resources import urdf_path
from .facing_arms import aluminium_strip

if TYPE_CHECKING:
    from ..result import Result

#: link lengths of urdf/planar_3r.urdf [m]
LINKS = (0.4, 0.4, 0.2)


def planar_ik(y: float, z: float, direction: float, elbow_back: bool = True) -> np.ndarray:
    """Joint angles (3,) [rad] of urdf/planar_3r.urdf that put its tool frame at (y, z) [m] in the
    base's y–z plane with the tool's z axis at ``direction`` [rad] (a joint angle θ turns a link
    pointing up, +z, towards −y: its direction is (−sin θ, cos θ)). ``elbow_back``: the elbow on
    the side away from +y. Raises SceneError when the point is out of reach."""
    l1, l2, l3 = LINKS
    wy, wz = y + l3 * math.sin(direction), z - l3 * math.cos(direction)  # the wrist
    X, Y = wz, -wy  # planar coordinates in which a link at angle θ points at (cos θ, sin θ)
    c2 = (X * X + Y * Y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    if not -1.0 <= c2 <= 1.0:
        raise SceneError(
            f"planar_ik: the wrist at ({wy:.3g}, {wz:.3g}) m is {math.hypot(wy, wz):.3g} m from the base, out of the arm's "
            f"reach ({abs(l1 - l2):g} to {l1 + l2:g} m): bring the tool nearer (a smaller reach or height)"
        )
    best = None
    for sign in (1.0, -1.0):
        t2 = sign * math.acos(c2)
        t1 = math.atan2(Y, X) - math.atan2(l2 * math.sin(t2), l1 + l2 * math.cos(t2))
        elbow_y = -l1 * math.sin(t1)
        if best is None or (elbow_y < best[0]) == elbow_back:
            best = (elbow_y, t1, t2)
    assert best is not None
    _, t1, t2 = best
    return np.array([t1, t2, direction - t1 - t2])


def planar_arms_beam(
    *,
    length: float = 1.0,
    section: Section | None = None,
    n_elements: int = 8,
    beam_damping: float = 1e-4,
    height: float = 0.5,
    reach: float = 0.35,
    stiffness: float = 1e5,
    rotational_ratio: float = 0.01,
    damping: float = 0.002,
    joint_damping: float = 0.5,
    gravity: Any = (0.0, 0.0, -9.81),
) -> Scene:
    """Two planar three-link arms (``urdf/planar_3r.urdf``, ``left`` at y < 0 and ``right`` at
    y > 0, both moving in the world's y–z plane) hold a flexible beam along world y by its ends,
    their tools pointing along the beam, at ``height`` [m].

    Args:
        length: beam length [m]. section: default a 30 × 3 mm aluminium strip (E = 70 GPa,
            2700 kg/m³), flat: it bends in the arms' plane. n_elements: beam elements.
            beam_damping: stiffness-proportional β [s].
        height: the beam's height [m]; reach: each tool's horizontal distance from its arm's
            base [m] (the bases stand ``length + 2·reach`` apart).
        stiffness: translational grasp stiffness k [N/m]; rotational = ``rotational_ratio``·k
            [N·m/rad]; damping: D = damping·K [s].
        joint_damping: the arms' viscous joint friction [N·m·s/rad].
        gravity: [m/s²].
    """
    from ..model.beam import Beam

    section = aluminium_strip() if section is None else section
    length = _validate.positive(length, "length", "m")
    height = _validate.number(height, "height", "m")
    reach = _validate.positive(reach, "reach", "m")
    k = _validate.positive(stiffness, "stiffness", "N/m")
    ratio = _validate.positive(rotational_ratio, "rotational_ratio", "m²/rad")
    d = _validate.non_negative(damping, "damping", "s")
    q0 = planar_ik(reach, height, -math.pi / 2)  # the tool along the base's +y, towards the beam
    urdf = str(urdf_path("planar_3r.urdf"))
    half = 0.5 * length + reach
    arms = [
        Arm("left", urdf, tip_frame="tip", base=[0.0, -half, 0.0], q0=q0, joint_damping=joint_damping),
        Arm("right", urdf, tip_frame="tip", base=pin.SE3(pin.utils.rotate("z", math.pi), np.array([0.0, half, 0.0])), q0=q0,
            joint_damping=joint_damping),
    ]  # fmt: skip
    K = diagonal(k, ratio * k)
    links = [Interconnection(arm.name, stiffness=K, damping=d * K if d > 0 else None) for arm in arms]
    beam = Beam(length, section, n_elements, pose=pin.SE3(pin.utils.rotate("z", math.pi / 2), np.array([0.0, 0.0, height])),
                damping=beam_damping)  # fmt: skip
    return Scene(arms, beam, links, gravity=gravity)


def midspan_deflection(result: Result) -> np.ndarray:
    """A beam's mid-span deflection (n,) [m] along a run (a :class:`coopdyn.Result` of a scene
    holding a :class:`~coopdyn.Beam`): how far its reference (middle) node lies below the chord
    between its end nodes, along world z (negative: above the chord)."""
    beam = result.scene.object
    n, middle_node = getattr(beam, "n_elements", None), getattr(beam, "reference_node", None)  # (a Beam's)
    if not isinstance(n, int) or not isinstance(middle_node, int):
        raise SceneError(f"midspan_deflection needs a run of a scene holding a Beam, not a {type(beam).__name__}")
    ends = [result.frame_position(f"{beam.name}/node{k}") for k in (0, n)]
    middle = result.frame_position(f"{beam.name}/node{middle_node}")
    return np.asarray(0.5 * (ends[0][:, 2] + ends[1][:, 2]) - middle[:, 2])
