"""The right-hand side of the cooperative system and its readouts.

Arm and object equations (DESIGN §1–§2), all in one merged model::

    H(q) q̈ + h(q, q̇) = S τ − B q̇ + Σ_i (J_Gᵢᵀ G_f_G + J_Tᵢᵀ T_f_T)

with S selecting the arm joints, B the viscous joint damping, and the interconnection wrenches
of :func:`coopdyn.interconnection.spring` mapped to joint space by the frame Jacobians.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from ..model.interconnection import SpringState, spring
from ..model.scene import Scene
from . import backend as _backend

LOCAL = pin.ReferenceFrame.LOCAL


class Energy(NamedTuple):
    """Energies of one state [J]."""

    kinetic: Any  #: float, or (n,) along a trajectory
    potential: Any  #: gravity, zero at the world origin
    elastic: Any  #: Σ ½ eᵀ K e over the interconnections

    @property
    def total(self) -> Any:
        """kinetic + potential + elastic [J]."""
        return self.kinetic + self.potential + self.elastic


class Dynamics:
    """Scratch space and evaluation of the scene's dynamics (one instance per thread).

    Args:
        scene: the scene; not modified.
        backend: ``"native"``, ``"python"`` or ``"auto"`` (see :mod:`coopdyn.backend`); ``None``
            reads the environment variable ``COOPDYN_BACKEND`` (default ``"auto"``).

    Attributes:
        backend: the backend that runs, ``"native"`` or ``"python"``.
    """

    def __init__(self, scene: Scene, backend: str | None = None) -> None:
        self.scene = scene
        model = scene.model
        self.model = model
        self.data = model.createData()
        # Per link: (T frame, G frame, K, D, whether D ≠ 0)
        self._hot = [(lk.tip_frame, lk.grasp_frame, lk.K, lk.D, bool(np.any(lk.D))) for lk in scene.links]
        self._damping = np.zeros(model.nv)
        for arm in scene.arms:
            self._damping[arm.v_index] = arm.damping
        self._has_damping = bool(np.any(self._damping))
        self.actuated_index = scene.actuated_index
        self._dissipation = 0.0
        self.backend = _backend.resolve(backend)
        self._kernel = None
        if self.backend == "native":
            self._kernel = _backend.kernel_module().Kernel(
                model,
                self.data,
                [(t, g, K, D) for t, g, K, D, _ in self._hot],
                self._damping,
                np.asarray(scene.actuated, dtype=np.int32),
                scene.object_frame,
            )

    @property
    def last_dissipation(self) -> float:
        """Power dissipated by dampers [W] at the state of the last right-hand side or implicit
        evaluation."""
        return self._kernel.last_dissipation if self._kernel is not None else self._dissipation

    # -- interconnections ---------------------------------------------------------------------
    def _springs(self) -> list[SpringState]:
        """Spring states after ``forwardKinematics(q, v)`` has run."""
        model, data = self.model, self.data
        out = []
        for t_id, g_id, K, D, _ in self._hot:
            oMT = pin.updateFramePlacement(model, data, t_id)
            oMG = pin.updateFramePlacement(model, data, g_id)
            T_v_T = pin.getFrameVelocity(model, data, t_id, LOCAL).vector
            G_v_G = pin.getFrameVelocity(model, data, g_id, LOCAL).vector
            out.append(spring(oMT, oMG, T_v_T, G_v_G, K, D))
        return out

    def springs(self, q: np.ndarray, v: np.ndarray) -> list[SpringState]:
        """The state of every interconnection at (q, v), in scene order."""
        pin.forwardKinematics(self.model, self.data, q, v)
        return self._springs()

    def _interconnections(
        self, q: np.ndarray, v: np.ndarray, matrices: bool, object_wrench: np.ndarray | None = None
    ) -> np.ndarray:
        """Run kinematics at (q, v) and return the interconnections' generalized force Q (nv,).

        With the LOCAL frame Jacobians, ``Jr = J_G − Ad(T_M_G⁻¹) J_T`` maps q̇ to the relative
        twist ξ and ``A = Jlog6(T_M_G) Jr`` maps q̇ to ė, so ``Q = −Σ Aᵀ (K e + D A q̇)`` — the
        same as ``J_Gᵀ G_f_G + J_Tᵀ T_f_T``. Also sets ``last_dissipation`` and, with
        ``matrices``, ``self.K_t = Σ Aᵀ K A`` and ``self.D_t = Σ Aᵀ D A + B``.
        """
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)  # forward kinematics (positions) + joint Jacobians
        Q = np.zeros(model.nv)
        p_diss = 0.0
        if matrices:
            K_t = np.zeros((model.nv, model.nv))
            D_t = np.diag(self._damping)
        for t_id, g_id, K, D, has_d in self._hot:
            T_M_G = pin.updateFramePlacement(model, data, t_id).actInv(pin.updateFramePlacement(model, data, g_id))
            J_G = pin.getFrameJacobian(model, data, g_id, LOCAL)
            J_T = pin.getFrameJacobian(model, data, t_id, LOCAL)
            A = pin.Jlog6(T_M_G) @ (J_G - T_M_G.toActionMatrixInverse() @ J_T)
            w = K @ pin.log6(T_M_G).vector
            if has_d:
                e_dot = A @ v
                D_e_dot = D @ e_dot
                p_diss += e_dot @ D_e_dot
                w += D_e_dot
            Q -= A.T @ w
            if matrices:
                K_t += A.T @ K @ A
                if has_d:
                    D_t += A.T @ D @ A
        if matrices:
            self.K_t, self.D_t = K_t, D_t
        if object_wrench is not None:  # world-aligned wrench at the object frame origin → LOCAL
            fo = self.scene.object_frame
            R = pin.updateFramePlacement(model, data, fo).rotation
            local = np.concatenate([R.T @ object_wrench[:3], R.T @ object_wrench[3:]])
            Q += pin.getFrameJacobian(model, data, fo, LOCAL).T @ local
        if self._has_damping:
            p_diss += v @ (self._damping * v)
        self._dissipation = p_diss
        return Q

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> np.ndarray:
        """Joint accelerations q̈ (nv,) for arm torques ``tau`` (n_actuated,) [N·m or N] and an
        optional external wrench on the object (6,) [N, N·m] (world axes, at the object frame origin).

        This is the hot path: the interconnection wrenches enter ABA as the generalized force
        ``Q`` (see :meth:`_interconnections`), which costs fewer Python-level operations than
        moving each wrench to its joint as an external force.
        """
        if self._kernel is not None:
            return self._kernel.acceleration(q, v, tau, object_wrench)
        t = self._interconnections(q, v, False, object_wrench)
        t[self.actuated_index] += tau
        if self._has_damping:
            t -= self._damping * v
        return pin.aba(self.model, self.data, q, v, t).copy()

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, ...]:
        """What a linearly implicit step needs at (q, v), from one kinematics pass:
        ``(f, M, K̃, D̃)`` with ``f = S τ + Q − B q̇ − b(q, q̇) = M q̈`` (nv,) and the matrices of
        :meth:`stiffness` (nv, nv)."""
        if self._kernel is not None:
            return self._kernel.implicit_terms(q, v, tau, object_wrench)
        model, data = self.model, self.data
        f = self._interconnections(q, v, True, object_wrench)
        f[self.actuated_index] += tau
        if self._has_damping:
            f -= self._damping * v
        f -= pin.nonLinearEffects(model, data, q, v)
        return f, pin.crba(model, data, q).copy(), self.K_t, self.D_t

    def implicit_euler_velocity(
        self,
        q: np.ndarray,
        v: np.ndarray,
        tau: np.ndarray,
        h: float,
        kp: np.ndarray,
        kd: np.ndarray,
        object_wrench: np.ndarray | None = None,
    ) -> np.ndarray:
        """The velocity after one linearly implicit Euler step of ``h`` [s] from (q, v):
        ``v⁺ = v + h k`` with ``(M + h D̃ + h² K̃) k = f − h K̃ v``, where K̃ and D̃ include the
        joint PD gains ``kp``, ``kd`` (n_actuated,) [N·m/rad], [N·m·s/rad] and f is that of
        :meth:`implicit_terms`. One kinematics pass and one Cholesky factorisation."""
        if self._kernel is not None:
            return self._kernel.implicit_euler_velocity(q, v, tau, h, kp, kd, object_wrench)
        f, M, K, D = self.implicit_terms(q, v, tau, object_wrench)
        self.add_joint_gains(K, D, kp, kd)
        return v + h * np.linalg.solve(M + h * D + (h * h) * K, f - h * (K @ v))

    def add_joint_gains(self, K: np.ndarray, D: np.ndarray, kp: np.ndarray, kd: np.ndarray) -> None:
        """Add joint PD gains (n_actuated,) to the diagonals of K̃ and D̃ (nv, nv), in place."""
        act = self.scene.actuated
        K[act, act] += kp
        D[act, act] += kd

    def generalized_spring_force(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Σ (J_Gᵀ G_f_G + J_Tᵀ T_f_T), the interconnections' generalized force (nv,)."""
        model, data = self.model, self.data
        states = self.springs(q, v)
        pin.computeJointJacobians(model, data, q)
        out = np.zeros(model.nv)
        for (t_id, g_id, *_), s in zip(self._hot, states, strict=True):
            out += pin.getFrameJacobian(model, data, g_id, LOCAL).T @ s.G_f_G
            out += pin.getFrameJacobian(model, data, t_id, LOCAL).T @ s.T_f_T
        return out

    def stiffness(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mass matrix and the interconnections' stiffness and damping in joint space at (q, v).

        With ``Jr = J_G − Ad(T_M_G⁻¹) J_T`` (LOCAL frame Jacobians) and ``A = Jlog6(T_M_G) Jr``:
        ``K̃ = Σ Aᵀ K A`` and ``D̃ = Σ Aᵀ D A + B`` (B: joint damping). This is the Gauss–Newton
        part of the Hessian of the elastic energy (the force-proportional geometric stiffness is
        left out), which is what linearly implicit methods need (DESIGN §2).

        Returns:
            (M, K̃, D̃), each (nv, nv) [kg or kg·m², N/m or N·m/rad, N·s/m or N·m·s/rad].
        """
        self._interconnections(q, v, matrices=True)
        return pin.crba(self.model, self.data, q).copy(), self.K_t, self.D_t

    # -- readouts -----------------------------------------------------------------------------
    def elastic_energy(self, q: np.ndarray) -> np.ndarray:
        """½ eᵀ K e of each interconnection (n_links,) [J]."""
        pin.forwardKinematics(self.model, self.data, q)
        return self._elastic()

    def _elastic(self) -> np.ndarray:
        """Elastic energies after forward kinematics."""
        if self._kernel is not None:
            return self._kernel.elastic_energies()
        model, data = self.model, self.data
        out = []
        for t_id, g_id, K, _, _ in self._hot:
            e = pin.log6(pin.updateFramePlacement(model, data, t_id).actInv(pin.updateFramePlacement(model, data, g_id))).vector
            out.append(0.5 * e @ K @ e)
        return np.array(out)

    def energy(self, q: np.ndarray, v: np.ndarray) -> Energy:
        """Kinetic, gravity and elastic energy at (q, v) [J] (one kinematics pass)."""
        model, data = self.model, self.data
        kinetic = float(pin.computeKineticEnergy(model, data, q, v))  # runs forward kinematics (q, v)
        potential = float(pin.computePotentialEnergy(model, data))
        return Energy(kinetic, potential, float(np.sum(self._elastic())))

    def dissipation(self, q: np.ndarray, v: np.ndarray) -> float:
        """Power dissipated by interconnection and joint damping [W] (≥ 0)."""
        states = self.springs(q, v)
        p = sum(float(s.e_dot @ lk.D @ s.e_dot) for s, lk in zip(states, self.scene.links, strict=True))
        return p + float(v @ (self._damping * v))
