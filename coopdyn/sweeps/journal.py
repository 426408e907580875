"""A sweep's journal: each finished row appended to ``table.journal`` in the sweep's folder as it
arrives, so that a sweep killed in any way (kill -9, SIGTERM, a closed terminal, two Ctrl-C, a
power cut short of the disk) keeps every row it finished, and ``resume`` runs only the rest.

The file is JSON lines: a header ``{"journal": FORMAT, "key": …}`` naming the sweep (a hash of
its source, settings and runs), then one row per line, written and flushed when its chunk
returns. A line cut short by a kill is ignored. The journal is removed once the table is written
whole; an interrupted sweep keeps it beside its partial table.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

from ..errors import SweepError
from .cases import Item

FORMAT = "coopdyn.sweep-journal/1"
JOURNAL_NAME = "table.journal"


def sweep_key(meta: dict[str, Any], items: Sequence[Item]) -> str:
    """What makes two sweeps the same sweep: their source (a function's place and the hash of its
    source text, or a spec's text), metrics, settings and runs (parameters and seeds)."""
    ident = {
        "source": meta.get("source"),
        "metrics": meta.get("metrics"),
        "settings": meta.get("settings"),
        "runs": [(i.run, i.params, i.seed) for i in items],
    }
    return hashlib.sha256(json.dumps(ident, sort_keys=True, default=repr).encode()).hexdigest()


def finished_rows(folder: Path, key: str) -> dict[int, dict[str, Any]]:
    """The rows the journal in ``folder`` holds for the sweep ``key`` (none without a journal).

    Raises:
        SweepError: the journal belongs to another sweep, or is not a journal.
    """
    path = folder / JOURNAL_NAME
    if not path.is_file():
        return {}
    rows: dict[int, dict[str, Any]] = {}
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    try:
        header = json.loads(lines[0])
    except ValueError:
        header = None
    if not isinstance(header, dict) or header.get("journal") != FORMAT:
        raise SweepError(f"{path} is not a sweep journal this coopdyn reads ({FORMAT})")
    if header.get("key") != key:
        raise SweepError(
            f"{path} is the journal of another sweep (other cases, settings or runs); resume it with the same sweep, "
            "or run without resume to start this one anew in that folder"
        )
    for line in lines[1:]:
        try:
            row = json.loads(line)
        except ValueError:  # the line a kill cut short (the last), or an empty one
            continue
        if isinstance(row, dict) and isinstance(row.get("run"), int):
            rows[row["run"]] = row
    return rows


class Journal:
    """Appends finished rows to ``folder/table.journal`` (a new journal unless ``append``)."""

    def __init__(self, folder: Path, key: str, append: bool) -> None:
        self.path = folder / JOURNAL_NAME
        fresh = not (append and self.path.is_file())
        if not fresh:  # a line a kill cut short is dropped, or the next record would be glued onto it
            data = self.path.read_bytes()
            with open(self.path, "r+b") as f:
                f.truncate(data.rfind(b"\n") + 1)
        self._file: IO[str] | None = open(self.path, "w" if fresh else "a", encoding="utf-8")
        if fresh:
            self._write([{"journal": FORMAT, "key": key}])

    def add(self, rows: Sequence[dict[str, Any]]) -> None:
        self._write(rows)

    def _write(self, records: Sequence[dict[str, Any]]) -> None:
        if self._file is None:
            return
        try:
            self._file.write("".join(json.dumps(r, allow_nan=True, default=_plain) + "\n" for r in records))
            self._file.flush()  # in the kernel's hands: a kill of this process loses nothing written
        except OSError as exc:  # a full disk: the sweep goes on, its rows in memory (the table is rescued if need be)
            warnings.warn(
                f"the sweep's journal {self.path} cannot be written ({exc.strerror or exc}): the sweep goes on, but a kill from "
                "now on loses the rows it finished",
                RuntimeWarning,
                stacklevel=4,
            )
            with contextlib.suppress(OSError):
                self._file.close()
            self._file = None

    def close(self, remove: bool) -> None:
        """Close; ``remove`` once the table holds every row."""
        if self._file is not None:
            self._file.close()
            self._file = None
        if remove:
            self.path.unlink(missing_ok=True)


def _plain(value: Any) -> Any:
    """A numpy scalar or array in a row, as JSON's plain values."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"a row value of type {type(value).__name__} cannot be journaled")


__all__ = ["JOURNAL_NAME", "Journal", "finished_rows", "sweep_key"]
