"""Run a sweep, and rerun one of its rows (:func:`sweep`, :func:`run_spec`, :func:`rerun`)."""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import hashlib
import importlib
import importlib.util
import inspect
import math
import os
import sys
import time
import warnings
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import _signals, _validate
from .._optional import require
from .._version import __version__
from ..errors import SweepError, SweepInterrupted
from ..outputs import TRAJECTORY_FILE, TRAJECTORY_TEMPORARY, check_folder
from . import table as tables
from .cases import (
    TIMING,
    Item,
    PythonJob,
    Settings,
    expand,
    placeholder,
    run_item,
    signature_check,
    source_name,
    versions,
)
from .engines import Executor, LocalProcesses, Serial, chunks, engine
from .journal import JOURNAL_NAME, Journal, finished_rows, sweep_key
from .spec import Spec, SpecJob

MAX_CHUNK = 64  #: the most runs per task with the automatic chunk size
PAYLOAD_WARN_BYTES = 10 << 20  #: a job bigger than this is sent to every worker: say so


def sweep(
    make_case: Callable[..., Any],
    params: Any = None,
    *,
    seeds: Any = None,
    duration: float | None = None,
    integrator: str = "rk4",
    dt: float = 1e-3,
    save_every: int | None = None,
    metrics: Callable[..., Mapping[str, Any]] | None = None,
    executor: Any = None,
    workers: int | None = None,
    chunk_size: int | None = None,
    out: str | Path | None = None,
    trajectories: bool = False,
    progress: bool = True,
    max_steps: int | None = 2 * 10**6,
    energy_check: str = "warn",
    accuracy_check: str = "auto",
    resume: bool = False,
) -> Any:
    """Run ``make_case`` for every parameter set (and seed) and collect a table, one row per run.

    Args:
        make_case: ``make_case(**params[, seed=…]) -> Case | Scene``, called in the worker that
            runs the case (so nothing heavy crosses a process boundary; the compiled kernel is
            built there, lazily). Any function works — a lambda or one defined in a notebook too
            (it is sent with cloudpickle); keep big objects inside it, not in globals it uses.
        params: a grid ``{name: [values…]}`` (every combination, the first name varying slowest;
            a list-valued parameter is given as a list of lists), given samples (a list of dicts
            or a pandas DataFrame, one run each), or None (one run).
        seeds: None, a count n (seeds 0..n−1) or a list of integers: every parameter set runs
            once per seed, passed as ``make_case(..., seed=s)``.
        duration, integrator, dt, save_every: simulation settings for cases that leave them
            unset (duration [s] and dt [s]; save_every default: a sample every millisecond, what
            the metrics see).
        metrics: ``metrics(result, case) -> {name: value}``: columns added to every completed
            row, beside the built-in ones (tracking error, internal and interconnection forces).
        executor: ``None`` or ``"processes"``: local processes (``workers`` of them, default
            every core); ``"serial"``: this process; any ``concurrent.futures.Executor``; or a
            ``dask.distributed.Client`` (a cluster: ``pip install -e ".[dask]"``).
        workers: the number of local processes.
        chunk_size: runs per task (default: up to 64, at least 4 tasks per worker): short runs in
            chunks cost less scheduling; long ones in chunks of one balance best.
        out: a folder for ``table.parquet`` (and ``trajectories/``); None writes nothing.
        trajectories: also save every run's trajectory (``trajectories/run-NNNNNN.npz``).
        progress: a progress bar (runs done, and how many did not complete).
        max_steps, energy_check: as for :func:`coopdyn.simulate`.
        accuracy_check: as for :func:`coopdyn.simulate`: ``"auto"`` checks a run the accuracy
            screen cannot clear against a reference run (a second run for that row);
            ``"screen"`` keeps the screen's warning without it, ``"off"`` drops both.
        resume: finish the sweep that was writing to ``out`` when it stopped (killed,
            interrupted, the machine went down): the rows its journal holds are kept, the
            others run. The same ``make_case``, parameters, seeds and settings are required.

    Every finished row is journaled in ``out`` as it arrives (``table.journal``), so a sweep
    stopped in any way loses no finished run.

    Returns:
        a pandas DataFrame, one row per run (columns: :mod:`coopdyn.sweeps.table`). A run that
        diverges, raises or kills its worker process is a row with its status and diagnosis.

    Raises:
        SweepError: invalid arguments (checked before anything runs).
        SweepInterrupted: Ctrl-C; its ``table`` holds the finished rows (the others
            ``"not run"``), also written to ``out`` when given.
    """
    if not callable(make_case):
        raise SweepError(f"make_case must be a function make_case(**params) -> Case, got {type(make_case).__name__}")
    items = expand(params, seeds)
    signature_check(make_case, items)
    if metrics is not None and not callable(metrics):
        raise SweepError(f"metrics must be a function metrics(result, case) -> dict, got {type(metrics).__name__}")
    settings = _settings(duration, integrator, dt, save_every, max_steps, energy_check, accuracy_check)
    job = PythonJob(make_case, metrics, settings, source_name(make_case))
    meta = {
        "source": {"kind": "python", **_reference(make_case)},
        "metrics": _reference(metrics) if metrics is not None else None,
    }
    return _execute(job, items, meta, executor, workers, chunk_size, out, trajectories, progress, resume)


def run_spec(
    spec: Any,
    *,
    executor: Any = None,
    workers: int | None = None,
    chunk_size: int | None = None,
    progress: bool = True,
    resume: bool = False,
) -> Any:
    """Run a loaded sweep spec (:func:`coopdyn.sweeps.spec.load_spec`) into its folder; the table.
    ``resume``: as for :func:`sweep`."""
    if not isinstance(spec, Spec):
        raise SweepError(f"run_spec takes a spec from coopdyn.sweeps.load_spec(path), got {type(spec).__name__}")
    settings = Settings()
    job = SpecJob(spec.text, str(spec.path), settings)
    meta = {"source": {"kind": "spec", "file": str(spec.path), "text": spec.text}, "metrics": None}
    return _execute(job, spec.items, meta, executor, workers, chunk_size, spec.folder, spec.trajectories, progress, resume)


def _settings(
    duration: Any, integrator: Any, dt: Any, save_every: Any, max_steps: Any, energy_check: Any, accuracy_check: Any = "auto"
) -> Settings:
    from ..integrators import INTEGRATORS
    from ..simulate import ACCURACY_CHECKS
    from ..stepping import ENERGY_CHECKS, MIN_DT

    # the checks simulate() makes, up front: a bad setting refused once, not as a failed row per run
    if duration is not None and (
        isinstance(duration, bool) or not isinstance(duration, int | float) or not 0 <= duration < math.inf
    ):
        raise SweepError(f"duration must be a finite number of seconds >= 0 (or None: each case's own), got {duration!r}")
    if not isinstance(integrator, str) or integrator not in INTEGRATORS:
        raise SweepError(f"integrator must be one of {sorted(INTEGRATORS)}, got {integrator!r}")
    if _validate.positive(dt, "dt", "s", SweepError) < MIN_DT:
        raise SweepError(f"dt must be >= {MIN_DT:g} [s], got {dt!r}")
    if save_every is not None:
        save_every = _validate.count(save_every, "save_every", SweepError, none="each case's own")
    if max_steps is not None:
        max_steps = _validate.count(max_steps, "max_steps", SweepError, none="no limit")
    for name, value, valid in (
        ("energy_check", energy_check, ENERGY_CHECKS),
        ("accuracy_check", accuracy_check, ACCURACY_CHECKS),
    ):
        if not isinstance(value, str) or value not in valid:
            raise SweepError(f"{name} must be one of {list(valid)}, got {_validate._short(value)}")
    return Settings(
        None if duration is None else float(duration), integrator, float(dt), save_every, max_steps, energy_check, accuracy_check
    )


def _execute(
    job: PythonJob | SpecJob,
    items: list[Item],
    meta: dict[str, Any],
    executor: Any,
    workers: int | None,
    chunk_size: int | None,
    out: str | Path | None,
    trajectories: bool,
    progress: bool,
    resume: bool = False,
) -> Any:
    trajectories, progress, resume = (
        _validate.flag(value, name, SweepError)
        for name, value in (("trajectories", trajectories), ("progress", progress), ("resume", resume))
    )
    folder = check_folder(out) if out is not None else None
    if trajectories and folder is None:
        raise SweepError("trajectories are saved as files: give out=a folder")
    if resume and folder is None:
        raise SweepError("resume finishes a sweep written to a folder: give out=the folder it was writing to")
    if chunk_size is not None:
        chunk_size = _validate.count(chunk_size, "chunk_size", SweepError, none="chosen from the runs and workers")
    key = sweep_key(meta | {"settings": dataclasses.asdict(job.settings)}, items)
    rows: dict[int, dict[str, Any]] = {}
    if resume and folder is not None:
        rows = finished_rows(folder, key)
        if not rows and (folder / tables.TABLE_NAME).is_file() and not (folder / JOURNAL_NAME).is_file():
            raise SweepError(
                f"nothing to resume in {folder}: its sweep finished (a table, no journal of unfinished runs); "
                "run it again without resume (--resume) to start it anew"
            )
    todo = [i for i in items if i.run not in rows]
    runner = engine(executor, workers)
    journal = None
    try:
        payload: Any = job
        if runner.pickles:
            payload = _pickled(job)
        size = chunk_size or (1 if isinstance(runner, Serial) else max(1, min(MAX_CHUNK, len(todo) // (4 * runner.workers))))
        traj_folder = None
        if folder is not None:
            try:
                folder.mkdir(parents=True, exist_ok=True)
                _clear(folder, finished=not resume)  # everything checked: the folder holds one sweep
                journal = Journal(folder, key, append=resume)
                if trajectories:
                    (folder / "trajectories").mkdir(exist_ok=True)
                    traj_folder = str(folder / "trajectories")
            except OSError as exc:
                raise SweepError(f"cannot write the sweep's files to {folder}: {exc.strerror or exc}; nothing ran") from exc
        meta = {
            "format": tables.FORMAT,
            "coopdyn": __version__,
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            **meta,
            "settings": dataclasses.asdict(job.settings),
            "params": list(items[0].params),
            "runs": len(items),
            "executor": runner.name,
            "chunk_size": size,
            "trajectories": traj_folder is not None,
            **({"resumed_rows": len(rows)} if resume else {}),
        }
        others: Counter[str] = Counter(r["status"] for r in rows.values() if r["status"] != "completed")
        bar = _bar(len(items), runner.name, len(rows)) if progress else None
        wall0 = time.perf_counter()
        try:
            with _signals.sigterm_as_interrupt():  # a killed job or a closed terminal: as Ctrl-C
                for done in runner.run(payload, chunks(todo, size), traj_folder) if todo else ():
                    if journal is not None:
                        journal.add(done)
                    for row in done:
                        rows[row["run"]] = row
                    others.update(r["status"] for r in done if r["status"] != "completed")
                    if bar is not None:
                        if others:
                            bar.set_postfix(others, refresh=False)
                        bar.update(len(done))
        except KeyboardInterrupt:
            with _signals.interrupts_deferred(reraise=False):  # a second Ctrl-C cannot cut the table short
                runner.abort()
                if journal is not None:
                    journal.close(remove=False)
                missing = [
                    placeholder(i, "not run", "the sweep was interrupted (Ctrl-C) before this run finished")
                    for i in items
                    if i.run not in rows
                ]
                meta["wall_s"] = time.perf_counter() - wall0
                table = tables.frame([*rows.values(), *missing], meta["params"], meta)
                saved = tables.save(table, folder / tables.TABLE_NAME) if folder is not None else None
            raise SweepInterrupted(
                f"sweep interrupted after {len(rows)} of {len(items)} runs"
                + (
                    f"; the table (the others 'not run') is in {saved}; resume=True (`coopdyn sweep SPEC --resume`) runs the rest"
                    if saved
                    else "; the table so far is in this exception's .table"
                ),
                table=table,
                saved=saved,
            ) from None
        finally:
            if bar is not None:
                bar.close()
        meta["wall_s"] = time.perf_counter() - wall0
        table = tables.frame(list(rows.values()), meta["params"], meta)
        if folder is not None:
            tables.save(table, folder / tables.TABLE_NAME)
            if journal is not None:
                journal.close(remove=True)
        return table
    finally:
        if journal is not None:
            journal.close(remove=False)
        runner.close()


def _clear(folder: Path, finished: bool) -> None:
    """Remove what an earlier sweep wrote in ``folder`` — the temporary files a killed one left,
    and with ``finished`` its table, journal, heat map and trajectories too: coopdyn's own files
    only (a file of the user's there was refused by :func:`check_folder` before anything ran)."""
    for name in (tables.TABLE_NAME, JOURNAL_NAME, "heatmap.png"):
        if finished:
            (folder / name).unlink(missing_ok=True)
        (folder / f".{name}.tmp").unlink(missing_ok=True)
    saved = folder / "trajectories"
    if saved.is_dir() and not saved.is_symlink():
        for path in saved.iterdir():
            mine = TRAJECTORY_TEMPORARY.fullmatch(path.name) or (finished and TRAJECTORY_FILE.fullmatch(path.name))
            if mine and path.is_file():
                path.unlink()
        with contextlib.suppress(OSError):
            saved.rmdir()  # only when empty


def _pickled(job: Any) -> bytes:
    cloudpickle = require("cloudpickle", "sending a sweep's cases to worker processes", "cloudpickle")
    try:
        data = cloudpickle.dumps(job)
    except Exception as exc:
        raise SweepError(
            f"cannot send make_case (or metrics) to the worker processes: {type(exc).__name__}: {exc}. "
            "Build what it holds inside the function, or run in this process with executor='serial'"
        ) from exc
    if len(data) > PAYLOAD_WARN_BYTES:
        warnings.warn(
            f"make_case and metrics pickle to {len(data) / 2**20:.0f} MiB, sent to every worker: they carry big objects "
            "(a scene with visual meshes?); build those inside make_case",
            stacklevel=4,
        )
    return data


def _bar(total: int, where: str, initial: int = 0) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, unit="run", desc=f"sweep ({where})", dynamic_ncols=True, leave=True)


# ---------------------------------------------------------------------------------------------
# rerun


def _reference(fn: Any) -> dict[str, Any]:
    """Where ``fn`` is defined, to find it again for a rerun (None fields: it cannot be found)."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    try:
        file = inspect.getsourcefile(fn)
    except TypeError:
        file = None
    findable = bool(module and qualname and "<" not in qualname)
    try:
        code = hashlib.sha256(inspect.getsource(fn).encode()).hexdigest()
    except (OSError, TypeError):
        code = None
    return {
        "module": module if findable else None,
        "qualname": qualname if findable else None,
        "file": str(Path(file).resolve()) if file and findable else None,
        "name": getattr(fn, "__qualname__", repr(fn)),
        "source_sha256": code,  #: its source's hash: a sweep resumes only with the same code
    }


def _resolve(ref: dict[str, Any], what: str) -> Callable[..., Any]:
    """The function a :func:`_reference` names: imported by module, or loaded from its file.
    This runs code: only for a reference the user gave, or one they said to trust."""
    if not ref.get("qualname"):
        raise SweepError(
            f"the sweep's {what} ({ref.get('name')}) is a lambda or a nested function, which cannot be found again; "
            "define it at the top level of a module or script to rerun rows"
        )
    module = None
    file = ref.get("file")
    if ref.get("module") and ref["module"] != "__main__":
        try:
            module = importlib.import_module(ref["module"])
        except Exception as exc:
            if not file:  # nothing else to load it from
                raise SweepError(f"cannot import {ref['module']} for the sweep's {what}: {type(exc).__name__}: {exc}") from exc
    if module is None:
        if not file or not Path(file).is_file():
            raise SweepError(f"the sweep's {what} {ref['qualname']} was defined in {file}, which is not there any more")
        name = f"_coopdyn_rerun_{Path(file).stem}"
        spec = importlib.util.spec_from_file_location(name, file)
        if spec is None or spec.loader is None:
            raise SweepError(f"cannot load {file}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)  # runs the script's top level (its sweep sits under `if __name__ == "__main__"`)
        except Exception as exc:
            raise SweepError(f"running {file} for the sweep's {what} raised {type(exc).__name__}: {exc}") from exc
    obj: Any = module
    try:
        for part in ref["qualname"].split("."):
            obj = getattr(obj, part)
    except AttributeError:
        raise SweepError(f"{ref.get('file') or ref['module']} defines no {ref['qualname']}") from None
    if not callable(obj):
        raise SweepError(f"{ref.get('file') or ref['module']}: {ref['qualname']} is not a function")
    return obj


def _named(where: str, what: str) -> dict[str, Any]:
    """A reference to the function ``where`` names: ``module:function`` or ``path/to/file.py:function``."""
    if not isinstance(where, str) or where.count(":") < 1 or not where.rpartition(":")[2]:
        raise SweepError(f"{what} is given as MODULE:FUNCTION or FILE.py:FUNCTION, got {where!r}")
    place, _, qualname = where.rpartition(":")
    if place.endswith(".py") or "/" in place or os.sep in place:
        path = _validate.path(place, f"the file of {what}", SweepError).resolve()
        if not path.is_file():
            raise SweepError(f"{what}: no file {path}")
        return {"module": None, "qualname": qualname, "file": str(path), "name": qualname}
    return {"module": place, "qualname": qualname, "file": None, "name": qualname}


def _recorded(ref: dict[str, Any] | None) -> str:
    """Where a table says a function is defined, as the option that would name it."""
    if not ref:
        return "nowhere"
    if ref.get("file"):
        return f"{ref['file']}:{ref.get('qualname') or ref.get('name')}"
    return f"{ref.get('module')}:{ref.get('qualname') or ref.get('name')}"


def _function(given: Any, recorded: dict[str, Any] | None, what: str, option: str, trust: bool) -> Callable[..., Any] | None:
    """The function to rerun with: the one the user gave (a callable or a name), or, with
    ``trust``, the one the table records; never code a table names on its own say-so."""
    if callable(given):
        return given
    if given is not None:
        return _resolve(_named(given, what), what)
    if not recorded:
        return None
    if trust:
        return _resolve(recorded, what)
    raise SweepError(
        f"the table says its {what} is {_recorded(recorded)}; a table is data, and coopdyn does not import or run code it "
        f"names. If you trust that code, name it yourself ({option} {_recorded(recorded)}, or {what}=… in Python), or "
        "pass --trust (trust=True) to load what the table records"
    )


def _value(value: Any) -> Any:
    """A table cell as the value the run had (lists from array cells, None for missing)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if value is None:
        return None
    try:
        import pandas as pd

        if not isinstance(value, list) and pd.isna(value):
            return None
    except (TypeError, ValueError):
        pass
    return value


def _same(a: Any, b: Any) -> bool:
    a, b = _value(a), _value(b)
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


@dataclass(frozen=True)
class Rerun:
    """A row run again: the stored and the new values of every compared column."""

    run: int
    compared: tuple[tuple[str, Any, Any], ...]  #: (column, stored, rerun) for every reproducible column
    differences: tuple[str, ...]  #: the columns whose values differ
    other_versions: tuple[str, ...]  #: versions that differ from the row's ("numpy 2.1 → 2.2")

    @property
    def identical(self) -> bool:
        return not self.differences


def rerun(path: str | Path, run: int, *, make_case: Any = None, metrics: Any = None, trust: bool = False) -> Rerun:
    """Run row ``run`` of a saved sweep table again, in this process, and compare it with the
    stored row column by column (all but the timing columns ``cpu_s``, ``wall_s``, ``worker``
    and ``trajectory``): the same code and versions give the same bits.

    A table is data: the module or script it records for ``make_case`` is shown, never imported
    or run, unless you name the code yourself or say you trust the table. A spec's rows need
    neither (a scene file's text runs no code).

    Args:
        path: the table (``table.parquet``) or its folder.
        run: the row's run number.
        make_case, metrics: the functions of a Python sweep: callables, or names
            ``"module:function"`` / ``"path/to/script.py:function"`` (importing the module or
            running the script's top level).
        trust: load the functions from where the table records them (runs that code).

    Raises:
        SweepError: no such row; a Python sweep's row without ``make_case`` and without ``trust``.
    """
    trust = _validate.flag(trust, "trust", SweepError)
    table = tables.load(path)
    meta = table.attrs["coopdyn.sweep"]
    if isinstance(run, bool) or not isinstance(run, int):
        raise SweepError(f"a row is given by its run number, got {run!r}")
    match = table[table["run"] == run]
    if match.empty:
        raise SweepError(f"{path} has runs 0..{len(table) - 1}, not {run}")
    stored = match.iloc[0].to_dict()
    try:
        settings = Settings(**meta["settings"])
        source = meta["source"]
        kind = source["kind"]
    except (KeyError, TypeError) as exc:
        raise SweepError(f"{path}: its sweep description is damaged ({type(exc).__name__}: {exc})") from exc
    if kind == "spec":
        job: PythonJob | SpecJob = SpecJob(source["text"], source["file"], settings)
    elif kind == "python":
        case_fn = _function(make_case, source, "make_case", "--case", trust)
        assert case_fn is not None
        metrics_fn = _function(metrics, meta.get("metrics"), "metrics", "--metrics", trust)
        job = PythonJob(case_fn, metrics_fn, settings, source_name(case_fn))
    else:
        raise SweepError(f"{path}: its sweep description is damaged (a source of kind {kind!r})")
    seed = _value(stored.get("seed"))
    item = Item(run, {name: _value(stored[name]) for name in meta["params"]}, None if seed is None else int(seed))
    new = run_item(job, item, None)
    mine = versions()
    other = tuple(
        f"{name.removesuffix('_version')} {stored.get(name)} → {mine[name]}"
        for name in mine
        if _value(stored.get(name)) is not None and stored.get(name) != mine[name]
    )
    skip = {*TIMING, "trajectory"}
    compared = tuple((c, stored[c], new.get(c)) for c in table.columns if c not in skip)
    return Rerun(run, compared, tuple(c for c, a, b in compared if not _same(a, b)), other)


__all__ = ["Executor", "LocalProcesses", "Rerun", "rerun", "run_spec", "sweep"]
