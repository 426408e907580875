"""The immutable scene description: arms, the object, interconnections, one Pinocchio model."""

from .arm import Arm
from .body import RigidObject
from .interconnection import Interconnection, axial, diagonal
from .limits import rigid_limit
from .scene import Scene

__all__ = ["Arm", "Interconnection", "RigidObject", "Scene", "axial", "diagonal", "rigid_limit"]
