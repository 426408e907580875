"""What an interconnection element is: a law between two frames of the scene model.

An element joins a frame T (an arm's tool frame, or a fixture on the world) and a frame G (a
grasp frame on the object). Everything it contributes follows from the pose of G in T,
``T_M_G = oMT⁻¹·oMG``, and the relative body twist ``ξ = V_G − Ad(T_M_G⁻¹) V_T`` (both LOCAL,
so ``d/dt T_M_G = T_M_G ξ^``) [m/s, rad/s]:

* its elastic energy U(T_M_G) [J] and a deformation vector (its own size and units);
* the wrench on G at G, in G axes, ``G_f_G = −∂U/∂ξ − (damping)`` [N, N·m] — the exact
  gradient of U along the relative motion, plus a damping force; the reaction on T, in T axes,
  is ``T_f_T = −T_M_G.act(G_f_G)`` (action = reaction), so an element never computes it;
* the power its damping dissipates [W] (≥ 0);
* for linearly implicit integrators, the Gauss–Newton stiffness and damping in relative-twist
  coordinates, ``S_K`` and ``S_D`` (6, 6): the dynamics add ``Jrᵀ S_K Jr`` and ``Jrᵀ S_D Jr``
  to K̃ and D̃, with ``Jr = J_G − Ad(T_M_G⁻¹) J_T`` the relative Jacobian (6, nv);
* for the exact linearisation (:func:`coopdyn.linearize`), :meth:`Element.tangent`: the
  derivatives of ``G_f_G`` with respect to a right perturbation of the pose, ``T_M_G·exp6(δ)``,
  and to ξ — the full second derivative of U, geometric stiffness included;
* for the derivative of a linearly implicit step (:mod:`coopdyn.sensitivity`),
  :meth:`Element.matrix_tangent`: the same derivatives of ``S_K w_K + S_D w_D`` for fixed twists.

Elements are immutable: their constructor validates the parameters and keeps them as read-only
arrays. The same :meth:`Element.evaluate` serves the dynamics, the implicit terms and every
readout. docs/extending.md walks through writing one.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar, NamedTuple

import numpy as np
import pinocchio as pin

from ...errors import SceneError


class ElementEval(NamedTuple):
    """What an element contributes at one relative pose and twist."""

    energy: float  #: elastic energy U [J]
    deformation: np.ndarray  #: the element's deformation (Element.deformation_size,)
    G_f_G: np.ndarray  #: wrench on G at G, in G axes (6,) [N, N·m]: elastic + damping
    power: float  #: power dissipated by the damping [W], ≥ 0
    S_K: np.ndarray | None  #: Gauss–Newton stiffness in relative-twist coordinates (6, 6), or None
    S_D: np.ndarray | None  #: damping in relative-twist coordinates (6, 6), or None
    theta: float  #: rotation angle of T_M_G [rad] (for the log-map warning near π)


class Parameter(NamedTuple):
    """One of an element's own parameters beyond its stiffness and damping (a scalar [unit])."""

    name: str  #: its keyword: in __init__, Interconnection.parameters, scene files and the C++ twin
    unit: str  #: e.g. "N/m³"
    doc: str  #: what it is, for messages and the scene-file schema


#: step of the default :meth:`Element.tangent`'s central differences, relative (cube root of ε)
_FD_STEP = 6e-6


def _differences(f: Any, T_M_G: pin.SE3, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central differences (6, 6) of ``f(pose, twist)`` (6,) along ``T_M_G·exp6(δ)`` and ξ: the
    default :meth:`Element.tangent` and :meth:`Element.matrix_tangent`."""
    xi = np.asarray(xi, dtype=float)
    D_d, D_x = np.zeros((6, 6)), np.zeros((6, 6))
    h_d = _FD_STEP * max(1.0, float(np.linalg.norm(T_M_G.translation)))
    h_x = _FD_STEP * max(1.0, float(np.linalg.norm(xi)))
    for k in range(6):
        d = np.zeros(6)
        d[k] = h_d
        D_d[:, k] = (f(T_M_G * pin.exp6(d), xi) - f(T_M_G * pin.exp6(-d), xi)) / (2.0 * h_d)
        d[k] = h_x
        D_x[:, k] = (f(T_M_G, xi + d) - f(T_M_G, xi - d)) / (2.0 * h_x)
    return D_d, D_x


def read_only(array: np.ndarray) -> np.ndarray:
    """``array`` with its write flag cleared (a parameter of an immutable element)."""
    array.setflags(write=False)
    return array


class Element(ABC):
    """Base class of interconnection elements (see the module docstring).

    A subclass sets :attr:`kind` (its registry name) and :attr:`deformation_size`, validates
    its parameters in ``__init__(stiffness, damping, name)`` and implements :meth:`evaluate`.
    An element with a C++ twin also implements :meth:`native_parameters`. Register it with
    :func:`coopdyn.model.elements.register`.
    """

    kind: ClassVar[str]
    deformation_size: ClassVar[int]
    #: True when, with translations only (prismatic joints), the law is linear in the relative
    #: translation and velocity (the exponential integrator needs it).
    linear: ClassVar[bool] = False
    #: ``None`` for a force law; ``"6D"`` or ``"3D"`` for a kinematic constraint whose wrench the
    #: constrained dynamics solve for (:mod:`.rigid`).
    constraint: ClassVar[str | None] = None
    #: the kind of the rigid element that stands for this one in :func:`coopdyn.rigid_limit`
    #: (``None``: it has no rigid counterpart)
    rigid: ClassVar[str | None] = None
    #: its own parameters beyond stiffness and damping, declared once: each is a keyword of
    #: ``__init__`` and an attribute of the element, a key of ``Interconnection.parameters`` and of
    #: a scene file's ``parameters`` table, and a field its C++ twin reads by name
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: True when :meth:`tangent` is exact to round-off; the default central differences are not
    exact_tangent: ClassVar[bool] = False

    @abstractmethod
    def __init__(self, stiffness: Any, damping: Any = None, name: str = "interconnection") -> None:
        """Validate and keep the parameters (raise :class:`coopdyn.SceneError` naming ``name``)."""

    @abstractmethod
    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        """Energy, deformation, wrench on G, dissipated power and (with ``jacobians``) S_K, S_D
        at the relative pose ``T_M_G`` and relative twist ``xi`` (6,) [m/s, rad/s]."""

    def tangent(self, T_M_G: pin.SE3, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(∂G_f_G/∂δ, ∂G_f_G/∂ξ)``, each (6, 6): the derivatives of the wrench on G with
        respect to a right perturbation of the pose, ``T_M_G·exp6(δ)`` (δ [m, rad], body axes
        of G), and to the relative twist ξ [m/s, rad/s].

        This default takes central differences of :meth:`evaluate` (about 1e-8 relative; the
        element's :attr:`exact_tangent` stays False and :func:`coopdyn.linearize` says so);
        the built-in elements override it with exact derivatives."""
        return _differences(lambda pose, twist: self.evaluate(pose, twist).G_f_G, T_M_G, xi)

    def matrix_tangent(self, T_M_G: pin.SE3, xi: np.ndarray, w_K: np.ndarray, w_D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The derivatives of ``S_K w_K + S_D w_D`` (6,) — the Gauss–Newton matrices applied to two
        fixed twists — with respect to a right perturbation of the pose, ``T_M_G·exp6(δ)``, and to
        the relative twist ξ, each (6, 6): what the derivative of a linearly implicit step needs
        (:mod:`coopdyn.sensitivity`).

        This default takes central differences of :meth:`evaluate` (the sensitivities built on it
        report ``exact = False``); the built-in elements override it with exact derivatives."""

        def applied(pose: pin.SE3, twist: np.ndarray) -> np.ndarray:
            ev = self.evaluate(pose, twist, True)
            return np.asarray(ev.S_K @ w_K + ev.S_D @ w_D)

        return _differences(applied, T_M_G, xi)

    @property
    def exact_matrix_tangent(self) -> bool:
        """Whether :meth:`matrix_tangent` is exact: an element's own, not the default differences."""
        return type(self).matrix_tangent is not Element.matrix_tangent

    @property
    def has_damping(self) -> bool:
        """Whether the element dissipates (``False`` lets the dynamics skip its S_D term)."""
        return True

    def parameter_values(self) -> dict[str, float]:
        """The values of :attr:`parameters`, by name."""
        return {p.name: float(getattr(self, p.name)) for p in self.parameters}

    def native_parameters(self) -> dict[str, Any]:
        """What the C++ twin (src/native/elements/<name>.hpp) reads, by name; it must read every
        one (only elements registered with a twin need this)."""
        raise NotImplementedError(f"{type(self).__name__} has no C++ twin")

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class SpringDamper(Element):
    """An element with a stiffness matrix ``K`` and a damping matrix ``D`` (the built-in ones):
    keeps them read-only, refuses both zero, and gives ``(K, D)`` to its C++ twin. A subclass's
    ``__init__`` validates the matrices and calls :meth:`_keep`."""

    K: np.ndarray
    D: np.ndarray

    def _keep(self, K: np.ndarray, D: np.ndarray, name: str) -> None:
        if not np.any(K) and not np.any(D):
            raise SceneError(f"{name}: stiffness and damping are both zero; the arm would not touch the object")
        self.K, self.D = read_only(K), read_only(D)
        self._damped = bool(np.any(D))

    @property
    def has_damping(self) -> bool:
        return self._damped

    def native_parameters(self) -> dict[str, Any]:
        return {"K": np.asarray(self.K), "D": np.asarray(self.D), **self.parameter_values()}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(K diag {np.diag(self.K).tolist()}, D diag {np.diag(self.D).tolist()})"
