"""Inverse kinematics of one arm: damped least squares on SE(3), within joint limits."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from .arm import Arm, load_arm


def solve_ik(
    arm: Arm,
    target: pin.SE3,
    *,
    q_init: np.ndarray | None = None,
    tol: float = 1e-10,
    max_iter: int = 2000,
    damping: float = 1e-6,
    posture_gain: float = 0.1,
    max_step: float = 0.1,
) -> np.ndarray:
    """Joint configuration placing ``arm``'s tip frame at ``target`` (pose in the world).

    Damped least squares (Levenberg–Marquardt) on the SE(3) error ``log6(oMtip⁻¹ · target)``,
    projected onto the joint limits at every iteration; in the null space of the pose task the
    solution is pulled towards the arm's reference posture, so redundant arms get a natural
    configuration rather than one at their limits.

    Args:
        arm: the arm (its base pose, locked joints and tip frame are used).
        target: desired world pose of the tip frame.
        q_init: start configuration (nq_arm,); default the arm's ``q0``/reference posture.
        tol: convergence threshold on ‖log6 error‖ [m, rad].
        max_iter: iteration budget.
        damping: Levenberg–Marquardt damping λ².
        posture_gain: gain of the null-space pull towards the reference posture (0 to disable).
        max_step: largest joint change per iteration [rad or m].

    Raises:
        SceneError: if the pose is not reached within the limits (unreachable or too far).
    """
    loaded = load_arm(arm)  # kinematics only
    model = loaded.model
    data = model.createData()
    frame = model.getFrameId(loaded.tip_frame)
    base_target = loaded.base.actInv(target)
    q_ref = loaded.q0.copy()
    q = q_ref.copy() if q_init is None else np.array(q_init, dtype=float)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    err = np.inf
    eye6, eye_n = np.eye(6), np.eye(model.nv)
    # joint limits act on 1-DOF joints (revolute, prismatic); their q index per v index
    bounded = np.array([j.nq == 1 and j.nv == 1 for j in model.joints[1:] for _ in range(j.nv)])
    q_of_v = np.array([j.idx_q for j in model.joints[1:] for _ in range(j.nv)])
    lo_v, hi_v = lo[q_of_v], hi[q_of_v]
    for _ in range(max_iter):
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[frame].actInv(base_target)
        error = pin.log6(M).vector
        err = float(np.linalg.norm(error))
        if err < tol:
            return q
        # d error / dq = −Jlog6(M⁻¹) J for error = log6(M), M = oMtip⁻¹ · target
        J = -pin.Jlog6(M.inverse()) @ pin.computeFrameJacobian(model, data, q, frame, pin.ReferenceFrame.LOCAL)
        posture = posture_gain if err > 1e-3 else 0.0  # the last iterations polish the pose only
        free = np.ones(model.nv, dtype=bool)
        for _ in range(model.nv):  # joints at a limit that the step would push further are frozen
            Jf = J * free
            J_pinv = Jf.T @ np.linalg.inv(Jf @ Jf.T + damping * eye6)
            # primary: the pose; secondary (null space): stay near the reference posture
            dq = -J_pinv @ error + (eye_n - J_pinv @ Jf) @ (posture * pin.difference(model, q, q_ref) * free)
            qv = q[q_of_v]
            blocked = free & bounded & (((qv <= lo_v + 1e-9) & (dq < 0.0)) | ((qv >= hi_v - 1e-9) & (dq > 0.0)))
            if not blocked.any():
                break
            free &= ~blocked
        step = float(np.max(np.abs(dq)))
        if step > max_step:  # small steps follow the error down instead of jumping to another branch
            dq *= max_step / step
        q = pin.integrate(model, q, dq)
        q[q_of_v[bounded]] = np.clip(q[q_of_v[bounded]], lo_v[bounded], hi_v[bounded])
    distance = float(np.linalg.norm(base_target.translation))
    raise SceneError(
        f"inverse kinematics of arm {arm.name!r} did not reach the target within the joint limits "
        f"(remaining error {err:.3g} after {max_iter} iterations): the target is {distance:.3g} m from the arm's base, "
        f"which reaches at most {reach(model, frame):.3g} m (its links' lengths added); the pose is unreachable, or far "
        "from q_init"
    )


def reach(model: pin.Model, frame: int) -> float:
    """An upper bound of how far ``frame`` gets from the model's root [m]: the lengths of the
    joint placements from the root to it, and its own offset, added."""
    total = float(np.linalg.norm(model.frames[frame].placement.translation))
    joint = model.frames[frame].parentJoint
    while joint > 0:
        total += float(np.linalg.norm(model.jointPlacements[joint].translation))
        joint = model.parents[joint]
    return total


def place_arm(arm: Arm, tool_pose: Any) -> Arm:
    """A copy of ``arm`` whose ``q0`` starts its tool frame at ``tool_pose`` (world; ``pin.SE3``,
    4x4 or translation [m]), found by :func:`solve_ik` near the reference posture — how arms of
    different robots are placed around one object (a scene file's ``tool_pose``). Raises
    SceneError with the target's distance and the arm's reach when it is out of reach."""
    if not isinstance(arm, Arm):
        raise SceneError(f"place_arm places a coopdyn.Arm, got {_validate._short(arm)}")
    return arm.replace(q0=solve_ik(arm.replace(q0=None), _validate.se3(tool_pose, f"arm {arm.name!r}: tool_pose")))
