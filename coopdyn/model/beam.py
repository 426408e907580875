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
import scipy.linalg

from .. import _validate
from ..errors import SceneError
from .body import RigidObject
from .elements.beam import BeamElement, BeamSegment, Section, tip_stiffness
from .fields import Field, pose_data
from .objects import InternalLink, Placement, SceneObject, Shape


def rigid_map(r: np.ndarray) -> np.ndarray:
    """The 6×6 map from a node's small displacement (δp, δθ) to that of a point at offset r
    rigidly attached to it: (δp + δθ × r, δθ)."""
    return pin.SE3(np.eye(3), -np.asarray(r, dtype=float)).toActionMatrix()


MAX_ELEMENTS = 500  #: a beam is a body per node, and its dense stiffness has 6·(n + 1) rows
#: the nodes' rotary inertia about the bending axes (Beam.rotary_inertia)
ROTARY_INERTIAS = ("slice", "section")


@dataclass(frozen=True, eq=False)
class Beam(SceneObject):
    """A straight, uniform, free elastic beam held by the arms.

    Attributes:
        length: [m], along the beam's x axis. section: its :class:`Section`.
        n_elements: beam elements (≥ 1); nodes = n_elements + 1, equally spaced.
        pose: initial pose of the beam frame (x along the beam, origin at its middle) in the
            world (``pin.SE3``, 4x4 or translation [m]).
        damping: β [s], stiffness-proportional damping of every element; default 0.
        name: prefix of its joints and frames; the object frame is named ``name``.
        rotary_inertia: what each node's rotary inertia about the bending axes is —
            ``"slice"`` (default): its slice of length l as a rigid body, ρI·l + m·l²/12;
            ``"section"``: the cross-section's own, ρI·l (a Rayleigh beam). The slice's extra
            m·l²/12 is an artefact of lumping that lowers the bending frequencies: with
            ``"section"`` the first three modes of a cantilever are within 0.5 % at 32 elements
            (``"slice"``: mode 3 0.65 % low), at the price of node rotations up to
            √(1 + l²/12r²) times faster (r the section's radius of gyration about the bending
            axis), which a step must resolve or an implicit method damp (tests/test_beam.py).
    """

    length: float
    section: Section
    n_elements: int = 8
    pose: Any = None
    damping: float = 0.0
    name: str = "beam"
    rotary_inertia: str = "slice"

    description_types: ClassVar[dict[str, dict[str, Field]]] = {
        "beam": {
            "length": Field("number", "length along the beam's x axis [m]", True),
            "section": Field("section", "material and cross-section", True),
            "n_elements": Field("integer", "beam elements (nodes = n_elements + 1); default 8"),
            "pose": Field("pose", "initial pose of the beam frame (x along the beam, origin at its middle) [m]"),
            "damping": Field("number", "stiffness-proportional damping β [s]; default 0"),
            "name": Field("string", "prefix of the beam's joints and frames; default 'beam'"),
            "rotary_inertia": Field(
                "string",
                "each node's rotary inertia about the bending axes: 'slice' (default; its slice as a rigid body, "
                "ρI·l + m·l²/12) or 'section' (ρI·l, a Rayleigh beam: the first modes more accurate, node rotations faster)",
            ),
        },
    }

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
        if not isinstance(self.rotary_inertia, str) or self.rotary_inertia not in ROTARY_INERTIAS:
            raise SceneError(
                f"Beam: rotary_inertia must be one of {list(ROTARY_INERTIAS)}, got {_validate._short(self.rotary_inertia)}"
            )
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
        as mass ρAl at the node, with the rotary inertia ρJ₀l about x (J₀ = Iy + Iz) and, about
        y and z, ρI l + m l²/12 (``rotary_inertia="slice"``) or ρI l (``"section"``)."""
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
                if self.rotary_inertia == "slice":
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

    # -- the object protocol (objects.SceneObject) -----------------------------------------------
    @property
    def joint_label(self) -> str:
        return "beam of free nodes"

    def mass_and_com(self) -> tuple[float, np.ndarray]:
        return self.mass, self.com

    @classmethod
    def from_description(cls, type_name: str, values: dict[str, Any]) -> Beam:
        return cls(**values)

    def describe(self) -> dict[str, Any]:
        s = self.section
        section = {k: float(getattr(s, k)) for k in ("E", "G", "rho", "A", "Iy", "Iz", "J")}
        if s.shear_factor is not None:
            section["shear_factor"] = float(s.shear_factor)
        out: dict[str, Any] = {"type": "beam", "length": self.length, "section": section, "n_elements": self.n_elements}
        out |= {"damping": self.damping, "name": self.name}
        if self.rotary_inertia != "slice":
            out["rotary_inertia"] = self.rotary_inertia
        if self.pose is not None:
            out["pose"] = pose_data(self.pose, "object pose")
        return out

    def add_to(self, model: pin.Model) -> Placement:
        """The nodes as free bodies, in beam axes at rest; the object frame on the reference node."""
        oMb = pin.SE3.Identity() if self.pose is None else _validate.se3(self.pose, "beam pose")
        joints, q = [], []
        for k, (x, inertia) in enumerate(zip(self.node_x(), self.node_inertias(), strict=True)):
            j = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), f"{self.name}/node{k}")
            model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
            model.addBodyFrame(f"{self.name}/node{k}", j, pin.SE3.Identity(), 0)
            joints.append(j)
            q.append(pin.SE3ToXYZQUAT(oMb * pin.SE3(np.eye(3), np.array([x, 0.0, 0.0]))))
        ref = joints[self.reference_node]
        model.addFrame(pin.Frame(self.name, ref, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
        return Placement(ref, tuple(joints), np.concatenate(q))

    def grasp_joint(self, placement: Placement, o_M_G: pin.SE3) -> tuple[int, pin.SE3]:
        """The node nearest the grasp point, and the grasp frame's placement on it."""
        offsets = self.node_offsets()
        k = int(np.argmin(np.linalg.norm(offsets - o_M_G.translation, axis=1)))
        return placement.joints[k], pin.SE3(np.eye(3), -offsets[k]) * o_M_G

    def internal_links(self, model: pin.Model, placement: Placement) -> list[InternalLink]:
        """The beam elements: T on node k where node k + 1 rests, G on node k + 1."""
        h, joints = self.element_length, placement.joints
        out = []
        for k in range(self.n_elements):
            name = f"{self.name}/element{k}"
            t_id = model.addFrame(
                pin.Frame(f"{name}/T", joints[k], pin.SE3(np.eye(3), np.array([h, 0.0, 0.0])), pin.FrameType.OP_FRAME)
            )
            g_id = model.addFrame(pin.Frame(f"{name}/G", joints[k + 1], pin.SE3.Identity(), pin.FrameType.OP_FRAME))
            out.append(InternalLink(name, int(t_id), int(g_id), self.element(k), "se3"))
        return out

    def memory_hint(self, nv: int, fits: int) -> str:
        most = self.n_elements - math.ceil((nv - fits) / 6)
        return f"; this beam fits with at most {max(most, 0)} elements" if most >= 1 else "; no beam of free nodes fits"

    def shapes(self, model: pin.Model) -> list[Shape]:
        """One box per node, an element long (half at the ends): the chain bends with the nodes."""
        h = self.element_length
        width, height = self._section_size()
        out = []
        for k in range(self.n_nodes):
            length = h if 0 < k < self.n_elements else h / 2
            shift = 0.0 if 0 < k < self.n_elements else (h / 4 if k == 0 else -h / 4)
            out.append(
                Shape(
                    f"{self.name}/segment{k}",
                    model.getJointId(f"{self.name}/node{k}"),
                    model.getFrameId(f"{self.name}/node{k}"),
                    pin.SE3(np.eye(3), np.array([shift, 0.0, 0.0])),
                    (length * 0.96, float(width), float(height)),
                )
            )
        return out

    def _section_size(self) -> tuple[float, float]:
        """The width (y) and height (z) [m] of the rectangle with the section's area moments
        (at least 5 mm: drawn visibly)."""
        s = self.section
        return max(float(np.sqrt(12 * s.Iz / s.A)), 0.005), max(float(np.sqrt(12 * s.Iy / s.A)), 0.005)

    def lowest_frequency(self) -> float:
        """The free beam's lowest elastic mode [Hz] (its six rigid-body modes left out)."""
        w = np.sqrt(np.clip(scipy.linalg.eigh(self.stiffness_matrix(), self.mass_matrix(), eigvals_only=True), 0.0, None))
        return float(w[w > 1e-6 * max(w.max(), 1.0)].min() / (2 * np.pi))

    def condensed(self, scene: Any) -> tuple[RigidObject, list[Any]]:
        """Static condensation: the nodes other than the reference one taken as massless and
        eliminated; the beam becomes one rigid body (its mass and inertia, on the reference
        node's frame), and each grasp's SE(3) spring the series stiffness of that spring and the
        beam between its node and the reference node (Schur complement of the assembled linear
        stiffness, reference node clamped), in the spring's own axes; dampers kept.

        Raises:
            SceneError: two grasps on the same side of the reference node (their condensed
                stiffnesses couple, which pairwise springs cannot represent), or an
                interconnection that is not an SE(3) spring.
        """
        import dataclasses

        model = scene.model
        node_of = {model.getJointId(f"{self.name}/node{k}"): k for k in range(self.n_nodes)}
        nodes = [node_of[model.frames[lk.grasp_frame].parentJoint] for lk in scene.links]
        ref = self.reference_node
        free = [k for k in range(self.n_nodes) if k != ref]
        K = self.stiffness_matrix()
        held = sorted(set(nodes) - {ref})
        a = (6 * np.array(held, dtype=int)[:, None] + np.arange(6)).ravel()  # their coordinates
        b = (6 * np.array([k for k in free if k not in held], dtype=int)[:, None] + np.arange(6)).ravel()
        K_held = K[np.ix_(a, a)] - K[np.ix_(a, b)] @ np.linalg.solve(K[np.ix_(b, b)], K[np.ix_(b, a)])
        for i, j in ((i, j) for i in range(len(held)) for j in range(len(held)) if i != j):
            if np.abs(K_held[6 * i : 6 * i + 6, 6 * j : 6 * j + 6]).max() > 1e-9 * np.abs(K_held).max():
                raise SceneError(
                    f"quasi_static: the grasps at nodes {held[i]} and {held[j]} lie on the same side of the reference node "
                    f"{ref}; their condensed stiffnesses couple, which springs between each arm and one rigid body cannot "
                    "represent"
                )
        offsets = self.node_offsets()
        specs = []
        for ic, lk, k in zip(scene.interconnection_specs, scene.links, nodes, strict=True):
            if lk.element.kind != "se3":
                raise SceneError(f"quasi_static condenses SE(3) springs only; {lk.name!r} is {lk.element.kind!r}")
            P = model.frames[lk.grasp_frame].placement  # G on its node
            K_ic = np.asarray(lk.element.K)
            if k == ref:
                K_tip = K_ic
            else:
                i = held.index(k)
                K_node = K_held[6 * i : 6 * i + 6, 6 * i : 6 * i + 6]
                R = np.kron(np.eye(2), P.rotation.T)
                A = R @ rigid_map(P.translation)  # node displacement → G's, in G (= T at rest) axes
                K_tip = K_ic - K_ic @ A @ np.linalg.solve(A.T @ K_ic @ A + K_node, A.T @ K_ic)
            grasp = pin.SE3(np.eye(3), offsets[k]) * P
            specs.append(dataclasses.replace(ic, stiffness=0.5 * (K_tip + K_tip.T), grasp=grasp, element="se3"))
        data = model.createData()
        pin.framesForwardKinematics(model, data, scene.q0)
        inertia = self.spatial_inertia()
        body = RigidObject(
            mass=inertia.mass,
            inertia=inertia.inertia,
            com=inertia.lever,
            pose=pin.SE3(data.oMf[scene.object_frame]),
            name=self.name,
            size=(self.length, *self._section_size()),  # (drawn as the beam, not a stand-in box)
        )
        return body, specs
