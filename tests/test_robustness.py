"""Bad input gets a coopdyn error, never another exception, a hang, or a scene that yields NaN.

Property-based: hypothesis throws random and malformed values at the scene builder and at the
scene-file loader."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import coopdyn as cd
from coopdyn.io.scenefile import load
from coopdyn.resources import urdf_path

SLIDER = str(urdf_path("slider_z.urdf"))

junk = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=8),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10, max_value=10),
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), max_size=8),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def mostly(valid: st.SearchStrategy[Any], bad: st.SearchStrategy[Any] = junk) -> st.SearchStrategy[Any]:
    """Valid values 95 % of the time, malformed ones otherwise: many examples build a scene."""
    return st.integers(0, 19).flatmap(lambda i: bad if i == 0 else valid)


any_float = st.floats(allow_nan=True, allow_infinity=True)
number = mostly(st.floats(min_value=1e-3, max_value=1e3), st.one_of(any_float, st.floats(max_value=0.0), junk))
vector3 = mostly(st.lists(st.floats(min_value=0.01, max_value=1.0), min_size=3, max_size=3))
spd6 = st.lists(st.floats(min_value=0.0, max_value=1e6), min_size=6, max_size=6)
matrix6 = mostly(
    st.one_of(spd6, spd6.map(np.diag)),
    st.one_of(
        st.lists(st.floats(min_value=-1e6, max_value=1e6), min_size=36, max_size=36).map(lambda x: np.reshape(x, (6, 6))), junk
    ),
)


def _assert_finite_or_error(scene: cd.Scene) -> None:
    """A scene that builds must simulate to a finite state or stop with a coopdyn error."""
    try:
        res = cd.simulate(scene, 0.01, integrator="rk4", dt=1e-3, energy_check="off")
    except cd.CoopdynError:
        return
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.v))


BUILDER_ARGS = dict(
    arm_name=mostly(st.just("a")),
    tip=mostly(st.just("tip"), st.one_of(st.just("tpi"), junk)),
    q0=mostly(st.lists(st.floats(min_value=-1.0, max_value=1.0), min_size=1, max_size=1), st.one_of(vector3, junk)),
    locked=mostly(st.just(()), st.one_of(st.lists(st.one_of(st.just("slide"), st.text(max_size=5)), max_size=2), junk)),
    damping=mostly(st.floats(min_value=0.0, max_value=100.0), number),
    mass_overrides=mostly(
        st.dictionaries(st.just("slide"), st.floats(min_value=0.1, max_value=100.0), max_size=1),
        st.one_of(st.dictionaries(st.sampled_from(["slide", "nope"]), number, max_size=1), junk),
    ),
    mass=number,
    size=vector3,
    joint=mostly(st.sampled_from(["freeflyer", "prismatic", "planar"])),
    stiffness=matrix6,
    grasp=mostly(st.one_of(st.none(), st.lists(st.floats(min_value=-0.5, max_value=0.5), min_size=3, max_size=3)), vector3),
    gravity=mostly(st.lists(st.floats(min_value=-20, max_value=20), min_size=3, max_size=3), vector3),
)


@settings(max_examples=200, deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(**BUILDER_ARGS)
def test_scene_builder_gives_a_scene_or_a_coopdyn_error(**kw: Any) -> None:
    try:
        arm = cd.Arm(
            kw["arm_name"], SLIDER, tip_frame=kw["tip"], q0=kw["q0"], locked_joints=kw["locked"],
            joint_damping=kw["damping"], mass_overrides=kw["mass_overrides"],
        )  # fmt: skip
        obj = cd.RigidObject.box(kw["mass"], kw["size"], joint=kw["joint"])
        link = cd.Interconnection("a", stiffness=kw["stiffness"], grasp=kw["grasp"])
        scene = cd.Scene([arm], obj, [link], gravity=kw["gravity"])
    except cd.CoopdynError as exc:
        event(f"refused: {type(exc).__name__}")
        return
    event("built")
    _assert_finite_or_error(scene)


TABLE_KEYS = {
    "scene": ["builder", "m", "c_p", "robot", "stiffness", "box_mass", "nope"],
    "controller": ["type", "squeeze", "kp", "stiffness", "nope"],
    "task": ["type", "squeeze", "lift"],
    "simulation": ["duration", "dt", "integrator", "save_every", "nope"],
    "output": ["folder", "plot", "html", "nope"],
    "bogus": ["x"],
}
VALID = {
    ("scene", "builder"): st.sampled_from(["linear_book", "linear_book", "facing_arms"]),
    ("scene", "m"): st.floats(min_value=0.1, max_value=100.0),
    ("scene", "c_p"): st.floats(min_value=1.0, max_value=1e6),
    ("simulation", "duration"): st.floats(min_value=0.0, max_value=0.05),
    ("simulation", "dt"): st.sampled_from([1e-4, 1e-3, 0.01]),
    ("simulation", "integrator"): st.sampled_from(["rk4", "implicit_euler", "exponential", "symplectic_euler"]),
    ("controller", "type"): st.sampled_from(["none", "book_drives", "gravity_pd"]),
}
toml_value = st.one_of(
    st.sampled_from(["linear_book", "facing_arms", "book_drives", "gravity_pd", "rk4", "exponential", "none", "hold"]),
    st.floats(min_value=-1e3, max_value=1e3),
    st.sampled_from([0.0, -1.0, 1e-3, 0.01, 1e300, math.inf, math.nan]),
    st.integers(min_value=-3, max_value=3),
    st.booleans(),
    st.text(alphabet="abc_", max_size=5),
    st.lists(st.floats(min_value=-10, max_value=10), max_size=3),
)


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if math.isinf(value) else repr(value))
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value + '"'
    return str(value)


@st.composite
def scene_files(draw: st.DrawFn) -> str:
    tables = ["scene", "simulation"] if draw(st.integers(0, 3)) else []  # usually the required tables
    tables += draw(st.lists(st.sampled_from(list(TABLE_KEYS)), min_size=0, max_size=4, unique=True))
    tables = list(dict.fromkeys(tables))
    lines = []
    for table in tables:
        lines.append(f"[{table}]")
        keys = [k for k in TABLE_KEYS[table] if (table, k) in VALID and draw(st.integers(0, 4))]  # usually the important keys
        keys += draw(st.lists(st.sampled_from(TABLE_KEYS[table]), max_size=3, unique=True))
        for key in dict.fromkeys(keys):
            valid = VALID.get((table, key))
            value = draw(valid) if valid is not None and draw(st.integers(0, 5)) else draw(toml_value)
            lines.append(f"{key} = {_toml(value)}")
    return "\n".join(lines) + "\n"


@settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(text=scene_files())
def test_scene_file_loader_gives_a_run_or_a_coopdyn_error(tmp_path: Path, text: str) -> None:
    path = tmp_path / "random.toml"
    path.write_text(text)
    try:
        run = load(path)
    except cd.CoopdynError as exc:
        event(f"refused: {type(exc).__name__}")
        return
    event("loaded")
    assert run.duration >= 0 and run.dt > 0
    if run.duration <= 1.0 and run.scene.nv <= 3:  # keep it fast: simulate only the small scenes
        try:
            res = cd.simulate(
                run.scene,
                min(run.duration, 0.01),
                controller=run.controller,
                integrator=run.integrator,
                dt=run.dt,
                energy_check="off",
            )
        except cd.CoopdynError:
            return
        assert np.all(np.isfinite(res.q))


# The same at thousands of examples, not derandomized (part of the 10 000-case fuzz run, with
# tests/test_reliability.py's slow tests).
@pytest.mark.slow
@settings(max_examples=2000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(**BUILDER_ARGS)
def test_scene_builder_fuzz_thousands(**kw: Any) -> None:
    test_scene_builder_gives_a_scene_or_a_coopdyn_error.hypothesis.inner_test(**kw)


@pytest.mark.slow
@settings(
    max_examples=2000,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(text=scene_files())
def test_scene_file_fuzz_thousands(tmp_path: Path, text: str) -> None:
    test_scene_file_loader_gives_a_run_or_a_coopdyn_error.hypothesis.inner_test(tmp_path, text)
