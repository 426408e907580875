"""coopdyn: dynamics and control of multi-arm cooperating robots with elastic interconnections."""

from . import backend, control, integrators, reference, scenes
from .arm import Arm
from .body import RigidObject
from .dynamics import Dynamics, Energy
from .errors import (
    ControllerError,
    CoopdynError,
    DivergenceError,
    ModelLoadError,
    SceneError,
    SimulationError,
    SimulationInterrupted,
)
from .interconnection import Interconnection, axial, diagonal
from .monitor import EnergyBalanceError, EnergyBalanceWarning
from .scene import Scene
from .simulate import Result, simulate
from .stability import Advice, advise, measure_stable_dt

__all__ = [
    "Advice",
    "Arm",
    "ControllerError",
    "CoopdynError",
    "DivergenceError",
    "Dynamics",
    "Energy",
    "EnergyBalanceError",
    "EnergyBalanceWarning",
    "Interconnection",
    "ModelLoadError",
    "Result",
    "RigidObject",
    "Scene",
    "SceneError",
    "SimulationError",
    "SimulationInterrupted",
    "advise",
    "axial",
    "backend",
    "control",
    "diagonal",
    "integrators",
    "measure_stable_dt",
    "reference",
    "scenes",
    "simulate",
]
__version__ = "0.1.0"
