"""One run of a sweep: what to simulate (:class:`Case`), the list of runs (:func:`expand`), and
the code a worker runs for each (:func:`run_chunk`), which turns any outcome into a row.

A worker receives a *job* — the user's ``make_case`` function, or a scene-file spec's text —
once per process where the engine allows (local processes: when the process starts; Dask: one
broadcast; another executor: with every chunk, :func:`run_chunk` unpacking it once by its hash)
and chunks of items (run number,
parameters, seed). It builds each case itself, so no scene, Pinocchio ``Data`` or compiled
kernel ever crosses a process boundary: the kernel is built lazily, in the worker, by the first
simulation of each scene.
"""

from __future__ import annotations

import hashlib
import inspect
import itertools
import math
import os
import socket
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .. import _validate
from .._validate import positive
from .._version import __version__
from ..errors import CoopdynError, DivergenceError, StepBudgetError, SweepError
from ..metrics import run_metrics
from ..model.scene import Scene
from ..simulate import simulate

#: columns every row has, besides the parameters and the metrics
STATUS = ("run", "seed", "status", "message")
SETTINGS = ("integrator", "dt_s", "duration_s", "save_every", "loop", "backend")
COUNTERS = ("t_reached_s", "n_steps", "n_rhs")
TIMING = ("cpu_s", "wall_s", "worker")  #: what depends on the machine and its load: not reproduced by a rerun
VERSIONS = ("coopdyn_version", "pinocchio_version", "numpy_version")
RESERVED = frozenset((*STATUS, *SETTINGS, *COUNTERS, *TIMING, *VERSIONS, "warnings", "trajectory"))
#: what a row's status says
STATUSES = {
    "completed": "the run reached its duration",
    "diverged": "the state stopped being finite or exceeded max_speed (message: the stability diagnosis)",
    "stopped": "an adaptive method used up max_steps, or its step fell below its h_min",
    "failed": "an exception: building the case, simulating or computing the metrics (message: what and where)",
    "crashed": "the worker process running it died (message: its exit code or signal)",
    "not run": "the sweep was interrupted (Ctrl-C) before this run finished",
}


@dataclass(frozen=True)
class Case:
    """One run of a sweep: a scene and how to simulate it. ``make_case`` returns one (or a bare
    :class:`coopdyn.Scene`, simulated without a controller).

    Attributes:
        scene: the scene.
        controller: ``controller(t, q, v) -> τ`` (a built-in one runs in the compiled loop).
        task: the object's reference ``task(t)`` for the tracking metrics (e.g. a
            :class:`coopdyn.cooperative.GripLiftOscillate`); default: the controller's
            ``reference`` when it has one.
        duration: simulated time [s]; integrator, dt [s], save_every: as for
            :func:`coopdyn.simulate`. ``None`` takes the sweep's setting.
        control_dt: the controller's sample period [s] (:func:`coopdyn.simulate`'s
            ``control_dt``); ``None``: called at every evaluation.
    """

    scene: Scene
    controller: Any = None
    task: Any = None
    duration: float | None = None
    integrator: str | None = None
    dt: float | None = None
    save_every: int | None = None
    control_dt: float | None = None  #: the controller's sample period [s] (None: every evaluation)


@dataclass(frozen=True)
class Settings:
    """The sweep's simulation settings, for cases that leave them unset."""

    duration: float | None = None
    integrator: str = "rk4"
    dt: float = 1e-3
    save_every: int | None = None  #: None: a sample every millisecond
    max_steps: int | None = 2 * 10**6
    energy_check: str = "warn"
    accuracy_check: str = "auto"


@dataclass(frozen=True)
class Item:
    """A run to do: its number, parameter values and seed."""

    run: int
    params: dict[str, Any]
    seed: int | None


#: the most runs one sweep takes (its items and its table are held in memory)
MAX_RUNS = 10**7


def _plain(value: Any, name: str, what: str = "parameter") -> Any:
    """A parameter (or metric) value as a plain number, string, bool or list of them (what a table stores)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, int | float):
        return value
    if isinstance(value, list | tuple):
        return [_plain(v, name, what) for v in value]
    hint = "; build objects inside make_case from plain values" if what == "parameter" else ""
    raise SweepError(
        f"{what} {name!r}: a value must be a number, string, bool or list of them (what a table stores), "
        f"got {type(value).__name__}{hint}"
    )


def expand(params: Any, seeds: Any) -> list[Item]:
    """The runs: ``params`` as a grid (a dict of value lists: every combination, the first key
    varying slowest; a scalar is one value), given samples (a list of dicts, or a pandas
    DataFrame, one run per row), or ``None`` (one run); each combined with every seed
    (``seeds``: None, a count n for 0..n-1, or a list of integers)."""
    if params is None:
        sets: list[dict[str, Any]] = [{}]
    elif hasattr(params, "to_dict") and hasattr(params, "columns"):  # a pandas DataFrame
        sets = [dict(r) for r in params.to_dict(orient="records")]
    elif isinstance(params, Mapping):
        names = list(params)
        values = []
        for name in names:
            v = params[name]
            if isinstance(v, np.ndarray):
                v = list(v)
            v = list(v) if isinstance(v, list | tuple | range) else [v]
            if not v:
                raise SweepError(f"parameter {name!r} has no values")
            values.append(v)
        if math.prod(map(len, values)) > MAX_RUNS:
            raise SweepError(
                f"a grid of {math.prod(map(len, values)):.3g} combinations: more than one sweep holds ({MAX_RUNS:.0e})"
            )
        sets = [dict(zip(names, combo, strict=True)) for combo in itertools.product(*values)]
    elif isinstance(params, Sequence) and not isinstance(params, str | bytes):
        sets = [dict(p) if isinstance(p, Mapping) else _bad_params(p) for p in params]
        if not sets:
            raise SweepError("params is an empty list: no runs to do")
    else:
        _bad_params(params)
    if any(list(s) != list(sets[0]) for s in sets):  # one column per parameter, each in every row
        different = next(s for s in sets if list(s) != list(sets[0]))
        raise SweepError(
            f"every parameter set must name the same parameters in the same order: {list(sets[0])} and {list(different)}"
        )
    for name in sets[0]:
        if not isinstance(name, str) or not name:
            raise SweepError(f"parameter names must be non-empty strings, got {name!r}")
        if name in RESERVED:
            raise SweepError(f"parameter name {name!r} is a column of every row; rename it (reserved: {sorted(RESERVED)})")
    plain = [{k: _plain(v, k) for k, v in p.items()} for p in sets]
    for name in sets[0]:
        _one_kind([p[name] for p in plain], name)
    seed_list = _seeds(seeds)
    if len(plain) * len(seed_list) > MAX_RUNS:
        raise SweepError(
            f"{len(plain)} parameter sets × {len(seed_list)} seeds = {len(plain) * len(seed_list):.3g} runs: more than "
            f"one sweep holds ({MAX_RUNS:.0e}); split it"
        )
    return [Item(i, p, seed) for i, (p, seed) in enumerate(itertools.product(plain, seed_list))]


def _one_kind(values: list[Any], name: str) -> None:
    """A table column holds one kind of value (numbers, strings, bools or lists; None for a gap),
    and integers a Parquet column can store."""
    kinds = {"number" if isinstance(v, int | float) and not isinstance(v, bool) else type(v).__name__ for v in values}
    kinds.discard("NoneType")
    if len(kinds) > 1:
        raise SweepError(f"parameter {name!r} mixes kinds of value ({', '.join(sorted(kinds))}); a table column holds one")
    big = next((v for v in values if isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 2**63), None)
    if big is not None:
        raise SweepError(f"parameter {name!r}: {big} does not fit a table's 64-bit integers; give it as a float")


def _bad_params(value: Any) -> dict[str, Any]:
    raise SweepError(
        "params must be a dict of value lists (a grid), a list of dicts or a pandas DataFrame (samples), or None; "
        f"got {type(value).__name__}"
    )


def _seeds(seeds: Any) -> Sequence[int | None]:
    if seeds is None:
        return [None]
    if _validate.integral(seeds):
        if not 1 <= seeds <= MAX_RUNS:
            raise SweepError(
                f"seeds must be a count from 1 to {MAX_RUNS:.0e} (what one sweep holds) or a list of integers, "
                f"got {_validate._short(seeds)}"
            )
        return range(int(seeds))  # not a list: a huge count is refused by its length
    if isinstance(seeds, Iterable) and not isinstance(seeds, str | bytes | bool | np.timedelta64):
        out = list(seeds)
        if not out or any(not _validate.integral(s) or not 0 <= s < 2**63 for s in out):
            raise SweepError(
                "seeds must be a non-empty list of integers from 0 to 2**63 - 1 (a table's integers), "
                f"got {_validate._short(out)}"
            )
        return [int(s) for s in out]
    raise SweepError(f"seeds must be a count or a list of integers, got {_validate._short(seeds)}")


# ---------------------------------------------------------------------------------------------
# jobs: how a worker turns an item into a case


class Job(Protocol):
    """What a worker turns an item into a case with: :class:`PythonJob`, or a scene file's
    :class:`~coopdyn.sweeps.spec.SpecJob`."""

    settings: Settings
    metrics: Callable[..., Mapping[str, Any]] | None

    def case(self, item: Item) -> Case: ...


@dataclass
class PythonJob:
    """Cases from the user's ``make_case(**params[, seed=…])``; ``metrics(result, case)``
    adds columns."""

    make_case: Callable[..., Any]
    metrics: Callable[..., Mapping[str, Any]] | None
    settings: Settings
    #: the file ``make_case`` is defined in, as the parent sees it: a function cloudpickle sends
    #: by value runs as ``<dynamic-code>`` in a worker, and a failed row's message names this
    #: file instead, so that the message is the same on every executor
    origin: str | None = None

    def case(self, item: Item) -> Case:
        kwargs = dict(item.params)
        if item.seed is not None:
            kwargs["seed"] = item.seed
        made = self.make_case(**kwargs)
        if isinstance(made, Scene):
            return Case(made)
        if not isinstance(made, Case):
            raise SweepError(f"make_case must return a coopdyn.sweeps.Case or a coopdyn.Scene, got {type(made).__name__}")
        return made


def signature_check(make_case: Callable[..., Any], items: Sequence[Item]) -> None:
    """Refuse, before anything runs, parameters ``make_case`` does not take."""
    try:
        sig = inspect.signature(make_case)
    except (TypeError, ValueError):
        return  # a builtin or C callable: its errors come per run
    seen: set[tuple[str, ...]] = set()
    for item in items:
        keys = (*item.params, *(("seed",) if item.seed is not None else ()))
        if keys in seen:
            continue
        seen.add(keys)
        try:
            sig.bind(**dict.fromkeys(keys))
        except TypeError as exc:
            hint = " (seeds are passed as seed=…)" if item.seed is not None else ""
            raise SweepError(f"make_case{sig} cannot take the parameters {list(keys)}: {exc}{hint}") from None


# ---------------------------------------------------------------------------------------------
# the worker


def versions() -> dict[str, str]:
    import pinocchio as pin

    return {"coopdyn_version": __version__, "pinocchio_version": str(pin.__version__), "numpy_version": np.__version__}


def default_metrics(result: Any, case: Case) -> tuple[dict[str, float], list[str]]:
    """The metrics every completed run gets (:func:`coopdyn.metrics.run_metrics`, the names the
    demo and scene-file summaries use), the tracking ones against the case's task, or its
    controller's reference; absent ones are NaN in the table."""
    reference = case.task if case.task is not None else getattr(case.controller, "reference", None)
    return run_metrics(result, reference)


def source_name(fn: Any) -> str | None:
    """The name of the file ``fn`` is defined in (None: unknown)."""
    try:
        file = inspect.getsourcefile(fn)
    except TypeError:
        return None
    return Path(file).name if file else None


def _where(exc: BaseException, origin: str | None = None) -> str:
    """`` (at file.py:12 in fn)``: the innermost frame outside coopdyn, or the innermost one; nothing
    for coopdyn's own error about the case (its message says what). Code cloudpickle sent by
    value runs as ``<dynamic-code>``: it is named ``origin``, the file it came from."""
    frames = traceback.extract_tb(exc.__traceback__)
    package = str(Path(__file__).resolve().parent.parent)
    outside = [f for f in frames if not str(Path(f.filename).resolve()).startswith(package)]
    if not outside and isinstance(exc, CoopdynError):
        return ""
    frame = (outside or frames)[-1] if frames else None
    if frame is None:
        return ""
    name = origin if frame.filename == DYNAMIC_CODE and origin else Path(frame.filename).name
    return f" (at {name}:{frame.lineno} in {frame.name})"


DYNAMIC_CODE = "<dynamic-code>"  #: the file name cloudpickle gives code it sends by value


def run_item(job: Job, item: Item, trajectories: str | None) -> dict[str, Any]:
    """Build, simulate and measure one case; every outcome is a row (a Ctrl-C propagates)."""
    row: dict[str, Any] = {"run": item.run, **item.params, "seed": item.seed}
    wall0 = time.perf_counter()
    result: Any = None
    status, message = "completed", ""
    metrics: dict[str, Any] = {}
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            case = job.case(item)
            s = job.settings
            duration = case.duration if case.duration is not None else s.duration
            if duration is None:
                raise SweepError("no duration: give sweep(..., duration=…) or Case(duration=…)")
            dt = positive(case.dt if case.dt is not None else s.dt, "dt", "s", SweepError)  # before 1e-3 / dt
            save_every = next((n for n in (case.save_every, s.save_every) if n is not None), max(1, round(1e-3 / dt)))
            integrator = case.integrator or s.integrator
            name = integrator if isinstance(integrator, str) else repr(integrator)  # the table stores text
            row.update(integrator=name, dt_s=float(dt), duration_s=float(duration), save_every=int(save_every))
            if case.control_dt is not None:
                row.update(control_dt_s=float(case.control_dt))
            try:
                result = simulate(
                    case.scene,
                    duration,
                    controller=case.controller,
                    integrator=integrator,
                    dt=dt,
                    save_every=save_every,
                    control_dt=case.control_dt,
                    max_steps=s.max_steps,
                    energy_check=s.energy_check,
                    accuracy_check=s.accuracy_check,
                )
            except DivergenceError as exc:
                result, status, message = exc.result, "diverged", exc.detail
            except StepBudgetError as exc:
                result, status, message = exc.result, "stopped", exc.detail
            if status == "completed":
                metrics, notes = default_metrics(result, case)
                if job.metrics is not None:
                    extra = job.metrics(result, case)
                    if not isinstance(extra, Mapping):
                        raise SweepError(f"metrics must return a dict of name → number, got {type(extra).__name__}")
                    for name, value in extra.items():
                        if name in RESERVED or name in item.params:
                            raise SweepError(f"metric {name!r} would overwrite a column of the row; rename it")
                        metrics[str(name)] = _plain(value, str(name), "metric")
        except KeyboardInterrupt:
            raise
        except BaseException as exc:
            result = getattr(exc, "result", result)
            status, message, metrics = (
                "failed",
                f"{type(exc).__name__}: {getattr(exc, 'detail', exc)}{_where(exc, getattr(job, 'origin', None))}",
                {},
            )
    row.update(status=status, message=message, **metrics)
    texts = dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in caught)
    row["warnings"] = "; ".join([*texts, *notes])
    if result is not None:
        row.update(
            t_reached_s=float(result.t[-1]) if len(result.t) else math.nan,
            n_steps=int(result.n_steps),
            n_rhs=int(result.n_rhs),
            loop=result.loop,
            backend=result.backend,
            cpu_s=float(result.cpu_time),
        )
        if trajectories is not None:
            name = f"run-{item.run:06d}.npz"
            try:
                result.save(Path(trajectories) / name)
                row["trajectory"] = name
            except Exception as exc:
                row["warnings"] = "; ".join(filter(None, [row["warnings"], f"trajectory not saved: {exc}"]))
    row.update(wall_s=time.perf_counter() - wall0, worker=f"{socket.gethostname()}:{os.getpid()}", **versions())
    return row


_JOBS: dict[str, Any] = {}  #: jobs a worker process has unpacked, by the hash of their bytes
_LAST_JOB: list[Any] = []  #: [the last payload object, its job]: no hash for a payload seen before


def _job(payload: bytes | Job) -> Any:
    if not isinstance(payload, bytes):
        return payload  # in-process: the job itself
    if _LAST_JOB and _LAST_JOB[0] is payload:  # a local worker's chunks share one payload object
        return _LAST_JOB[1]
    key = hashlib.sha256(payload).hexdigest()
    if key not in _JOBS:
        import cloudpickle

        if len(_JOBS) > 8:
            _JOBS.clear()
        _JOBS[key] = cloudpickle.loads(payload)
    _LAST_JOB[:] = [payload, _JOBS[key]]
    return _JOBS[key]


def run_chunk(
    payload: bytes | Job, items: Sequence[Item], trajectories: str | None, markers: str | None = None
) -> list[dict[str, Any]]:
    """A worker's task: run ``items`` one after the other; the rows. With ``markers`` (a folder),
    the run in progress is written to ``markers/<pid>`` so that the parent can tell, if this
    process dies, which run it was running."""
    job = _job(payload)
    mark = Path(markers) / str(os.getpid()) if markers else None
    rows = []
    for item in items:
        if mark is not None:
            mark.write_text(str(item.run))
        rows.append(run_item(job, item, trajectories))
        if mark is not None:
            mark.write_text("")
    return rows


def placeholder(item: Item, status: str, message: str) -> dict[str, Any]:
    """The row of a run that produced none (crashed worker, not run)."""
    return {"run": item.run, **item.params, "seed": item.seed, "status": status, "message": message, **versions()}
