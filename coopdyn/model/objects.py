"""The object protocol: what a scene asks of the object the arms hold.

A :class:`~coopdyn.model.scene.Scene` adds its object to the Pinocchio model, puts the grasp
frames on it, takes its internal elastic elements, draws it, describes it as data and builds it
back — all through :class:`SceneObject`, which :class:`~coopdyn.model.body.RigidObject` and
:class:`~coopdyn.model.beam.Beam` implement; nothing outside the object modules asks which kind
of object a scene has. A new object is a module with a subclass, its tests and one line in
:data:`coopdyn.model.object_types.OBJECTS` (docs/extending.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar, NamedTuple

import numpy as np
import pinocchio as pin

from .elements import Element
from .fields import Field


class Placement(NamedTuple):
    """Where an object went in a scene's model."""

    reference: int  #: the joint the object frame rides on
    joints: tuple[int, ...]  #: every joint of the object, in order (a rigid object: one)
    q0: np.ndarray  #: their initial coordinates, in order (the joints' nq summed,)


class InternalLink(NamedTuple):
    """One of the object's own elastic elements (a beam's elements): between two of its frames."""

    name: str
    tip_frame: int  #: T
    grasp_frame: int  #: G
    element: Element
    native: str | None  #: the element's C++ twin


class Shape(NamedTuple):
    """A box drawn for the object (the viewer's geometry)."""

    name: str
    joint: int
    frame: int
    placement: pin.SE3  #: in the joint's frame
    size: tuple[float, float, float]  #: edge lengths x, y, z [m]


class SceneObject(ABC):
    """What a scene asks of its object (see the module docstring).

    A subclass is an immutable dataclass with at least ``name`` and ``pose`` (the initial pose of
    the object frame in the world, or None) and implements the abstract methods.
    """

    name: str
    pose: Any
    #: its types in a description (scene files, saved results): type name → its keys
    description_types: ClassVar[dict[str, dict[str, Field]]]

    @property
    @abstractmethod
    def joint_label(self) -> str:
        """What a scene's summary calls the object's joints (``"freeflyer"``, ``"beam of free nodes"``)."""

    @classmethod
    @abstractmethod
    def from_description(cls, type_name: str, values: dict[str, Any]) -> SceneObject:
        """The object a description's ``[object]`` table of ``type_name`` holds (``values``:
        its keys, checked and converted by kind); raise SceneError when it is not one."""

    @abstractmethod
    def describe(self) -> dict[str, Any]:
        """This object as a description's ``[object]`` table (``type`` and its keys)."""

    def check(self) -> None:  # noqa: B027 (a hook: most objects check everything when made)
        """Refuse (SceneError) what its constructor could not check on its own."""

    @abstractmethod
    def mass_and_com(self) -> tuple[float, np.ndarray]:
        """Its mass [kg] and centre of mass in the object frame (3,) [m] (at rest)."""

    def with_mass(self, mass: float) -> SceneObject | None:
        """This object with its mass set to ``mass`` [kg] and its inertia scaled with it (the same
        shape, another density) — what identifying a mass changes — or None when it is not one
        body on one joint (an elastic object: its mass is spread over nodes)."""
        return None

    @abstractmethod
    def spatial_inertia(self) -> pin.Inertia:
        """Its mass [kg], centre of mass (3,) [m] in the object frame and rotational inertia about
        that centre of mass (3, 3) [kg·m²], at rest: Pinocchio's ``Inertia(mass, lever, inertia)``."""

    @abstractmethod
    def add_to(self, model: pin.Model) -> Placement:
        """Add the object's joints, bodies and its frame (named :attr:`name`) to ``model``."""

    def grasp_joint(self, placement: Placement, o_M_G: pin.SE3) -> tuple[int, pin.SE3]:
        """The joint a grasp frame at ``o_M_G`` (in the object frame) rides on, and its placement
        there. Default: the reference joint."""
        return placement.reference, o_M_G

    def internal_links(self, model: pin.Model, placement: Placement) -> list[InternalLink]:
        """The object's own elastic elements, their frames added to ``model``. Default: none."""
        return []

    def memory_hint(self, nv: int, fits: int) -> str:
        """A hint appended to the refusal of a scene too big for memory: it has ``nv`` velocities and
        at most ``fits`` would fit; the text starts with ``"; "`` (the beam: "; this beam fits with
        at most 12 elements"). Default: no hint."""
        return ""

    @abstractmethod
    def shapes(self, model: pin.Model) -> list[Shape]:
        """The boxes the viewer draws for it."""

    def bounds(self, model: pin.Model) -> list[Shape] | None:
        """The boxes it fills, for the check that each grasp is on it (a SceneWarning names a
        grasp farther from them than the object's size); None when it does not say its size
        (:meth:`shapes` then draws a stand-in). Default: its shapes."""
        return self.shapes(model)

    def lowest_frequency(self) -> float | None:
        """Its own lowest elastic mode when free [Hz]; None for a rigid object (no elastic model of its own)."""
        return None

    def condensed(self, scene: Any) -> tuple[SceneObject, list[Any]] | None:
        """The quasi-static model of ``scene`` (this object's scene): the object made one rigid
        body, and the :class:`~coopdyn.model.interconnection.Interconnection` list that holds
        it with the object's elasticity condensed into them; None when there is nothing to
        condense (a rigid object)."""
        return None


__all__ = ["InternalLink", "Placement", "SceneObject", "Shape"]
