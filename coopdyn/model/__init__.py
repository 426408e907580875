"""The immutable scene description: arms, the object, interconnections, one Pinocchio model."""

from .arm import Arm
from .beam import Beam
from .body import RigidObject
from .elastic_joints import JointElasticity
from .elements import BeamSegment, Section
from .ik import place_arm
from .interconnection import Interconnection, axial, diagonal
from .limits import quasi_static, rigid_limit
from .scene import Scene

__all__ = [
    "Arm",
    "Beam",
    "BeamSegment",
    "Interconnection",
    "JointElasticity",
    "RigidObject",
    "Scene",
    "Section",
    "axial",
    "diagonal",
    "place_arm",
    "quasi_static",
    "rigid_limit",
]
