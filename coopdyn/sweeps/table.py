"""A sweep's table: one row per run (pandas), saved as Parquet with what reruns need.

Columns, in order: ``run``; the parameters; ``seed``; ``status`` and ``message``
(:data:`coopdyn.sweeps.cases.STATUSES`); the metrics; ``warnings``; the counters
(``t_reached_s``, ``n_steps``, ``n_rhs``); the settings (``integrator``, ``dt_s``,
``duration_s``, ``save_every``, ``loop``, ``backend``); ``cpu_s``, ``wall_s``, ``worker``; the
coopdyn, Pinocchio and NumPy versions; ``trajectory`` (a file in the folder's
``trajectories/``, when saved). The sweep's description (its source, settings and executor) is
in ``table.attrs["coopdyn.sweep"]`` and in the Parquet file's metadata.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .. import _validate
from .._files import temporary
from .._optional import require
from ..errors import SweepError
from .cases import COUNTERS, SETTINGS, STATUS, TIMING, VERSIONS

FORMAT = "coopdyn.sweep/1"
MAX_LOAD_BYTES = 4e9  #: [bytes] the most a sweep table may take in memory, checked from its metadata before reading
META_KEY = b"coopdyn.sweep"
TABLE_NAME = "table.parquet"


def frame(rows: Sequence[dict[str, Any]], params: Sequence[str], meta: dict[str, Any]) -> Any:
    """The tidy table of ``rows`` (sorted by run), its columns in the documented order."""
    pd = require("pandas", "coopdyn sweeps", "pandas")
    table = pd.DataFrame(sorted(rows, key=lambda r: r["run"]))
    head = ["run", *params, *STATUS[1:]]
    tail = ["warnings", *COUNTERS, *SETTINGS, *TIMING, *VERSIONS, "trajectory"]
    for name in (*head, *tail):
        if name not in table.columns:
            table[name] = None
    metrics = [c for c in table.columns if c not in head and c not in tail]
    table = table[[*head, *metrics, *tail]]
    for name in ("seed", "n_steps", "n_rhs", "save_every"):
        table[name] = table[name].astype("Int64")  # integers with gaps (runs that produced no result)
    table.attrs["coopdyn.sweep"] = meta
    return table


def save(table: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``table`` as Parquet (atomically: a temporary file, then a rename)."""
    pa = require("pyarrow", "saving a sweep table (Parquet)", "pyarrow")
    pq = require("pyarrow.parquet", "saving a sweep table (Parquet)", "pyarrow")
    path = _validate.path(path, "the sweep table", SweepError)
    try:
        arrow = pa.Table.from_pandas(table, preserve_index=False)
    except (pa.ArrowException, OverflowError, TypeError, ValueError) as exc:  # e.g. a metric column of mixed kinds
        raise SweepError(
            f"the sweep table cannot be stored as Parquet ({type(exc).__name__}: {exc}); give each metric one kind of "
            "value (numbers, strings or bools) and integers below 2**63. The table is in this exception's .table",
            table=table,
        ) from exc
    metadata = dict(arrow.schema.metadata or {})
    metadata[META_KEY] = json.dumps(table.attrs.get("coopdyn.sweep", {}), allow_nan=False).encode()
    arrow = arrow.replace_schema_metadata(metadata)
    tmp = temporary(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(arrow, tmp, compression="zstd")
        os.replace(tmp, path)
    except OSError as exc:  # a full disk, a folder gone read-only: the rows are not lost
        raise SweepError(f"cannot write the sweep table to {path} ({exc}). {_rescue(arrow)}", table=table) from exc
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
    return path


def _rescue(arrow: Any) -> str:
    """Write the table to a fresh folder in the temporary directory; say where."""
    pq = require("pyarrow.parquet", "saving a sweep table (Parquet)", "pyarrow")
    try:
        rescue = Path(tempfile.mkdtemp(prefix="coopdyn-rescue-")) / TABLE_NAME
        pq.write_table(arrow, rescue, compression="zstd")
    except OSError as exc:
        return f"It could not be saved anywhere else either ({exc}); it is in this exception's .table"
    return f"The table was saved to {rescue} instead (and is in this exception's .table)"


def _groups(pq: Any, path: Path) -> int:
    return int(pq.ParquetFile(path).metadata.num_row_groups)


def load(path: str | os.PathLike[str]) -> Any:
    """A sweep table saved by :func:`coopdyn.sweep` (a ``table.parquet``, or the folder holding
    it), with its description in ``attrs["coopdyn.sweep"]``."""
    pq = require("pyarrow.parquet", "reading a sweep table (Parquet)", "pyarrow")
    path = _validate.path(path, "a sweep table", SweepError)
    if path.is_dir():
        path = path / TABLE_NAME
    if not path.is_file():
        raise SweepError(f"no sweep table at {path}")
    try:
        size = sum(g.total_byte_size for g in (pq.ParquetFile(path).metadata.row_group(i) for i in range(_groups(pq, path))))
        if size > MAX_LOAD_BYTES:
            raise SweepError(
                f"{path}: its table would take {size / 1e9:.3g} GB in memory (from its metadata), more than the "
                f"{MAX_LOAD_BYTES / 1e9:.3g} GB a sweep table may take"
            )
        arrow = pq.read_table(path)
    except SweepError:
        raise
    except Exception as exc:
        raise SweepError(f"{path} is not a Parquet table ({type(exc).__name__}: {exc})") from exc
    raw = (arrow.schema.metadata or {}).get(META_KEY)
    if raw is None:
        raise SweepError(f"{path} is a Parquet table, but not one coopdyn.sweep wrote (no {META_KEY.decode()} metadata)")
    try:
        meta = json.loads(raw)
        if meta.get("format") != FORMAT:
            raise ValueError(f"format {meta.get('format')!r}, this coopdyn reads {FORMAT!r}")
    except ValueError as exc:
        raise SweepError(f"{path}: its sweep description is damaged ({exc})") from exc
    table = arrow.to_pandas()
    table.attrs["coopdyn.sweep"] = meta
    return table
