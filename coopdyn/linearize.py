"""The exact linearisation of a scene's open-loop dynamics at one state: ``ẋ ≈ A x + B u``.

The state is ``x = (δq, v)`` (2·nv): δq the tangent coordinates of the configuration about q,
``q ⊕ δq = pin.integrate(model, q, δq)`` (a free-flyer's δq is a body twist times time, linear
part first), and v the joint velocities; the input u is the torque of the actuated joints
[N·m or N]. ::

    A = [[Ω(v),   I    ],        B = [[0     ],
         [∂q̈/∂q, ∂q̈/∂v]]             [∂q̈/∂τ]]

``Ω(v)`` is zero for ordinary joints and ``−ad(v_j)`` on a free-flyer's block (−[ω]^ on a
spherical joint): the tangent coordinates about a moving reference drift as ``δq̇ = δv −
ad(v) δq``. Nothing is approximated: Pinocchio's ABA derivatives for the arms and the object,
the elements' exact second derivatives (geometric stiffness) for the interconnections —
:mod:`coopdyn.dynamics.derivatives` says how, ``tests/test_linearize.py`` checks every built-in
element against finite differences.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from . import _validate
from .closed_loop import Controller, System
from .dynamics import Dynamics
from .dynamics.derivatives import motion_cross
from .errors import SceneError
from .model.scene import Scene

#: joints whose tangent coordinates add like vectors (Ω = 0); shortnames without "JointModel"
_FLAT_LIE = ("RUBX", "RUBY", "RUBZ", "RevoluteUnboundedUnaligned")


@dataclass(frozen=True)
class Linearization:
    """The result of :func:`linearize` (see the module docstring for the state)."""

    A: np.ndarray  #: (2nv, 2nv) ∂ẋ/∂x [1/s, 1/s² in the acceleration rows' position columns]
    B: np.ndarray  #: (2nv, n_actuated) ∂ẋ/∂τ [1/(kg·m²·s) or 1/(kg·s): acceleration per N·m or N]
    acceleration: np.ndarray  #: q̈ (nv,) at the state [m/s², rad/s²]
    wrench: np.ndarray  #: (L, 6) each interconnection's wrench on G at G, G axes [N, N·m]
    dwrench_dx: np.ndarray  #: (L, 6, 2nv) its derivative with respect to x [N or N·m per m, rad, m/s or rad/s]
    exact: bool  #: False when something is finite differences: a user element's tangent, or the controller
    controller_gain: np.ndarray | None  #: (n_actuated, 2nv) ∂τ/∂x of the controller [N·m per rad or rad/s, …], else None
    q: np.ndarray  #: the configuration (nq,)
    v: np.ndarray  #: the velocity (nv,)
    tau: np.ndarray  #: the torques (n_actuated,)
    t: float  #: the time the controller was evaluated at [s]

    @property
    def eigenvalues(self) -> np.ndarray:
        """The eigenvalues of A [1/s], sorted by imaginary part (a mode at f Hz: ±2πf·i)."""
        lam = np.linalg.eigvals(self.A)
        return lam[np.argsort(lam.imag, kind="stable")]


def _omega(model: pin.Model, v: np.ndarray) -> np.ndarray:
    """Ω(v) (nv, nv): the drift of tangent coordinates about a reference moving at v."""
    out = np.zeros((model.nv, model.nv))
    for joint in model.joints[1:]:
        kind, i, n = joint.shortname().removeprefix("JointModel"), joint.idx_v, joint.nv
        if kind == "FreeFlyer":
            out[i : i + 6, i : i + 6] = -motion_cross(v[i : i + 6])
        elif kind == "Spherical":
            out[i : i + 3, i : i + 3] = -pin.skew(v[i : i + 3])
        elif joint.nq != n and kind not in _FLAT_LIE:
            raise SceneError(
                f"linearize: joint type {kind} ({model.names[joint.id]}) has no tangent coordinates here; supported: "
                "free-flyer, spherical, continuous (unbounded revolute) and every joint whose configuration is its coordinates"
            )
    return out


def linearize(
    scene: Scene,
    q: Any = None,
    v: Any = None,
    tau: Any = None,
    *,
    controller: Controller | None = None,
    t: float = 0.0,
    object_wrench: Any = None,
    backend: str | None = None,
) -> Linearization:
    """The exact linearisation of the scene's open-loop dynamics at (q, v, τ) — or of the closed
    loop under ``controller``.

    Args:
        scene: the scene (elastic interconnections; rigid grasps are refused).
        q: the configuration (nq,); default ``scene.q0``.
        v: the velocities (nv,) [m/s, rad/s]; default zero.
        tau: the actuated joints' torques (n_actuated,) [N·m or N]; default zero, or the
            controller's at (t, q, v).
        controller: ``controller(t, q, v) -> τ``: A becomes the closed loop's, ``A + B·∂τ/∂x``,
            with ∂τ/∂x (``controller_gain``) by central differences of the controller (4·nv
            calls at time ``t``; ``exact`` is then False). A controller with internal state
            (a hold, a filter) must not mind being probed.
        t: the time the controller is evaluated at [s] (default 0).
        object_wrench: a constant external wrench on the object (6,) [N, N·m], world axes, at
            the object frame's origin; default none.
        backend: ``"native"`` (the compiled kernel's twin), ``"python"`` or ``"auto"``, as for
            :class:`coopdyn.Dynamics`; the two agree to round-off.

    Raises:
        SceneError: a bad argument, a rigid grasp, or a joint type without tangent coordinates here.
    """
    if not isinstance(scene, Scene):
        raise SceneError(f"linearize: scene must be a coopdyn.Scene, got {type(scene).__name__}")
    if scene.constraints:
        raise SceneError("linearize: the scene has rigid grasps (constraints); linearise the elastic scene they stand for")
    nv = scene.nv
    q, v = scene.check_state(scene.q0 if q is None else q, np.zeros(nv) if v is None else v)
    t = _validate.number(t, "t", "s")
    if controller is not None and not callable(controller):
        raise SceneError(f"linearize: controller must be a callable controller(t, q, v) -> tau, got {type(controller).__name__}")
    dynamics = Dynamics(scene, backend)
    system = None if controller is None else System(dynamics, controller)  # (its checked torque)
    if tau is None and system is not None:
        tau = system.torque(t, q, v)
    lin = open_loop(dynamics, q, v, tau, object_wrench, t)
    if system is None:
        return lin
    gain = controller_gain(system, t, q, v)
    return replace(lin, A=lin.A + lin.B @ gain, exact=False, controller_gain=gain)


def open_loop(
    dynamics: Dynamics, q: np.ndarray, v: np.ndarray, tau: Any, object_wrench: Any = None, t: float = 0.0
) -> Linearization:
    """:func:`linearize`'s open loop on ``dynamics`` — a run's own, whose scene's Pinocchio data
    (large for a beam) is then not built again — at a checked state (q, v); ``tau`` (default
    zero) and ``object_wrench`` as there.

    Raises:
        SceneError: rigid grasps, a joint type without tangent coordinates here, a bad ``tau``
            or ``object_wrench``.
    """
    scene = dynamics.scene
    if scene.constraints:
        raise SceneError("linearize: the scene has rigid grasps (constraints); linearise the elastic scene they stand for")
    nv = scene.nv
    tau = np.zeros(scene.n_actuated) if tau is None else _validate.finite_array(tau, "tau [N·m or N]", (scene.n_actuated,))
    wrench = None if object_wrench is None else _validate.finite_array(object_wrench, "object_wrench [N, N·m]", (6,))
    omega = _omega(scene.model, v)
    d = dynamics.derivatives(q, v, tau, wrench)
    A = np.zeros((2 * nv, 2 * nv))
    A[:nv, :nv], A[:nv, nv:] = omega, np.eye(nv)
    A[nv:, :nv], A[nv:, nv:] = d.da_dq, d.da_dv
    B = np.zeros((2 * nv, scene.n_actuated))
    B[nv:] = d.da_dtau
    dW = np.concatenate([d.dwrench_dq, d.dwrench_dv], axis=2)
    return Linearization(A, B, d.acceleration, d.wrench, dW, d.exact, None, q, v, np.array(tau, dtype=float), t)


def controller_gain(system: System, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """∂τ/∂x (n_actuated, 2nv) of the closed loop's controller at (t, q, v) in the tangent
    coordinates of :func:`linearize`, by central differences of its checked torque
    (:meth:`System.torque`; steps 1e-6 in δq [m or rad], 1e-6·max(1, |v|) in v)."""
    scene = system.dynamics.scene
    nv, model = scene.nv, scene.model
    out = np.empty((scene.n_actuated, 2 * nv))
    h_q, h_v = 1e-6, 1e-6 * max(1.0, float(np.max(np.abs(v), initial=0.0)))
    for k in range(nv):
        e = np.zeros(nv)
        e[k] = h_q
        plus, minus = system.torque(t, pin.integrate(model, q, e), v), system.torque(t, pin.integrate(model, q, -e), v)
        out[:, k] = (plus - minus) / (2.0 * h_q)
        e[k] = h_v
        plus, minus = system.torque(t, q, v + e), system.torque(t, q, v - e)
        out[:, nv + k] = (plus - minus) / (2.0 * h_v)
    return out
