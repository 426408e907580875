"""Exact first derivatives of the coupled dynamics: ∂q̈/∂(q, v, τ) and ∂(grasp wrenches)/∂(q, v).

The generalized force of the elements, ``Q = Σ Jrᵀ G_f_G``, is written as body-fixed wrenches on
the two frames of each element — ``G_f_G`` on G and its reaction ``T_f_T = −X.act(G_f_G)`` on T
(``X = T_M_G``) — so that ::

    q̈ = ABA(q, v, S τ − B v, fext(q, v))

with ``fext`` those wrenches moved to their joints. Pinocchio's ``computeABADerivatives`` with
``fext`` differentiates everything at fixed body-frame wrenches (the arms, the object, gravity,
Coriolis, the motion of the wrenches with their bodies); what is left is M⁻¹ times the
wrenches' own variation, through the element's :meth:`~coopdyn.model.elements.Element.tangent`:

* the pose: ``X(q ⊕ δq) = X·exp6(Jr δq)`` to first order (Jr is X's body Jacobian);
* the twist ``ξ = V_G − Ad(X⁻¹) V_T``: ``∂ξ/∂q = ∂V_G/∂q − ad(Ad(X⁻¹)V_T)·Jr − Ad(X⁻¹)·∂V_T/∂q``
  (Pinocchio's frame-velocity derivatives), ``∂ξ/∂v = Jr``;
* the reaction: ``∂T_f_T = −X.dual·(∂G_f_G + Λ(G_f_G)·Jr δq)``, Λ the linear map δ ↦ δ ×* f;
* an external wrench on the object, constant in world axes: its body-axes value turns with the
  object, ``∂f/∂δ_ω = [f]^``.

Every derivative is with respect to Pinocchio's tangent coordinates: ``q ⊕ δq =
pin.integrate(model, q, δq)`` (LOCAL for a free-flyer: δq = body twist · time).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..errors import KernelError
from ..model.elements import Element
from ..model.elements.joint_spring import JointSprings

LOCAL = pin.ReferenceFrame.LOCAL


class Derivatives(NamedTuple):
    """First derivatives of the dynamics at one state (see the module docstring)."""

    acceleration: np.ndarray  #: q̈ (nv,) [m/s², rad/s²]
    da_dq: np.ndarray  #: ∂q̈/∂δq (nv, nv) in tangent coordinates [1/s²]
    da_dv: np.ndarray  #: ∂q̈/∂v (nv, nv) [1/s]
    da_dtau: np.ndarray  #: ∂q̈/∂τ (nv, n_actuated): the columns of M⁻¹ of the actuated joints [1/kg, 1/(kg·m²)]
    wrench: np.ndarray  #: (L, 6) every element's G_f_G: wrench on G at G, G axes [N, N·m]
    dwrench_dq: np.ndarray  #: (L, 6, nv) [N or N·m per m or rad]
    dwrench_dv: np.ndarray  #: (L, 6, nv) [N or N·m per m/s or rad/s]
    exact: bool  #: False when an element's tangent is finite differences (its exact_tangent)


def motion_cross(w: np.ndarray) -> np.ndarray:
    """ad(w) (6, 6) for a twist w = [v; ω]: ``ad(w)·u = w × u`` (Pinocchio's Motion.cross)."""
    out = np.zeros((6, 6))
    out[:3, :3] = out[3:, 3:] = pin.skew(w[3:])
    out[:3, 3:] = pin.skew(w[:3])
    return out


def force_cross_map(f: np.ndarray) -> np.ndarray:
    """Λ(f) (6, 6) with ``Λ(f)·δ = δ ×* f`` for a wrench f = [force; torque] (linear in δ)."""
    out = np.zeros((6, 6))
    out[:3, 3:] = out[3:, :3] = -pin.skew(f[:3])
    out[3:, 3:] = -pin.skew(f[3:])
    return out


class RelativeTwist(NamedTuple):
    """A frame pair's (T, G) relative kinematics at (q, v) (:func:`relative_twist`)."""

    X: pin.SE3  #: T_M_G
    J_G: np.ndarray  #: G's LOCAL Jacobian (6, nv)
    J_T: np.ndarray  #: T's LOCAL Jacobian (6, nv)
    Jr: np.ndarray  #: the relative Jacobian J_G − Ad(X⁻¹) J_T (6, nv)
    xi: np.ndarray  #: the relative twist ξ = Jr v (6,)
    dxi_dq: np.ndarray  #: ∂ξ/∂q at fixed v (6, nv)


def relative_twist(model: pin.Model, data: pin.Data, t_id: int, g_id: int) -> RelativeTwist:
    """The relative kinematics of the frame pair (T, G) after ``computeForwardKinematicsDerivatives``
    and ``updateFramePlacements`` at (q, v) (the first fills the joint Jacobians too)."""
    nv = model.nv
    X = data.oMf[t_id].actInv(data.oMf[g_id])
    J_G = pin.getFrameJacobian(model, data, g_id, LOCAL).reshape(6, nv)
    J_T = pin.getFrameJacobian(model, data, t_id, LOCAL).reshape(6, nv)
    Ad_inv = X.toActionMatrixInverse()
    Jr = J_G - Ad_inv @ J_T
    dVG_dq, _ = pin.getFrameVelocityDerivatives(model, data, g_id, LOCAL)
    dVT_dq, _ = pin.getFrameVelocityDerivatives(model, data, t_id, LOCAL)
    V_T = Ad_inv @ pin.getFrameVelocity(model, data, t_id, LOCAL).vector  # V_T in G axes
    xi = pin.getFrameVelocity(model, data, g_id, LOCAL).vector - V_T
    return RelativeTwist(X, J_G, J_T, Jr, xi, dVG_dq - motion_cross(V_T) @ Jr - Ad_inv @ dVT_dq)


def dynamics_derivatives(
    model: pin.Model,
    data: pin.Data,
    links: Sequence[tuple[int, int, int, Element]],
    damping: np.ndarray,
    actuated: slice | np.ndarray,
    object_frame: int,
    q: np.ndarray,
    v: np.ndarray,
    tau_full: np.ndarray,
    object_wrench: np.ndarray | None,
    springs: JointSprings | None = None,
) -> Derivatives:
    """The derivatives at (q, v) for the generalized joint force ``tau_full`` (nv,) (torques on
    the actuated joints, already placed) — see the module docstring.

    Args:
        links: ``(link index, T frame, G frame, element)`` of every element with a force law.
        damping: the joints' viscous damping B (nv,).
        actuated: the actuated joints' indices into v.
        object_frame: the frame an ``object_wrench`` (6,) acts at (world axes, constant).
        springs: the elastic joints' transmissions (linear in the state: a generalized force
            and constant matrices).
    """
    nv = model.nv
    zero = np.zeros(nv)
    pin.computeForwardKinematicsDerivatives(model, data, q, v, zero)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    fext = [pin.Force.Zero() for _ in range(model.njoints)]
    dQ_dq, dQ_dv = np.zeros((nv, nv)), -np.diag(damping)
    n_links = len(links)
    W, dW_dq, dW_dv = np.zeros((n_links, 6)), np.zeros((n_links, 6, nv)), np.zeros((n_links, 6, nv))
    exact = True

    def frame_jacobian(frame: int) -> np.ndarray:
        return pin.getFrameJacobian(model, data, frame, LOCAL).reshape(6, nv)

    def add_wrench(frame: int, f: np.ndarray) -> None:
        joint = model.frames[frame].parentJoint
        fext[joint] += model.frames[frame].placement.act(pin.Force(f))

    for i, (_, t_id, g_id, element) in enumerate(links):
        X, J_G, J_T, Jr, xi, dxi_dq = relative_twist(model, data, t_id, g_id)
        f_G = element.evaluate(X, xi).G_f_G
        F_d, F_x = element.tangent(X, xi)
        exact = exact and bool(element.exact_tangent)
        df_dq = F_d @ Jr + F_x @ dxi_dq
        df_dv = F_x @ Jr
        dual = X.toDualActionMatrix()
        f_T = -(dual @ f_G)
        dfT_dq = -(dual @ (df_dq + force_cross_map(f_G) @ Jr))
        dfT_dv = -(dual @ df_dv)
        dQ_dq += J_G.T @ df_dq + J_T.T @ dfT_dq
        dQ_dv += J_G.T @ df_dv + J_T.T @ dfT_dv
        add_wrench(g_id, f_G)
        add_wrench(t_id, f_T)
        W[i], dW_dq[i], dW_dv[i] = f_G, df_dq, df_dv
    if object_wrench is not None:  # constant in world axes → body axes turn with the object
        R = data.oMf[object_frame].rotation
        f_o = np.concatenate([R.T @ object_wrench[:3], R.T @ object_wrench[3:]])
        J_o = frame_jacobian(object_frame)
        df = np.zeros((6, 6))
        df[:3, 3:], df[3:, 3:] = pin.skew(f_o[:3]), pin.skew(f_o[3:])
        dQ_dq += J_o.T @ (df @ J_o)
        add_wrench(object_frame, f_o)
    tau = tau_full - damping * v
    if springs is not None and springs.size:
        springs.add_force(tau, q, v)
        K_s, D_s = np.zeros((nv, nv)), np.zeros((nv, nv))
        springs.add_matrices(K_s, D_s)
        dQ_dq -= K_s
        dQ_dv -= D_s
    da_dq, da_dv, Minv = (np.array(m, copy=True) for m in pin.computeABADerivatives(model, data, q, v, tau, fext))
    Minv = np.triu(Minv) + np.triu(Minv, 1).T  # (Pinocchio fills the upper triangle)
    a = np.array(data.ddq, copy=True)
    if not (np.all(np.isfinite(da_dq)) and np.all(np.isfinite(da_dv)) and np.all(np.isfinite(a))):
        raise KernelError("the dynamics' derivatives are not finite at this state")
    da_dq += Minv @ dQ_dq
    da_dv += Minv @ dQ_dv
    return Derivatives(a, da_dq, da_dv, Minv[:, actuated], W, dW_dq, dW_dv, exact)


class MatrixDerivatives:
    """Exact derivatives of the linearly implicit methods' matrices applied to fixed vectors:
    ``G(q, v) = M(q) w_M + D̃(q, v) w_D + K̃(q, v) w_K`` (nv,), with K̃ and D̃ the Gauss–Newton
    matrices of :meth:`coopdyn.Dynamics.implicit_terms` — what the derivative of an implicit step
    needs (its step matrix and right-hand side are made of them).

    ``K̃ w = Σ Jrᵀ S_K Jr w`` is the generalized force of the body wrenches ``g = S_K·(Jr w)`` on
    G and ``−X.dual·g`` on T, so it is differentiated as :func:`dynamics_derivatives`
    differentiates the elements' force: the wrenches' own variation through
    :meth:`~coopdyn.model.elements.Element.matrix_tangent` and ``∂(Jr w)/∂q`` (Pinocchio's
    frame-velocity derivatives at the velocity w), their motion with the bodies together with
    ``∂(M w_M)/∂q`` from one ``computeRNEADerivatives(q, 0, w_M, −fext)`` without gravity
    (``RNEA(q, 0, a, fext) = M a − Σ Jᵀ fext`` there). B and the elastic joints' matrices are
    constant.

    Args:
        model: the scene's model (a copy without gravity is kept).
        links: ``(link index, T frame, G frame, element)`` of every element with a force law.
        damped: for each of ``links``, whether its S_D enters D̃ (the element's ``has_damping``).
    """

    def __init__(self, model: pin.Model, links: Sequence[tuple[int, int, int, Element]], damped: Sequence[bool]) -> None:
        self.model, self.data = model, model.createData()
        self.free = pin.Model(model)  # (no gravity: RNEA(q, 0, a) = M a)
        self.free.gravity = pin.Motion.Zero()
        self.free_data = self.free.createData()
        self.links, self.damped = list(links), list(damped)
        self.exact = all(element.exact_matrix_tangent for *_, element in self.links)

    def kinematics(self, q: np.ndarray, *velocities: np.ndarray) -> list[list[RelativeTwist]]:
        """:func:`relative_twist` of every link at q for each velocity (one pass each)."""
        model, data, zero = self.model, self.data, np.zeros(self.model.nv)
        out = []
        for w in velocities:
            pin.computeForwardKinematicsDerivatives(model, data, q, w, zero)  # (fills the joint Jacobians too)
            pin.updateFramePlacements(model, data)
            out.append([relative_twist(model, data, t_id, g_id) for _, t_id, g_id, _ in self.links])
        return out

    def __call__(
        self, q: np.ndarray, v: np.ndarray, w_M: np.ndarray, w_D: np.ndarray, w_K: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, tuple[list[RelativeTwist], ...]]:
        """``(∂G/∂q, ∂G/∂v)`` (nv, nv) at (q, v) in tangent coordinates, and the links'
        :func:`relative_twist` at v, w_D and w_K (for the parameters' columns)."""
        model, free, nv = self.model, self.free, self.model.nv
        at_v, at_D, at_K = self.kinematics(q, v, w_D, w_K)
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        dG_dq, dG_dv = np.zeros((nv, nv)), np.zeros((nv, nv))

        def add_wrench(frame: int, f: np.ndarray) -> None:
            joint = model.frames[frame].parentJoint
            fext[joint] -= model.frames[frame].placement.act(pin.Force(f))  # (−fext: RNEA subtracts Jᵀ fext)

        for (_, t_id, g_id, element), damped, kin_v, kin_D, kin_K in zip(self.links, self.damped, at_v, at_D, at_K, strict=True):
            X, J_G, J_T, Jr, xi, dxi_dq = kin_v
            xi_K, dxiK_dq, xi_D, dxiD_dq = kin_K.xi, kin_K.dxi_dq, kin_D.xi, kin_D.dxi_dq
            if not damped:
                xi_D, dxiD_dq = np.zeros(6), np.zeros((6, nv))
            ev = element.evaluate(X, xi, True)
            g = ev.S_K @ xi_K + ev.S_D @ xi_D
            G_d, G_x = element.matrix_tangent(X, xi, xi_K, xi_D)
            dg_dq = G_d @ Jr + G_x @ dxi_dq + ev.S_K @ dxiK_dq + ev.S_D @ dxiD_dq
            dg_dv = G_x @ Jr
            dual = X.toDualActionMatrix()
            dG_dq += J_G.T @ dg_dq - J_T.T @ (dual @ (dg_dq + force_cross_map(g) @ Jr))
            dG_dv += J_G.T @ dg_dv - J_T.T @ (dual @ dg_dv)
            add_wrench(g_id, g)
            add_wrench(t_id, -(dual @ g))
        dtau_dq, _, _ = pin.computeRNEADerivatives(free, self.free_data, q, np.zeros(nv), w_M, fext)
        return dG_dq + np.asarray(dtau_dq), dG_dv, (at_v, at_D, at_K)
