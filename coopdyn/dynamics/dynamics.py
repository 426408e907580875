"""The right-hand side of the cooperative system, its implicit terms and its readouts.

Arm and object equations, all in one merged model (docs/physics.md)::

    H(q) q̈ + h(q, q̇) = S τ − B q̇ + Q,   Q = Σ_i Jr_iᵀ G_f_G,i

with S selecting the arm joints, B the viscous joint damping, ``Jr = J_G − Ad(T_M_G⁻¹) J_T``
the relative Jacobian of interconnection i (LOCAL frame Jacobians of its frames T and G) and
``G_f_G`` the wrench its element (:mod:`coopdyn.model.elements`) puts on G. Everything below —
dynamics, implicit terms, energies and the trajectory readouts — evaluates the elements through
:meth:`Element.evaluate`; the compiled kernel (:mod:`.native`) does the same with the elements'
C++ twins.

:class:`Dynamics` holds scratch only (``pin.Data`` and buffers): nothing a later call reads
from what an earlier one left behind, except the factorisation :meth:`Dynamics.factor` makes
for :meth:`Dynamics.solve`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from ..errors import KernelError, SceneError, StepMatrixError
from ..model.elements import ElementEval
from ..model.scene import Scene
from . import backend as _backend
from .derivatives import Derivatives, dynamics_derivatives

LOCAL = pin.ReferenceFrame.LOCAL

#: Rotation of a deformation [rad] above which the SE(3) logarithm nears its jump at π.
ROTATION_ALARM = 0.9 * math.pi


def step_coefficients(gh: Any, gh2: Any) -> tuple[float, float]:
    """``(gh, gh2)`` of :meth:`Dynamics.factor` as floats, ``gh2 = gh²`` when None; a
    KernelError for anything that is not a real number (non-finite ones make S not finite)."""
    try:
        if isinstance(gh, complex) or isinstance(gh2, complex):
            raise TypeError("complex")
        g = float(gh)
        return g, g * g if gh2 is None else float(gh2)
    except (TypeError, ValueError, OverflowError):
        raise KernelError(f"factor: gh and gh2 must be real numbers, got {repr(gh)[:40]} and {repr(gh2)[:40]}") from None


class Energy(NamedTuple):
    """Energies of one state [J]."""

    kinetic: Any  #: float, or (n,) along a trajectory
    potential: Any  #: gravity, zero at the world origin
    elastic: Any  #: Σ of the elements' elastic energies

    @property
    def total(self) -> Any:
        """kinetic + potential + elastic [J]."""
        return self.kinetic + self.potential + self.elastic


class Readouts(NamedTuple):
    """Every interconnection's readouts along a trajectory of n samples and L interconnections."""

    deformation: np.ndarray  #: (n, L, 6), each element's deformation, zero-padded to 6
    energy: np.ndarray  #: (n, L) elastic energy [J]
    power: np.ndarray  #: (n, L) power dissipated by the element's damping [W]
    object_wrench: np.ndarray  #: (n, L, 6) wrench on the object at G, world axes [N, N·m]
    arm_wrench: np.ndarray  #: (n, L, 6) wrench on the arm at T, world axes [N, N·m]
    grasp_position: np.ndarray  #: (n, L, 3) world position of G [m]
    tip_position: np.ndarray  #: (n, L, 3) world position of T [m]
    object_position: np.ndarray  #: (n, 3) world position of the object frame [m]
    kinetic: np.ndarray  #: (n,) kinetic energy [J]
    potential: np.ndarray  #: (n,) gravity energy [J]


class Dynamics:
    """Scratch space and evaluation of the scene's dynamics (one instance per thread).

    ``Dynamics(scene, backend)`` builds a :class:`PythonDynamics` (the reference) or a
    :class:`coopdyn.dynamics.native.NativeDynamics` (the compiled kernel) — same interface,
    same results to round-off.

    Args:
        scene: the scene; not modified.
        backend: ``"native"``, ``"python"`` or ``"auto"`` (see :mod:`coopdyn.dynamics.backend`);
            ``None`` reads the environment variable ``COOPDYN_BACKEND`` (default ``"auto"``).
            A scene with an element that has no C++ twin runs on Python (``"auto"``: one warning).

    Attributes:
        backend: the backend that runs, ``"native"`` or ``"python"``.
    """

    backend: str

    def __new__(cls, scene: Scene, backend: str | None = None) -> Dynamics:
        if cls is not Dynamics:
            return super().__new__(cls)
        name = _backend.resolve(backend, scene)  # (refuses what the backend cannot run, e.g. rigid grasps on "native")
        return super().__new__(KINDS["constrained" if scene.constraints else name])

    def __init__(self, scene: Scene, backend: str | None = None) -> None:
        self.scene = scene
        self.model = scene.model
        self.data = scene.model.createData()
        self._damping = np.zeros(scene.nv)
        for arm in scene.arms:
            self._damping[arm.v_index] = arm.damping
            self._damping[arm.motor_v_index] = arm.motor_damping
        self._springs = scene.joint_springs  # (elastic joints: their transmissions, joint_spring.py)
        self._has_damping = bool(np.any(self._damping))
        self.actuated_index = scene.actuated_index
        self._frames = [(lk.tip_frame, lk.grasp_frame, lk.element) for lk in scene.elements]
        # (link index, T, G, element) of the elements with a force law; a constraint has none (the
        # constraint solver's λ, dynamics.constrained)
        self._forces = [(i, *link) for i, link in enumerate(self._frames) if link[2].constraint is None]

    @property
    def force_links(self) -> list[tuple[int, int, int, Any]]:
        """``(link index, T frame, G frame, element)`` of every element with a force law (a rigid
        grasp's constraint has none), in scene order."""
        return list(self._forces)

    # -- the interface (implemented by both backends) --------------------------------------------
    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> np.ndarray:
        """Joint accelerations q̈ (nv,) for arm torques ``tau`` (n_actuated,) [N·m or N] and an
        optional external wrench on the object (6,) [N, N·m] (world axes, at the object frame origin)."""
        raise NotImplementedError

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What a linearly implicit step needs at (q, v), from one kinematics pass:
        ``(f, M, K̃, D̃)`` with ``f = S τ + Q − B q̇ − b(q, q̇) = M q̈`` (nv,) and the (nv, nv)
        mass matrix, Gauss–Newton stiffness ``K̃ = Σ Jrᵀ S_K Jr`` and damping
        ``D̃ = Σ Jrᵀ S_D Jr + B`` (the force-proportional geometric stiffness is left out); Q and
        both matrices include the elastic joints' springs (exact: they are linear)."""
        raise NotImplementedError

    def factor(
        self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, kp: np.ndarray, kd: np.ndarray, gh2: float | None = None
    ) -> None:
        """Factorise the step matrix ``S = M + γh (D̃ + Kd) + (γh)² (K̃ + Kp)`` (Cholesky) for
        :meth:`solve`; ``kp``, ``kd`` (n_actuated,) are joint PD gains [N·m/rad], [N·m·s/rad];
        ``gh2`` [s²], when given, replaces (γh)² (generalized-α's β' ≠ γ'²).

        Raises:
            StepMatrixError: S is not finite or not positive definite.
        """
        raise NotImplementedError

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(k_q, k_v)`` with the last :meth:`factor`, given ``M f_v``:
        ``S k_v = M f_v − γh (K̃ + Kp) f_q``, ``k_q = f_q + γh k_v`` — the solution of
        ``(I − γhJ) k = (f_q, f_v)`` when S was factored with ``gh2 = (γh)²``."""
        raise NotImplementedError

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
        :meth:`implicit_terms`, :meth:`factor` with γh = h, and :meth:`solve` of (v, f):
        ``v⁺ = v + h k_v``."""
        f, M, K, D = self.implicit_terms(q, v, tau, object_wrench)
        self.factor(M, K, D, h, kp, kd)
        return v + h * self.solve(v, f)[1]

    def element_states(self, q: np.ndarray, v: np.ndarray) -> list[ElementEval]:
        """Every interconnection element's evaluation at (q, v), with its S_K, S_D, in scene order."""
        raise NotImplementedError

    def readouts(self, Q: np.ndarray, V: np.ndarray, TAU: np.ndarray | None = None) -> Readouts:
        """The interconnections' readouts along a trajectory Q (n, nq), V (n, nv) (one pass);
        the torques TAU (n, n_actuated) only matter for rigid grasps, whose wrench depends on them."""
        raise NotImplementedError

    def elastic_energy(self, q: np.ndarray) -> np.ndarray:
        """Elastic energy of each interconnection (n_links,) [J] (the elastic joints' springs:
        ``scene.joint_springs.energy(q)``)."""
        pin.forwardKinematics(self.model, self.data, q)
        return self._elastic(q)

    def _elastic(self, q: np.ndarray) -> np.ndarray:
        """Each interconnection's elastic energy at q, after ``forwardKinematics(model, data, q)``."""
        raise NotImplementedError

    @property
    def last_dissipation(self) -> float:
        """Power dissipated by dampers [W] at the state of the last right-hand side or implicit
        evaluation."""
        raise NotImplementedError

    def rotation_alarm(self) -> tuple[int, float] | None:
        """``(link, θ)`` of the first interconnection whose deformation rotated beyond 0.9π [rad]
        in the evaluations since the last :meth:`clear_rotation_alarm`, else ``None``."""
        raise NotImplementedError

    def clear_rotation_alarm(self) -> None:
        """Forget a raised rotation alarm."""
        raise NotImplementedError

    def reraise_python_error(self) -> None:
        """Raise what a Python-only element raised inside a compiled evaluation, if one did (the
        native backend keeps it; in Python it was raised where it happened)."""

    # -- built on the interface ------------------------------------------------------------------
    def add_joint_gains(self, K: np.ndarray, D: np.ndarray, kp: np.ndarray, kd: np.ndarray) -> None:
        """Add joint PD gains (n_actuated,) to the diagonals of K̃ and D̃ (nv, nv), in place."""
        act = self.scene.actuated
        K[act, act] += kp
        D[act, act] += kd

    def derivatives(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> Derivatives:
        """Exact ∂q̈/∂(q, v, τ) and the elements' wrenches with their derivatives at (q, v) for the
        torques ``tau`` (n_actuated,) and an optional object wrench (as :meth:`acceleration`);
        :mod:`coopdyn.dynamics.derivatives` says how (the kernel's twin computes the same).

        Raises:
            KernelError: the scene has rigid grasps (constraints), or a shape is wrong.
        """
        if self.scene.constraints:
            raise KernelError("derivatives: the scene has rigid grasps (constraints); linearise its elastic scene instead")
        if np.shape(tau) != (self.scene.n_actuated,):
            raise KernelError(f"tau must have shape ({self.scene.n_actuated},), got {np.shape(tau)}")
        return self._derivatives(q, v, tau, object_wrench)

    def _derivatives(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None) -> Derivatives:
        raise NotImplementedError

    def stiffness(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M, K̃, D̃), each (nv, nv) [kg or kg·m², N/m or N·m/rad, N·s/m or N·m·s/rad], at (q, v):
        the matrices of :meth:`implicit_terms`."""
        _, M, K, D = self.implicit_terms(q, v, np.zeros(self.scene.n_actuated))
        return M, K, D

    def generalized_spring_force(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``Q = Σ Jrᵀ G_f_G``, the interconnections' generalized force (nv,) at (q, v) (and the
        elastic joints' springs')."""
        f = self.implicit_terms(q, v, np.zeros(self.scene.n_actuated))[0]  # Q − B q̇ − b(q, q̇)
        return f + pin.nonLinearEffects(self.model, self.data, q, v) + self._damping * v

    def energy(self, q: np.ndarray, v: np.ndarray) -> Energy:
        """Kinetic, gravity and elastic energy at (q, v) [J] (one kinematics pass); elastic: the
        interconnections', the object's own elements' and the elastic joints' springs'."""
        if np.shape(q) != (self.scene.nq,) or np.shape(v) != (self.scene.nv,):
            raise SceneError(f"energy: q must have shape ({self.scene.nq},) and v ({self.scene.nv},)")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise SceneError("energy: q and v must be finite")
        model, data = self.model, self.data
        kinetic = float(pin.computeKineticEnergy(model, data, q, v))  # runs forward kinematics (q, v)
        potential = float(pin.computePotentialEnergy(model, data))
        return Energy(kinetic, potential, float(np.sum(self._elastic(q)) + self._springs.energy(q)))


class PythonDynamics(Dynamics):
    """The reference implementation, on Pinocchio's Python bindings and the elements' Python laws."""

    backend = "python"

    def __init__(self, scene: Scene, backend: str | None = None) -> None:
        super().__init__(scene, backend)
        self._dissipation = 0.0
        self._alarm: tuple[int, float] | None = None
        self._K: np.ndarray | None = None
        self._D: np.ndarray | None = None
        self._step: tuple[np.ndarray, np.ndarray, float] | None = None  # (S⁻¹, K̃ + Kp, γh)

    @property
    def last_dissipation(self) -> float:
        return self._dissipation

    def rotation_alarm(self) -> tuple[int, float] | None:
        return self._alarm

    def clear_rotation_alarm(self) -> None:
        self._alarm = None

    def _relative(self, t_id: int, g_id: int) -> tuple[pin.SE3, np.ndarray]:
        """T_M_G and the relative Jacobian Jr (6, nv), after computeJointJacobians."""
        model, data = self.model, self.data
        T_M_G = pin.updateFramePlacement(model, data, t_id).actInv(pin.updateFramePlacement(model, data, g_id))
        nv = model.nv  # reshape: eigenpy returns a 6×1 Jacobian as a vector
        J_G = pin.getFrameJacobian(model, data, g_id, LOCAL).reshape(6, nv)
        J_T = pin.getFrameJacobian(model, data, t_id, LOCAL).reshape(6, nv)
        return T_M_G, J_G - T_M_G.toActionMatrixInverse() @ J_T

    def _generalized_force(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, matrices: bool, object_wrench: np.ndarray | None
    ) -> np.ndarray:
        """Kinematics at (q, v), then ``S τ + Q − B q̇`` (+ the object wrench) (nv,); with
        ``matrices``, also K̃ and D̃ in ``self._K``, ``self._D``."""
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)  # forward kinematics (positions) + joint Jacobians
        Q = np.zeros(model.nv)
        p_diss = 0.0
        if matrices:
            K_t = np.zeros((model.nv, model.nv))
            D_t = np.diag(self._damping)
        for i, t_id, g_id, element in self._forces:
            T_M_G, Jr = self._relative(t_id, g_id)
            ev = element.evaluate(T_M_G, Jr @ v, matrices)
            Q += Jr.T @ ev.G_f_G
            p_diss += ev.power
            if ev.theta > ROTATION_ALARM and self._alarm is None:
                self._alarm = (i, ev.theta)
            if matrices:
                K_t += Jr.T @ ev.S_K @ Jr
                if element.has_damping:
                    D_t += Jr.T @ ev.S_D @ Jr
        if matrices:
            self._K, self._D = K_t, D_t
        if object_wrench is not None:  # world-aligned wrench at the object frame origin → LOCAL
            fo = self.scene.object_frame
            R = pin.updateFramePlacement(model, data, fo).rotation
            local = np.concatenate([R.T @ object_wrench[:3], R.T @ object_wrench[3:]])
            Q += pin.getFrameJacobian(model, data, fo, LOCAL).reshape(6, model.nv).T @ local
        if np.shape(tau) != (self.scene.n_actuated,):
            raise KernelError(f"tau must have shape ({self.scene.n_actuated},), got {np.shape(tau)}")
        Q[self.actuated_index] += tau
        if self._has_damping:
            Q -= self._damping * v
            p_diss += v @ (self._damping * v)
        if self._springs.size:
            p_diss += self._springs.add_force(Q, q, v)
            if matrices:
                self._springs.add_matrices(K_t, D_t)
        self._dissipation = p_diss
        return Q

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> np.ndarray:
        t = self._generalized_force(q, v, tau, False, object_wrench)
        return pin.aba(self.model, self.data, q, v, t).copy()

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        model, data = self.model, self.data
        f = self._generalized_force(q, v, tau, True, object_wrench)
        f -= pin.nonLinearEffects(model, data, q, v)
        assert self._K is not None and self._D is not None
        return f, pin.crba(model, data, q).reshape(model.nv, model.nv).copy(), self._K, self._D

    def factor(
        self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, kp: np.ndarray, kd: np.ndarray, gh2: float | None = None
    ) -> None:
        self._step = None  # (until this factor succeeds: a failed one leaves nothing to solve with)
        nv = self.scene.nv
        if not all(np.shape(x) == (nv, nv) for x in (M, K, D)):
            raise KernelError(f"factor: M, K and D must be nv x nv ({nv} x {nv})")
        gh, gh2 = step_coefficients(gh, gh2)
        K_g, D_g = K.copy(), D.copy()
        self.add_joint_gains(K_g, D_g, kp, kd)
        S = M + gh * D_g + gh2 * K_g
        if not np.all(np.isfinite(S)):  # numpy's Cholesky "succeeds" on NaN
            raise StepMatrixError("the step matrix M + γh·D̃ + (γh)²·K̃ is not finite")
        try:
            L = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            raise StepMatrixError("the step matrix M + γh·D̃ + (γh)²·K̃ is not positive definite") from None
        # For the small S of a few arms (nv ≲ 50) an explicit inverse from the Cholesky factor and a
        # matrix–vector product per solve cost less than LAPACK's triangular solves through numpy.
        L_inv = np.linalg.inv(L)
        self._step = (L_inv.T @ L_inv, K_g, gh)

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._step is None:
            raise KernelError("solve() needs a successful factor() first")
        S_inv, K_g, gh = self._step
        k_v = S_inv @ (Mf_v - gh * (K_g @ f_q))
        return f_q + gh * k_v, k_v

    def _derivatives(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None) -> Derivatives:
        tau_full = np.zeros(self.scene.nv)
        tau_full[self.actuated_index] += tau
        frame = self.scene.object_frame
        return dynamics_derivatives(
            self.model,
            self.data,
            self._forces,
            self._damping,
            self.actuated_index,
            frame,
            q,
            v,
            tau_full,
            object_wrench,
            self._springs,
        )

    def element_states(self, q: np.ndarray, v: np.ndarray) -> list[ElementEval]:
        model, data = self.model, self.data
        pin.forwardKinematics(model, data, q, v)
        return [self._element(t_id, g_id, element, True) for t_id, g_id, element in self._frames]

    def _element(self, t_id: int, g_id: int, element: Any, jacobians: bool) -> ElementEval:
        """An element at the kinematics of the last forwardKinematics(q, v)."""
        model, data = self.model, self.data
        oMT = pin.updateFramePlacement(model, data, t_id)
        oMG = pin.updateFramePlacement(model, data, g_id)
        T_M_G = oMT.actInv(oMG)
        V_T = pin.getFrameVelocity(model, data, t_id, LOCAL)
        V_G = pin.getFrameVelocity(model, data, g_id, LOCAL)
        return element.evaluate(T_M_G, (V_G - T_M_G.actInv(V_T)).vector, jacobians)

    def _elastic(self, q: np.ndarray) -> np.ndarray:
        model, data = self.model, self.data
        zero = np.zeros(6)
        out = []
        for t_id, g_id, element in self._frames:
            T_M_G = pin.updateFramePlacement(model, data, t_id).actInv(pin.updateFramePlacement(model, data, g_id))
            out.append(element.evaluate(T_M_G, zero).energy)
        return np.array(out)

    def readouts(self, Q: np.ndarray, V: np.ndarray, TAU: np.ndarray | None = None) -> Readouts:
        model, data = self.model, self.data
        n, L = len(Q), len(self._frames)
        E, U, P = np.zeros((n, L, 6)), np.zeros((n, L)), np.zeros((n, L))
        WG, WT, PG, PT = np.zeros((n, L, 6)), np.zeros((n, L, 6)), np.zeros((n, L, 3)), np.zeros((n, L, 3))
        PO, KE, PE = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
        for k in range(n):
            pin.forwardKinematics(model, data, Q[k], V[k])
            KE[k] = pin.computeKineticEnergy(model, data)
            PE[k] = pin.computePotentialEnergy(model, data)
            PO[k] = pin.updateFramePlacement(model, data, self.scene.object_frame).translation
            for i, (t_id, g_id, element) in enumerate(self._frames):
                ev = self._element(t_id, g_id, element, False)
                oMT, oMG = data.oMf[t_id], data.oMf[g_id]
                f_T = -(oMT.actInv(oMG).act(pin.Force(ev.G_f_G))).vector  # action = reaction, in T
                E[k, i, : ev.deformation.size] = ev.deformation
                U[k, i], P[k, i] = ev.energy, ev.power
                WG[k, i, :3], WG[k, i, 3:] = oMG.rotation @ ev.G_f_G[:3], oMG.rotation @ ev.G_f_G[3:]
                WT[k, i, :3], WT[k, i, 3:] = oMT.rotation @ f_T[:3], oMT.rotation @ f_T[3:]
                PG[k, i], PT[k, i] = oMG.translation, oMT.translation
        return Readouts(E, U, P, WG, WT, PG, PT, PO, KE, PE)


#: what ``Dynamics(scene, backend)`` builds, by kind: ``"python"``, ``"native"`` and
#: ``"constrained"`` (rigid grasps); each module registers its class (dynamics/__init__.py imports them)
KINDS: dict[str, type[Dynamics]] = {"python": PythonDynamics}
