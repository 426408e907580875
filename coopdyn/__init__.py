"""coopdyn: dynamics and control of multi-arm cooperating robots with elastic interconnections."""

from . import reference, scenes
from .arm import Arm
from .body import RigidObject
from .dynamics import Dynamics, Energy
from .errors import ControllerError, CoopdynError, ModelLoadError, SceneError, SimulationError
from .interconnection import Interconnection, axial, diagonal
from .scene import Scene
from .simulate import Result, simulate

__all__ = [
    "Arm",
    "ControllerError",
    "CoopdynError",
    "Dynamics",
    "Energy",
    "Interconnection",
    "ModelLoadError",
    "Result",
    "RigidObject",
    "Scene",
    "SceneError",
    "SimulationError",
    "axial",
    "diagonal",
    "reference",
    "scenes",
    "simulate",
]
__version__ = "0.1.0"
