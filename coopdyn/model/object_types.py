"""The registry of objects a scene can hold: one line per object class (its description types
come with it). :mod:`coopdyn.model.objects` says what a class must implement."""

from __future__ import annotations

from .beam import Beam
from .body import RigidObject
from .fields import Field
from .objects import SceneObject

#: every object class a description can name, in the order their types are listed
OBJECTS: tuple[type[SceneObject], ...] = (
    RigidObject,  # types "box" and "rigid"
    Beam,  # type "beam"
)


def description_types() -> dict[str, tuple[type[SceneObject], dict[str, Field]]]:
    """A description's object type name → (its class, its keys)."""
    return {name: (cls, fields) for cls in OBJECTS for name, fields in cls.description_types.items()}


__all__ = ["OBJECTS", "description_types"]
