"""Statics: where the object comes to rest on its interconnections, the arms held.

The book's recipe for the elastic system starts with statics — the minimum of deformation
energy, ``F = K y`` — before dynamics. :func:`equilibrium` finds that rest pose for the scene's
object with the arm joints held at a given configuration, by Newton steps on the object's
coordinates with the elements' stiffness ``K̃`` (Gauss–Newton: exact for linear elements,
converging linearly where the geometric stiffness matters).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from . import _validate
from .dynamics import Dynamics
from .errors import SimulationError
from .model.scene import Scene


@dataclass(frozen=True)
class Equilibrium:
    """The result of :func:`equilibrium`."""

    q: np.ndarray  #: the configuration (nq,): the arms as given, the object at rest
    residual: float  #: largest generalized force left on the object [N or N·m]
    iterations: int  #: Newton steps taken


MAX_ITER = 1000  #: the most Newton steps equilibrium() takes
ROUND_OFF_STEP = 1e-13  #: [m, rad] a Newton step this small means the residual is round-off


def equilibrium(
    scene: Scene, q: Any = None, *, tol: float = 1e-9, max_iter: int = 100, backend: str | None = None
) -> Equilibrium:
    """The object's rest pose, with gravity and the interconnections, the arm joints held at ``q``.

    Args:
        scene: the scene. q: the configuration to start from (default ``scene.q0``); its arm
            coordinates are kept.
        tol: stop when every generalized force on the object is below this [N, N·m], or when
            a Newton step moves the object less than 1e-13 [m, rad] (what is left is round-off).
        max_iter: Newton steps before giving up (at most 1000).
        backend: the dynamics backend (see :class:`coopdyn.Dynamics`).

    Raises:
        SimulationError: when the interconnections do not hold the object in every direction
            (a singular stiffness) or the iteration does not converge.
    """
    if not isinstance(scene, Scene):
        raise SimulationError(f"scene must be a coopdyn.Scene, got {type(scene).__name__}")
    tol = _validate.positive(tol, "tol", "N or N·m", SimulationError)
    max_iter = _validate.count(max_iter, "max_iter", SimulationError)
    if max_iter > MAX_ITER:
        raise SimulationError(f"max_iter must be at most {MAX_ITER} (Newton converges in a handful of steps or not at all)")
    q, _ = scene.check_state(scene.q0 if q is None else q, np.zeros(scene.nv))
    return rest_pose(Dynamics(scene, backend), q, tol, max_iter)


def rest_pose(dynamics: Dynamics, q: np.ndarray, tol: float, max_iter: int) -> Equilibrium:
    """:func:`equilibrium`'s Newton iteration on a Dynamics already built (its arguments checked):
    ``simulate``'s sag check runs it on the run's own dynamics."""
    scene = dynamics.scene
    v = np.zeros(scene.nv)
    obj, tau = scene.object_v, np.zeros(scene.n_actuated)
    for it in range(max_iter + 1):
        f, _, K, _ = dynamics.implicit_terms(q, v, tau)
        r = f[obj]
        residual = float(np.max(np.abs(r)))
        if residual <= tol:
            return Equilibrium(q, residual, it)
        if it == max_iter:
            break
        try:
            dx = np.linalg.solve(K[np.ix_(obj, obj)], r)  # f(q ⊕ δ) ≈ f(q) − K̃ δ
        except np.linalg.LinAlgError:
            raise SimulationError(
                "the interconnections do not hold the object in every direction (their stiffness on the object's "
                "coordinates is singular): it has no rest pose"
            ) from None
        if float(np.max(np.abs(dx))) <= ROUND_OFF_STEP:  # the residual left is round-off: this is the rest pose
            return Equilibrium(q, residual, it)
        step = np.zeros(scene.nv)
        step[obj] = dx
        q = pin.integrate(scene.model, q, step)
    raise SimulationError(f"no equilibrium within {max_iter} Newton steps: the force left on the object is {residual:.3g}")


__all__ = ["Equilibrium", "equilibrium", "rest_pose"]
