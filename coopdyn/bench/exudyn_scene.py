"""A coopdyn scene of revolute arms and a free-flying object built in Exudyn from coopdyn's own
model — the Exudyn peer of the benchmark's Panda scene.

The arms become one ``ObjectKinematicTree`` (Pinocchio's joint placements are Exudyn's joint
transformations and offsets; forward kinematics agree to round-off, tested), the object an
Exudyn rigid body with the same inertia, each interconnection Exudyn's own
``RigidBodySpringDamper`` with the same 6×6 K and D in the tip frame and its intrinsic (SE(3)
log) formulation. That law differs from coopdyn's at second order in the deformation (Exudyn's
is not the gradient of an energy), so Exudyn's errors are measured against Exudyn's own tight
reference. The controller is coopdyn's, called from the tree's ``forceUserFunction`` at every
evaluation with the arms' joint state (only controllers of the arm joints:
``GravityCompensationPD`` or none).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pinocchio as pin

from .._optional import require
from ..control import GravityCompensationPD
from ..errors import SimulationError
from ..model.scene import Scene

#: Exudyn's solvers in the comparison
EXUDYN_SOLVERS = ("RK44", "GeneralizedAlpha")


class ExudynScene:
    """A coopdyn scene in Exudyn (see the module docstring).

    Args:
        scene: revolute arms (1-DOF joints) and an object on a free-flyer.
        controller: ``GravityCompensationPD`` of this scene, or None.
    """

    def __init__(self, scene: Scene, controller: Callable[..., np.ndarray] | None) -> None:
        if scene.joint_springs.size:
            raise SimulationError("the Exudyn peer does not model elastic joints (their motors and springs); give rigid arms")
        exu: Any = require("exudyn", "the Exudyn peer", "exudyn")
        from exudyn.itemInterface import (  # type: ignore[import-not-found,unused-ignore]
            MarkerBodyRigid,
            MarkerKinematicTreeRigid,
            NodeGenericODE2,
            ObjectConnectorRigidBodySpringDamper,
            ObjectKinematicTree,
            SensorBody,
            SensorNode,
        )
        from exudyn.rigidBodyUtilities import (  # type: ignore[import-not-found,unused-ignore]
            HomogeneousTransformation,
            RigidBodyInertia,
        )

        if controller is not None and not (isinstance(controller, GravityCompensationPD) and controller.scene is scene):
            raise SimulationError("the Exudyn peer takes GravityCompensationPD of the same scene, or no controller")
        self.exu, self.scene, self.controller = exu, scene, controller
        model = scene.model
        arm_joints = [j for j in range(1, model.njoints) if model.joints[j].nv == 1]
        free = [j for j in range(1, model.njoints) if model.joints[j].nv == 6]
        if len(free) != 1 or len(arm_joints) + 1 != model.njoints - 1:
            raise SimulationError("the Exudyn peer takes revolute arms and one free-flying object")
        kinds = {"JointModelRX": "RevoluteX", "JointModelRY": "RevoluteY", "JointModelRZ": "RevoluteZ"}
        if any(model.joints[j].shortname() not in kinds for j in arm_joints):
            raise SimulationError("the Exudyn peer takes revolute joints about x, y or z")
        self._arm_q = np.array([model.joints[j].idx_q for j in arm_joints])
        self._arm_v = np.array([model.joints[j].idx_v for j in arm_joints])
        link = {j: i for i, j in enumerate(arm_joints)}
        self._q_full = scene.q0.copy()
        self._v_full = np.zeros(scene.nv)
        act_order = {v: i for i, v in enumerate(scene.actuated.tolist())}
        self._tau_of_link = np.array([act_order.get(int(v), -1) for v in self._arm_v])

        self.SC = exu.SystemContainer()
        mbs = self.mbs = self.SC.AddSystem()
        n = len(arm_joints)
        self._node = mbs.AddNode(
            NodeGenericODE2(
                referenceCoordinates=[0.0] * n,
                initialCoordinates=[0.0] * n,
                initialCoordinates_t=[0.0] * n,
                numberOfODE2Coordinates=n,
            )
        )
        damping = np.zeros(scene.nv)
        for arm in scene.arms:
            damping[arm.v_index] = arm.damping
        self._tree = mbs.AddObject(
            ObjectKinematicTree(
                nodeNumber=self._node,
                jointTypes=[getattr(exu.JointType, kinds[model.joints[j].shortname()]) for j in arm_joints],
                linkParents=[link.get(model.parents[j], -1) for j in arm_joints],
                jointTransformations=exu.Matrix3DList([model.jointPlacements[j].rotation.copy() for j in arm_joints]),
                jointOffsets=exu.Vector3DList([model.jointPlacements[j].translation.copy() for j in arm_joints]),
                linkInertiasCOM=exu.Matrix3DList([model.inertias[j].inertia.copy() for j in arm_joints]),
                linkCOMs=exu.Vector3DList([model.inertias[j].lever.copy() for j in arm_joints]),
                linkMasses=[float(model.inertias[j].mass) for j in arm_joints],
                jointPositionOffsetVector=[0.0] * n,
                jointVelocityOffsetVector=[0.0] * n,
                jointPControlVector=[0.0] * n,
                jointDControlVector=[float(damping[model.joints[j].idx_v]) for j in arm_joints],
                gravity=[float(g) for g in scene.gravity],
                forceUserFunction=cast(Any, self._force) if controller is not None else 0,
            )
        )
        j_box = free[0]
        if not model.jointPlacements[j_box].isIdentity():
            raise SimulationError("the Exudyn peer needs the free-flyer's placement to be the identity")
        self._box_q = model.joints[j_box].idx_q
        self._box_v = model.joints[j_box].idx_v
        I = model.inertias[j_box]
        oMb = pin.XYZQUATToSE3(scene.q0[self._box_q : self._box_q + 7])
        self._box = mbs.CreateRigidBody(
            referencePosition=oMb.translation.tolist(),
            referenceRotationMatrix=oMb.rotation,
            inertia=RigidBodyInertia(float(I.mass), I.inertia.copy(), I.lever.copy(), inertiaTensorAtCOM=True),
            gravity=[float(g) for g in scene.gravity],
            nodeType=exu.NodeType.RotationRotationVector,  # Lie-group node: explicit and implicit solvers
            show=False,
        )
        self._box_node = mbs.GetObject(self._box)["nodeNumber"]
        for lk in scene.links:
            ft, fg = model.frames[lk.tip_frame], model.frames[lk.grasp_frame]
            if ft.parentJoint not in link or fg.parentJoint != j_box:
                raise SimulationError("the Exudyn peer takes interconnections from an arm's tip to the object")
            if lk.element.kind != "se3":
                raise SimulationError("the Exudyn peer takes SE(3) spring-dampers")
            # the markers carry the tip and grasp frames (rotation and position on their bodies)
            m_tip = mbs.AddMarker(
                MarkerKinematicTreeRigid(
                    objectNumber=self._tree,
                    linkNumber=link[ft.parentJoint],
                    localHT=HomogeneousTransformation(ft.placement.rotation, ft.placement.translation),
                )
            )
            m_grasp = mbs.AddMarker(
                MarkerBodyRigid(
                    bodyNumber=self._box, localHT=HomogeneousTransformation(fg.placement.rotation, fg.placement.translation)
                )
            )
            mbs.AddObject(
                ObjectConnectorRigidBodySpringDamper(
                    markerNumbers=[m_tip, m_grasp],
                    stiffness=np.asarray(cast(Any, lk.element).K).tolist(),
                    damping=np.asarray(cast(Any, lk.element).D).tolist(),
                    useIntrinsicFormulation=True,
                )
            )
        out = exu.OutputVariableType
        self._sensors = [
            mbs.AddSensor(SensorNode(nodeNumber=self._node, outputVariableType=ov, storeInternal=True, writeToFile=False))
            for ov in (out.Coordinates, out.Coordinates_t)
        ] + [
            mbs.AddSensor(SensorBody(bodyNumber=self._box, outputVariableType=ov, storeInternal=True, writeToFile=False))
            for ov in (out.Position, out.RotationMatrix, out.VelocityLocal, out.AngularVelocityLocal)
        ]
        mbs.Assemble()

    def _force(self, mbs: Any, t: float, item: int, q: Any, q_t: Any) -> list[float]:
        self._q_full[self._arm_q] = q
        self._v_full[self._arm_v] = q_t
        assert self.controller is not None
        tau = np.asarray(self.controller(t, self._q_full, self._v_full), dtype=float)
        return [float(tau[i]) if i >= 0 else 0.0 for i in self._tau_of_link]

    def set_initial_state(self, q0: np.ndarray, v0: np.ndarray) -> None:
        """Exudyn's initial values from coopdyn's (q, v); the object starts at the scene's pose
        (its node's reference)."""
        if not np.allclose(q0[self._box_q : self._box_q + 7], self.scene.q0[self._box_q : self._box_q + 7], atol=0.0, rtol=0.0):
            raise SimulationError("the Exudyn peer starts the object at the scene's initial pose")
        mbs = self.mbs
        mbs.SetNodeParameter(self._node, "initialCoordinates", q0[self._arm_q].tolist())
        mbs.SetNodeParameter(self._node, "initialCoordinates_t", v0[self._arm_v].tolist())
        R = pin.XYZQUATToSE3(q0[self._box_q : self._box_q + 7]).rotation
        lin, ang = v0[self._box_v : self._box_v + 3], v0[self._box_v + 3 : self._box_v + 6]
        # rotation-vector node: [global velocity of the reference point; local angular velocity]
        mbs.SetNodeParameter(self._box_node, "initialVelocities", [*(R @ lin).tolist(), *ang.tolist()])
        mbs.Assemble()

    def run(
        self, q0: np.ndarray, v0: np.ndarray, t_final: float, dt: float, solver: str, rtol: float | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(t, Q, V) on a 10 ms grid in coopdyn's coordinates and the CPU seconds of ``SolveDynamic``
        (``solver``: an ``exudyn.DynamicSolverType`` name; ``rtol``: step control for an adaptive
        one, ``dt`` then its first step)."""
        exu = self.exu
        self.set_initial_state(q0, v0)
        settings = exu.SimulationSettings()
        settings.timeIntegration.numberOfSteps = round(t_final / dt)
        settings.timeIntegration.endTime = t_final
        settings.timeIntegration.verboseMode = 0
        settings.solution.file.write = False
        settings.solution.sensors.writePeriod = 0.01
        if rtol is not None:
            settings.timeIntegration.automaticStepSize = True
            settings.timeIntegration.relativeTolerance = rtol
            settings.timeIntegration.absoluteTolerance = rtol * 1e-2
            settings.timeIntegration.initialStepSize = dt
        settings.show.statistics = False
        settings.show.computationTime = False
        printing = exu.config.printToConsole
        exu.config.printToConsole = False  # Exudyn's notes (e.g. on the Python user function) are not ours to print
        try:
            cpu0 = time.process_time()
            ok = self.mbs.SolveDynamic(settings, solverType=getattr(exu.DynamicSolverType, solver))
            cpu = time.process_time() - cpu0
        finally:
            exu.config.printToConsole = printing
        data = [np.asarray(self.mbs.GetSensorStoredData(s)) for s in self._sensors]
        t = data[0][:, 0]
        n = t.size
        Q, V = np.tile(self.scene.q0, (n, 1)), np.zeros((n, self.scene.nv))
        Q[:, self._arm_q], V[:, self._arm_v] = data[0][:, 1:], data[1][:, 1:]
        for k in range(n):
            R = data[3][k, 1:].reshape(3, 3)
            Q[k, self._box_q : self._box_q + 7] = pin.SE3ToXYZQUAT(pin.SE3(R, data[2][k, 1:]))
        V[:, self._box_v : self._box_v + 3] = data[4][:, 1:]
        V[:, self._box_v + 3 : self._box_v + 6] = data[5][:, 1:]
        if not ok:
            raise SimulationError(f"Exudyn's {solver} did not finish")
        return t, Q, V, cpu
