"""An elastic object: a straight beam of nodes and 3-D beam elements (direct stiffness method).

The book's elastic system (docs/physics.md, "Three models"): nodes carry lumped mass; beam
elements (:class:`coopdyn.model.elements.beam.BeamElement`) join consecutive nodes. In a
:class:`~coopdyn.model.scene.Scene` each node is a rigid body on its own free-flyer joint (all
in beam axes at rest), the elements are the scene's internal elements (``scene.elements`` after
the interconnections), and an arm grasps the node nearest its grasp point. The *object frame*
(what controllers and ``Result.object_position`` follow) is the reference node's, at the middle.

:meth:`Beam.stiffness_matrix` assembles the free beam's linear stiffness (6 per node, beam axes)
and :meth:`Beam.zero_modes` counts its rigid-body modes — six for a free object: rank K = 6N − 6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from .elements.beam import BeamElement, BeamSegment, Section, tip_stiffness


def rigid_map(r: np.ndarray) -> np.ndarray:
    """The 6×6 map from a node's small displacement (δp, δθ) to that of a point at offset r
    rigidly attached to it: (δp + δθ × r, δθ)."""
    return pin.SE3(np.eye(3), -np.asarray(r, dtype=float)).toActionMatrix()


MAX_ELEMENTS = 500  #: a beam is a body per node, and its dense stiffness has 6·(n + 1) rows


@dataclass(frozen=True, eq=False)
class Beam:
    """A straight, uniform, free elastic beam held by the arms.

    Attributes:
        length: [m], along the beam's x axis. section: its :class:`Section`.
        n_elements: beam elements (≥ 1); nodes = n_elements + 1, equally spaced.
        pose: initial pose of the beam frame (x along the beam, origin at its middle) in the
            world (``pin.SE3``, 4x4 or translation [m]).
        damping: β [s], stiffness-proportional damping of every element; default 0.
        name: prefix of its joints and frames; the object frame is named ``name``.
    """

    length: float
    section: Section
    n_elements: int = 8
    pose: Any = None
    damping: float = 0.0
    name: str = "beam"
    #: what a scene's summary calls its root joints (one free flyer per node)
    joint: ClassVar[str] = "beam of free nodes"
    size: ClassVar[None] = None  #: (a box's edge lengths; a beam is drawn from its nodes)

    def __post_init__(self) -> None:
        object.__setattr__(self, "length", _validate.positive(self.length, "Beam: length", "m"))
        if not isinstance(self.section, Section):
            raise SceneError(f"Beam: section must be a coopdyn Section, got {type(self.section).__name__}")
        object.__setattr__(self, "n_elements", _validate.count(self.n_elements, "Beam: n_elements"))
        if self.n_elements > MAX_ELEMENTS:
            raise SceneError(
                f"Beam: n_elements = {self.n_elements} is more than {MAX_ELEMENTS}: each node is a body of the scene; "
                "the first modes converge at second order (0.5 % at 32 elements)"
            )
        object.__setattr__(self, "damping", _validate.non_negative(self.damping, "Beam: damping β", "s"))
        tip_stiffness(self.section, self.element_length)  # refuses elements whose stiffness floating point cannot hold
        self._lumped()  # and masses

    # -- geometry and mass -----------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return self.n_elements + 1

    @property
    def reference_node(self) -> int:
        """The node whose frame is the object frame (the middle one)."""
        return self.n_elements // 2

    @property
    def element_length(self) -> float:
        return self.length / self.n_elements

    def node_x(self) -> np.ndarray:
        """Node positions along the beam from its middle (n_nodes,) [m]."""
        return np.linspace(-self.length / 2, self.length / 2, self.n_nodes)

    def node_offsets(self) -> np.ndarray:
        """Node positions in the object frame (the reference node's) (n_nodes, 3) [m]."""
        x = self.node_x() - self.node_x()[self.reference_node]
        return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])

    @property
    def mass(self) -> float:
        """Total mass [kg]."""
        return self.section.rho * self.section.A * self.length

    @property
    def com(self) -> np.ndarray:
        """Centre of mass in the object frame (3,) [m]."""
        return np.array([-self.node_x()[self.reference_node], 0.0, 0.0])

    def node_inertias(self) -> list[pin.Inertia]:
        """Lumped mass: each node takes its tributary length l (half of each adjacent element)
        as mass ρAl at the node, with the slice's rotary inertia ρJ₀l about x and ρI l + m l²/12
        about y and z (J₀ = Iy + Iz)."""
        return [pin.Inertia(m, np.zeros(3), np.diag(I)) for m, I in zip(*self._lumped(), strict=True)]

    def _lumped(self) -> tuple[list[float], list[np.ndarray]]:
        """Each node's mass [kg] and principal inertias (3,) [kg·m²] (:meth:`node_inertias`)."""
        s, h = self.section, self.element_length
        masses, inertias = [], []
        with np.errstate(all="ignore"):
            for k in range(self.n_nodes):
                tributary = np.float64(h if 0 < k < self.n_elements else h / 2)  # numpy: an overflow is inf, not an error
                m = s.rho * s.A * tributary
                I = np.array([s.rho * (s.Iy + s.Iz), s.rho * s.Iy, s.rho * s.Iz]) * tributary
                I[1:] += m * tributary**2 / 12
                masses.append(float(m))
                inertias.append(I)
        if not all(
            math.isfinite(m) and m > 0 and np.all(np.isfinite(I)) and np.all(I > 0) for m, I in zip(masses, inertias, strict=True)
        ):
            raise SceneError(
                f"Beam: its node masses or inertias are not representable in floating point (node mass {masses[0]:.3g} kg, "
                f"inertias {inertias[0]} kg·m²); give lengths in metres and densities in kg/m³ of a real beam"
            )
        return masses, inertias

    def mass_matrix(self) -> np.ndarray:
        """The lumped (block-diagonal) mass matrix (6N, 6N), per node (δp, δθ) in beam axes."""
        M = np.zeros((6 * self.n_nodes, 6 * self.n_nodes))
        for k, inertia in enumerate(self.node_inertias()):
            M[6 * k : 6 * k + 6, 6 * k : 6 * k + 6] = inertia.matrix()
        return M

    def element(self, k: int) -> BeamElement:
        """Element k, joining nodes k and k + 1."""
        return BeamElement(BeamSegment(self.section, self.element_length), self.damping or None, f"{self.name} element {k}")

    # -- the direct stiffness method -------------------------------------------------------------
    def stiffness_matrix(self) -> np.ndarray:
        """The free beam's assembled linear stiffness (6N, 6N) [SI], per node (δp, δθ) in beam
        axes: each element adds ``Bᵀ K B`` with K its tip stiffness and ``B = [−T(L e_x), I]``
        the deformation of its far node relative to the rigid extension of its near one."""
        n, h = self.n_nodes, self.element_length
        Ke = tip_stiffness(self.section, h)
        B = np.hstack([-rigid_map(np.array([h, 0.0, 0.0])), np.eye(6)])
        K = np.zeros((6 * n, 6 * n))
        for k in range(self.n_elements):
            idx = np.r_[6 * k : 6 * k + 12]
            K[np.ix_(idx, idx)] += B.T @ Ke @ B
        return K

    def zero_modes(self, rtol: float = 1e-9) -> int:
        """Number of zero-energy modes of the free beam (6N − rank K): six rigid-body motions;
        an eigenvalue within ``rtol`` (0 < rtol < 1) of the largest counts as zero."""
        rtol = _validate.positive(rtol, "rtol", "1")
        if rtol >= 1.0:
            raise SceneError(f"rtol must be below 1 (a fraction of the largest eigenvalue), got {rtol:g}")
        w = np.linalg.eigvalsh(self.stiffness_matrix())
        return int(np.sum(np.abs(w) <= rtol * np.abs(w).max()))

    def report(self) -> str:
        """One line: nodes, elastic states, rank of K and its rigid-body modes."""
        n_y = 6 * self.n_nodes
        zero = self.zero_modes()
        return (
            f"{self.name}: {self.n_nodes} nodes, {self.n_elements} elements, n_y = {n_y} displacements, "
            f"rank K = {n_y - zero} ({zero} rigid-body modes), mass {self.mass:.4g} kg"
        )

    def spatial_inertia(self) -> pin.Inertia:
        """The whole beam as one rigid body about the object frame (the quasi-static and rigid models)."""
        total = pin.Inertia.Zero()
        for inertia, r in zip(self.node_inertias(), self.node_offsets(), strict=True):
            total += pin.SE3(np.eye(3), r).act(inertia)
        return total
