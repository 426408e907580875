"""Any coopdyn scene of revolute/prismatic arms and a free-flying object, built in MuJoCo from
coopdyn's own model (:func:`coopdyn.mujoco.mjcf`), with coopdyn's interconnection law as MuJoCo
passive forces — the MuJoCo peer of the benchmark's Panda scenes, two ways:

* ``compiled=True`` (the fair peer, as MuJoCo's experts run custom forces): the law and the
  controller are C callbacks of coopdyn's kernel given to MuJoCo as ctypes function pointers
  (:class:`coopdyn.mujoco.Callbacks`): no Python per evaluation;
* ``compiled=False``: the same law and controller called from Python in ``mjcb_passive`` /
  ``mjcb_control`` (the generalized force ``Σ Jrᵀ f`` from coopdyn's compiled kernel, the
  controller's Python ``__call__``) — what a Python user writes first, and what MuJoCo's
  documentation warns is slow; kept as a labelled second row.

What is carried over: every joint's placement, axis and inertia; gravity; joint damping and
armature; elastic joints (the motors' hinges, their transmissions as tendons); the initial
state; the tip and grasp frames. What is not: geometry (collisions are off, as in coopdyn) and
joint limits (coopdyn has none). A MuJoCo weld is not a spring (it
sets a reference acceleration), so each interconnection's wrench is coopdyn's own element law.
The controller runs in ``mjcb_control`` (at every stage of RK4). Before any timing,
:meth:`MujocoScene.check` compares MuJoCo's accelerations with coopdyn's at random states.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from .._optional import require
from ..model.scene import Scene
from ..mujoco import Callbacks, _rotation, mjcf

__all__ = ["MujocoScene"]


class MujocoScene:
    """A coopdyn scene in MuJoCo (see the module docstring).

    Args:
        scene: revolute/prismatic arms, at most one free-flyer (the object).
        controller: coopdyn's ``controller(t, q, v) -> τ`` (Pinocchio q, v), or None; compiled:
            a built-in with a compiled twin.
        integrator: a MuJoCo integrator name (``"implicitfast"``, ``"RK4"``, ``"Euler"``).
        dt: MuJoCo's step [s].
        compiled: the law and controller as C callbacks (True, the fair peer) or Python ones.
    """

    def __init__(
        self, scene: Scene, controller: Callable[..., np.ndarray] | None, integrator: str, dt: float, compiled: bool = True
    ) -> None:
        mujoco: Any = require("mujoco", "the MuJoCo peer", "coopdyn[peers]")
        self.mj, self.scene, self.controller, self.compiled = mujoco, scene, controller, compiled
        self.model = mujoco.MjModel.from_xml_string(mjcf(scene, integrator, dt))
        self.data = mujoco.MjData(self.model)
        # the index maps and conversions; with compiled=False only those (nothing is installed)
        self.callbacks = Callbacks(scene, self.model, controller if compiled else None)
        m = self.callbacks
        self._vi, self._vm, self._free = m._v_pin, m._v_mj, m._free
        order = {v: i for i, v in enumerate(scene.actuated.tolist())}
        self._ctrl_from_tau = np.array([order[j.idx_v] for j in scene.model.joints[1:] if j.idx_v in order], dtype=int)
        from ..dynamics import Dynamics

        self._dynamics = Dynamics(scene)
        self._qv: tuple[np.ndarray, np.ndarray] | None = None  # the state of the current evaluation
        self.warnings: list[str] = []  #: MuJoCo's warnings (e.g. "Nan, Inf or huge value in QACC")

    # --- state conversion (Pinocchio ↔ MuJoCo) ------------------------------------------------
    def set_state(self, q: np.ndarray, v: np.ndarray) -> None:
        self.callbacks.set_state(self.data, q, v)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) in Pinocchio's convention."""
        return self.callbacks.state(self.data)

    def acceleration(self) -> np.ndarray:
        """MuJoCo's q̈ in Pinocchio's convention (after ``mj_forward``)."""
        return self.callbacks.acceleration(self.data)

    # --- the Python callbacks (compiled=False) ----------------------------------------------------
    def _passive(self, m: Any, d: Any) -> None:
        q, v = self._qv = self.state()
        Q = self._dynamics.generalized_spring_force(q, v)  # Pinocchio's dofs; joint damping is MuJoCo's
        d.qfrc_passive[self._vm] += Q[self._vi]
        if self._free[0] >= 0:
            _, iv, qa, da = self._free
            R = _rotation(*d.qpos[qa + 3 : qa + 7])
            d.qfrc_passive[da : da + 3] += R @ Q[iv : iv + 3]  # Q·v = (R Q_lin)·ṗ + …
            d.qfrc_passive[da + 3 : da + 6] += Q[iv + 3 : iv + 6]

    def _control(self, m: Any, d: Any) -> None:
        if self.controller is None:
            return
        q, v = self._qv if self._qv is not None else self.state()  # passive forces come first: same state
        self._qv = None
        tau = np.asarray(self.controller(d.time, q, v), dtype=float)
        d.ctrl[:] = tau[self._ctrl_from_tau]

    def __enter__(self) -> MujocoScene:
        self._previous = self.mj.get_mju_user_warning()
        self.mj.set_mju_user_warning(self.warnings.append)  # not MUJOCO_LOG.TXT in the user's folder
        if self.compiled:
            self.callbacks.__enter__()
        else:
            self._callbacks_before = (self.mj.get_mjcb_passive(), self.mj.get_mjcb_control())
            self.mj.set_mjcb_passive(self._passive)
            self.mj.set_mjcb_control(self._control)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.compiled:
            self.callbacks.__exit__(*exc)
        else:
            passive, control = self._callbacks_before  # whatever the caller had installed
            self.mj.set_mjcb_passive(passive)
            self.mj.set_mjcb_control(control)
        self.mj.set_mju_user_warning(self._previous)

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
                if self.compiled:
                    self.callbacks.raise_if_failed()
                a_mj, a_cd = self.acceleration(), system.acceleration(0.0, q, v)
                worst = max(worst, float(np.max(np.abs(a_mj - a_cd)) / max(1.0, np.max(np.abs(a_cd)))))
        return worst

    def run(
        self, q0: np.ndarray, v0: np.ndarray, t_final: float, save_every: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
        """Step from (q0, v0) to t_final; (t, Q, V) on every ``save_every``-th step (Pinocchio
        convention), CPU seconds of the stepping, steps. ``save_every`` steps are one
        ``mj_step(..., nstep=save_every)`` call (no Python between them). Stops early at a
        non-finite state or a MuJoCo warning (MuJoCo resets a state whose acceleration blew up)."""
        dt = float(self.model.opt.timestep)
        n_steps = round(t_final / dt)
        self.mj.mj_resetData(self.model, self.data)
        self.set_state(q0, v0)
        ts, Q, V = [0.0], [q0.copy()], [v0.copy()]
        self.warnings.clear()
        with self:
            cpu0 = time.process_time()
            for k in range(save_every, n_steps + 1, save_every):
                self.mj.mj_step(self.model, self.data, nstep=save_every)
                if self.warnings or not np.all(np.isfinite(self.data.qvel)):
                    break
                q, v = self.state()
                ts.append(k * dt)
                Q.append(q)
                V.append(v)
            cpu = time.process_time() - cpu0
            if self.compiled:
                self.callbacks.raise_if_failed()
        return np.array(ts), np.array(Q), np.array(V), cpu, n_steps
