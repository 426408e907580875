"""The scene file's JSON Schema, made from the code that reads scene files.

The scene tables come from the key lists of :mod:`coopdyn.model.description` (the same lists
its checks use); the builders, controllers and tasks from the signatures of the functions and
classes the loader calls (:data:`coopdyn.io.scenefile.BUILDERS`, ``CONTROLLERS``, ``TASKS``).
``docs/scene-file.schema.json`` is :func:`scene_file_schema` written out (a test keeps it so);
editors with TOML schema support (e.g. Even Better TOML) can check scene files against it.
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable, Mapping
from typing import Any

from ..integrators import INTEGRATORS
from ..model import description as d
from . import scenefile
from .scenefile import accepts

NUMBER: dict[str, Any] = {"type": "number"}
NUMBERS: dict[str, Any] = {"type": "array", "items": NUMBER}
ROWS: dict[str, Any] = {"type": "array", "items": NUMBERS}
VECTOR3: dict[str, Any] = {"type": "array", "items": NUMBER, "minItems": 3, "maxItems": 3}

#: the JSON Schema of each kind of value in :data:`coopdyn.model.description.KINDS`
KIND_SCHEMAS: dict[str, dict[str, Any]] = {
    "string": {"type": "string", "minLength": 1},
    "number": NUMBER,
    "integer": {"type": "integer"},
    "boolean": {"type": "boolean"},
    "vector3": VECTOR3,
    "vector": NUMBERS,
    "axis": {"oneOf": [{"enum": ["x", "y", "z"]}, VECTOR3]},
    "pose": {
        "oneOf": [
            VECTOR3,
            {"type": "array", "items": NUMBERS, "minItems": 4, "maxItems": 4},
            {
                "type": "object",
                "properties": {
                    "translation": VECTOR3,
                    "rotation": {"type": "array", "items": VECTOR3, "minItems": 3, "maxItems": 3},
                    "rpy": VECTOR3,
                    "quaternion": {"type": "array", "items": NUMBER, "minItems": 4, "maxItems": 4},
                },
                "additionalProperties": False,
            },
        ]
    },
    "matrix": {"oneOf": [NUMBER, NUMBERS, ROWS]},
    "names": {"oneOf": [{"type": "array", "items": {"type": "string"}}, {"type": "object", "additionalProperties": NUMBER}]},
    "joint_damping": {"oneOf": [NUMBER, NUMBERS, {"const": "urdf"}]},
    "masses": {"type": "object", "additionalProperties": NUMBER},
    "parameters": {"type": "object", "additionalProperties": NUMBER},
    "paths": {"type": "array", "items": {"type": "string", "minLength": 1}},
    "per_joint": {"oneOf": [NUMBER, {"const": "inf"}, {"type": "array", "items": {"oneOf": [NUMBER, {"const": "inf"}]}}]},
    "joint_names": {"type": "array", "items": {"type": "string"}, "minItems": 1},
}


_PAIR: dict[str, Any] = {"type": "array", "items": NUMBER, "minItems": 2, "maxItems": 2}
_NAME: dict[str, Any] = {"type": "string", "minLength": 1}
#: ``[sweep]``: what changes from run to run (coopdyn.sweeps.spec reads it; a test keeps the two in step)
SWEEP: dict[str, Any] = {
    "type": "object",
    "description": "what changes from run to run: `coopdyn sweep` (docs/sweeps.md); `coopdyn simulate` ignores it",
    "properties": {
        "grid": {
            "type": "object",
            "description": '"table.key" = [values]: every combination',
            "additionalProperties": {"type": "array", "minItems": 1},
        },
        "random": {
            "type": "object",
            "description": '"table.key" = {uniform | loguniform | normal = [a, b]} or {choice = [values]}, drawn per seed',
            "additionalProperties": {
                "type": "object",
                "properties": {
                    "uniform": _PAIR,
                    "loguniform": _PAIR,
                    "normal": _PAIR,
                    "choice": {"type": "array", "minItems": 1},
                },
                "minProperties": 1,
                "maxProperties": 1,
                "additionalProperties": False,
            },
        },
        "seeds": {
            "oneOf": [
                {"type": "integer", "minimum": 1},
                {"type": "array", "items": {"type": "integer", "minimum": 0}, "minItems": 1},
            ]
        },
        "folder": _NAME,
        "trajectories": {"type": "boolean"},
        "heatmap": {
            "type": "object",
            "properties": {
                "x": _NAME,
                "y": _NAME,
                "values": {"type": "array", "items": _NAME},
                "xlabel": _NAME,
                "ylabel": _NAME,
                "limits": {"type": "object", "additionalProperties": {"type": "number"}},
            },
            "required": ["x", "y", "values"],
            "additionalProperties": False,
        },
    },
    "additionalProperties": False,
}


def _table(fields: Mapping[str, d.Field], extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    properties: dict[str, Any] = {}
    for key, f in fields.items():
        schema = _section() if f.kind == "section" else _table(d.ELASTICITY) if f.kind == "elasticity" else KIND_SCHEMAS[f.kind]
        properties[key] = {**schema, "description": f.doc}
    properties.update(extra or {})
    required = [k for k, f in fields.items() if f.required]
    return {
        "type": "object",
        "properties": properties,
        "additionalProperties": False,
        **({"required": required} if required else {}),
    }


def _section() -> dict[str, Any]:
    shapes = []
    for shape, fields in d.SECTION.items():
        table = _table(fields, {"shape": {"const": shape, "description": f"the section is {shape}"}})
        if shape != "properties":
            table["required"] = [*table.get("required", []), "shape"]
        shapes.append(table)
    return {"oneOf": shapes, "description": d.KINDS["section"]}


def _parameter(parameter: inspect.Parameter) -> dict[str, Any]:
    """The schema of a keyword parameter: what the loader accepts (:func:`coopdyn.io.scenefile.accepts`)."""
    takes = accepts(parameter)
    scalar = {bool: {"type": "boolean"}, int: {"type": "integer"}, float: NUMBER, str: {"type": "string"}}.get(takes.scalar)  # type: ignore[arg-type]
    if scalar is None:
        return {}  # anything: checked by the function it goes to
    also = [{"type": "array"}] * takes.lists + [{"type": "string"}] * takes.strings  # the callee checks their contents
    return {"anyOf": [scalar, *also]} if also else scalar


def _signature_table(target: Callable[..., Any], skip: tuple[str, ...], tag: str, value: str) -> dict[str, Any]:
    properties: dict[str, Any] = {tag: {"const": value}}
    required = [tag]
    for name, p in inspect.signature(target).parameters.items():
        if name in skip or p.kind not in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD):
            continue
        if p.default is inspect.Parameter.empty:
            properties[name] = {}
            required.append(name)
        else:
            properties[name] = {**_parameter(p), "description": f"default: {json.dumps(_plain(p.default))}"}
    return {"type": "object", "properties": properties, "required": required, "additionalProperties": False}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value if value is None or isinstance(value, bool | int | float | str) else repr(value)


def scene_file_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scene file, read as TOML into JSON-like data."""
    builders = [
        _signature_table(scenefile.SIGNATURES.get(name, fn), (), "builder", name) for name, fn in scenefile.BUILDERS.items()
    ]
    described = {
        "type": "object",
        "properties": {"gravity": {**VECTOR3, "description": d.GRAVITY.doc}},
        "additionalProperties": False,
    }
    controllers = []
    for name, target in scenefile.CONTROLLERS.items():
        if target is None:
            controllers.append(
                {"type": "object", "properties": {"type": {"const": name}}, "required": ["type"], "additionalProperties": False}
            )
        elif target == "book_drives":
            controllers.append(_signature_table(scenefile.scenes.book_task, ("params",), "type", name))
        else:
            controllers.append(_signature_table(target, ("scene", "reference"), "type", name))
    tasks = []
    for name, target in scenefile.TASKS.items():
        if target is None:
            tasks.append(
                {"type": "object", "properties": {"type": {"const": name}}, "required": ["type"], "additionalProperties": False}
            )
        else:
            tasks.append(_signature_table(target, ("start",), "type", name))
    objects = [
        _table(fields, {"type": {"const": kind}}) | {"required": ["type", *_required(fields)]}
        for kind, fields in d.OBJECT.items()
    ]
    simple = {float: NUMBER, int: {"type": "integer"}, str: {"type": "string"}, bool: {"type": "boolean"}}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://coopdyn.invalid/scene-file.schema.json",
        "title": "coopdyn scene file",
        "description": "A whole run: the scene (a builder's shorthand, or [[arms]], [object] and [[interconnections]]), "
        "controller, task, integrator, duration and outputs. Generated by coopdyn.io.schema.scene_file_schema().",
        "type": "object",
        "properties": {
            "scene": {"oneOf": [*builders, described], "description": "a builder and its parameters, or gravity"},
            "arms": {"type": "array", "items": _table(d.ARM), "description": "one table per arm ([[arms]])"},
            "object": {"oneOf": objects, "description": "the held object"},
            "interconnections": {
                "type": "array",
                "items": _table(d.INTERCONNECTION),
                "minItems": 1,
                "description": "one table per interconnection ([[interconnections]])",
            },
            "controller": {"oneOf": controllers},
            "task": {"oneOf": tasks},
            "simulation": {
                "type": "object",
                "properties": {
                    **{k: simple[t] for k, t in scenefile.SIMULATION_KEYS.items()},
                    "integrator": {"enum": [*sorted(INTEGRATORS), "auto"]},
                },
                "required": ["duration"],
                "additionalProperties": False,
            },
            "output": {
                "type": "object",
                "properties": {k: simple[t] for k, t in scenefile.OUTPUT_KEYS.items()},
                "additionalProperties": False,
            },
            "sweep": SWEEP,
        },
        "required": ["simulation"],
        "additionalProperties": False,
        "oneOf": [
            {"required": ["scene"], "properties": {"scene": {"required": ["builder"]}}, "not": {"required": ["object"]}},
            {"required": ["object", "interconnections"]},
        ],
    }


def _required(fields: Mapping[str, d.Field]) -> list[str]:
    return [k for k, f in fields.items() if f.required]


def schema_text() -> str:
    """:func:`scene_file_schema` as the text of ``docs/scene-file.schema.json``."""
    return json.dumps(scene_file_schema(), indent=2, ensure_ascii=False) + "\n"
