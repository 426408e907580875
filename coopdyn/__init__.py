"""coopdyn: dynamics and control of multi-arm cooperating robots with elastic interconnections."""

from . import control, cooperative, integrators, reference, scenes
from ._version import __version__
from .advisor import ModelAdvice, advise_model
from .bench.stability import measure_stable_dt
from .dynamics import Dynamics, Energy, backend
from .errors import (
    AccuracyWarning,
    ControllerError,
    CoopdynError,
    DivergenceError,
    EnergyBalanceError,
    EnergyBalanceWarning,
    FitWarning,
    ModelLoadError,
    OutputError,
    SceneError,
    SceneFileError,
    SceneWarning,
    SimulationError,
    SimulationInterrupted,
    StepBudgetError,
    SweepError,
    SweepInterrupted,
    ViewerError,
)
from .identify import Identification, Measurements, identify
from .linearize import Linearization, linearize
from .model import (
    Arm,
    Beam,
    BeamSegment,
    Interconnection,
    JointElasticity,
    RigidObject,
    Scene,
    Section,
    axial,
    diagonal,
    place_arm,
    quasi_static,
    rigid_limit,
)
from .parameters import with_parameters
from .result import Result
from .rollout import Rollouts, rollout
from .sensitivity import (
    LossGradient,
    Sensitivity,
    StepSensitivity,
    TrajectorySensitivity,
    Transitions,
    step_sensitivity,
    trajectory_sensitivity,
)
from .simulate import simulate
from .simulator import Simulator
from .stability import Advice, advise
from .sweeps import Case, sweep

__all__ = [
    "AccuracyWarning",
    "Advice",
    "Arm",
    "Beam",
    "BeamSegment",
    "Case",
    "ControllerError",
    "CoopdynError",
    "DivergenceError",
    "Dynamics",
    "Energy",
    "EnergyBalanceError",
    "EnergyBalanceWarning",
    "FitWarning",
    "Identification",
    "Interconnection",
    "JointElasticity",
    "Linearization",
    "LossGradient",
    "Measurements",
    "ModelAdvice",
    "ModelLoadError",
    "OutputError",
    "Result",
    "RigidObject",
    "Rollouts",
    "Scene",
    "SceneError",
    "SceneFileError",
    "SceneWarning",
    "Section",
    "Sensitivity",
    "SimulationError",
    "SimulationInterrupted",
    "Simulator",
    "StepBudgetError",
    "StepSensitivity",
    "SweepError",
    "SweepInterrupted",
    "TrajectorySensitivity",
    "Transitions",
    "ViewerError",
    "__version__",
    "advise",
    "advise_model",
    "axial",
    "backend",
    "control",
    "cooperative",
    "diagonal",
    "identify",
    "integrators",
    "linearize",
    "measure_stable_dt",
    "place_arm",
    "quasi_static",
    "reference",
    "rigid_limit",
    "rollout",
    "scenes",
    "simulate",
    "step_sensitivity",
    "sweep",
    "trajectory_sensitivity",
    "with_parameters",
]
