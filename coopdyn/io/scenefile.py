"""Scene files: a whole run (scene, controller, task, integrator, duration, outputs) in TOML.

The scene is either described table by table — ``[[arms]]``, ``[object]``,
``[[interconnections]]`` and ``[scene] gravity``, the tables of
:mod:`coopdyn.model.description`, so any scene the Python API builds can be written — or
given by a builder's shorthand (``[scene] builder = "facing_arms"`` or ``"linear_book"`` with
the builder's parameters). Every other table maps onto a coopdyn function or class and every
key onto one of its parameters; an unknown key, a value of the wrong type or a missing field
raises :class:`SceneFileError` naming the file, the key, its line and what is valid. The format's
JSON Schema is ``docs/scene-file.schema.json`` (:mod:`coopdyn.io.schema`); examples are in
``examples/scenes/``.
"""

from __future__ import annotations

import inspect
import math
import re
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import _validate, scenes
from .._validate import _short
from ..control import ComputedTorque, GravityCompensationPD, MotorPD
from ..cooperative import GripLiftOscillate, ObjectImpedance
from ..errors import CoopdynError, SceneFileError, SimulationError, did_you_mean
from ..integrators import INTEGRATORS
from ..metrics import metric_lines, run_metrics
from ..model.description import DescriptionError, build
from ..model.scene import Scene
from ..problems.facing_arms import object_start
from ..problems.linear_book import BookParameters

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


#: [scene] builder → function; [controller] type → class; [task] type → class
BUILDERS: dict[str, Callable[..., Scene]] = {"facing_arms": scenes.facing_arms, "linear_book": scenes.linear_book}
#: where a builder's keyword parameters are declared, when not in its own signature
SIGNATURES: dict[str, Callable[..., Any]] = {"linear_book": BookParameters}
CONTROLLERS: dict[str, Any] = {
    "none": None,
    "gravity_pd": GravityCompensationPD,
    "computed_torque": ComputedTorque,
    "motor_pd": MotorPD,
    "object_impedance": ObjectImpedance,
    "book_drives": "book_drives",
}
TASKS: dict[str, Any] = {"grip_lift_oscillate": GripLiftOscillate, "hold": None}
TABLES = ("scene", "arms", "object", "interconnections", "controller", "task", "simulation", "output", "sweep")
DESCRIBED = ("arms", "object", "interconnections")  #: the tables that describe a scene without a builder
SIMULATION_KEYS = {"duration": float, "integrator": str, "dt": float, "save_every": int, "control_dt": float, "accuracy": float}
#: [N] the force error a run may have when its file names no integrator (the method and step are then chosen for it)
DEFAULT_ACCURACY = 0.1
OUTPUT_KEYS = {"folder": str, "plot": bool, "html": bool, "npz": bool, "csv": bool}


@dataclass
class Run:
    """A loaded scene file, ready to simulate."""

    path: Path
    scene: Scene
    controller: Any
    task: Any
    duration: float
    integrator: str
    dt: float
    save_every: int
    output: dict[str, Any] = field(default_factory=dict)
    control_dt: float | None = None  #: the controller's sample period [s] (None: every evaluation)
    accuracy: float | None = None  #: [N] the force error the run may have: dt is the step to start from (simulate's accuracy)
    #: (integrator, dt [s], save_every) a sweep's cases take when the file names neither an
    #: integrator nor an accuracy (a sweep's runs do not search for their method and step): rk4 at dt
    sweep_method: tuple[str, float, int] | None = None


class _File:
    """The raw text, for line numbers in messages."""

    def __init__(self, path: Path, text: str) -> None:
        self.path, self.lines = path, text.splitlines()

    def line(self, table: str | None, key: str | None = None, index: int | None = None) -> int | None:
        """1-based line of ``key`` inside ``[table]`` (or of the table header); ``index``: inside
        the index-th ``[[table]]``."""
        start = 0
        if table is not None:
            brackets = (r"\[\[", r"\]\]") if index is not None else (r"\[", r"\]")
            header = re.compile(rf"^\s*{brackets[0]}\s*{re.escape(table)}\s*{brackets[1]}")
            hits = [i for i, s in enumerate(self.lines) if header.match(s)]
            if len(hits) <= (index or 0):
                return None
            start = hits[index or 0]
            if key is None:
                return start + 1
        first, _, rest = (key or "").partition(".")  # ("elasticity.stiffness": a sub-table's key)
        found, end = self._key_line(start + (1 if table else 0), first, stop_at_table=table is not None)
        if found is None and rest and end is not None:  # written as a [table.sub] table of its own
            if re.match(rf"^\s*\[\s*{re.escape(table or '')}\.{re.escape(first)}\s*\]", self.lines[end]):
                return self._key_line(end + 1, rest, stop_at_table=True)[0] or end + 1
        return found

    def _key_line(self, start: int, key: str, stop_at_table: bool) -> tuple[int | None, int | None]:
        """(1-based line of ``key = …`` from line ``start`` (0-based) on, or None; the 0-based line of
        the next table header that stopped the search, or None)."""
        pattern = re.compile(rf"^\s*{re.escape(key)}\s*=")
        for i in range(start, len(self.lines)):
            if stop_at_table and re.match(r"^\s*\[", self.lines[i]):
                return None, i
            if pattern.match(self.lines[i]):
                return i + 1, None
        return None, None

    def error(self, message: str, table: str | None, key: str | None = None, index: int | None = None) -> SceneFileError:
        line = self.line(table, key, index)
        where = f"{self.path}" + (f", line {line}" if line else "")
        name = f"[[{table}]] #{index + 1}" if index is not None else f"[{table}]"
        what = f"{name} {key}" if table and key else (name if table else (key or ""))
        return SceneFileError(f"{where}: {what}: {message}")


def _check_type(f: _File, table: str, key: str, value: Any, kind: Any) -> Any:
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not (abs(value) <= sys.float_info.max):
            raise f.error(f"must be a finite number, got {_short(value)}", table, key)
        return float(value)
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise f.error(f"must be an integer, got {_short(value)}", table, key)
        return value
    if kind is bool:
        if not isinstance(value, bool):
            raise f.error(f"must be true or false, got {_short(value)}", table, key)
        return value
    if kind is str and not isinstance(value, str):
        raise f.error(f"must be a string, got {_short(value)}", table, key)
    return value


@dataclass(frozen=True)
class Accepts:
    """What a keyword parameter of a builder, controller or task takes in a scene file: the type
    of its default (None: anything, the callee checks it), and whether a list or a string also
    does (its annotation says ``Sequence``/``Any`` or ``str``, e.g. ``facing_arms``'
    ``stiffness: float | Sequence[float]`` and ``joint_damping: float | str``). The loader and
    the JSON Schema (:mod:`coopdyn.io.schema`) both read it from here."""

    scalar: type | None
    lists: bool
    strings: bool


def accepts(parameter: inspect.Parameter) -> Accepts:
    """What ``parameter`` takes (see :class:`Accepts`), from its default and annotation."""
    default, annotation = parameter.default, str(parameter.annotation)
    lists = "Sequence" in annotation or "Any" in annotation
    scalar: type | None = None
    if isinstance(default, bool):
        scalar = bool
    elif isinstance(default, int | float):
        scalar = type(default)
    elif isinstance(default, str):
        scalar = str
    return Accepts(scalar, lists, scalar is not str and "str" in annotation.replace("Sequence[str]", ""))


def _params(
    f: _File, table: str, target: Callable[..., Any], values: Mapping[str, Any], skip: tuple[str, ...] = ()
) -> dict[str, Any]:
    """Check ``values`` against ``target``'s keyword parameters (names and, from the defaults, types)."""
    sig = inspect.signature(target)
    valid = {n: p for n, p in sig.parameters.items() if n not in skip and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
    var_kw = any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
    out = {}
    for key, value in values.items():
        if key not in valid and not var_kw:
            raise f.error(f"unknown key; valid keys: {sorted(valid)}", table, key)
        takes = accepts(valid[key]) if key in valid else Accepts(None, False, False)
        if (isinstance(value, list) and takes.lists) or (isinstance(value, str) and takes.strings):
            pass  # a list or a string where the parameter takes one: the callee checks it
        elif takes.scalar is not None:
            value = _check_type(f, table, key, value, takes.scalar)
        elif var_kw and isinstance(value, int | float) and not isinstance(value, bool):
            value = _check_type(f, table, key, value, float)
        out[key] = value
    missing = [n for n, p in valid.items() if p.default is inspect.Parameter.empty and n not in out]
    if missing:
        raise f.error(f"missing required key(s) {missing}", table)
    return out


MAX_FILE_BYTES = 1 << 20  #: a scene file is a few kB; a larger one is refused unread


def _read_text(path: Path) -> str:
    """The file's text: UTF-8 (TOML's encoding), at most :data:`MAX_FILE_BYTES`."""
    try:
        if not path.is_file():
            raise SceneFileError(f"scene file not found: {path}")
        if path.stat().st_size > MAX_FILE_BYTES:
            raise SceneFileError(f"{path}: {path.stat().st_size:,} bytes; a scene file has at most {MAX_FILE_BYTES:,}")
        data = path.read_bytes()
    except OSError as exc:
        raise SceneFileError(f"cannot read the scene file {path}: {exc.strerror or exc}") from exc
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise SceneFileError(
            f"{path}, line {line}: not UTF-8 text (byte {data[exc.start]:#04x} at offset {exc.start}); TOML files are UTF-8"
        ) from None


def load(path: str | Path) -> Run:
    """Read and validate a scene file; build the scene, controller and task."""
    if not isinstance(path, str | Path):
        raise SceneFileError(f"a scene file path must be a str or pathlib.Path, got {type(path).__name__}")
    path = Path(path)
    text = _read_text(path)
    return from_document(parse(text, path), _File(path, text))


def parse(text: str, path: Path) -> dict[str, Any]:
    """The TOML document of a scene file's text (``path`` names it in messages)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneFileError(f"{path}: not valid TOML: {exc}") from exc
    except RecursionError:
        raise SceneFileError(f"{path}: not valid TOML: arrays or tables nested too deeply") from None


def from_document(doc: dict[str, Any], f: _File) -> Run:
    """Validate a scene file's document and build its run; messages name the lines of ``f``'s text
    (a sweep builds each of its runs from the spec's document with the run's values put in)."""
    path = f.path
    for table, value in doc.items():
        if table in ("arms", "interconnections") and isinstance(value, list):
            continue
        if isinstance(value, list) and value and all(isinstance(x, dict) for x in value):  # [[table]], unknown
            arrays = [f"[[{t}]]" for t in ("arms", "interconnections")]
            hint = did_you_mean(f"[[{table}]]", arrays)
            raise f.error(f"unknown array of tables; valid: {', '.join(arrays)}.{hint}", table, None, 0)
        if not isinstance(value, dict):
            hint = f" (write [[{table}]], one per entry)" if table in ("arms", "interconnections") else ""
            raise f.error(f"a top-level key; everything goes in one of the tables {list(TABLES)}{hint}", None, table)
        if table not in TABLES:
            raise f.error(f"unknown table; valid tables: {list(TABLES)}.{did_you_mean(table, TABLES)}", table)
    if "simulation" not in doc:
        raise SceneFileError(f"{path}: missing table [simulation]")
    scene, builder_name, kwargs = _scene(f, doc)
    sim = doc["simulation"]
    for key in sim:
        if key not in SIMULATION_KEYS:
            raise f.error(f"unknown key; valid keys: {sorted(SIMULATION_KEYS)}", "simulation", key)
    if "duration" not in sim:
        raise f.error("missing required key 'duration' [s]", "simulation")
    duration = _check_type(f, "simulation", "duration", sim["duration"], float)
    chosen_for_it = "integrator" not in sim  # the method and step chosen for an accuracy (DEFAULT_ACCURACY)
    dt = _check_type(f, "simulation", "dt", sim.get("dt", 1e-3), float)  # (with "auto": the step the search starts from)
    integrator = _check_type(f, "simulation", "integrator", sim.get("integrator", "auto"), str)
    if integrator not in INTEGRATORS and integrator != "auto":
        valid = [*sorted(INTEGRATORS), "auto (with accuracy)"]
        raise f.error(f"unknown integrator {integrator!r}; valid: {valid}", "simulation", "integrator")
    if integrator == "auto" and "accuracy" not in sim and not chosen_for_it:
        why = "'auto' chooses the method for a force accuracy: give accuracy [N] too (e.g. 0.1)"
        raise f.error(why, "simulation", "integrator")
    if not dt >= 1e-12:
        raise f.error(f"must be >= 1e-12 [s], got {dt:g}", "simulation", "dt")
    save_every = _check_type(f, "simulation", "save_every", sim.get("save_every", max(1, round(0.01 / dt))), int)
    if duration < 0:
        raise f.error(f"must be >= 0 [s], got {duration:g}", "simulation", "duration")
    if save_every < 1:
        raise f.error(f"must be >= 1 (keep every k-th step), got {save_every}", "simulation", "save_every")
    control_dt = None
    if "control_dt" in sim:
        control_dt = _check_type(f, "simulation", "control_dt", sim["control_dt"], float)
        if not control_dt >= 1e-12:
            raise f.error(f"the controller's sample period must be >= 1e-12 [s], got {control_dt:g}", "simulation", "control_dt")
        from ..integrators import get_integrator
        from ..stepping import _control_period  # (the run's own check: a fixed-step method's steps land on every sample)

        try:
            fixed = "trapezoid" if integrator == "auto" else integrator  # ("auto": dt, dt/2, … or dopri5, which lands on samples)
            control_dt = _control_period(control_dt, dt, get_integrator(fixed))
        except SimulationError as exc:
            raise f.error(str(exc), "simulation", "control_dt") from None

    accuracy = DEFAULT_ACCURACY if chosen_for_it else None
    if "accuracy" in sim:
        accuracy = _check_type(f, "simulation", "accuracy", sim["accuracy"], float)
        if not 0.0 < accuracy < math.inf:
            raise f.error(f"the force error the run may have must be > 0 [N], got {accuracy:g}", "simulation", "accuracy")
        chosen = INTEGRATORS.get(integrator)  # (None: "auto")
        if chosen is not None and (chosen.adaptive or chosen.exact_discretisation):
            what = "controls its own error (give its rtol in Python)" if chosen.adaptive else "is exact at any dt"
            raise f.error(
                f'chooses a fixed-step method\'s step; {integrator} {what}: use a fixed-step method, "auto", or drop accuracy',
                "simulation",
                "accuracy",
            )

    task = _task(f, doc.get("task"), scene)
    controller = _controller(f, doc.get("controller", {"type": "none"}), scene, task, builder_name, kwargs)

    out_doc = doc.get("output", {})
    output = {"folder": f"out/{path.stem}", "plot": True, "html": False, "npz": True, "csv": False}
    for key, value in out_doc.items():
        if key not in OUTPUT_KEYS:
            raise f.error(f"unknown key; valid keys: {sorted(OUTPUT_KEYS)}", "output", key)
        output[key] = _check_type(f, "output", key, value, OUTPUT_KEYS[key])
    try:
        folder = _validate.path(str(output["folder"]), "a folder", SceneFileError)
    except SceneFileError as exc:
        raise f.error(str(exc), "output", "folder") from None
    output["folder"] = str(folder if folder.is_absolute() else (path.parent / folder).resolve())  # the file's own folder
    # a sweep of a file that asks for nothing runs rk4 at dt (an accuracy written is refused there)
    sweep_method = ("rk4", dt, save_every) if chosen_for_it and "accuracy" not in sim else None
    return Run(path, scene, controller, task, duration, integrator, dt, save_every, output, control_dt, accuracy, sweep_method)


def _scene(f: _File, doc: dict[str, Any]) -> tuple[Scene, str | None, dict[str, Any]]:
    """The scene, the builder that made it (``None``: described table by table) and its keywords."""
    scene_doc = dict(doc.get("scene", {}))
    described = [t for t in DESCRIBED if t in doc]
    if "builder" in scene_doc:
        if described:
            raise f.error(
                f"a scene is either a builder's shorthand or described by [[arms]], [object] and [[interconnections]]; "
                f"this file has both (builder and {described})",
                "scene",
                "builder",
            )
        builder_name = scene_doc.pop("builder")
        if not isinstance(builder_name, str) or builder_name not in BUILDERS:
            raise f.error(f"must be one of {sorted(BUILDERS)}, got {builder_name!r}", "scene", "builder")
        builder = BUILDERS[builder_name]
        kwargs = _params(f, "scene", SIGNATURES.get(builder_name, builder), scene_doc)
        try:
            return builder(**kwargs), builder_name, kwargs
        except CoopdynError as exc:
            raise f.error(str(exc), "scene") from exc
    if not described:
        raise SceneFileError(
            f"{f.path}: no scene: describe it with [[arms]], [object] and [[interconnections]] tables, "
            f"or use a builder ([scene] builder = one of {sorted(BUILDERS)})"
        )
    for key in scene_doc:
        if key != "gravity":
            raise f.error(
                f"unknown key; without a builder, [scene] holds only gravity (or give builder = one of {sorted(BUILDERS)})",
                "scene",
                key,
            )
    try:
        return build({**{t: doc[t] for t in described}, **scene_doc}, base=f.path.parent), None, {}
    except DescriptionError as exc:
        where = exc.location
        if where.table == "gravity":
            raise f.error(exc.reason, "scene", "gravity") from None
        raise f.error(exc.reason, where.table, where.key, where.entry) from None
    except CoopdynError as exc:
        raise SceneFileError(f"{f.path}: {exc}") from None


def _pick(f: _File, doc: dict[str, Any], table: str, registry: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """The registry entry named by the table's ``type`` key, and the table's other keys."""
    rest = dict(doc)
    kind = rest.pop("type", None)
    if not isinstance(kind, str) or kind not in registry:
        raise f.error(f"must be one of {sorted(registry)}, got {kind!r}", table, "type")
    return registry[kind], rest


def _task(f: _File, doc: dict[str, Any] | None, scene: Scene) -> Any:
    if doc is None:
        return None
    cls, doc = _pick(f, doc, "task", TASKS)
    if cls is None:
        return None
    kwargs = _params(f, "task", cls, doc, skip=("start",))
    try:
        return cls(start=object_start(scene), **kwargs)
    except CoopdynError as exc:
        raise f.error(str(exc), "task") from exc


def _controller(f: _File, doc: dict[str, Any], scene: Scene, task: Any, builder: str | None, scene_kwargs: dict[str, Any]) -> Any:
    target, doc = _pick(f, doc, "controller", CONTROLLERS)
    if target is None:
        if doc:
            raise f.error("takes no other keys", "controller")
        return None
    if target == "book_drives":
        if builder != "linear_book":
            raise f.error(
                "'book_drives' drives the book's linear system: it needs [scene] builder = 'linear_book'", "controller", "type"
            )
        kwargs = _params(f, "controller", scenes.book_task, doc, skip=("params",))
        try:
            return scenes.drives_controller(*scenes.book_task(BookParameters.from_kwargs(**scene_kwargs), **kwargs))
        except CoopdynError as exc:
            raise f.error(str(exc), "controller") from exc
    kwargs = _params(f, "controller", target, doc, skip=("scene", "reference"))
    try:
        if target is ObjectImpedance:
            return ObjectImpedance(scene, task, **kwargs)
        return target(scene, **kwargs)
    except CoopdynError as exc:
        raise f.error(str(exc), "controller") from exc


def relocated(text: str) -> str:
    """A scene file's text for the copy written into its output folder: ``[output] folder`` set to
    ``"."``, so that the copy names the folder it sits in (``coopdyn view OUT/scene.toml``)."""
    lines = text.splitlines()
    f = _File(Path("scene.toml"), text)
    header = f.line("output")
    setting = 'folder = "."  # this folder: the copy coopdyn simulate wrote beside its results'
    if header is None:
        return text + ("" if text.endswith("\n") or not text else "\n") + f"\n[output]\n{setting}\n"
    key = f.line("output", "folder")
    if key is not None:
        lines[key - 1] = setting
    else:
        lines.insert(header, setting)
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class RunReport:
    """What :func:`run` did: the result, the files it wrote and a summary (lines of text)."""

    result: Any
    written: tuple[Path, ...]
    summary: tuple[str, ...]
    #: the run's metrics (:func:`coopdyn.metrics.run_metrics`: the demo's and sweep tables' names)
    metrics: dict[str, float] = field(default_factory=dict)

    def __str__(self) -> str:
        return "\n".join([*self.summary, *(f"  wrote {w}" for w in self.written)])


def run(loaded: Run, *, folder: str | Path | None = None, progress: bool = True, max_steps: int | None = 2 * 10**6) -> RunReport:
    """Simulate a loaded scene file and write its outputs; returns what it did (print it to show it).
    ``max_steps`` is :func:`coopdyn.simulate`'s (``None``: no limit).

    On a divergence or Ctrl-C the trajectory so far is written (``trajectory.npz``/``.csv`` and
    ``diagnosis.txt``) and the error is re-raised with those paths in its ``saved`` attribute."""

    from ..errors import DivergenceError, SimulationInterrupted, StepBudgetError
    from ..outputs import check_folder, save_partial, write_outputs
    from ..simulate import _setting, simulate
    from ..viz.plotting import result_figure

    out = check_folder(folder or loaded.output["folder"])  # before the run: a refusal costs nothing yet
    source = relocated(_read_text(loaded.path)).encode("utf-8")  # the copy written beside the results
    wall0 = time.perf_counter()
    try:
        res = simulate(
            loaded.scene,
            loaded.duration,
            controller=loaded.controller,
            integrator=loaded.integrator,
            dt=loaded.dt,
            save_every=loaded.save_every,
            control_dt=loaded.control_dt,
            accuracy=loaded.accuracy,
            progress=progress,
            max_steps=max_steps,
        )
    except (DivergenceError, SimulationInterrupted, StepBudgetError) as exc:
        exc.saved = save_partial(exc, out)  # type: ignore[union-attr]
        raise
    wall = time.perf_counter() - wall0

    def trajectory(folder: Path) -> list[Path]:
        (folder / "scene.toml").write_bytes(source)
        files = [folder / "scene.toml"]
        if loaded.output["npz"]:
            files.append(res.save(folder / "trajectory.npz"))
        if loaded.output["csv"]:
            files.append(res.save(folder / "trajectory.csv"))
        return files

    def plot(folder: Path) -> Path:
        result_figure(res, loaded.task, folder / "plot.png")
        return folder / "plot.png"

    def animation(folder: Path) -> Path:
        from ..viz.viewer import export_html

        return export_html(res, folder / "animation.html")

    optional = [("plot", plot)] if loaded.output["plot"] else []
    optional += [("animation", animation)] if loaded.output["html"] else []
    done = write_outputs(out, [("trajectory", trajectory)], optional)
    written = list(done.files)
    summary = [
        f"{loaded.path}: {loaded.duration:g} s with "
        + _setting(res)
        + (
            f" (chosen for a force error <= {loaded.accuracy:g} N: {res.force_error_estimate:.3g} N against dopri5)"
            if loaded.accuracy is not None
            else ""
        ),
        (
            f"  CPU {res.cpu_time:.2f} s for the search (its reference run and every try; the run kept: {res.n_rhs} RHS); "
            f"wall {wall:.2f} s"
            if loaded.accuracy is not None
            else f"  CPU {res.cpu_time:.2f} s ({res.cpu_time / max(loaded.duration, 1e-300):.3f} CPU s per simulated s), "
            f"{res.n_rhs} RHS; wall {wall:.2f} s: real-time factor {loaded.duration / max(wall, 1e-300):.3g}"
        ),
    ]
    metrics, notes = run_metrics(res, loaded.task)  # the names the demo and sweep tables use
    summary += metric_lines(metrics, commanded_squeeze=getattr(loaded.task, "squeeze", None))
    summary += [f"  {note}" for note in notes]
    summary += [f"  not written: {p}" for p in done.problems]
    return RunReport(res, tuple(written), tuple(summary), metrics)


def load_result(loaded: Run, path: str | Path | None = None) -> Any:
    """The Result saved by :func:`run` for this scene file (``trajectory.npz`` in its output
    folder, or ``path``). A result that carries its scene (every one this version writes) is
    loaded by :meth:`coopdyn.Result.load`; an older one gets the scene file's scene."""
    import numpy as np

    from ..result import Result, read_npz

    path = Path(path) if path is not None else Path(loaded.output["folder"]) / "trajectory.npz"
    if not path.is_file():
        raise SceneFileError(f"no saved trajectory at {path}: run `coopdyn simulate {loaded.path}` first (with npz = true)")
    try:
        with np.load(path, allow_pickle=False) as z:
            if "meta" in z.files:
                return Result.load(path)
        arrays = read_npz(path, ("t", "q", "v", "tau", "integrator", "dt"))
    except CoopdynError:
        raise
    except Exception as exc:
        raise SceneFileError(f"{path} is not a trajectory coopdyn wrote ({type(exc).__name__}: {exc})") from exc
    scene = loaded.scene
    n = arrays["t"].shape[0] if arrays["t"].ndim == 1 else -1
    shapes = {"q": (n, scene.nq), "v": (n, scene.nv), "tau": (n, scene.n_actuated)}
    for key, shape in shapes.items():
        if arrays[key].shape != shape or arrays[key].dtype.kind != "f":
            raise SceneFileError(
                f"{path}: {key} has shape {arrays[key].shape}, the scene of {loaded.path} needs {shape} "
                "(a trajectory of another scene, or a damaged file)"
            )
    if arrays["t"].dtype.kind not in "iuf" or not all(np.all(np.isfinite(arrays[k])) for k in ("t", "q", "v", "tau")):
        raise SceneFileError(f"{path}: the trajectory's t, q, v and tau must be finite numbers")
    dt = arrays["dt"]
    if dt.shape != () or dt.dtype.kind not in "iuf" or not float(dt) > 0 or arrays["integrator"].dtype.kind != "U":
        raise SceneFileError(f"{path}: dt must be one positive number and integrator a name (a damaged file?)")
    return Result(
        scene=scene,
        t=arrays["t"].astype(float),
        q=arrays["q"],
        v=arrays["v"],
        tau=arrays["tau"],
        integrator=str(arrays["integrator"]),
        dt=float(dt),
        n_rhs=0,
        cpu_time=0.0,
    )


@dataclass(frozen=True)
class Saved:
    """A saved result found by :func:`open_result`, with the scene file's task when there is one."""

    result: Any  #: the :class:`coopdyn.Result`
    path: Path  #: the ``.npz`` it came from
    task: Any  #: the task of the scene file it belongs to (a reference for plots), or None


def open_result(path: str | Path, *, task: bool = False) -> Saved:
    """The saved result at ``path``: a ``.npz`` :meth:`coopdyn.Result.save` wrote, an output
    folder holding ``trajectory.npz`` (from ``coopdyn simulate`` or ``coopdyn demo``), or a scene
    file (the result in its ``[output] folder``). With ``task``, also the task of that scene file
    (or of the ``scene.toml`` copy beside the result), built on the result's scene."""
    if not isinstance(path, str | Path) or not str(path):
        raise SceneFileError(f"a result is given by a path, got {path!r}")
    path = _validate.path(path, "a result", SceneFileError)
    if path.suffix == ".toml":
        loaded = load(path)
        npz = Path(loaded.output["folder"]) / "trajectory.npz"
        if not npz.is_file() and (path.parent / "trajectory.npz").is_file():
            npz = path.parent / "trajectory.npz"  # a copy beside its results, written by an older coopdyn
        return Saved(load_result(loaded, npz), npz, loaded.task)
    npz = path / "trajectory.npz" if path.is_dir() else path
    if npz.suffix != ".npz":
        raise SceneFileError(f"{path}: give a result (.npz), an output folder holding trajectory.npz, or a scene file (.toml)")
    if not npz.is_file():
        where = "holds no trajectory.npz" if path.is_dir() else "does not exist"
        raise SceneFileError(f"{path} {where}: run `coopdyn simulate` or `coopdyn demo` first")
    from ..result import Result

    result = Result.load(npz)
    beside = npz.parent / "scene.toml"
    return Saved(result, npz, _task_of(beside, result.scene) if task and beside.is_file() else None)


def _task_of(path: Path, scene: Scene) -> Any:
    """The task a scene file describes, on ``scene`` (None when the file cannot be read: the
    result carries its own scene, the file only adds the reference)."""
    try:
        text = _read_text(path)
        doc = tomllib.loads(text).get("task")
        return _task(_File(path, text), doc if isinstance(doc, dict) else None, scene)
    except (CoopdynError, tomllib.TOMLDecodeError):
        return None
