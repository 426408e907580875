"""The rigid limit's dynamics: rigid grasps as kinematic constraints (Pinocchio's ``constraintDynamics``).

A scene whose interconnections include rigid elements (:mod:`coopdyn.model.elements.rigid`) runs
on :class:`ConstrainedDynamics`: the force elements contribute ``Q`` as on the Python path, and
each rigid grasp becomes a ``RigidConstraintModel`` (``CONTACT_6D`` for ``"rigid"``,
``CONTACT_3D`` for ``"rigid_point"``) between the object's joint at G and the arm's (or the
world's) joint at T. ``constraintDynamics`` then solves

    H q̈ + h = S τ − B q̇ + Q + Σ_c J_cᵀ λ_c,   J_c q̈ + J̇_c q̇ = −Kp·drift − Kd·(drift rate)

with Baumgarte stabilisation. λ_c, the wrench on the object at G in G axes, is what
:meth:`readouts` report as the interconnection's wrench. Where the constraints are redundant (a
rigid object held at two grasps by arms that cannot move it, or by fixtures) the force is
statically indeterminate, and the proximal solver returns the solution of least Euclidean norm
(the stacked λ in SI units): one particular distribution of the internal force.

Only explicit integrators run it (a linearly implicit step would need the constrained step
matrix); :func:`check_integrator` says so.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import KernelError, SimulationError
from ..model.scene import Scene
from .dynamics import KINDS, PythonDynamics, Readouts

#: The proximal solver's settings: absolute and relative accuracy, regularisation μ, iterations.
#: μ only has to be small against the constraints' inverse inertia; the iterations from λ = 0
#: converge to the least-norm λ where the constraints are redundant.
PROXIMAL = (1e-12, 1e-12, 1e-4, 200)

_TYPES = {"6D": pin.ContactType.CONTACT_6D, "3D": pin.ContactType.CONTACT_3D}


def has_constraints(scene: Scene) -> bool:
    """Whether a scene has rigid (constraint) interconnections."""
    return bool(scene.constraints)


def check_integrator(scene: Scene, method: Any) -> None:
    """Refuse an implicit or exponential integrator for a scene with rigid grasps."""
    if has_constraints(scene) and (method.a_stable or method.exact_discretisation):
        raise SimulationError(
            f"{method.name} cannot run a scene with rigid grasps (the rigid limit): they are solved as constraints, "
            "which the linearly implicit and exponential steps do not take. Use an explicit method: rk4, dopri5, "
            "dop853 or symplectic_euler"
        )


class ConstrainedDynamics(PythonDynamics):
    """The Python dynamics plus the rigid grasps as constraints (see the module docstring)."""

    backend = "python"

    def __init__(self, scene: Scene, backend: str | None = None) -> None:
        super().__init__(scene, backend)
        model = self.model
        self._constrained = scene.constraints
        self._cmodels = pin.StdVec_RigidConstraintModel()
        self._cdatas = pin.StdVec_RigidConstraintData()
        for i in self._constrained:
            lk = scene.links[i]
            G, T = model.frames[lk.grasp_frame], model.frames[lk.tip_frame]
            c = pin.RigidConstraintModel(
                _TYPES[str(lk.element.constraint)],
                model,
                G.parentJoint,
                G.placement,
                T.parentJoint,
                T.placement,
                pin.ReferenceFrame.LOCAL,
            )
            c.name = lk.name
            c.m_baumgarte_parameters.Kp = lk.element.kp  # type: ignore[attr-defined]
            c.m_baumgarte_parameters.Kd = lk.element.kd  # type: ignore[attr-defined]
            self._cmodels.append(c)
            self._cdatas.append(c.createData())
        self._cdata_model = model.createData()  # constraintDynamics' own Data (it resizes internals)
        pin.initConstraintDynamics(model, self._cdata_model, self._cmodels, self._cdatas)
        self._settings = pin.ProximalSettings(*PROXIMAL)

    def _solve(self, q: np.ndarray, v: np.ndarray, generalized: np.ndarray) -> np.ndarray:
        """q̈ under the constraints, for the generalized force ``generalized`` (nv,) besides
        gravity and the velocity terms; λ stays in the constraint data."""
        a = pin.constraintDynamics(self.model, self._cdata_model, q, v, generalized, self._cmodels, self._cdatas, self._settings)
        return np.array(a)

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> np.ndarray:
        a = self._solve(q, v, self._generalized_force(q, v, tau, False, object_wrench))
        # An exact constraint does no work; while the state drifts, the stabilisation does
        # (λ · relative velocity of the grasp frames). The energy balance counts it as dissipated
        # power (negative when it feeds energy in).
        self._dissipation -= sum(float(cd.contact_force.vector @ cd.contact_velocity_error.vector) for cd in self._cdatas)
        return a

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        raise KernelError("a scene with rigid grasps runs with explicit integrators only (rk4, dopri5, dop853, symplectic_euler)")

    def constraint_wrenches(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> np.ndarray:
        """Every rigid grasp's wrench on the object at G, in G axes (n_rigid, 6) [N, N·m], at
        (q, v) under the arm torques ``tau`` (a point grasp's moment is zero)."""
        self.acceleration(q, v, tau, object_wrench)
        out = np.zeros((len(self._constrained), 6))
        for k, cd in enumerate(self._cdatas):
            out[k] = cd.contact_force.vector  # a point grasp's has no moment
        return out

    def readouts(self, Q: np.ndarray, V: np.ndarray, TAU: np.ndarray | None = None) -> Readouts:
        r = super().readouts(Q, V)
        if TAU is None:
            raise KernelError("the readouts of a scene with rigid grasps need the torques along the trajectory")
        model, data = self.model, self.data
        for k in range(len(Q)):
            lam = self.constraint_wrenches(Q[k], V[k], TAU[k])  # leaves Q[k]'s kinematics in data
            for j, i in enumerate(self._constrained):
                lk = self.scene.links[i]
                oMG = pin.updateFramePlacement(model, data, lk.grasp_frame)
                oMT = pin.updateFramePlacement(model, data, lk.tip_frame)
                f_T = -(oMT.actInv(oMG).act(pin.Force(lam[j]))).vector  # action = reaction, in T
                r.object_wrench[k, i, :3], r.object_wrench[k, i, 3:] = oMG.rotation @ lam[j, :3], oMG.rotation @ lam[j, 3:]
                r.arm_wrench[k, i, :3], r.arm_wrench[k, i, 3:] = oMT.rotation @ f_T[:3], oMT.rotation @ f_T[3:]
        return r


KINDS["constrained"] = ConstrainedDynamics

__all__ = ["ConstrainedDynamics", "check_integrator", "has_constraints"]
