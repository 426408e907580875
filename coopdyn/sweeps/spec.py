"""Sweep specs: a scene file with a ``[sweep]`` table (``coopdyn sweep spec.toml``).

The file is an ordinary scene file (``coopdyn simulate`` runs its base case); ``[sweep]`` says
which of its values change from run to run:

* ``[sweep.grid]``: ``"table.key" = [values…]`` — every combination, e.g.
  ``"scene.stiffness" = [1e3, 1e4]``; in an array of tables ``"interconnections.stiffness"``
  sets the key in every entry and ``"interconnections.0.stiffness"`` in the first;
* ``[sweep.random]``: ``"table.key" = {uniform = [a, b]}`` (also ``loguniform``, ``normal =
  [mean, sd]``, ``choice = [values…]``), drawn for each seed (``seeds = n`` or a list) from
  ``numpy.random.default_rng(seed)`` in the order of the file; every grid point gets the same
  draws for the same seed (common random numbers);
* ``folder``: where the table goes (default ``out/<file name>-sweep`` beside the file);
  ``trajectories = true`` also saves each run's trajectory there;
* ``[sweep.heatmap]``: ``x``, ``y`` (two parameters), ``values`` (metric columns) and optionally
  ``xlabel``, ``ylabel`` (axis names) and ``limits`` (metric = largest sensible value, in the
  column's units): a heat map per value, ``heatmap.png`` in the folder; cells whose completed
  runs warned or pass a limit are hatched.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import _validate
from ..errors import CoopdynError, SweepError
from ..io import scenefile
from ..metrics import METRICS
from .cases import COUNTERS, Case, Item, Settings, _plain, expand

SWEEP_KEYS = ("grid", "random", "seeds", "folder", "trajectories", "heatmap")
DISTRIBUTIONS = ("uniform", "loguniform", "normal", "choice")
SETTABLE = ("scene", "arms", "object", "interconnections", "controller", "task", "simulation")


@dataclass(frozen=True)
class Spec:
    """A loaded sweep spec: the scene file's text and the runs it asks for."""

    path: Path
    text: str
    items: list[Item]
    folder: Path
    trajectories: bool
    heatmap: dict[str, Any] | None = None


def put(doc: dict[str, Any], name: str, value: Any) -> None:
    """Set the scene-file value named ``"table.key"`` (or ``"table.N.key"`` / ``"table.key"`` in
    every entry of an array of tables; a key of a sub-table as ``"arms.elasticity.stiffness"`` or
    ``"arms.N.elasticity.stiffness"``) in the TOML document ``doc``."""
    parts = name.split(".")
    if not 2 <= len(parts) <= 4 or parts[0] not in SETTABLE:
        raise SweepError(
            f"{name!r}: a swept value is named 'table.key' (or 'table.N.key' in [[arms]] / [[interconnections]], "
            f"'arms.elasticity.stiffness' in a sub-table), table one of {list(SETTABLE)}"
        )
    table, rest = parts[0], parts[1:]
    if table not in doc:
        raise SweepError(f"{name!r}: the file has no [{table}] table to set {rest[-1]!r} in")
    target = doc[table]
    numbered = rest[0].lstrip("-").isdigit() and len(rest) > 1
    if isinstance(target, list):
        if numbered:
            try:
                index = int(rest[0])
                if index < 0:
                    raise IndexError
                entries = [target[index]]
            except (ValueError, IndexError):
                raise SweepError(f"{name!r}: [[{table}]] has entries 0..{len(target) - 1}, not {rest[0]!r}") from None
            rest = rest[1:]
        else:
            entries = target
    elif numbered:
        raise SweepError(f"{name!r}: [{table}] is one table, not an array of tables: write '{table}.{'.'.join(rest[1:])}'")
    else:
        entries = [target]
    if len(rest) > 2:
        raise SweepError(f"{name!r}: a swept value is a key of a table or of one of its sub-tables, not deeper")
    for entry in entries:
        if len(rest) == 2:
            sub = entry.get(rest[0])
            if not isinstance(sub, dict):
                raise SweepError(f"{name!r}: a [{table}] entry has no {rest[0]!r} table to set {rest[1]!r} in")
            entry = sub
        entry[rest[-1]] = value


@dataclass
class SpecJob:
    """Cases from a scene file's document with each run's values put in (:mod:`.spec`)."""

    text: str
    path: str
    settings: Settings
    metrics: Callable[..., Mapping[str, Any]] | None = None
    _parsed: Any = field(default=None, repr=False, compare=False)

    def case(self, item: Item) -> Case:
        if self._parsed is None:
            path = Path(self.path)
            self._parsed = (scenefile.parse(self.text, path), scenefile._File(path, self.text))
        doc, f = self._parsed
        doc = copy.deepcopy(doc)
        for name, value in item.params.items():
            put(doc, name, value)
        run = scenefile.from_document(doc, f)
        if run.sweep_method is not None:  # (no integrator named: the cases run rk4 at dt, not a search each)
            integrator, dt, save_every = run.sweep_method
            return Case(run.scene, run.controller, run.task, run.duration, integrator, dt, save_every, run.control_dt)
        if run.accuracy is not None:
            raise SweepError("[simulation] accuracy is not taken by sweeps yet (each run would choose its own step): give dt")
        return Case(run.scene, run.controller, run.task, run.duration, run.integrator, run.dt, run.save_every, run.control_dt)


def _draw(rng: np.random.Generator, name: str, dist: Any) -> Any:
    if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
        raise SweepError(
            f"[sweep.random] {name!r}: give one of {list(DISTRIBUTIONS)}, e.g. {{uniform = [1e3, 1e4]}}; got {dist!r}"
        )
    kind, args = next(iter(dist.items()))
    if kind == "choice":
        if not isinstance(args, list) or not args:
            raise SweepError(f"[sweep.random] {name!r}: choice needs a non-empty list of values")
        return args[int(rng.integers(len(args)))]
    if not isinstance(args, list) or len(args) != 2 or not all(isinstance(a, int | float) and np.isfinite(a) for a in args):
        raise SweepError(f"[sweep.random] {name!r}: {kind} needs two finite numbers, got {args!r}")
    a, b = float(args[0]), float(args[1])
    if kind == "uniform":
        if not a < b:
            raise SweepError(f"[sweep.random] {name!r}: uniform needs low < high, got {args}")
        return float(rng.uniform(a, b))
    if kind == "loguniform":
        if not 0 < a < b:
            raise SweepError(f"[sweep.random] {name!r}: loguniform needs 0 < low < high, got {args}")
        return float(np.exp(rng.uniform(np.log(a), np.log(b))))
    if not b >= 0:
        raise SweepError(f"[sweep.random] {name!r}: normal needs a standard deviation >= 0, got {b}")
    return float(rng.normal(a, b))


def load_spec(path: str | Path) -> Spec:
    """Read a sweep spec; check its ``[sweep]`` table and that its first run builds (so that a
    misspelt key fails now, naming its line, not once per run)."""
    path = _validate.path(path, "a sweep spec", SweepError)
    text = scenefile._read_text(path)
    doc = scenefile.parse(text, path)
    f = scenefile._File(path, text)
    table = doc.get("sweep")
    if not isinstance(table, dict):
        raise SweepError(f"{path}: no [sweep] table: add [sweep.grid] or [sweep.random] with the values to sweep")
    for key in table:
        if key not in SWEEP_KEYS:
            raise f.error(f"unknown key; valid keys: {list(SWEEP_KEYS)}", "sweep", key)
    grid = table.get("grid", {})
    random = table.get("random", {})
    if not isinstance(grid, dict) or not isinstance(random, dict):
        raise f.error("grid and random are tables: [sweep.grid], [sweep.random]", "sweep")
    if not grid and not random:
        raise f.error("nothing to sweep: give [sweep.grid] and/or [sweep.random]", "sweep")
    for name, values in grid.items():
        if not isinstance(values, list) or not values:
            raise f.error(f"{name!r}: a grid value is a non-empty list of the values to run", "sweep.grid")
    both = sorted(set(grid) & set(random))
    if both:
        raise f.error(f"{both} are in both [sweep.grid] and [sweep.random]", "sweep.random")
    seeds = table.get("seeds")
    if random and seeds is None:
        raise f.error("[sweep.random] draws its values per seed: give seeds = a count or a list", "sweep")
    if seeds is not None and not random:
        raise f.error("seeds without [sweep.random] would repeat identical runs", "sweep", "seeds")
    try:
        base = expand(grid or None, seeds)
    except SweepError as exc:
        raise f.error(str(exc), "sweep") from None
    items = []
    for item in base:
        params = dict(item.params)
        if random:
            rng = np.random.default_rng(item.seed)
            params.update({name: _plain(_draw(rng, name, dist), name) for name, dist in random.items()})
        items.append(Item(item.run, params, item.seed))
    folder = table.get("folder", f"out/{path.stem}-sweep")
    if not isinstance(folder, str) or not folder:
        raise f.error("must be a folder name", "sweep", "folder")
    trajectories = table.get("trajectories", False)
    if not isinstance(trajectories, bool):
        raise f.error("must be true or false", "sweep", "trajectories")
    try:  # every name reaches a table the file has, and the first run builds (what the heat map names follows)
        SpecJob(text, str(path), Settings()).case(items[0])
    except CoopdynError as exc:
        raise SweepError(f"the first run ({items[0].params}) does not build: {exc}") from exc
    heatmap = table.get("heatmap")
    if heatmap is not None:
        names = list(items[0].params)
        if (
            not isinstance(heatmap, dict)
            or not {"x", "y", "values"} <= set(heatmap) <= {"x", "y", "values", "xlabel", "ylabel", "limits"}
            or heatmap["x"] not in names
            or heatmap["y"] not in names
            or not isinstance(heatmap["values"], list)
            or not all(isinstance(v, str) for v in heatmap["values"])
        ):
            raise f.error(
                f"give x and y (two of the swept values {names}), values (a list of metric columns) and optionally "
                "xlabel, ylabel (axis names with units) and limits (a table metric = largest sensible value)",
                "sweep.heatmap",
            )
        numeric = (*METRICS, *COUNTERS, "cpu_s", "wall_s")  # the numeric columns (TIMING also has the worker)
        unknown = [v for v in heatmap["values"] if v not in numeric]
        if unknown:
            raise f.error(f"values {unknown}: a spec's runs have the columns {list(numeric)}", "sweep.heatmap", "values")
        limits = heatmap.get("limits", {})
        if not isinstance(limits, dict) or not all(
            k in numeric and not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)
            for k, v in limits.items()
        ):
            raise f.error(
                f"limits must be a table metric = largest sensible value (a finite number, in the column's units), the metrics "
                f"among {list(numeric)}; got {limits!r}",
                "sweep.heatmap",
                "limits",
            )
    try:
        out = _validate.path(folder, "a folder", SweepError)
    except SweepError as exc:
        raise f.error(str(exc), "sweep", "folder") from None
    return Spec(path.resolve(), text, items, out if out.is_absolute() else (path.parent / out).resolve(), trajectories, heatmap)
