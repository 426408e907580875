"""Files (internal): one written whole or not at all, its path checked first, every failure an
:class:`~coopdyn.errors.OutputError` that names the path."""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

from . import _validate
from .errors import OutputError

TEMPORARY = re.compile(r"\..+\.tmp")  #: the names temporary() gives


def temporary(path: Path) -> Path:
    """The temporary file ``path`` is written as before its rename: ``.NAME.tmp`` beside it, or,
    for a name within 5 bytes of the file system's limit, ``.coopdyn-PID.tmp``."""
    if len(os.fsencode(path.name)) + 5 <= _validate.NAME_MAX:
        return path.with_name(f".{path.name}.tmp")
    return path.with_name(f".coopdyn-{os.getpid()}.tmp")


def write_atomically(path: Any, what: str, write: Callable[[Path], Any], suffixes: Collection[str] = ()) -> Path:
    """Write the file ``path`` by ``write(temporary path)``, then a rename: a reader never sees
    half a file. ``suffixes``: the endings the format takes (none: any).

    Raises:
        OutputError: not a path, an ending the format does not take, a folder, or the file
            cannot be written (the reason from the system).
    """
    path = _validate.path(path, what, OutputError)
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(f"{what} {path} must end in {' or '.join(sorted(suffixes))}, got {path.suffix or 'no ending'!r}")
    if path.is_dir():
        raise OutputError(f"{what} {path} is a folder; give a file name")
    tmp = temporary(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"cannot write {what} {path}: {exc.strerror or exc}") from exc
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
    return path
