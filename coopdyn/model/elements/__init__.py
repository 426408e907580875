"""Interconnection elements and their registry.

:data:`ELEMENTS` maps an element kind (``Interconnection(..., element=kind)``) to its Python
class — the reference implementation — and the name of its C++ twin in ``coopdyn._native``
(``None``: the compiled kernel calls the element's Python ``evaluate`` for it, with one
warning, and keeps the rest of the scene compiled). docs/extending.md says how to add one.
"""

from __future__ import annotations

from typing import NamedTuple

from ..._validate import _short
from ...errors import SceneError, did_you_mean
from .ball_spring import BallSpring
from .base import Element, ElementEval, Parameter, SpringDamper
from .beam import BeamElement, BeamSegment, Section
from .hardening_spring import HardeningSpring
from .rigid import RigidGrasp, RigidPoint
from .se3_spring import SE3Spring


class ElementType(NamedTuple):
    """A registered element kind."""

    python: type[Element]  #: the reference implementation
    native: str | None  #: name of the C++ twin in coopdyn._native, or None


#: kind → (Python class, C++ twin)
ELEMENTS: dict[str, ElementType] = {
    "se3": ElementType(SE3Spring, "se3"),
    "ball": ElementType(BallSpring, "ball"),
    "beam": ElementType(BeamElement, "se3"),  # the SE(3) law with the beam's stiffness
    "hardening": ElementType(HardeningSpring, "hardening"),
    "rigid": ElementType(RigidGrasp, None),
    "rigid_point": ElementType(RigidPoint, None),
}


def register(cls: type[Element], native: str | None = None) -> type[Element]:
    """Register an element class under ``cls.kind`` (``native``: its C++ twin, if the kernel has
    one). Returns ``cls`` (usable as a class decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, Element)):
        raise SceneError(f"register() takes a subclass of coopdyn.model.elements.Element, got {cls!r}")
    kind = getattr(cls, "kind", None)
    if not isinstance(kind, str) or not kind:
        raise SceneError(f"{cls.__name__} needs a class attribute kind = '<name>' to be registered")
    ELEMENTS[kind] = ElementType(cls, native)
    return cls


def lookup(kind: str | type[Element]) -> ElementType:
    """The registered element for a kind name (or an Element subclass, registered or not)."""
    if isinstance(kind, type) and issubclass(kind, Element):
        name = getattr(kind, "kind", None)
        if not isinstance(name, str) or not name or getattr(kind, "__abstractmethods__", None):
            raise SceneError(f"{kind.__name__} is not an element to build: a concrete Element subclass with kind = '<name>'")
        known = ELEMENTS.get(name)
        return known if known is not None and known.python is kind else ElementType(kind, None)
    if not isinstance(kind, str) or kind not in ELEMENTS:
        hint = did_you_mean(kind, ELEMENTS) if isinstance(kind, str) else ""
        raise SceneError(f"unknown interconnection element {_short(kind)}.{hint} Registered: {sorted(ELEMENTS)}")
    return ELEMENTS[kind]


__all__ = [
    "ELEMENTS",
    "BallSpring",
    "BeamElement",
    "BeamSegment",
    "Element",
    "ElementEval",
    "ElementType",
    "HardeningSpring",
    "Parameter",
    "RigidGrasp",
    "RigidPoint",
    "SE3Spring",
    "Section",
    "SpringDamper",
    "lookup",
    "register",
]
