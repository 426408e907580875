"""Cooperative object-level control (``coopdyn.cooperative``): the public home of
:class:`ObjectImpedance` and :class:`GripLiftOscillate`, defined in :mod:`coopdyn.control.cooperative`."""

from .control.cooperative import GripLiftOscillate, ObjectImpedance, ObjectReference

__all__ = ["GripLiftOscillate", "ObjectImpedance", "ObjectReference"]
