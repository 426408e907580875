"""Any coopdyn scene of revolute/prismatic arms and a free-flying object, built in MuJoCo from
coopdyn's own model, with coopdyn's interconnection law as MuJoCo passive forces — the faithful
MuJoCo peer of the benchmark's Panda scene.

What is carried over: every joint's placement, axis and inertia (Pinocchio has already merged
the fixed links, e.g. the Panda's hand and locked fingers, into their joints' bodies); gravity;
joint damping; the initial state; the tip and grasp frames. What is not: geometry (collisions
are off, as in coopdyn), joint limits and armature (coopdyn has neither). A MuJoCo weld is not a
spring (it sets a reference acceleration), so each interconnection's wrench is coopdyn's own
element law, added in an ``mjcb_passive`` callback as the generalized force ``Σ Jrᵀ f`` that
coopdyn's compiled kernel evaluates at MuJoCo's state (the fastest exact evaluation available
from Python; applying each wrench with ``mj_applyFT`` from a numpy SE(3) spring costs several
times more per call). The controller is coopdyn's,
called in ``mjcb_control`` (at every stage of RK4). Before any timing, :meth:`MujocoScene.check`
compares MuJoCo's accelerations with coopdyn's at random states.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from .._optional import require
from ..errors import SimulationError
from ..model.scene import Scene

_AXES = {"RX": "1 0 0", "RY": "0 1 0", "RZ": "0 0 1", "PX": "1 0 0", "PY": "0 1 0", "PZ": "0 0 1"}


def _rotation(w: float, x: float, y: float, z: float) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z)."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _quat(R: np.ndarray) -> str:
    x, y, z, w = (float(c) for c in pin.Quaternion(R).coeffs())
    return f"{w!r} {x!r} {y!r} {z!r}"


def _mjcf(scene: Scene, integrator: str, dt: float) -> str:
    """MJCF of the scene's kinematic tree (one body per Pinocchio joint, named after it)."""
    model = scene.model
    joint_damping = np.zeros(model.nv)
    for arm in scene.arms:
        joint_damping[arm.v_index] = arm.damping
    children: dict[int, list[int]] = {}
    for j in range(1, model.njoints):
        children.setdefault(model.parents[j], []).append(j)

    def body(j: int, indent: str) -> str:
        name, kind = model.names[j], model.joints[j].shortname().replace("JointModel", "")
        M, I = model.jointPlacements[j], model.inertias[j]
        mass = max(float(I.mass), 1e-9)
        Ic = I.inertia if I.mass > 0 else np.eye(3) * 1e-9
        full = " ".join(repr(float(x)) for x in (Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]))
        if kind == "FreeFlyer":
            joint = f'<freejoint name="{name}"/>'
        elif kind in _AXES:
            jtype = "hinge" if kind.startswith("R") else "slide"
            damping = float(joint_damping[model.joints[j].idx_v])
            joint = f'<joint name="{name}" type="{jtype}" axis="{_AXES[kind]}" damping="{damping!r}" limited="false"/>'
        else:
            raise SimulationError(f"the MuJoCo peer takes revolute, prismatic and free-flyer joints; {name!r} is {kind}")
        pos = " ".join(repr(float(x)) for x in M.translation)
        inner = "".join(body(c, indent + "  ") for c in children.get(j, []))
        return (
            f'{indent}<body name="{name}" pos="{pos}" quat="{_quat(M.rotation)}">\n{indent}  {joint}\n'
            f'{indent}  <inertial pos="{" ".join(repr(float(x)) for x in I.lever)}" mass="{mass!r}" fullinertia="{full}"/>\n'
            f"{inner}{indent}</body>\n"
        )

    g = " ".join(repr(float(x)) for x in scene.gravity)
    motors = "".join(
        f'    <motor joint="{model.names[j]}" ctrllimited="false"/>\n'
        for j in range(1, model.njoints)
        if model.joints[j].idx_v in set(scene.actuated.tolist())
    )
    return (
        f'<mujoco model="coopdyn">\n  <option timestep="{dt!r}" integrator="{integrator}" gravity="{g}">\n'
        '    <flag contact="disable"/>\n  </option>\n  <worldbody>\n'
        + "".join(body(c, "    ") for c in children.get(0, []))
        + f"  </worldbody>\n  <actuator>\n{motors}  </actuator>\n</mujoco>\n"
    )


class MujocoScene:
    """A coopdyn scene in MuJoCo (see the module docstring).

    Args:
        scene: revolute/prismatic arms, at most one free-flyer (the object).
        controller: coopdyn's ``controller(t, q, v) -> τ`` (Pinocchio q, v), or None.
        integrator: a MuJoCo integrator name (``"implicitfast"``, ``"RK4"``, ``"Euler"``).
        dt: MuJoCo's step [s].
    """

    def __init__(self, scene: Scene, controller: Callable[..., np.ndarray] | None, integrator: str, dt: float) -> None:
        mujoco: Any = require("mujoco", "the MuJoCo peer", "coopdyn[peers]")
        self.mj, self.scene, self.controller = mujoco, scene, controller
        self.model = mujoco.MjModel.from_xml_string(_mjcf(scene, integrator, dt))
        self.data = mujoco.MjData(self.model)
        model = scene.model
        self._data = model.createData()
        self._q_map: list[tuple[int, int, int]] = []  # (pin q index, mj qpos index, nq) for 1-DOF joints
        self._v_map: list[tuple[int, int]] = []
        self._free: tuple[int, int, int, int] | None = None  # (pin idx_q, pin idx_v, mj qposadr, mj dofadr)
        for j in range(1, model.njoints):
            jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, model.names[j])
            qa, da = int(self.model.jnt_qposadr[jid]), int(self.model.jnt_dofadr[jid])
            jm = model.joints[j]
            if jm.nv == 6:
                if self._free is not None:
                    raise SimulationError("the MuJoCo peer takes one free-flying body")
                if not model.jointPlacements[j].isIdentity():
                    raise SimulationError("the MuJoCo peer needs the free-flyer's placement to be the identity")
                self._free = (jm.idx_q, jm.idx_v, qa, da)
            else:
                self._q_map.append((jm.idx_q, qa, 1))
                self._v_map.append((jm.idx_v, da))
        self._qi = np.array([a for a, _, _ in self._q_map], dtype=int)
        self._qm = np.array([b for _, b, _ in self._q_map], dtype=int)
        self._vi = np.array([a for a, _ in self._v_map], dtype=int)
        self._vm = np.array([b for _, b in self._v_map], dtype=int)
        act = set(scene.actuated.tolist())
        self._ctrl_v = np.array([j.idx_v for j in model.joints[1:] if j.idx_v in act], dtype=int)
        order = {v: i for i, v in enumerate(scene.actuated.tolist())}
        self._ctrl_from_tau = np.array([order[v] for v in self._ctrl_v], dtype=int)  # motor k drives τ[...]
        from ..dynamics import Dynamics

        self._dynamics = Dynamics(scene)
        self._qv: tuple[np.ndarray, np.ndarray] | None = None  # the state of the current evaluation
        self.warnings: list[str] = []  #: MuJoCo's warnings (e.g. "Nan, Inf or huge value in QACC")
        self._R = np.eye(3)  # the free body's rotation at that state

    # --- state conversion (Pinocchio ↔ MuJoCo) ------------------------------------------------
    def set_state(self, q: np.ndarray, v: np.ndarray) -> None:
        d = self.data
        d.qpos[self._qm] = q[self._qi]
        d.qvel[self._vm] = v[self._vi]
        if self._free is not None:
            iq, iv, qa, da = self._free
            x, y, z, w = q[iq + 3 : iq + 7]
            d.qpos[qa : qa + 7] = [*q[iq : iq + 3], w, x, y, z]
            d.qvel[da : da + 3] = _rotation(w, x, y, z) @ v[iv : iv + 3]
            d.qvel[da + 3 : da + 6] = v[iv + 3 : iv + 6]

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) in Pinocchio's convention."""
        d, model = self.data, self.scene.model
        q, v = np.zeros(model.nq), np.zeros(model.nv)
        q[self._qi] = d.qpos[self._qm]
        v[self._vi] = d.qvel[self._vm]
        if self._free is not None:
            iq, iv, qa, da = self._free
            w, x, y, z = d.qpos[qa + 3 : qa + 7]
            q[iq : iq + 3] = d.qpos[qa : qa + 3]
            q[iq + 3 : iq + 7] = [x, y, z, w]
            self._R = R = _rotation(w, x, y, z)
            v[iv : iv + 3] = R.T @ d.qvel[da : da + 3]
            v[iv + 3 : iv + 6] = d.qvel[da + 3 : da + 6]
        return q, v

    def acceleration(self) -> np.ndarray:
        """MuJoCo's q̈ in Pinocchio's convention (after ``mj_forward``)."""
        d, model = self.data, self.scene.model
        a = np.zeros(model.nv)
        a[self._vi] = d.qacc[self._vm]
        if self._free is not None:
            _, iv, qa, da = self._free
            R = _rotation(*d.qpos[qa + 3 : qa + 7])
            omega = d.qvel[da + 3 : da + 6]
            v_lin = R.T @ d.qvel[da : da + 3]
            a[iv : iv + 3] = R.T @ d.qacc[da : da + 3] - np.cross(omega, v_lin)  # p̈ = R(v̇ + ω × v)
            a[iv + 3 : iv + 6] = d.qacc[da + 3 : da + 6]
        return a

    # --- the callbacks ---------------------------------------------------------------------------
    def _passive(self, m: Any, d: Any) -> None:
        q, v = self._qv = self.state()
        Q = self._dynamics.generalized_spring_force(q, v)  # Pinocchio's dofs; joint damping is MuJoCo's
        d.qfrc_passive[self._vm] += Q[self._vi]
        if self._free is not None:
            _, iv, _, da = self._free
            d.qfrc_passive[da : da + 3] += self._R @ Q[iv : iv + 3]  # R: read by state(); Q·v = (R Q_lin)·ṗ + …
            d.qfrc_passive[da + 3 : da + 6] += Q[iv + 3 : iv + 6]

    def _control(self, m: Any, d: Any) -> None:
        if self.controller is None:
            return
        q, v = self._qv if self._qv is not None else self.state()  # passive forces come first: same state
        self._qv = None
        tau = np.asarray(self.controller(d.time, q, v), dtype=float)
        d.ctrl[:] = tau[self._ctrl_from_tau]

    def __enter__(self) -> MujocoScene:
        self._previous = (self.mj.get_mjcb_passive(), self.mj.get_mjcb_control(), self.mj.get_mju_user_warning())
        self.mj.set_mjcb_passive(self._passive)
        self.mj.set_mjcb_control(self._control)
        self.mj.set_mju_user_warning(self.warnings.append)  # not MUJOCO_LOG.TXT in the user's folder
        return self

    def __exit__(self, *exc: object) -> None:
        passive, control, warning = self._previous  # whatever the caller had installed
        self.mj.set_mjcb_passive(passive)
        self.mj.set_mjcb_control(control)
        self.mj.set_mju_user_warning(warning)

    # --- checks and runs -------------------------------------------------------------------------
    def check(self, n: int = 5, seed: int = 0) -> float:
        """Largest relative difference between MuJoCo's and coopdyn's accelerations (controller
        included) at ``n`` random states near the initial one."""
        from ..closed_loop import System
        from ..dynamics import Dynamics

        system = System(Dynamics(self.scene), self.controller)
        rng = np.random.default_rng(seed)
        worst = 0.0
        with self:
            for _ in range(n):
                q = pin.integrate(self.scene.model, self.scene.q0, rng.normal(size=self.scene.nv) * 0.05)
                v = rng.normal(size=self.scene.nv) * 0.3
                self.set_state(q, v)
                self.data.time = 0.0
                self.mj.mj_forward(self.model, self.data)
                a_mj, a_cd = self.acceleration(), system.acceleration(0.0, q, v)
                worst = max(worst, float(np.max(np.abs(a_mj - a_cd)) / max(1.0, np.max(np.abs(a_cd)))))
        return worst

    def run(
        self, q0: np.ndarray, v0: np.ndarray, t_final: float, save_every: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
        """Step from (q0, v0) to t_final; (t, Q, V) on every ``save_every``-th step (Pinocchio
        convention), CPU seconds of the stepping, steps. Stops early at a non-finite state."""
        dt = float(self.model.opt.timestep)
        n_steps = round(t_final / dt)
        self.mj.mj_resetData(self.model, self.data)
        self.set_state(q0, v0)
        ts, Q, V = [0.0], [q0.copy()], [v0.copy()]
        with self:
            cpu0 = time.process_time()
            for k in range(1, n_steps + 1):
                self.mj.mj_step(self.model, self.data)
                if k % save_every == 0:
                    if not np.all(np.isfinite(self.data.qvel)):
                        break
                    q, v = self.state()
                    ts.append(k * dt)
                    Q.append(q)
                    V.append(v)
            cpu = time.process_time() - cpu0
        return np.array(ts), np.array(Q), np.array(V), cpu, n_steps
