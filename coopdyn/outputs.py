"""A run's output folder, written whole or not at all.

The files go into a staging folder beside the target, which then replaces the target in two
renames: a reader (``coopdyn view``) never sees a mix of two runs, a kill leaves the previous
run or this one (plus a hidden staging folder, removed by the next run), and Ctrl-C waits until
the folder is in place. A plot or an animation that fails is reported, not fatal: the trajectory
is kept. When the folder cannot be written (read-only, disk full), the trajectory goes to a
rescue folder in the system's temporary directory and the error says where.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import _validate
from ._signals import interrupts_deferred
from .errors import OutputError
from .result import Result

#: Files coopdyn writes into an output folder; a folder holding anything else is not replaced.
KNOWN_FILES = frozenset(
    {
        "scene.toml",
        "trajectory.npz",
        "trajectory.csv",
        "plot.png",
        "animation.html",
        "demo.png",
        "demo.html",
        "diagnosis.txt",
        "table.parquet",  # a sweep's (coopdyn.sweeps)
        "table.journal",
        "heatmap.png",
        "trajectories",
    }
)
#: the files coopdyn writes in a sweep's ``trajectories/`` folder
TRAJECTORY_FILE = re.compile(r"run-\d{6,}\.npz")
#: what a killed writer of one leaves (its temporary file)
TRAJECTORY_TEMPORARY = re.compile(r"\.run-\d{6,}\.npz\.tmp")


def _own_temporary(name: str, known: frozenset[str]) -> bool:
    """Whether ``name`` is the temporary file a killed writer of a coopdyn file left."""
    return name.startswith(".") and name.endswith(".tmp") and (name[1:-4] in known or name.startswith(".coopdyn-"))


Writer = Callable[[Path], Any]  #: writes into the given folder; returns the path(s) written


@dataclass(frozen=True)
class Written:
    """What :func:`write_outputs` did."""

    folder: Path  #: absolute
    files: tuple[Path, ...]  #: absolute, in the final folder
    problems: tuple[str, ...]  #: optional outputs that failed, each "name: why"


def write_outputs(
    folder: str | os.PathLike[str], essential: Sequence[tuple[str, Writer]], optional: Sequence[tuple[str, Writer]] = ()
) -> Written:
    """Write ``essential`` outputs (all must succeed) and ``optional`` ones (failures reported in
    ``problems``) into ``folder``, replacing what an earlier run wrote there.

    Raises:
        OutputError: the folder holds files coopdyn did not write, or it cannot be written; the
            message says where the essential outputs went instead, if anywhere.
    """
    try:
        target = check_folder(folder)
    except OutputError as exc:  # the run is done: keep what it made somewhere
        raise OutputError(f"{exc}. {_rescue(essential)}") from None
    with interrupts_deferred():  # a Ctrl-C now would lose a finished run: it waits for the folder
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            _remove_stale(target)
            staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.writing-{os.getpid()}-", dir=target.parent))
            staging.chmod(0o777 & ~_umask())  # mkdtemp makes it private; the folder gets the usual mode
        except OSError as exc:
            raise OutputError(f"cannot write to {target.parent}: {_reason(exc)}. {_rescue(essential)}") from exc
        try:
            files = _run(essential, staging)
        except OSError as exc:
            shutil.rmtree(staging, ignore_errors=True)
            raise OutputError(f"cannot write the outputs to {target}: {_reason(exc)}. {_rescue(essential)}") from exc
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)  # no staging folder left behind, whatever failed
            raise
        problems = []
        for name, writer in optional:
            try:
                files += _run([(name, writer)], staging)
            except Exception as exc:
                problems.append(f"{name}: {type(exc).__name__}: {exc}")
        try:
            _publish(staging, target)
        except OSError as exc:
            shutil.rmtree(staging, ignore_errors=True)
            raise OutputError(f"cannot move the outputs into {target}: {_reason(exc)}. {_rescue(essential)}") from exc
    return Written(target, tuple(target / f.relative_to(staging) for f in files), tuple(problems))


def check_folder(folder: Any) -> Path:
    """The absolute output folder (a symbolic link: its target), checked before a run starts: a
    path, not a file, not the working folder or one of its parents (a run replaces its folder
    whole), and holding only what coopdyn writes."""
    target = _validate.path(folder, "the output folder", OutputError)
    try:
        target = target.absolute()
        if target.is_symlink():
            target = target.resolve()  # (a loop raises; a link to a folder not made yet is fine)
        cwd = Path.cwd().resolve()
        if target.resolve() == cwd or target.resolve() in cwd.parents:
            raise OutputError(f"the output folder {target} is the working folder or holds it; a run replaces its folder whole")
        _refuse_foreign(target)
    except (OSError, RuntimeError) as exc:  # a link that points nowhere or to itself, a working folder deleted
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"the output folder {folder} cannot be used: {getattr(exc, 'strerror', None) or exc}") from None
    return target


def _run(writers: Sequence[tuple[str, Writer]], folder: Path) -> list[Path]:
    out: list[Path] = []
    for _, writer in writers:
        written = writer(folder)
        out += [Path(p) for p in (written if isinstance(written, list | tuple) else [written]) if p is not None]
    return out


def _refuse_foreign(target: Path) -> None:
    if target.exists() and not target.is_dir():
        raise OutputError(f"the output folder {target} is a file")
    if target.is_dir():
        foreign = sorted(
            p.name for p in target.iterdir() if p.name not in KNOWN_FILES and not _own_temporary(p.name, KNOWN_FILES)
        )
        saved = target / "trajectories"
        if saved.is_symlink() or (saved.exists() and not saved.is_dir()):
            foreign.append("trajectories (not a folder coopdyn made)")
        elif saved.is_dir():
            foreign += sorted(
                f"trajectories/{p.name}"
                for p in saved.iterdir()
                if not TRAJECTORY_FILE.fullmatch(p.name) and not TRAJECTORY_TEMPORARY.fullmatch(p.name)
            )
        if foreign:
            shown = ", ".join(foreign[:5]) + (", …" if len(foreign) > 5 else "")
            raise OutputError(
                f"the output folder {target} holds files coopdyn did not write ({shown}); a run replaces its folder "
                "whole, so choose another (an empty or new folder, or one an earlier run wrote)"
            )


def _remove_stale(target: Path) -> None:
    """Staging folders of earlier runs that were killed (their process is gone)."""
    mine = re.compile(rf"\.{re.escape(target.name)}\.(writing|old)-(\d+)-[\w]+")
    for p in target.parent.glob(f".{glob.escape(target.name)}.*-*"):
        m = mine.fullmatch(p.name)
        if m and p.is_dir() and not p.is_symlink() and not _alive(int(m.group(2))):
            shutil.rmtree(p, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _publish(staging: Path, target: Path) -> None:
    """Put ``staging`` in place of ``target`` (two renames: never a mix of both)."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old-{os.getpid()}-{time.monotonic_ns()}")
        os.rename(target, old)
    os.rename(staging, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _reason(exc: OSError) -> str:
    return f"{exc.strerror or exc}" + (f" ({exc.filename})" if exc.filename else "")


def _rescue(essential: Sequence[tuple[str, Writer]]) -> str:
    """Write the essential outputs to a fresh folder in the temporary directory; say where."""
    if not essential:
        return "Nothing was written"
    try:
        rescue = Path(tempfile.mkdtemp(prefix="coopdyn-rescue-"))
        files = _run(essential, rescue)
    except Exception as exc:
        return f"The trajectory could not be saved anywhere else either ({type(exc).__name__}: {exc})"
    return "The trajectory was saved to " + ", ".join(str(f) for f in files) + " instead"


def save_partial(error: BaseException, folder: str | os.PathLike[str]) -> list[Path]:
    """After a ``DivergenceError``, ``SimulationInterrupted`` or ``StepBudgetError``: write the
    trajectory it carries (``trajectory.npz``, ``trajectory.csv``) and the message
    (``diagnosis.txt``) to ``folder``, replacing the folder whole (see
    :func:`write_outputs`). Returns the paths written."""
    result = getattr(error, "result", None)
    advice = getattr(error, "advice", None)

    def trajectory(folder: Path) -> list[Path]:
        if isinstance(result, Result) and len(result.t):
            return [result.save(folder / "trajectory.npz"), result.save(folder / "trajectory.csv")]
        return []

    def diagnosis(folder: Path) -> Path:
        note = folder / "diagnosis.txt"
        note.write_text(f"{type(error).__name__}: {error}\n" + (f"\n{advice}\n" if advice is not None else ""))
        return note

    return list(write_outputs(folder, [("trajectory", trajectory), ("diagnosis", diagnosis)]).files)
