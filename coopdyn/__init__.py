"""coopdyn: dynamics and control of multi-arm cooperating robots with elastic interconnections."""

from . import control, cooperative, integrators, reference, scenes
from .bench.stability import measure_stable_dt
from .dynamics import Dynamics, Energy, backend
from .errors import (
    AccuracyWarning,
    ControllerError,
    CoopdynError,
    DivergenceError,
    EnergyBalanceError,
    EnergyBalanceWarning,
    ModelLoadError,
    OutputError,
    SceneError,
    SceneFileError,
    SimulationError,
    SimulationInterrupted,
    StepBudgetError,
    ViewerError,
)
from .model import Arm, Interconnection, RigidObject, Scene, axial, diagonal, rigid_limit
from .result import Result
from .simulate import simulate
from .stability import Advice, advise

__all__ = [
    "AccuracyWarning",
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
    "OutputError",
    "Result",
    "RigidObject",
    "Scene",
    "SceneError",
    "SceneFileError",
    "SimulationError",
    "SimulationInterrupted",
    "StepBudgetError",
    "ViewerError",
    "advise",
    "axial",
    "backend",
    "control",
    "cooperative",
    "diagonal",
    "integrators",
    "measure_stable_dt",
    "reference",
    "rigid_limit",
    "scenes",
    "simulate",
]
__version__ = "0.1.0"
