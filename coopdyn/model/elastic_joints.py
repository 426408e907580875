"""Elastic joints: a motor coordinate, a motor inertia and a spring per joint (Spong's reduced model).

An arm's joint with elasticity gets a motor angle θ (link side: the motor's own angle divided by
the gear ratio) beside its link angle q::

    M(q) q̈ + h(q, q̇) = K (θ − q) + D (θ̇ − q̇) + Jᵀ f        (link side)
    B θ̈ + K (θ − q) + D (θ̇ − q̇) = τ_m − d_m θ̇              (motor side)

with B the motor inertia reflected through the gear (n² J_m), K the transmission's stiffness, D
its damping and d_m the motor's viscous friction. The reduced model keeps the motor's kinetic
energy of its own rotation only (½ B θ̇²; the gyroscopic coupling with the links is left out,
which is exact up to O(1/n) for high gear ratios). The arm's torques act on θ.

In the merged model each motor is one more 1-DOF joint on the world, carrying a body that has
only the rotor's inertia about its axis (no mass: gravity does not act on it); its coordinates
sit last, after the object's (docs/physics.md, "Elastic joints").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError, did_you_mean
from .elements.joint_spring import JointSprings


@dataclass(frozen=True, eq=False)
class JointElasticity:
    """The elastic transmissions of an arm (``Arm(..., elasticity=JointElasticity(...))``).

    Each numeric field is a scalar (every elastic joint) or one value per elastic joint, in the
    order of ``joints`` (default: the arm's joint order). For a prismatic joint read N/m for
    N·m/rad, kg for kg·m², N·s/m for N·m·s/rad.

    Attributes:
        stiffness: K, the transmission's spring [N·m/rad], > 0; ``math.inf`` makes that joint
            rigid with the motor inertia as armature (no motor coordinate: the K → ∞ limit).
        motor_inertia: the rotor's inertia [kg·m²], > 0: reflected to the joint (B) when
            ``gear_ratio`` is 1, else the motor-side J_m, and B = n² J_m.
        damping: D, the transmission's viscous damping on θ̇ − q̇ [N·m·s/rad], ≥ 0. Default 0.
        gear_ratio: n (≥ 1 in magnitude), only to reflect ``motor_inertia`` and ``motor_damping``;
            the motor coordinate θ is always on the joint side (θ − q is the spring's deflection).
        motor_damping: the motor's viscous friction d_m [N·m·s/rad] on θ̇, given like
            ``motor_inertia`` (motor side when ``gear_ratio`` ≠ 1: reflected as n² d_m). Default 0.
        joints: the joints that are elastic (names as in the URDF, without the arm prefix);
            default: every unlocked joint of the arm.
    """

    stiffness: float | Sequence[float]
    motor_inertia: float | Sequence[float]
    damping: float | Sequence[float] = 0.0
    gear_ratio: float | Sequence[float] = 1.0
    motor_damping: float | Sequence[float] = 0.0
    joints: Sequence[str] | None = None


@dataclass(frozen=True, eq=False)
class ResolvedElasticity:
    """An arm's elasticity checked against its model: one entry per elastic joint."""

    joint_ids: np.ndarray  #: (m,) the elastic joints' ids in the arm's model, in its joint order
    joints: np.ndarray  #: (m,) their velocity indices within the arm (offsets into ``ArmInfo.v_index``)
    stiffness: np.ndarray  #: (m,) K [N·m/rad or N/m] (inf: rigid, B as armature)
    damping: np.ndarray  #: (m,) D [N·m·s/rad or N·s/m]
    inertia: np.ndarray  #: (m,) B, reflected [kg·m² or kg]
    motor_damping: np.ndarray  #: (m,) d_m, reflected [N·m·s/rad or N·s/m]


#: Pinocchio joints a motor can drive through a spring, each mapped to whether it is continuous:
#: one coordinate (revolute, prismatic: False) or a continuous joint's (cos, sin) pair (True).
_DRIVABLE = {
    **dict.fromkeys(("RX", "RY", "RZ", "RevoluteUnaligned", "PX", "PY", "PZ", "PrismaticUnaligned"), False),
    **dict.fromkeys(("RUBX", "RUBY", "RUBZ", "RevoluteUnboundedUnaligned"), True),
}


def continuous(joint: pin.JointModel) -> bool | None:
    """Whether a joint a motor can drive is continuous (q a (cos, sin) pair): True or False; None
    for a joint no motor drives (a free flyer, a planar joint, …)."""
    return _DRIVABLE.get(joint.shortname().removeprefix("JointModel"))


#: a finite transmission stiffness above this [N·m/rad or N/m] is refused: its spring force would
#: overflow or its mode outrun any step; math.inf is the rigid limit
MAX_STIFFNESS = 1e12


def resolve(spec: Any, model: pin.Model, what: str, locked: Sequence[str] = ()) -> ResolvedElasticity | None:
    """Check an arm's ``elasticity`` against its (reduced, unprefixed) model, whose ``locked``
    joints were removed."""
    if spec is None:
        return None
    if not isinstance(spec, JointElasticity):
        raise SceneError(f"{what}: elasticity must be a coopdyn.JointElasticity, got {_validate._short(spec)}")
    names = [model.names[j] for j in range(1, model.njoints)]
    if spec.joints is None:
        chosen = list(range(len(names)))
    else:
        if isinstance(spec.joints, str) or not isinstance(spec.joints, Sequence) or not spec.joints:
            raise SceneError(
                f"{what}: elasticity.joints must be a non-empty list of joint names, got {_validate._short(spec.joints)}"
            )
        chosen = []
        for name in spec.joints:
            if name in locked:
                raise SceneError(f"{what}: elasticity.joints names {name!r}, a locked joint (removed from the model)")
            if name not in names:
                hint = did_you_mean(name, names) if isinstance(name, str) else ""
                raise SceneError(
                    f"{what}: elasticity.joints names {_validate._short(name)}, not a joint of the arm.{hint} Joints: {names}"
                )
            if names.index(name) in chosen:
                raise SceneError(f"{what}: elasticity.joints names {name!r} twice")
            chosen.append(names.index(name))
    for k in chosen:
        joint = model.joints[k + 1]
        if continuous(joint) is None or joint.nv != 1:
            raise SceneError(
                f"{what}: joint {names[k]!r} ({joint.shortname()}) cannot be elastic: a motor drives a revolute, "
                "prismatic or continuous joint"
            )
    n = len(chosen)
    turning = [continuous(model.joints[k + 1]) or model.joints[k + 1].shortname().startswith("JointModelR") for k in chosen]
    rotary = all(turning)
    linear = not any(turning)

    def unit(rotational: str, translational: str) -> str:
        return rotational if rotary else translational if linear else f"{rotational} or {translational}"

    def per_joint(value: Any, field: str, unit: str, positive: bool, infinite: bool = False) -> np.ndarray:
        name = f"{what}, elasticity.{field} [{unit}]"
        rigid: Any = False  # (stiffness: its +inf entries, a rigid joint each)
        if infinite and not isinstance(value, str | bytes | bool):
            try:
                given = np.asarray(value)
                if given.dtype.kind == "f":  # (text, booleans and the rest: finite_array names what is wrong)
                    rigid, value = np.isposinf(given), np.where(np.isposinf(given), 1.0, given)
            except (TypeError, ValueError, OverflowError):
                pass
        x = _validate.finite_array(value, name)
        if x.ndim == 0:
            x, rigid = np.full(n, float(x)), np.full(n, bool(rigid))
        if x.shape != (n,):
            raise SceneError(
                f"{what}: elasticity.{field} must be a scalar or have {n} entries (one per elastic joint, in the order of "
                f"joints), got shape {x.shape}"
            )
        if np.any(x <= 0.0) if positive else np.any(x < 0.0):
            raise SceneError(f"{what}: elasticity.{field} must be {'> 0' if positive else '>= 0'} [{unit}], got {x.tolist()}")
        return np.where(rigid, np.inf, x)

    stiffness = per_joint(spec.stiffness, "stiffness", unit("N·m/rad", "N/m"), True, infinite=True)
    if np.any(np.isfinite(stiffness) & (stiffness > MAX_STIFFNESS)):
        raise SceneError(
            f"{what}: elasticity.stiffness above {MAX_STIFFNESS:g} [{unit('N·m/rad', 'N/m')}], got {stiffness.tolist()}: "
            "give math.inf for a rigid transmission (the motor inertia as the joint's armature)"
        )
    inertia = per_joint(spec.motor_inertia, "motor_inertia", unit("kg·m²", "kg"), True)
    ratio = _validate.finite_array(spec.gear_ratio, f"{what}, elasticity.gear_ratio")
    ratio = np.full(n, float(ratio)) if ratio.ndim == 0 else ratio
    if ratio.shape != (n,) or np.any(np.abs(ratio) < 1.0):
        raise SceneError(
            f"{what}: elasticity.gear_ratio must be a scalar or one per elastic joint, each |n| >= 1, got {ratio.tolist()}"
        )
    squared = ratio**2
    damping = per_joint(spec.damping, "damping", unit("N·m·s/rad", "N·s/m"), False)
    motor_damping = squared * per_joint(spec.motor_damping, "motor_damping", unit("N·m·s/rad", "N·s/m"), False)
    order = np.argsort(chosen)  # (the values pair with the names as given; kept in the arm's joint order)
    ids = np.array(chosen, dtype=int)[order] + 1
    return ResolvedElasticity(
        joint_ids=ids,
        joints=np.array([model.joints[int(j)].idx_v for j in ids], dtype=int),
        stiffness=stiffness[order],
        damping=damping[order],
        inertia=(squared * inertia)[order],
        motor_damping=motor_damping[order],
    )


def add_motor(model: pin.Model, name: str, inertia: float, is_continuous: bool) -> int:
    """Add one motor to ``model``: a joint on the world turning about z (continuous when its
    link's joint is) whose body has only the rotor inertia ``inertia`` about that axis. Returns
    its joint id."""
    joint = pin.JointModelRUBZ() if is_continuous else pin.JointModelRZ()
    jid = model.addJoint(0, joint, pin.SE3.Identity(), name)
    rotor = np.diag([0.0, 0.0, float(inertia)])
    model.appendBodyToJoint(jid, pin.Inertia(0.0, np.zeros(3), rotor), pin.SE3.Identity())
    model.addJointFrame(jid, 0)
    return int(jid)


def q_entries(index: np.ndarray, wide: np.ndarray) -> np.ndarray:
    """The q entries of joints starting at ``index``: one each, two for a continuous joint."""
    return np.concatenate([np.arange(i, i + (2 if w else 1)) for i, w in zip(index, wide, strict=True)] + [np.zeros(0, int)])


def motors_at_links(q: np.ndarray, springs: JointSprings) -> np.ndarray:
    """``q`` with each motor's coordinates set to its link's."""
    out = q.copy()
    out[q_entries(springs.motor_q, springs.continuous)] = q[q_entries(springs.link_q, springs.continuous)]
    return out


def turned(model: pin.Model, q: np.ndarray, v_index: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``q ⊕ angle`` along the coordinates ``v_index``."""
    dv = np.zeros(model.nv)
    dv[v_index] = angle
    return pin.integrate(model, q, dv)
