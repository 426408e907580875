"""coopdyn's interconnection law, compiled, inside MuJoCo.

MuJoCo has no elastic interconnection between two arbitrary frames (a weld is a constraint, not
a spring). :class:`Callbacks` gives MuJoCo coopdyn's own law — the scene's elements (SE(3)
springs, ball springs, hardening springs …) between tips and grasps — and, optionally, one of
coopdyn's compiled controllers, as MuJoCo's ``mjcb_passive`` and ``mjcb_control`` callbacks.
They are C functions of coopdyn's kernel handed to MuJoCo as ctypes function pointers
(src/native/mujoco_bridge.hpp): MuJoCo calls them without Python or the GIL, as its
documentation recommends for custom forces. This is how ``coopdyn bench --peers`` builds its
fair MuJoCo peer, and how a user runs coopdyn's grasps in a MuJoCo model of their own (with
contacts, sensors, rendering — whatever MuJoCo offers)::

    import mujoco
    import coopdyn as cd
    from coopdyn.control import GravityCompensationPD
    from coopdyn.mujoco import Callbacks, mjcf

    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    model = mujoco.MjModel.from_xml_string(mjcf(scene, "implicitfast", 1e-3))  # or your own model
    data = mujoco.MjData(model)
    with Callbacks(scene, model, controller=GravityCompensationPD(scene)) as cb:
        cb.set_state(data, scene.q0, scene.v0)
        mujoco.mj_step(model, data, nstep=1000)
        cb.raise_if_failed()
        q, v = cb.state(data)  # Pinocchio's convention

The MuJoCo model must hold the scene's joints under the same names (revolute → hinge,
prismatic → slide, the object's free flyer → a free joint), with the same kinematics: the law
is evaluated on coopdyn's Pinocchio model at MuJoCo's joint coordinates. :func:`mjcf` writes
such a model from the scene (bodies, inertias, joint damping, gravity, one motor per actuated
joint); :meth:`Callbacks.check` compares MuJoCo's accelerations with coopdyn's at random
states. A controller must be one of coopdyn's built-ins with a compiled twin (or None); it
drives MuJoCo motors on the actuated joints (gear 1, no bias, no limits).

Frames and units: the forces are coopdyn's, SI units; MuJoCo's free joint keeps its own
convention ((p, w x y z), ṗ in world axes, ω in body axes) and :meth:`Callbacks.state` /
:meth:`Callbacks.set_state` convert to and from Pinocchio's ((p, x y z w), body-axes twist).

MuJoCo's callbacks are global to the process: one :class:`Callbacks` is active at a time, and
leaving the ``with`` block restores the callbacks that were installed before. MuJoCo's implicit
integrators do not differentiate callback forces: the law stays explicit there, as any custom
force in MuJoCo does.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from ._optional import require
from .dynamics import backend as _backend
from .errors import KernelError, SimulationError
from .model.scene import MOTOR_SUFFIX, Scene

__all__ = ["Callbacks", "mjcf"]

_AXES = {"RX": "1 0 0", "RY": "0 1 0", "RZ": "0 0 1", "PX": "1 0 0", "PY": "0 1 0", "PZ": "0 0 1"}
_CALLBACK = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)  # MuJoCo's mjfGeneric


def _quat(R: np.ndarray) -> str:
    x, y, z, w = (float(c) for c in pin.Quaternion(R).coeffs())
    return f"{w!r} {x!r} {y!r} {z!r}"


def _rotation(w: float, x: float, y: float, z: float) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z)."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def mjcf(scene: Scene, integrator: str = "implicitfast", dt: float = 1e-3) -> str:
    """MJCF of the scene's kinematic tree: one body per Pinocchio joint, named after it, with its
    placement, axis and inertia (Pinocchio has merged fixed links into their joints' bodies);
    gravity; joint damping and armature; one motor per actuated joint (gear 1, unlimited). An
    elastic joint (:class:`coopdyn.JointElasticity`) is two hinges: its motor's on the world,
    carrying the rotor inertia B as armature, and the link's, joined by a fixed tendon θ − q with
    the transmission's stiffness K and damping D — Spong's reduced model, as coopdyn's. No
    geometry: collisions are off, as in coopdyn. ``integrator``: a MuJoCo integrator name;
    ``dt`` [s]."""
    model = scene.model
    joint_damping = np.zeros(model.nv)
    for arm in scene.arms:
        joint_damping[arm.v_index] = arm.damping
        joint_damping[arm.motor_v_index] = arm.motor_damping
    motors = {int(model.joints[j].idx_v): j for j in range(1, model.njoints) if model.names[j].endswith(MOTOR_SUFFIX)}
    children: dict[int, list[int]] = {}
    for j in range(1, model.njoints):
        children.setdefault(model.parents[j], []).append(j)

    def body(j: int, indent: str) -> str:
        name, kind = model.names[j], model.joints[j].shortname().replace("JointModel", "")
        M, I = model.jointPlacements[j], model.inertias[j]
        mass = max(float(I.mass), 1e-9)
        Ic = I.inertia if I.mass > 0 else np.eye(3) * 1e-9
        armature = float(model.armature[model.joints[j].idx_v]) if model.joints[j].nv == 1 else 0.0
        if model.joints[j].idx_v in motors:  # a motor: its rotor inertia B as the hinge's armature (less the 1e-9 stand-in)
            armature += float(I.inertia[2, 2]) - 1e-9
        full = " ".join(repr(float(x)) for x in (Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]))
        if kind == "FreeFlyer":
            joint = f'<freejoint name="{name}"/>'
        elif kind in _AXES:
            jtype = "hinge" if kind.startswith("R") else "slide"
            damping = float(joint_damping[model.joints[j].idx_v])
            joint = (
                f'<joint name="{name}" type="{jtype}" axis="{_AXES[kind]}" damping="{damping!r}" armature="{armature!r}" '
                'limited="false"/>'
            )
        else:
            raise SimulationError(f"coopdyn.mujoco takes revolute, prismatic and free-flyer joints; {name!r} is {kind}")
        pos = " ".join(repr(float(x)) for x in M.translation)
        inner = "".join(body(c, indent + "  ") for c in children.get(j, []))
        return (
            f'{indent}<body name="{name}" pos="{pos}" quat="{_quat(M.rotation)}">\n{indent}  {joint}\n'
            f'{indent}  <inertial pos="{" ".join(repr(float(x)) for x in I.lever)}" mass="{mass!r}" fullinertia="{full}"/>\n'
            f"{inner}{indent}</body>\n"
        )

    g = " ".join(repr(float(x)) for x in scene.gravity)
    springs = scene.joint_springs
    tendons = "".join(
        f'    <fixed name="{model.names[motors[int(mv)]]}.spring" stiffness="{float(K)!r}" damping="{float(D)!r}" '
        f'springlength="0">\n      <joint joint="{model.names[motors[int(mv)]]}" coef="1"/>\n'
        f'      <joint joint="{model.names[motors[int(mv)]].removesuffix(MOTOR_SUFFIX)}" coef="-1"/>\n    </fixed>\n'
        for mv, K, D in zip(springs.motor_v, springs.stiffness, springs.damping, strict=True)
    )
    actuated = set(scene.actuated.tolist())
    actuators = "".join(
        f'    <motor joint="{model.names[j]}" ctrllimited="false"/>\n'
        for j in range(1, model.njoints)
        if model.joints[j].idx_v in actuated
    )
    return (
        f'<mujoco model="coopdyn">\n  <option timestep="{dt!r}" integrator="{integrator}" gravity="{g}">\n'
        '    <flag contact="disable"/>\n  </option>\n  <worldbody>\n'
        + "".join(body(c, "    ") for c in children.get(0, []))
        + "  </worldbody>\n"
        + (f"  <tendon>\n{tendons}  </tendon>\n" if tendons else "")
        + f"  <actuator>\n{actuators}  </actuator>\n</mujoco>\n"
    )


class MjDataLayout(NamedTuple):
    """Byte offsets in mjData of ``time`` (a double) and of the pointer fields ``qpos, qvel,
    ctrl, qfrc_passive`` (double*), for the installed MuJoCo."""

    time: int
    qpos: int
    qvel: int
    ctrl: int
    qfrc_passive: int


_LAYOUT: MjDataLayout | None = None
#: a model with every field the layout needs non-empty (a hinge, a motor): the probe
_PROBE = (
    '<mujoco><worldbody><body><joint name="j" type="hinge"/><geom size="0.1"/></body></worldbody>'
    '<actuator><motor joint="j"/></actuator></mujoco>'
)


def _layout(mujoco: Any) -> MjDataLayout:
    """Where the installed MuJoCo's mjData keeps what the callbacks read and write, found on a
    probe model and checked: ``time`` is the double just before ``energy`` (whose numpy view
    points into the struct; checked by writing two values through the binding and reading them
    back at the offset); each pointer field is the word holding its array's address, searched
    word by word after ``energy`` in the header's order (mjdata.h: buffer, arena, qpos, qvel, …,
    ctrl, …, qfrc_passive), where an empty array shares the next one's address (the field is the
    last of such a run). Cached for the process. Raises KernelError when the layout is not
    the one known (written against MuJoCo 4.0.0)."""
    global _LAYOUT
    if _LAYOUT is not None:
        return _LAYOUT
    model = mujoco.MjModel.from_xml_string(_PROBE)
    data = mujoco.MjData(model)
    advice = f"coopdyn.mujoco was written against MuJoCo 4.0.0 (pip install 'mujoco==4.0.0'); this is {mujoco.__version__}"
    base, energy = int(data._address), int(data.energy.ctypes.data)
    time_offset = energy - 8 - base
    if not 0 < time_offset < 1 << 24:
        raise KernelError(f"coopdyn.mujoco: mjData's layout is not the one it knows (energy): {advice}")
    for probe in (0.3141592653589793, -2.718281828459045):
        data.time = probe
        if ctypes.c_double.from_address(base + time_offset).value != probe:
            raise KernelError(f"coopdyn.mujoco: mjData keeps `time` elsewhere: {advice}")
    found, word = {}, 1  # (words 0 and 1 after energy: buffer and arena)
    for name in ("qpos", "qvel", "ctrl", "qfrc_passive"):
        address = getattr(data, name).ctypes.data
        for _ in range(400):  # (mjData has about 180 fields after energy: qfrc_passive is well inside)
            word += 1
            if ctypes.c_uint64.from_address(energy + 16 + 8 * word).value == address:
                break
        else:
            raise KernelError(f"coopdyn.mujoco: cannot find mjData.{name}: {advice}")
        while ctypes.c_uint64.from_address(energy + 16 + 8 * (word + 1)).value == address:
            word += 1
        found[name] = energy + 16 + 8 * word - base
    _LAYOUT = MjDataLayout(time_offset, found["qpos"], found["qvel"], found["ctrl"], found["qfrc_passive"])
    return _LAYOUT


class Callbacks:
    """coopdyn's interconnection law (and a compiled controller) as MuJoCo's ``mjcb_passive`` and
    ``mjcb_control``, for ``model`` (see the module docstring); a context manager.

    Args:
        scene: the coopdyn scene the MuJoCo model is built from (its elements are the law).
        model: the ``mujoco.MjModel``: the scene's joints by name, one motor per actuated joint
            when a controller is given.
        controller: a built-in coopdyn controller with a compiled twin
            (``GravityCompensationPD``, ``ObjectImpedance`` …), or None (no control callback).

    Raises:
        SimulationError: a joint of the scene is missing or of another type in the model, a
            motor is missing or not a plain motor, or the controller has no compiled twin.
    """

    def __init__(self, scene: Scene, model: Any, controller: Any = None) -> None:
        self.mj: Any = require("mujoco", "coopdyn.mujoco", "coopdyn[peers]")
        from .compiled import _own_spec
        from .dynamics import Dynamics

        if not isinstance(scene, Scene):
            raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
        self.scene, self.model = scene, model
        self._dynamics = Dynamics(scene, "native")  # the kernel the callbacks evaluate
        mj, pm = self.mj, scene.model
        q_pin, q_mj, v_pin, v_mj, free = [], [], [], [], [-1, -1, -1, -1]
        for j in range(1, pm.njoints):
            name, jm = pm.names[j], pm.joints[j]
            jid = mj.mj_name2id(model, mj.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                raise SimulationError(f"the MuJoCo model has no joint named {name!r} (coopdyn.mujoco maps joints by name)")
            kind = jm.shortname().replace("JointModel", "")
            if kind != "FreeFlyer" and kind not in _AXES:
                raise SimulationError(f"coopdyn.mujoco takes revolute, prismatic and free-flyer joints; {name!r} is {kind}")
            want = (
                mj.mjtJoint.mjJNT_FREE
                if kind == "FreeFlyer"
                else mj.mjtJoint.mjJNT_HINGE
                if kind[0] == "R"
                else mj.mjtJoint.mjJNT_SLIDE
            )
            if int(model.jnt_type[jid]) != int(want):
                raise SimulationError(f"joint {name!r} is {kind} in coopdyn but of MuJoCo type {int(model.jnt_type[jid])}")
            qa, da = int(model.jnt_qposadr[jid]), int(model.jnt_dofadr[jid])
            if jm.nv == 6:
                if free[0] >= 0:
                    raise SimulationError("coopdyn.mujoco takes one free-flying body")
                if not pm.jointPlacements[j].isIdentity():
                    raise SimulationError("coopdyn.mujoco needs the free flyer's placement to be the identity")
                free = [jm.idx_q, jm.idx_v, qa, da]
            else:
                q_pin.append(jm.idx_q)
                q_mj.append(qa)
                v_pin.append(jm.idx_v)
                v_mj.append(da)
        self._q_pin, self._q_mj = np.array(q_pin, dtype=np.int32), np.array(q_mj, dtype=np.int32)
        self._v_pin, self._v_mj = np.array(v_pin, dtype=np.int32), np.array(v_mj, dtype=np.int32)
        self._free = tuple(free)
        spec = None
        motor_ctrl: list[int] = []
        motor_tau: list[int] = []
        if controller is not None:
            spec = _own_spec(controller, scene)
            if spec is None:
                raise SimulationError(
                    f"{type(controller).__name__} has no compiled twin for this scene: coopdyn.mujoco runs built-in "
                    "controllers compiled (a Python controller belongs in MuJoCo's own mjcb_control)"
                )
            motor_ctrl, motor_tau = self._motors()
        self._controller = controller
        self._bridge: Any = None  # made when entering, with the layout of a real mjData
        self._spec = spec
        self._motor_ctrl, self._motor_tau = motor_ctrl, motor_tau
        self._previous: tuple[Any, Any, Any] | None = None  # while installed: what was before
        self._pointers = (
            _CALLBACK(_backend.kernel_module().mujoco_passive_address()),
            _CALLBACK(_backend.kernel_module().mujoco_control_address()),
        )

    def _motors(self) -> tuple[list[int], list[int]]:
        """(actuator index, τ index) of the motor on each actuated joint."""
        mj, model, pm = self.mj, self.model, self.scene.model
        order = {v: i for i, v in enumerate(self.scene.actuated.tolist())}
        by_joint: dict[int, list[int]] = {}
        for k in range(model.nu):
            if int(model.actuator_trntype[k]) == int(mj.mjtTrn.mjTRN_JOINT):
                by_joint.setdefault(int(model.actuator_trnid[k, 0]), []).append(k)
        ctrl, tau = [], []
        for j in range(1, pm.njoints):
            idx_v = pm.joints[j].idx_v
            if idx_v not in order:
                continue
            jid = mj.mj_name2id(model, mj.mjtObj.mjOBJ_JOINT, pm.names[j])
            if len(by_joint.get(jid, [])) != 1:
                raise SimulationError(
                    f"the actuated joint {pm.names[j]!r} needs exactly one actuator in the MuJoCo model (the controller's "
                    f"motor), it has {len(by_joint.get(jid, []))}"
                )
            k = by_joint[jid][0]
            plain = (
                model.actuator_gear[k, 0] == 1.0
                and not np.any(model.actuator_gear[k, 1:])
                and int(model.actuator_gaintype[k]) == int(mj.mjtGain.mjGAIN_FIXED)
                and model.actuator_gainprm[k, 0] == 1.0
                and int(model.actuator_biastype[k]) == int(mj.mjtBias.mjBIAS_NONE)
                and int(model.actuator_dyntype[k]) == int(mj.mjtDyn.mjDYN_NONE)
                and not model.actuator_ctrllimited[k]
                and not model.actuator_forcelimited[k]
                and not model.jnt_actfrclimited[jid]
            )
            if not plain:
                raise SimulationError(
                    f"actuator {k} on joint {pm.names[j]!r} must be a plain motor (gear 1, fixed gain 1, no bias, no "
                    "dynamics, no control or force limits): the controller's torque goes to ctrl as is"
                )
            ctrl.append(k)
            tau.append(order[idx_v])
        return ctrl, tau

    # --- state conversion (Pinocchio ↔ MuJoCo) --------------------------------------------------
    def set_state(self, data: Any, q: np.ndarray, v: np.ndarray) -> None:
        """Write Pinocchio's (q (nq,), v (nv,)) into MuJoCo's qpos and qvel."""
        q, v = self.scene.check_state(q, v)
        data.qpos[self._q_mj] = q[self._q_pin]
        data.qvel[self._v_mj] = v[self._v_pin]
        if self._free[0] >= 0:
            iq, iv, qa, da = self._free
            x, y, z, w = q[iq + 3 : iq + 7]
            data.qpos[qa : qa + 7] = [*q[iq : iq + 3], w, x, y, z]
            data.qvel[da : da + 3] = _rotation(w, x, y, z) @ v[iv : iv + 3]
            data.qvel[da + 3 : da + 6] = v[iv + 3 : iv + 6]

    def state(self, data: Any) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo's state as Pinocchio's (q (nq,), v (nv,))."""
        pm = self.scene.model
        q, v = np.zeros(pm.nq), np.zeros(pm.nv)
        q[self._q_pin] = data.qpos[self._q_mj]
        v[self._v_pin] = data.qvel[self._v_mj]
        if self._free[0] >= 0:
            iq, iv, qa, da = self._free
            w, x, y, z = data.qpos[qa + 3 : qa + 7]
            q[iq : iq + 3] = data.qpos[qa : qa + 3]
            q[iq + 3 : iq + 7] = [x, y, z, w]
            v[iv : iv + 3] = _rotation(w, x, y, z).T @ data.qvel[da : da + 3]
            v[iv + 3 : iv + 6] = data.qvel[da + 3 : da + 6]
        return q, v

    def acceleration(self, data: Any) -> np.ndarray:
        """MuJoCo's q̈ (after ``mj_forward``) in Pinocchio's convention (nv,)."""
        a = np.zeros(self.scene.model.nv)
        a[self._v_pin] = data.qacc[self._v_mj]
        if self._free[0] >= 0:
            _, iv, qa, da = self._free
            R = _rotation(*data.qpos[qa + 3 : qa + 7])
            omega = data.qvel[da + 3 : da + 6]
            v_lin = R.T @ data.qvel[da : da + 3]
            a[iv : iv + 3] = R.T @ data.qacc[da : da + 3] - np.cross(omega, v_lin)  # p̈ = R(v̇ + ω × v)
            a[iv + 3 : iv + 6] = data.qacc[da + 3 : da + 6]
        return a

    # --- installing ------------------------------------------------------------------------------
    def __enter__(self) -> Callbacks:
        if self._previous is not None:
            raise SimulationError("these Callbacks are already installed (a `with` block of them is running)")
        mj = self.mj
        layout = _layout(mj)
        kernel = _backend.kernel_module()
        self._bridge = kernel.make_mujoco_bridge(
            self._dynamics._kernel,  # type: ignore[attr-defined]  # (the bridge keeps it alive)
            None if self._spec is None else self._spec.fields(),
            tuple(layout),
            self._q_pin,
            self._q_mj,
            self._v_pin,
            self._v_mj,
            np.array(self._free, dtype=np.int32),
            np.array(self._motor_ctrl, dtype=np.int32),
            np.array(self._motor_tau, dtype=np.int32),
        )
        previous_bridge = kernel.install_mujoco_bridge(self._bridge)
        self._previous = (mj.get_mjcb_passive(), mj.get_mjcb_control(), previous_bridge)
        mj.set_mjcb_passive(self._pointers[0])
        mj.set_mjcb_control(self._pointers[1] if self._spec is not None else None)
        return self

    def __exit__(self, *exc: object) -> None:
        """Put back the callbacks (and the coopdyn law, for nested blocks) installed before."""
        if self._previous is None:
            return
        passive, control, previous_bridge = self._previous
        self.mj.set_mjcb_passive(passive)
        self.mj.set_mjcb_control(control)
        _backend.kernel_module().install_mujoco_bridge(previous_bridge)
        self._previous = None

    @property
    def evaluations(self) -> int:
        """How many times MuJoCo has called the law (in the last ``with`` block)."""
        return 0 if self._bridge is None else int(self._bridge.evaluations)

    def raise_if_failed(self) -> None:
        """Raise the first error a callback met since the last call (a callback cannot raise into
        MuJoCo: it makes the passive force NaN, MuJoCo warns and resets, and this says why)."""
        message = "" if self._bridge is None else self._bridge.take_error()
        if message:
            raise KernelError(f"coopdyn's MuJoCo callbacks failed: {message}")

    def check(self, n: int = 5, seed: int = 0) -> float:
        """Largest relative difference between MuJoCo's accelerations (with these callbacks) and
        coopdyn's (same law, same controller) at ``n`` random states near the scene's start and
        random times in [0, 2] s."""
        from .closed_loop import System
        from .dynamics import Dynamics

        system = System(Dynamics(self.scene), self._controller)
        data = self.mj.MjData(self.model)
        rng = np.random.default_rng(seed)
        worst = 0.0
        with self if self._previous is None else contextlib.nullcontext():
            for _ in range(n):
                q = pin.integrate(self.scene.model, self.scene.q0, rng.normal(size=self.scene.nv) * 0.05)
                v = rng.normal(size=self.scene.nv) * 0.3
                t = float(rng.uniform(0.0, 2.0))  # (a time-dependent controller sees MuJoCo's time)
                self.set_state(data, q, v)
                data.time = t
                self.mj.mj_forward(self.model, data)
                self.raise_if_failed()
                a_mj, a_cd = self.acceleration(data), system.acceleration(t, q, v)
                worst = max(worst, float(np.max(np.abs(a_mj - a_cd)) / max(1.0, np.max(np.abs(a_cd)))))
        return worst


def _uninstall_at_exit() -> None:
    """Let go of an installed law before the interpreter ends (the bridge holds a Python kernel)."""
    try:
        _backend.kernel_module().install_mujoco_bridge(None)
    except Exception:  # (no kernel: nothing was installed)
        return


atexit.register(_uninstall_at_exit)
