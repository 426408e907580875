"""Parameter sweeps that scale from a laptop to a cluster: ``coopdyn.sweep(make_case, params)``
and ``coopdyn sweep spec.toml``.

Every run becomes one row of a tidy table (pandas, saved as Parquet): its parameters and seed,
its status and diagnosis, its metrics, and what reproduces it (settings, versions). Runs go to
local processes by default, or to any ``concurrent.futures.Executor`` — a Dask cluster through
its ``Client`` (``pip install -e ".[dask]"``). ``coopdyn sweep --rerun TABLE RUN`` (or
:func:`rerun`) runs a row again and compares it bit for bit. docs/sweeps.md walks through it.
"""

from .cases import STATUSES, Case
from .run import Rerun, rerun, run_spec, sweep
from .spec import load_spec
from .table import load

__all__ = ["STATUSES", "Case", "Rerun", "load", "load_spec", "rerun", "run_spec", "sweep"]
