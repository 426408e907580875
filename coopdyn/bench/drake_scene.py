"""Any coopdyn scene of revolute/prismatic arms and a free-flying object, built as a Drake
``MultibodyPlant`` from coopdyn's own model, with coopdyn's interconnection law and controller
as the plant's applied generalized force — the Drake peer of the benchmark's Panda scene.

What is carried over, as for MuJoCo (:mod:`.mujoco_scene`): every joint's placement, axis and
inertia (one Drake body per Pinocchio joint, Pinocchio having merged the fixed links), joint
damping (Drake's own), gravity, the initial state. Drake's bushing
(``LinearBushingRollPitchYaw``) is not coopdyn's SE(3) spring (it measures roll–pitch–yaw
angles, singular at ±90° pitch), so each interconnection's wrench is coopdyn's element law,
evaluated by coopdyn's compiled kernel in a Drake ``LeafSystem`` together with the controller
and fed to the plant's ``applied_generalized_force`` input. Before any timing,
:meth:`DrakeScene.check` compares Drake's accelerations with coopdyn's at random states.

Two ways of running it, as Drake users do:

* ``"discrete"``: ``MultibodyPlant(time_step=dt)``, Drake's default discrete solver (joint
  damping implicit; the applied forces held over the step);
* a continuous plant with one of Drake's error-controlled integrators (``"runge_kutta3"``,
  Drake's default, or ``"runge_kutta5"``) at a target accuracy.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from .._optional import require
from ..errors import CoopdynError, SimulationError
from ..model.scene import Scene
from ..mujoco import _rotation

_AXES = {"RX": (1.0, 0.0, 0.0), "RY": (0.0, 1.0, 0.0), "RZ": (0.0, 0.0, 1.0)}
_AXES.update({"P" + k[1]: a for k, a in list(_AXES.items())})
#: Drake's integrators the peer runs on a continuous plant, by their Drake names
CONTINUOUS = ("runge_kutta3", "runge_kutta5")


def drake_available() -> bool:
    """True when ``import pydrake`` works."""
    try:
        import pydrake  # type: ignore[import-not-found,unused-ignore]  # noqa: F401
    except ImportError:
        return False
    return True


class DrakeScene:
    """A coopdyn scene in Drake (see the module docstring).

    Args:
        scene: revolute/prismatic arms, at most one free-flyer (the object).
        controller: coopdyn's ``controller(t, q, v) -> τ`` (Pinocchio q, v), or None.
        time_step: Drake's discrete step [s]; 0 builds a continuous plant.
    """

    def __init__(self, scene: Scene, controller: Callable[..., np.ndarray] | None, time_step: float = 0.0) -> None:
        if not isinstance(scene, Scene):
            raise SimulationError(f"the Drake peer takes a coopdyn.Scene, got {type(scene).__name__}")
        if scene.joint_springs.size:
            raise SimulationError("the Drake peer does not model elastic joints (their motors and springs); give rigid arms")
        time_step = _validate.number(time_step, "time_step", "s", SimulationError)
        if time_step < 0:
            raise SimulationError(f"time_step must be >= 0 [s] (0: a continuous plant), got {time_step!r}")
        drake: Any = require("pydrake.all", "the Drake peer", "coopdyn[peers]")
        self.drake, self.scene, self.controller = drake, scene, controller
        model = scene.model
        plant = self.plant = drake.MultibodyPlant(time_step=float(time_step))
        damping = np.zeros(model.nv)
        for arm in scene.arms:
            damping[arm.v_index] = arm.damping
        bodies: dict[int, Any] = {0: plant.world_body()}
        self._free_body: Any = None
        free_joint = 0
        for j in range(1, model.njoints):
            name, kind = model.names[j], model.joints[j].shortname().replace("JointModel", "")
            I = model.inertias[j]
            # Pinocchio allows a massless body, Drake does not: 1e-9 kg and kg·m² change no acceleration
            # the check below can see (as in the MuJoCo peer)
            mass = max(float(I.mass), 1e-9)
            Ic = np.asarray(I.inertia) if I.mass > 0 else np.eye(3) * 1e-9
            inertia = drake.SpatialInertia.MakeFromCentralInertia(
                mass,
                np.asarray(I.lever, dtype=float),
                drake.RotationalInertia(*(float(Ic[i, k]) for i, k in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))),
            )
            body = bodies[j] = plant.AddRigidBody(name, inertia)
            if kind == "FreeFlyer":
                if self._free_body is not None:
                    raise SimulationError("the Drake peer takes one free-flying body")
                if not model.jointPlacements[j].isIdentity() or model.parents[j] != 0:
                    raise SimulationError("the Drake peer needs the free-flyer attached to the world at the identity")
                self._free_body, free_joint = body, j
                continue
            if kind not in _AXES:
                raise SimulationError(f"the Drake peer takes revolute, prismatic and free-flyer joints; {name!r} is {kind}")
            M = model.jointPlacements[j]
            X = drake.RigidTransform(drake.RotationMatrix(np.asarray(M.rotation)), np.asarray(M.translation))
            parent = plant.AddFrame(drake.FixedOffsetFrame(f"{name}_parent", bodies[model.parents[j]].body_frame(), X))
            cls = drake.RevoluteJoint if kind.startswith("R") else drake.PrismaticJoint
            plant.AddJoint(cls(name, parent, body.body_frame(), np.array(_AXES[kind]), float(damping[model.joints[j].idx_v])))
        plant.mutable_gravity_field().set_gravity_vector(np.asarray(scene.gravity, dtype=float))
        plant.Finalize()
        if plant.num_velocities() != model.nv or plant.num_positions() != model.nq:
            raise SimulationError("the Drake plant's size differs from coopdyn's model")
        # Pinocchio ↔ Drake index maps (1-DOF joints), and the free body's blocks
        qi, qd, vi, vd = [], [], [], []
        for j in range(1, model.njoints):
            if j == free_joint:
                continue
            joint = plant.GetJointByName(model.names[j])
            qi.append(model.joints[j].idx_q)
            qd.append(joint.position_start())
            vi.append(model.joints[j].idx_v)
            vd.append(joint.velocity_start())
        self._qi, self._qd, self._vi, self._vd = (np.array(x, dtype=int) for x in (qi, qd, vi, vd))
        self._free: tuple[int, int, int, int] | None = None  # (pin idx_q, pin idx_v, drake q start, drake v start)
        self._R: np.ndarray | None = None  # the free body's rotation at the last to_pinocchio state
        if self._free_body is not None:
            jm = model.joints[free_joint]
            self._free = (
                jm.idx_q,
                jm.idx_v,
                self._free_body.floating_positions_start(),
                self._free_body.floating_velocities_start_in_v(),
            )
        from ..dynamics import Dynamics

        self._dynamics = Dynamics(scene)
        self._built: Any = None  # the diagram, once run() has built it
        self._actuated = np.asarray(scene.actuated, dtype=int)

    # --- state and force conversion (Pinocchio ↔ Drake) ----------------------------------------
    def to_drake(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Drake's state x = (q, v) (nq + nv,) from Pinocchio's q (nq,) and v (nv,)."""
        nq = self.plant.num_positions()
        x = np.zeros(nq + self.plant.num_velocities())
        x[self._qd] = q[self._qi]
        x[nq + self._vd] = v[self._vi]
        if self._free is not None:
            iq, iv, qa, va = self._free
            qx, qy, qz, qw = q[iq + 3 : iq + 7]
            x[qa : qa + 7] = [qw, qx, qy, qz, *q[iq : iq + 3]]
            R = _rotation(qw, qx, qy, qz)
            x[nq + va : nq + va + 3] = R @ v[iv + 3 : iv + 6]  # ω in the world frame
            x[nq + va + 3 : nq + va + 6] = R @ v[iv : iv + 3]  # the origin's velocity in the world frame
        return x

    def to_pinocchio(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pinocchio's q (nq,) and v (nv,) from Drake's state x (nq + nv,); the free body's
        rotation is kept for :meth:`generalized_force` at this state."""
        model, nq = self.scene.model, self.plant.num_positions()
        q, v = np.zeros(model.nq), np.zeros(model.nv)
        q[self._qi] = x[self._qd]
        v[self._vi] = x[nq + self._vd]
        if self._free is not None:
            iq, iv, qa, va = self._free
            qw, qx, qy, qz = x[qa : qa + 4] / np.linalg.norm(x[qa : qa + 4])
            q[iq : iq + 3] = x[qa + 4 : qa + 7]
            q[iq + 3 : iq + 7] = [qx, qy, qz, qw]
            R = self._R = _rotation(qw, qx, qy, qz)
            v[iv : iv + 3] = R.T @ x[nq + va + 3 : nq + va + 6]
            v[iv + 3 : iv + 6] = R.T @ x[nq + va : nq + va + 3]
        return q, v

    def generalized_force(self, t: float, q: np.ndarray, v: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        """The interconnections' and the controller's generalized force (nv,) [N, N·m] at time t [s]
        and Pinocchio's (q, v), in Drake's velocity coordinates (``R``: the free body's rotation at
        q, when known)."""
        Q = self._dynamics.generalized_spring_force(q, v)  # joint damping is Drake's own
        if self.controller is not None:
            Q[self._actuated] += np.asarray(self.controller(t, q, v), dtype=float)
        out = np.zeros(self.plant.num_velocities())
        out[self._vd] = Q[self._vi]
        if self._free is not None:
            iq, iv, _, va = self._free
            R = _rotation(q[iq + 6], *q[iq + 3 : iq + 6]) if R is None else R
            out[va : va + 3] = R @ Q[iv + 3 : iv + 6]  # Q·v = (R Q_ang)·ω_W + (R Q_lin)·v_W
            out[va + 3 : va + 6] = R @ Q[iv : iv + 3]
        return out

    def _diagram(self) -> Any:
        """The plant with the force system in a loop, built once (a plant belongs to one diagram)."""
        if self._built is not None:
            return self._built
        drake, plant, peer = self.drake, self.plant, self
        nx = plant.num_positions() + plant.num_velocities()

        class Forces(drake.LeafSystem):  # type: ignore[name-defined,unused-ignore]
            def __init__(self) -> None:
                super().__init__()
                self.x = self.DeclareVectorInputPort("x", nx)
                self.DeclareVectorOutputPort("tau", plant.num_velocities(), self.calc)

            def calc(self, context: Any, output: Any) -> None:
                q, v = peer.to_pinocchio(self.x.Eval(context))
                output.SetFromVector(peer.generalized_force(context.get_time(), q, v, peer._R))

        builder = drake.DiagramBuilder()
        builder.AddSystem(plant)
        forces = builder.AddSystem(Forces())
        builder.Connect(plant.get_state_output_port(), forces.get_input_port(0))
        builder.Connect(forces.get_output_port(0), plant.get_applied_generalized_force_input_port())
        self._built = builder.Build()
        return self._built

    # --- checks and runs -------------------------------------------------------------------------
    def check(self, n: int = 5, seed: int = 0) -> float:
        """Largest relative difference between Drake's and coopdyn's accelerations (controller
        included) at ``n`` random states near the initial one (continuous plants only)."""
        from ..closed_loop import System

        if self.plant.time_step() > 0:
            raise SimulationError("check() needs a continuous plant (time_step=0)")
        system = System(self._dynamics, self.controller)
        plant, nq = self.plant, self.plant.num_positions()
        context = plant.CreateDefaultContext()
        rng = np.random.default_rng(seed)
        worst = 0.0
        for _ in range(n):
            q = pin.integrate(self.scene.model, self.scene.q0, rng.normal(size=self.scene.nv) * 0.05)
            v = rng.normal(size=self.scene.nv) * 0.3
            x = self.to_drake(q, v)
            plant.SetPositionsAndVelocities(context, x)
            plant.get_applied_generalized_force_input_port().FixValue(context, self.generalized_force(0.0, q, v))
            xdot = plant.EvalTimeDerivatives(context).CopyToVector()
            a_dk = self._acceleration(x, xdot[nq:])
            a_cd = system.acceleration(0.0, q, v)
            worst = max(worst, float(np.max(np.abs(a_dk - a_cd)) / max(1.0, np.max(np.abs(a_cd)))))
        return worst

    def _acceleration(self, x: np.ndarray, vdot: np.ndarray) -> np.ndarray:
        """Drake's v̇ in Pinocchio's convention."""
        a = np.zeros(self.scene.nv)
        a[self._vi] = vdot[self._vd]
        if self._free is not None:
            _, iv, qa, va = self._free
            nq = self.plant.num_positions()
            R = _rotation(*(x[qa : qa + 4] / np.linalg.norm(x[qa : qa + 4])))
            omega = R.T @ x[nq + va : nq + va + 3]
            v_lin = R.T @ x[nq + va + 3 : nq + va + 6]
            a[iv : iv + 3] = R.T @ vdot[va + 3 : va + 6] - np.cross(omega, v_lin)  # p̈ = R(v̇ + ω × v)
            a[iv + 3 : iv + 6] = R.T @ vdot[va : va + 3]  # ω̇_W = R ω̇
        return a

    def run(
        self,
        q0: np.ndarray,
        v0: np.ndarray,
        t_final: float,
        output_interval: float,
        integrator: str | None = None,
        accuracy: float = 1e-3,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
        """Simulate from (q0, v0) to t_final; (t, Q, V) every ``output_interval`` [s] (Pinocchio
        convention), the CPU seconds of the simulation and the number of steps Drake took. A
        discrete plant steps at its time_step; a continuous one uses ``integrator`` (one of
        :data:`CONTINUOUS`) at the target ``accuracy``. Stops early at a non-finite state."""
        model = self.scene.model
        q0 = _validate.finite_array(q0, "q0", (model.nq,), SimulationError)
        v0 = _validate.finite_array(v0, "v0", (model.nv,), SimulationError)
        t_final = _validate.positive(t_final, "t_final", "s", SimulationError)
        output_interval = _validate.positive(output_interval, "output_interval", "s", SimulationError)
        accuracy = _validate.positive(accuracy, "accuracy", "1", SimulationError)
        drake, plant = self.drake, self.plant
        diagram = self._diagram()
        context = diagram.CreateDefaultContext()
        plant_context = plant.GetMyMutableContextFromRoot(context)
        plant.SetPositionsAndVelocities(plant_context, self.to_drake(q0, v0))
        simulator = drake.Simulator(diagram, context)
        if plant.time_step() == 0:
            if integrator not in CONTINUOUS:
                raise SimulationError(f"a continuous Drake plant runs {CONTINUOUS}, not {integrator!r}")
            drake.ResetIntegratorFromFlags(simulator, integrator, output_interval)
            simulator.get_mutable_integrator().set_target_accuracy(accuracy)
        simulator.Initialize()
        n_out = round(t_final / output_interval)
        ts, Q, V = [0.0], [np.asarray(q0, dtype=float).copy()], [np.asarray(v0, dtype=float).copy()]
        cpu0 = time.process_time()
        try:
            for k in range(1, n_out + 1):
                simulator.AdvanceTo(min(k * output_interval, t_final))
                x = plant.GetPositionsAndVelocities(plant_context)
                if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > 1e6:
                    break
                q, v = self.to_pinocchio(x)
                ts.append(k * output_interval)
                Q.append(q)
                V.append(v)
        except CoopdynError:  # coopdyn's own failures (a controller's, a kernel's) are not a diverged run
            raise
        except RuntimeError:  # Drake's integrator gave up (its step fell below its minimum): the samples so far
            pass
        cpu = time.process_time() - cpu0
        if plant.time_step() > 0:
            steps = round(ts[-1] / plant.time_step())
        else:
            steps = int(simulator.get_integrator().get_num_steps_taken())
        return np.array(ts), np.array(Q), np.array(V), cpu, steps
