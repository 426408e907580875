"""``coopdyn.simulate``: run a scene under a controller and return a :class:`Result`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import pinocchio as pin

from .dynamics import Dynamics, Energy
from .errors import SimulationError
from .integrators import Controller, Integrator, System, get_integrator
from .scene import Scene


def simulate(
    scene: Scene,
    t_final: float,
    controller: Controller | None = None,
    integrator: str | Integrator = "rk4",
    dt: float = 1e-3,
    save_every: int = 1,
    q0: Any = None,
    v0: Any = None,
    progress: bool = False,
) -> Result:
    """Simulate ``scene`` from t = 0 to ``t_final``.

    Args:
        scene: the scene.
        t_final: duration [s], ≥ 0.
        controller: ``controller(t, q, v) -> τ``, one torque/force per arm joint in scene order
            (``scene.n_actuated``) [N·m or N]; ``None`` applies none.
        integrator: a name from ``coopdyn.integrators.INTEGRATORS`` or an instance.
        dt: time step [s], > 0. The last step is shortened to end exactly at ``t_final``.
        save_every: keep every k-th step (the initial and final states are always kept).
        q0, v0: initial state (nq,), (nv,); default ``scene.q0`` and ``scene.v0``.
        progress: show a progress bar.

    Returns:
        the saved trajectory, with readouts (wrenches, deformations, energies).

    Raises:
        SimulationError: on invalid arguments, or when the state stops being finite.
        ControllerError: when the controller output has the wrong length or is not finite.
    """
    if not isinstance(scene, Scene):
        raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
    t_final = _number(t_final, "t_final")
    dt = _number(dt, "dt")
    if t_final < 0.0:
        raise SimulationError(f"t_final must be >= 0 [s], got {t_final}")
    if dt <= 0.0:
        raise SimulationError(f"dt must be > 0 [s], got {dt}")
    if not isinstance(save_every, int | np.integer) or isinstance(save_every, bool) or save_every < 1:
        raise SimulationError(f"save_every must be an integer >= 1, got {save_every!r}")
    method = get_integrator(integrator)
    q, v = scene.check_state(scene.q0 if q0 is None else q0, scene.v0 if v0 is None else v0)

    system = System(Dynamics(scene), controller)
    n_steps = max(0, math.ceil(t_final / dt - 1e-9))
    saved = [k for k in range(0, n_steps, save_every)] + [n_steps]
    n_saved = len(saved)
    ts, qs, vs = np.empty(n_saved), np.empty((n_saved, scene.nq)), np.empty((n_saved, scene.nv))
    taus = np.empty((n_saved, scene.n_actuated))

    bar = _progress_bar(n_steps, method.name) if progress else None
    cpu0 = time.process_time()
    t, i_save = 0.0, 0
    with np.errstate(over="ignore", invalid="ignore"):  # a blow-up is reported below, as an error
        for k in range(n_steps + 1):
            if k == saved[i_save]:
                ts[i_save], qs[i_save], vs[i_save] = t, q, v
                taus[i_save] = system.torque(t, q, v)
                i_save += 1
            if k == n_steps:
                break
            h = min(dt, t_final - k * dt)
            q, v = method.step(system, t, q, v, h)
            t = t_final if k + 1 == n_steps else (k + 1) * dt
            if not (np.all(np.isfinite(v)) and np.all(np.isfinite(q))):
                raise SimulationError(
                    f"the state became non-finite at t = {t:.6g} s with {method.name} at dt = {dt:g} s: the step is "
                    "beyond the method's stability limit for this scene; reduce dt or choose another integrator"
                )
            if bar is not None and (k & 255) == 0:
                bar.update(min(256, n_steps - bar.n))
    cpu = time.process_time() - cpu0
    if bar is not None:
        bar.update(n_steps - bar.n)
        bar.close()
    return Result(scene=scene, t=ts, q=qs, v=vs, tau=taus, integrator=method.name, dt=dt, n_rhs=system.n_rhs, cpu_time=cpu)


def _number(x: Any, name: str) -> float:
    try:
        value = float(x)
    except (TypeError, ValueError) as exc:
        raise SimulationError(f"{name} must be a number [s], got {x!r}") from exc
    if not math.isfinite(value):
        raise SimulationError(f"{name} must be finite [s], got {value}")
    return value


def _progress_bar(total: int, desc: str) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", leave=False)


@dataclass(frozen=True, eq=False)
class Result:
    """A saved trajectory and its readouts.

    Attributes:
        scene: the simulated scene.
        t: sample times (n,) [s].
        q, v: configurations (n, nq) and velocities (n, nv).
        tau: controller output at the samples (n, n_actuated) [N·m or N].
        integrator: name of the method; dt: its step [s].
        n_rhs: right-hand-side evaluations; cpu_time: CPU time of the integration loop [s].
    """

    scene: Scene
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    integrator: str
    dt: float
    n_rhs: int
    cpu_time: float
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    @cached_property
    def _dynamics(self) -> Dynamics:
        return Dynamics(self.scene)

    def _link(self, i: int) -> int:
        n = len(self.scene.links)
        if not -n <= i < n:
            raise SimulationError(f"interconnection index {i} out of range: the scene has {n}")
        return i % n

    def _springs(self) -> list[list[Any]]:
        if "springs" not in self._cache:
            dyn = self._dynamics
            self._cache["springs"] = [dyn.springs(q, v) for q, v in zip(self.q, self.v, strict=True)]
        return self._cache["springs"]

    def _frame_rotations(self, frame: int) -> np.ndarray:
        model, data = self.scene.model, self._dynamics.data
        out = np.empty((len(self.t), 3, 3))
        for k, q in enumerate(self.q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, frame).rotation
        return out

    def _world(self, frame: int, local: np.ndarray) -> np.ndarray:
        R = self._frame_rotations(frame)
        return np.concatenate([np.einsum("nij,nj->ni", R, local[:, :3]), np.einsum("nij,nj->ni", R, local[:, 3:])], axis=1)

    def wrench(self, i: int) -> np.ndarray:
        """Wrench of interconnection i on the object (n, 6) [N, N·m]: force, then moment about the
        grasp point, in world-aligned axes."""
        i = self._link(i)
        local = np.array([s[i].G_f_G for s in self._springs()])
        return self._world(self.scene.links[i].grasp_frame, local)

    def arm_wrench(self, i: int) -> np.ndarray:
        """Wrench of interconnection i on its arm (n, 6) [N, N·m], about the tip point, world axes."""
        i = self._link(i)
        local = np.array([s[i].T_f_T for s in self._springs()])
        return self._world(self.scene.links[i].tip_frame, local)

    def deformation(self, i: int) -> np.ndarray:
        """Deformation e = log6(T_M_G) of interconnection i (n, 6) [m, rad], in tip-frame axes."""
        i = self._link(i)
        return np.array([s[i].e for s in self._springs()])

    def elastic_energy(self, i: int) -> np.ndarray:
        """½ eᵀ K e of interconnection i (n,) [J]."""
        e = self.deformation(i)
        K = self.scene.links[self._link(i)].K
        return 0.5 * np.einsum("ni,ij,nj->n", e, K, e)

    def energy(self) -> Energy:
        """Kinetic, gravity and elastic energy along the trajectory, each (n,) [J]."""
        dyn = self._dynamics
        parts = np.array([dyn.energy(q, v) for q, v in zip(self.q, self.v, strict=True)])
        return Energy(parts[:, 0], parts[:, 1], parts[:, 2])

    def frame_position(self, frame: str | int) -> np.ndarray:
        """World position of a frame of the scene model (n, 3) [m]."""
        model = self.scene.model
        if isinstance(frame, str):
            if not model.existFrame(frame):
                from .errors import did_you_mean

                raise SimulationError(f"no frame {frame!r} in the scene.{did_you_mean(frame, [f.name for f in model.frames])}")
            frame = int(model.getFrameId(frame))
        data = self._dynamics.data
        out = np.empty((len(self.t), 3))
        for k, q in enumerate(self.q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, frame).translation
        return out

    def tip_position(self, arm: int | str) -> np.ndarray:
        """World position of an arm's tip frame (n, 3) [m]."""
        return self.frame_position(self.scene.arms[self.scene.arm_index(arm)].tip_frame)

    def object_position(self) -> np.ndarray:
        """World position of the object frame origin (n, 3) [m]."""
        return self.frame_position(self.scene.object_frame)
