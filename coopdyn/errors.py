"""The exception hierarchy: every error coopdyn raises derives from :class:`CoopdynError`."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class CoopdynError(Exception):
    """Root of every error raised by coopdyn."""


class SceneError(CoopdynError, ValueError):
    """A scene description (arm, object, interconnection, parameter) is invalid."""


class GraspGeometryError(SceneError):
    """The grasps' geometry admits no squeeze direction (grasp points at their centroid). An
    adaptive method's trial stage can fling the grasps there: its attempt is then rejected."""


class ModelLoadError(SceneError):
    """A robot model could not be found or parsed."""


class SimulationError(CoopdynError, RuntimeError):
    """A simulation was asked something invalid or could not proceed."""


class _CarriesResult(BaseException):
    """An error that carries the trajectory computed so far in ``result``; its message says so,
    and ``detail`` is the message without that sentence (what the command line prints, with
    where it saved the trajectory instead)."""

    def __init__(self, message: str, *, result: object = None) -> None:
        t = getattr(result, "t", None)
        if t is None:
            full = message
        else:
            upto = f"up to t = {t[-1]:.6g} s" if len(t) else "(no sample yet)"
            kind = "exception" if isinstance(self, KeyboardInterrupt) else "error"
            full = f"{message}. The trajectory {upto} is in this {kind}'s .result"
        super().__init__(full)
        self.detail = message
        self.result = result


class DivergenceError(_CarriesResult, SimulationError):
    """The simulation blew up. ``result`` holds the trajectory up to the failure and ``advice``
    the stability analysis (:class:`coopdyn.stability.Advice`) at the last saved state."""

    def __init__(self, message: str, *, result: object = None, advice: object = None) -> None:
        super().__init__(message, result=result)
        self.advice = advice


class SimulationInterrupted(_CarriesResult, KeyboardInterrupt):
    """Ctrl-C during a simulation. A ``KeyboardInterrupt`` (it stops a script like one), with
    the trajectory computed so far in ``result``."""


class StepBudgetError(_CarriesResult, SimulationError):
    """An adaptive method used up ``simulate``'s ``max_steps`` (accepted and rejected steps) before
    the end: its steps shrank to follow a mode it cannot step over. ``result`` holds the
    trajectory so far."""


class StepSizeError(StepBudgetError):
    """An adaptive method's step fell below its ``h_min`` without meeting its tolerances (a
    :class:`StepBudgetError`: its step control gave up). ``result`` holds the trajectory so far."""


class StepMatrixError(_CarriesResult, SimulationError):
    """The step matrix of a linearly implicit step, M + γh·D̃ + (γh)²·K̃, is not positive definite
    (a negative gain or stiffness, or a state that is no longer finite). Raised by ``simulate``
    with the time and the method, and ``result`` holding the trajectory up to there."""


class SweepError(CoopdynError, ValueError):
    """A sweep was asked something invalid (its parameters, executor or spec), or its table cannot
    be read or written; a single run that fails is a row of the table, never this error. When the
    runs finished but the table could not be written, ``table`` holds it."""

    def __init__(self, message: str, *, table: object = None) -> None:
        super().__init__(message)
        self.table = table


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep. A ``KeyboardInterrupt``, with the table so far in ``table`` (the
    finished runs, and the others with status ``"not run"``) and the Parquet file it was written
    to, if any, in ``saved``."""

    def __init__(self, message: str, *, table: object = None, saved: object = None) -> None:
        super().__init__(message)
        self.detail = message
        self.table = table
        self.saved = saved


class KernelError(SimulationError):
    """The compiled kernel refused a call (wrong shapes or types reaching it)."""


class ControllerError(SimulationError):
    """A controller returned something that is not a finite torque vector of the right length."""


class SceneFileError(SceneError):
    """A scene file is malformed; the message names the file, the key and its line."""


class OutputError(CoopdynError, OSError):
    """A run's outputs could not be written where asked; the message says where they went instead."""


class ViewerError(CoopdynError, RuntimeError):
    """The live viewer's server could not start."""


class MissingDependencyError(CoopdynError, ImportError):
    """A dependency a feature needs is not installed."""


class BackendError(CoopdynError, RuntimeError):
    """The requested backend cannot be used."""


class EnergyBalanceError(CoopdynError, RuntimeError):
    """Raised instead of :class:`EnergyBalanceWarning` with ``energy_check="raise"``."""


class EnergyBalanceWarning(UserWarning):
    """Total energy grew more than the net input work explains."""


class AccuracyWarning(UserWarning):
    """A stable method's step does not resolve an oscillatory mode: the run completes, but the
    forces that mode carries are damped away or out of phase (see :func:`coopdyn.advise`)."""


class ControlRateWarning(UserWarning):
    """A built-in controller sampled too slowly for its gains (``simulate(control_dt=…)``): the
    sampled closed loop, linearised exactly at the start, grows by more than e over the run where
    the same gains applied continuously do not. The run completes; the message says whether its
    motion already shows that instability."""


class UnstableLoopWarning(UserWarning):
    """The closed loop under a built-in controller, linearised exactly at the start, has an
    oscillating mode that grows by more than e over the run (no method makes it stable). The
    message says whether the run shows it — its grasp forces grow ×2 from its first third to its
    last, and its figures are the instability's, dependent on the step — or not yet."""


class SceneWarning(UserWarning):
    """A scene or task that runs but looks wrong: a task that starts away from the object, a
    grasp far from it. The message gives the figure and the fix."""


class LogMapWarning(UserWarning):
    """A deformation's rotation neared π, where the SE(3) logarithm jumps."""


class FitWarning(UserWarning):
    """An identification finished, but its estimate should not be trusted as it stands: the model
    does not explain the data (a residual far above the noise), or a parameter is not determined
    by them (its uncertainty as large as its value). The message names which and why."""


class NativeBackendWarning(UserWarning):
    """The compiled kernel is unavailable; the (slower) Python path runs instead."""


def did_you_mean(name: str, candidates: Iterable[str], *, n: int = 3) -> str:
    """Return ``" Did you mean 'a', 'b'?"`` for the closest candidates, or ``""``."""
    if not isinstance(name, str):  # a wrong type gets no suggestion (its message says what is valid)
        return ""
    try:
        names = [c for c in candidates if isinstance(c, str)]
    except TypeError:
        return ""
    close = difflib.get_close_matches(name, names, n=n, cutoff=0.5)
    if not close:
        return ""
    return " Did you mean " + ", ".join(repr(c) for c in close) + "?"
