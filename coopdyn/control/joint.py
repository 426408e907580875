"""Joint-space controllers: callables ``controller(t, q, v) -> τ`` for :func:`coopdyn.simulate`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from .._spec import ComputedTorqueSpec, GravityPDSpec, MotorPDSpec, TorqueSequenceSpec
from ..errors import SceneError
from ..model.elastic_joints import motors_at_links, q_entries, turned
from ..model.scene import Scene


class _Gain:
    """A joint gain, checked on every assignment — a scalar becomes one value per actuated joint —
    so a controller retuned in place (``controller.kp = 100.0`` between Simulator runs) runs with
    a gain of the shape its compiled twin reads."""

    def __init__(self, unit: str) -> None:
        self.unit = unit

    def __set_name__(self, owner: type, name: str) -> None:
        self.name, self.slot = name, "_" + name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        return self if obj is None else getattr(obj, self.slot)

    def __set__(self, obj: Any, value: Any) -> None:
        who = f"{type(obj).__name__}: {self.name}"
        setattr(obj, self.slot, _validate.gain(value, who, obj.scene.n_actuated, self.unit))


class ScratchData:
    """A controller's Pinocchio ``Data`` of its scene's model (``self._data``), made at its first
    use: a controller whose law runs compiled may never compute in Python (GravityCompensationPD
    does not), and a beam scene's ``Data`` is large (Pinocchio sizes its derivative tensors
    nv × nv × nv: 2 GB at 64 elements)."""

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        data = obj.__dict__.get("_scratch_data")
        if data is None:
            data = obj.__dict__["_scratch_data"] = obj.scene.model.createData()
        return data


def _scene(scene: Any, who: str, elastic: bool = False) -> Scene:
    if not isinstance(scene, Scene):
        raise SceneError(f"{who}: scene must be a coopdyn.Scene, got {type(scene).__name__}")
    if not scene.arms:
        raise SceneError(f"{who} drives arm joints; this scene has no arms (its object is held by fixtures only)")
    if not elastic:
        rigid_joints_only(scene, who)
    return scene


def rigid_joints_only(scene: Scene, who: str) -> None:
    """Refuse a scene with elastic joints for a controller written for rigid ones (its torque
    would reach the link through a motor and a spring it does not know of)."""
    elastic = [a.name for a in scene.arms if a.elastic.size]
    if elastic:
        raise SceneError(
            f"{who} is written for rigid joints, and arms {elastic} have elastic ones (their torques act on the motors): "
            "use coopdyn.control.MotorPD (motor-side PD with gravity compensation) or a controller of your own"
        )


class GravityCompensationPD:
    """``τ = g(q) + Kp (q_d − q) − Kd q̇`` on every arm joint.

    ``g(q)`` is the arms' own gravity torque (the object hangs on the interconnections, which the
    PD absorbs). Args:
        scene: the scene.
        kp: proportional gain [N·m/rad], scalar or (n_actuated,).
        kd: derivative gain [N·m·s/rad], scalar or (n_actuated,).
        q_des: desired arm configuration (n_actuated,) for 1-DOF joints; default the scene's q0.
    """

    _data = ScratchData()

    kp = _Gain("N·m/rad")
    kd = _Gain("N·m·s/rad")

    def __init__(self, scene: Scene, kp: Any = 50.0, kd: Any = 5.0, q_des: Any = None) -> None:
        n = _scene(scene, "GravityCompensationPD").n_actuated
        self.scene = scene
        self.kp, self.kd = kp, kd
        self._q_index = np.concatenate([a.q_index for a in scene.arms])
        self.q_des = scene.q0.copy()  # a full configuration: pin.difference handles any joint type
        if q_des is not None:
            if self._q_index.size != n:
                raise SceneError("q_des is per joint coordinate; give it only for arms of 1-DOF joints (nq = nv)")
            self.q_des[self._q_index] = _validate.finite_array(q_des, "q_des", (n,))

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """(Kp, Kd) (n_actuated,) [N·m/rad], [N·m·s/rad]: the stiffness and damping the controller
        adds to the joints, for implicit integrators and :func:`coopdyn.advise`."""
        return self.kp, self.kd

    def compiled_spec(self, scene: Scene) -> GravityPDSpec | None:
        """This law for the compiled step loop (None: the scene is not this controller's)."""
        if scene is not self.scene:
            return None
        return GravityPDSpec(kp=self.kp.copy(), kd=self.kd.copy(), q_des=self.q_des.copy())

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        act, model = self.scene.actuated_index, self.scene.model
        g = pin.computeGeneralizedGravity(model, self._data, q)[act]
        g += self.kp * pin.difference(model, q, self.q_des)[act]
        g -= self.kd * v[act]
        return g


class ComputedTorque:
    """``τ = M(q)(q̈_d + Kp (q_d − q) + Kd (q̇_d − q̇)) + h(q, q̇)`` on the arm joints.

    Uses each arm's own inertia and nonlinear effects (the interconnection forces are not
    compensated: they act as a disturbance). Args:
        scene: the scene.
        kp: [1/s²], kd: [1/s] — per joint, scalar or (n_actuated,) (the error dynamics'
            ω² and 2ζω).
        reference: ``reference(t) -> (q_d, q̇_d, q̈_d)`` each (n_actuated,); default: hold q0.
    """

    _data = ScratchData()

    kp = _Gain("1/s²")
    kd = _Gain("1/s")

    def __init__(self, scene: Scene, kp: Any = 400.0, kd: Any = 40.0, reference: Any = None) -> None:
        n = _scene(scene, "ComputedTorque").n_actuated
        self.scene = scene
        self.kp, self.kd = kp, kd
        self._q_index = np.concatenate([a.q_index for a in scene.arms])
        if reference is not None and not callable(reference):
            raise SceneError(
                f"ComputedTorque: reference must be a callable reference(t) -> (q_d, q̇_d, q̈_d), got {type(reference).__name__}"
            )
        if self._q_index.size != n:
            raise SceneError("ComputedTorque needs arms made of 1-DOF joints (nq = nv)")
        q0 = scene.q0[self._q_index]
        zero = np.zeros(n)
        self._hold = q0

        def hold(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return q0, zero, zero

        self._hold_reference = hold
        self.reference = reference if reference is not None else hold

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        model, data, act = self.scene.model, self._data, self.scene.actuated
        q_d, v_d, a_d = self.reference(t)
        M = pin.crba(model, data, q)[np.ix_(act, act)]
        h = pin.nonLinearEffects(model, data, q, v)[act]
        return M @ (a_d + self.kp * (q_d - q[self._q_index]) + self.kd * (v_d - v[act])) + h

    def compiled_spec(self, scene: Scene) -> ComputedTorqueSpec | None:
        """This law for the compiled step loop, when it holds q0 (a Python reference runs in Python)."""
        if scene is not self.scene or self.reference is not self._hold_reference:
            return None
        return ComputedTorqueSpec(
            q_index=self._q_index.astype(np.int32), kp=self.kp.copy(), kd=self.kd.copy(), q_d=self._hold.copy()
        )

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """Approximate joint stiffness/damping [N·m/rad], [N·m·s/rad]: diag(M)·(Kp, Kd) at q0."""
        M = pin.crba(self.scene.model, self._data, self.scene.q0)
        d = np.diag(M)[self.scene.actuated]
        return d * self.kp, d * self.kd


class MotorPD:
    """Motor-side PD with gravity compensation, for arms with elastic joints (docs/physics.md).

    On every arm joint's motor (a rigid joint: on the joint itself, θ ≡ q)::

        τ = Kp (θ_d − θ) − Kd θ̇ + g_c,    θ_d = q_d + K⁻¹ g(q_d)

    with g the arms' own gravity torque on their joints. ``gravity="constant"`` takes
    ``g_c = g(q_d)`` (Tomei 1991); ``"online"`` takes ``g_c = g(θ̄)`` at the biased motor position
    ``θ̄ = θ − K⁻¹ g(q_d)``, which equals q_d at rest (De Luca, Siciliano & Zollo, Automatica 41
    (2005) 1809–1819). Both measure only the motors (position and velocity), and both regulate
    to ``q = q_d`` when the stiffness K and the gain Kp dominate the gradient of g (the papers'
    conditions). At rest the link is at q_d, the motor at θ_d.

    Args:
        scene: the scene (its arms may mix rigid and elastic joints).
        kp: [N·m/rad], kd: [N·m·s/rad] — scalar or (n_actuated,).
        q_des: the arms' joint targets q_d (n_actuated,) for 1-DOF joints; default the arms' q0.
        gravity: ``"online"`` (default) or ``"constant"``.
    """

    _data = ScratchData()

    GRAVITY = ("online", "constant")
    kp = _Gain("N·m/rad")
    kd = _Gain("N·m·s/rad")

    def __init__(self, scene: Scene, kp: Any = 400.0, kd: Any = 40.0, q_des: Any = None, gravity: str = "online") -> None:
        n = _scene(scene, "MotorPD", elastic=True).n_actuated
        if gravity not in self.GRAVITY:
            raise SceneError(f"MotorPD: gravity must be one of {self.GRAVITY}, got {_validate._short(gravity)}")
        self.scene, self.gravity = scene, gravity
        self.kp, self.kd = kp, kd
        model = scene.model
        link_q = np.concatenate([a.q_index for a in scene.arms])
        q_ref = scene.q0.copy()
        if q_des is not None:
            if link_q.size != n:
                raise SceneError("MotorPD: q_des is per joint coordinate; give it only for arms of 1-DOF joints (nq = nv)")
            q_ref[link_q] = _validate.finite_array(q_des, "MotorPD: q_des", (n,))
        springs = scene.joint_springs
        self._arm_joints = scene.arm_joints
        self.g_d = pin.computeGeneralizedGravity(model, self._data, q_ref)[self._arm_joints].copy()
        position = np.searchsorted(self._arm_joints, springs.link_v)  # each elastic joint among the arm joints
        if not np.array_equal(self._arm_joints[position], springs.link_v):  # (arm_joints is sorted: arms in order)
            raise SceneError("MotorPD: the scene's elastic joints are not among its arm joints")
        self._bias = self.g_d[position] / springs.stiffness  # K⁻¹ g(q_d) [rad]
        self._springs = springs
        self._link_entries = q_entries(springs.link_q, springs.continuous)
        self._motor_entries = q_entries(springs.motor_q, springs.continuous)
        self.target = turned(model, motors_at_links(q_ref, springs), springs.motor_v, self._bias)

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """(Kp, Kd) (n_actuated,) on the motors [N·m/rad], [N·m·s/rad], for implicit integrators
        and :func:`coopdyn.advise`."""
        return self.kp, self.kd

    def compiled_spec(self, scene: Scene) -> MotorPDSpec | None:
        """This law for the compiled step loop (None: the scene is not this controller's)."""
        if scene is not self.scene:
            return None
        s = self._springs
        elastic = np.column_stack([s.link_q, s.link_v, s.motor_q, s.continuous, self._bias])
        return MotorPDSpec(
            kp=self.kp.copy(),
            kd=self.kd.copy(),
            target=self.target.copy(),
            g_d=self.g_d.copy(),
            online=self.gravity == "online",
            arm_joints=self._arm_joints.astype(np.int32),
            elastic=elastic.astype(float).reshape(s.size, 5),
        )

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        model, act = self.scene.model, self.scene.actuated_index
        tau = self.kp * pin.difference(model, q, self.target)[act] - self.kd * v[act]
        if self.gravity == "constant":
            return tau + self.g_d
        q_bar = q.copy()
        q_bar[self._link_entries] = q[self._motor_entries]
        q_bar = turned(model, q_bar, self._springs.link_v, -self._bias)  # θ̄ = θ − K⁻¹ g(q_d), link coordinates
        return tau + pin.computeGeneralizedGravity(model, self._data, q_bar)[self._arm_joints]


class TorqueSequence:
    """Torques given in advance: ``torques[k]`` from ``k·period`` to ``(k + 1)·period`` (zero-order
    hold), the last one held to the end — an open-loop input, as :func:`coopdyn.rollout` plays.

    An instant within 1e-9·period of a boundary counts as the next period's. Called at every
    stage, a method's stage at the end of a period's last step (rk4's, implicit Euler's) reads the
    next row; ``simulate(..., control_dt=period)`` samples it once per period instead, so every
    stage of the period's steps sees row k — what :func:`coopdyn.rollout` does.

    Args:
        scene: the scene.
        torques: (N, n_actuated) [N·m or N] (an elastic joint's: its motor's).
        period: how long each row is held [s].
    """

    def __init__(self, scene: Scene, torques: Any, period: float) -> None:
        n = _scene(scene, "TorqueSequence", elastic=True).n_actuated
        self.scene = scene
        self.torques = _validate.finite_array(torques, "TorqueSequence: torques [N·m or N]")
        if self.torques.ndim != 2 or self.torques.shape[1] != n or self.torques.shape[0] < 1:
            raise SceneError(
                f"TorqueSequence: torques must be (N, {n}): one row of the {n} arm torques per period, got shape "
                f"{self.torques.shape}"
            )
        self.period = _validate.positive(period, "TorqueSequence: period", "s")

    def compiled_spec(self, scene: Scene) -> TorqueSequenceSpec | None:
        """This law for the compiled step loop (None: the scene is not this controller's)."""
        if scene is not self.scene:
            return None
        return TorqueSequenceSpec(torques=self.torques.copy(), period=float(self.period))

    def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        k = math.floor(t / self.period + 1e-9)  # (the compiled twin's and the loop's samples' tolerance)
        return self.torques[min(max(k, 0), len(self.torques) - 1)].copy()
