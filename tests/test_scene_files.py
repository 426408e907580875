"""Results that reload, scenes as data, scene files for any scene, and the command line around them."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import jsonschema
import numpy as np
import pinocchio as pin
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import coopdyn as cd
from coopdyn import _progress
from coopdyn.__main__ import main
from coopdyn.control import GravityCompensationPD
from coopdyn.errors import DivergenceError, EnergyBalanceWarning, SceneError, SceneFileError, SimulationError
from coopdyn.io.scenefile import load
from coopdyn.io.schema import scene_file_schema, schema_text
from coopdyn.model.description import DescriptionError, build, describe

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples" / "scenes"


def _same_model(a: cd.Scene, b: cd.Scene) -> None:
    assert a.model.names.tolist() == b.model.names.tolist() and [f.name for f in a.model.frames] == [
        f.name for f in b.model.frames
    ]
    for i in range(a.model.njoints):
        assert np.array_equal(a.model.jointPlacements[i].homogeneous, b.model.jointPlacements[i].homogeneous)
        assert np.array_equal(a.model.inertias[i].toDynamicParameters(), b.model.inertias[i].toDynamicParameters())
    assert np.array_equal(a.q0, b.q0) and np.array_equal(a.gravity, b.gravity)
    assert [lk.name for lk in a.elements] == [lk.name for lk in b.elements]
    for x, y in zip(a.elements, b.elements, strict=True):
        assert type(x.element) is type(y.element) and (x.tip_frame, x.grasp_frame, x.arm) == (y.tip_frame, y.grasp_frame, y.arm)
        for attr in ("K", "D"):
            assert np.array_equal(getattr(x.element, attr, 0), getattr(y.element, attr, 0))
    for field in ("link_v", "motor_v", "stiffness", "damping"):
        assert np.array_equal(getattr(a.joint_springs, field), getattr(b.joint_springs, field))
    assert [arm.motor_damping.tolist() for arm in a.arms] == [arm.motor_damping.tolist() for arm in b.arms]


SCENES = {
    "pandas": lambda: cd.scenes.facing_arms("panda", stiffness=[1e4, 2e4, 3e4], damping=0.002),
    "book": cd.scenes.linear_book,
    "beam": lambda: cd.scenes.held_beam(n_elements=4),
    "rigid": lambda: cd.rigid_limit(cd.scenes.facing_arms("ur5")),
    "elastic_joints": lambda: _with_elastic_joints(cd.scenes.facing_arms("panda")),
}


def _with_elastic_joints(scene: cd.Scene) -> cd.Scene:
    """The scene with the first arm's joints 2 and 4 elastic, the second arm's all."""
    first = cd.JointElasticity([4000.0, 2500.0], 1e-4, damping=2.0, gear_ratio=60.0, joints=["panda_joint2", "panda_joint4"])
    arms = [scene.arm_specs[0].replace(elasticity=first), scene.arm_specs[1].replace(elasticity=cd.JointElasticity(5e3, 0.3))]
    return cd.Scene(arms, scene.object, scene.interconnection_specs)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_a_description_rebuilds_the_same_scene_and_fits_the_schema(name: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # rigid_limit: a preload is dropped
        scene = SCENES[name]()
    doc = json.loads(json.dumps(describe(scene)))  # plain data: survives JSON (and TOML) exactly
    _same_model(scene, build(doc))
    gravity = doc.pop("gravity")
    jsonschema.validate({**doc, "scene": {"gravity": gravity}, "simulation": {"duration": 1.0}}, scene_file_schema())


def test_poses_as_rpy_quaternion_rotation_and_matrix_agree() -> None:
    M = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([0.1, 0.2, 0.3]))
    q = pin.Quaternion(M.rotation).coeffs().tolist()  # x, y, z, w
    forms = [
        {"translation": M.translation.tolist(), "rpy": [0.1, -0.2, 0.3]},
        {"translation": M.translation.tolist(), "quaternion": q},
        {"translation": M.translation.tolist(), "rotation": M.rotation.tolist()},
        M.homogeneous.tolist(),
    ]
    doc = describe(cd.scenes.linear_book())
    for form in forms:
        doc["interconnections"][0]["grasp"] = form
        scene = build(doc)
        G = scene.model.frames[scene.links[0].grasp_frame].placement
        assert np.allclose(G.homogeneous, M.homogeneous, atol=1e-12)


def test_description_errors_say_where() -> None:
    doc = describe(cd.scenes.linear_book())
    cases = [
        (lambda d: d["arms"][1].update(robot="../nowhere.urdf"), r"arms\[1\]: URDF file not found"),
        (
            lambda d: d["interconnections"][0].update(stifness=1.0),
            r"interconnections\[0\].stifness: unknown key.*Did you mean 'stiffness'",
        ),
        (lambda d: d["interconnections"][1].update(arm="tip3"), r"interconnections\[1\].arm: no arm named 'tip3'"),
        (lambda d: d["object"].update(type="sphere"), r"object.type: type must be one of \['beam', 'box', 'rigid'\]"),
        (
            lambda d: d["arms"][0].update(base={"translation": [0, 0, 0], "rpy": [0, 0, 0], "rotation": np.eye(3).tolist()}),
            r"arms\[0\].base: .*give one of",
        ),
        (lambda d: d["interconnections"][0].update(stiffness=[[1.0, 2.0], [3.0, 4.0]]), r"interconnections\[0\]: .*stiffness"),
        (lambda d: d.update(gravity=[0, 0]), r"gravity: must be 3 numbers"),
        (lambda d: d.update(gravity=[0, 0, float("nan")]), r"^gravity: must be finite, got \[0.0, 0.0, nan\]$"),
        (lambda d: d["arms"][1].update(name="tip1"), r"arms\[1\].name: arm names must be unique; arms\[0\] is named 'tip1' too"),
        (lambda d: d["object"].update(pose=[0, 0, 0, 1]), r"object.pose: must be a translation \[x, y, z\], a 4x4 matrix"),
    ]
    for change, message in cases:
        bad = json.loads(json.dumps(doc))
        change(bad)
        with pytest.raises(DescriptionError, match=message):
            build(bad, base=ROOT)


def test_a_result_saves_and_loads_whole(tmp_path: Path, pandas: cd.Scene) -> None:
    res = cd.simulate(
        pandas, 0.05, controller=GravityCompensationPD(pandas), integrator="rk4", dt=1e-3, save_every=5, progress=False
    )
    back = cd.Result.load(res.save(tmp_path / "r.npz"))
    for key in (
        "integrator",
        "dt",
        "n_rhs",
        "cpu_time",
        "n_jac",
        "n_factor",
        "n_steps",
        "n_rejected",
        "status",
        "backend",
        "loop",
    ):
        assert getattr(back, key) == getattr(res, key), key
    for key in ("t", "q", "v", "tau"):
        assert np.array_equal(getattr(back, key), getattr(res, key))
    _same_model(res.scene, back.scene)
    assert np.array_equal(back.wrenches(), res.wrenches()) and np.array_equal(back.energy().total, res.energy().total)
    assert repr(back) == repr(res) and "\n" not in repr(res) and len(repr(res)) < 200


def test_the_csv_names_its_columns_with_units(tmp_path: Path, book: cd.Scene) -> None:
    res = cd.simulate(book, 0.01, integrator="exponential", dt=1e-3, progress=False)
    header = res.save(tmp_path / "r.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    assert header[:4] == ["t [s]", "q tip1/slide [m]", "q tip2/slide [m]", "q object [m]"]
    assert (
        "v object [m/s]" in header
        and "tau tip2/slide [N]" in header
        and header[-1] == "wrench tip2.mz [N·m; world axes; about the grasp]"
    )
    table = np.loadtxt(tmp_path / "r.csv", delimiter=",", skiprows=1)
    assert table.shape == (len(res.t), len(header))
    assert np.array_equal(table[:, header.index("wrench tip1.fz [N; world axes]")], res.wrench(0)[:, 2])


def test_the_csv_reads_back_to_the_same_doubles(tmp_path: Path) -> None:
    """Every value is written as a decimal that parses to the same double: extremes, subnormals,
    signed zeros and the values next to round numbers."""
    from coopdyn.result import _write_csv

    rng = np.random.default_rng(3)
    special = [0.0, -0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, 0.1, 1 / 3, np.nextafter(1.0, 2.0)]
    data = np.column_stack([rng.standard_normal(64) * 10.0 ** rng.integers(-300, 300, 64), np.resize(special, 64)])
    _write_csv(tmp_path / "x.csv", ["a [m]", "b [N]"], list(data.T))
    back = np.loadtxt(tmp_path / "x.csv", delimiter=",", skiprows=1)
    assert np.array_equal(back, data) and np.array_equal(np.signbit(back), np.signbit(data))


def test_loading_what_is_not_a_result_says_so(tmp_path: Path, book: cd.Scene) -> None:
    res = cd.simulate(book, 0.01, integrator="exponential", dt=1e-3, progress=False)
    with pytest.raises(SimulationError, match=r"a \.csv is a table only"):
        cd.Result.load(res.save(tmp_path / "r.csv"))
    with pytest.raises(SimulationError, match="no saved result at"):
        cd.Result.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "old.npz", t=res.t, q=res.q)
    with pytest.raises(SimulationError, match="has no description of its scene"):
        cd.Result.load(tmp_path / "old.npz")
    np.savez(tmp_path / "bad.npz", t=res.t, q=res.q, v=res.v, tau=res.tau, meta=np.array("{not json"))
    with pytest.raises(SimulationError, match="not a result coopdyn wrote, or damaged"):
        cd.Result.load(tmp_path / "bad.npz")
    arrays = {"t": res.t, "q": res.q, "v": res.v, "tau": res.tau}
    res.save(tmp_path / "r.npz")
    meta = json.loads(str(np.load(tmp_path / "r.npz")["meta"]))
    for change, message in (
        ({"q": None}, r"no q in the file"),
        ({"q": res.q.astype(int)}, r"q is int64 of shape \(11, 3\); its scene and the 11 samples need floats of shape \(11, 3\)"),
        ({"meta": {**meta, "dt": "x"}}, r"dt = 'x' is not of type float"),
        ({"meta": {**meta, "n_rhs": float("nan")}}, r"n_rhs = nan is not of type int"),
        (
            {"meta": {**meta, "format": "coopdyn.result/2", "coopdyn": "9.0"}},
            r"is in format 'coopdyn.result/2', written by coopdyn 9.0; this coopdyn \(.+\) reads 'coopdyn.result/1'",
        ),
        (  # the format's tag, but not its contents: the versions that wrote and read it
            {"meta": {k: v for k, v in meta.items() if k != "scene"} | {"coopdyn": "0.0.9"}},
            r"not a result coopdyn wrote, or damaged \(written by coopdyn 0\.0\.9, read by coopdyn .+; KeyError: 'scene'\)",
        ),
    ):
        bad = {**arrays, "meta": np.array(json.dumps(change.pop("meta", meta)))} | change
        np.savez(tmp_path / "damaged.npz", **{k: v for k, v in bad.items() if v is not None})
        with pytest.raises(SimulationError, match=message):
            cd.Result.load(tmp_path / "damaged.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(SimulationError, match="is not a result coopdyn wrote"):
        cd.Result.load(tmp_path / "text.npz")


def test_the_shipped_schema_is_the_code_s_and_every_example_fits_it() -> None:
    assert (ROOT / "docs" / "scene-file.schema.json").read_text(encoding="utf-8") == schema_text(), (
        "docs/scene-file.schema.json is stale: regenerate it with "
        "python -c \"from coopdyn.io.schema import schema_text; open('docs/scene-file.schema.json', 'w').write(schema_text())\""
    )
    validator = jsonschema.Draft202012Validator(scene_file_schema())
    validator.check_schema(scene_file_schema())
    files = sorted(EXAMPLES.glob("*.toml"))
    assert len(files) >= 4
    for path in files:
        errors = [e.message for e in validator.iter_errors(tomllib.loads(path.read_text(encoding="utf-8")))]
        assert not errors, (path.name, errors)
    wrong = tomllib.loads((EXAMPLES / "two_ur5s.toml").read_text(encoding="utf-8"))
    wrong["interconnections"][0]["stiffnes"] = wrong["interconnections"][0].pop("stiffness")
    assert not validator.is_valid(wrong)


def test_the_loader_and_the_schema_accept_the_same_lists_and_strings(tmp_path: Path) -> None:
    """facing_arms takes a stiffness per tool axis (a list) and joint_damping = "urdf" (a string):
    the loader builds the scene and the schema validates the file — they read what a parameter
    takes from one place."""
    text = (EXAMPLES / "two_pandas.toml").read_text(encoding="utf-8")
    doc = tomllib.loads(text)
    doc["scene"].update({"stiffness": [1e4, 1e4, 2e4], "joint_damping": "urdf"})
    assert jsonschema.Draft202012Validator(scene_file_schema()).is_valid(doc)
    path = tmp_path / "lists.toml"
    first = text.index("\nstiffness = ")  # the [scene] table's
    path.write_text(
        text[:first] + '\nstiffness = [1e4, 1e4, 2e4]\njoint_damping = "urdf"\n#' + text[first + 1 :], encoding="utf-8"
    )
    scene = load(path).scene
    assert np.allclose(np.diag(scene.links[0].element.K)[:3], [1e4, 1e4, 2e4])
    doc["scene"]["joint_damping"] = [1, 2]  # a list where only a number or a string goes
    assert not jsonschema.Draft202012Validator(scene_file_schema()).is_valid(doc)


def test_scene_files_describe_arms_objects_and_interconnections() -> None:
    ur5 = load(EXAMPLES / "two_ur5s.toml").scene
    assert [a.name for a in ur5.arms] == ["left", "right"] and ur5.nq == 2 * 6 + 7
    assert np.array_equal(np.diag(ur5.links[0].element.K), [1e4, 2e4, 3e4, 100.0, 100.0, 100.0])
    assert ur5.model.frames[ur5.arms[0].tip_frame].name == "left/tool0"
    base = ur5.loaded_arms[0].base
    assert np.allclose(base.rotation, pin.utils.rotate("z", np.pi / 2)) and np.allclose(base.translation, [0, -0.5, 0])
    fixed = load(EXAMPLES / "slider_and_fixture.toml").scene
    assert [lk.arm for lk in fixed.links] == [0, None] and type(fixed.links[0].element).kind == "ball"
    assert fixed.arm_specs[0].robot == str((ROOT / "urdf" / "slider_z.urdf").resolve())
    assert fixed.object.joint == "prismatic" and fixed.model.inertias[1].mass == 2.0


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (('robot = "ur5"', 'robot = "ur55"', 2), r"line 16: \[\[arms\]\] #2: unknown robot 'ur55'.*Did you mean 'ur5'"),
        (("stiffness = [1e4, 2e4", "stifness = [1e4, 2e4", 2), r"line 37: \[\[interconnections\]\] #2 stifness: unknown key"),
        (('type = "box"', 'type = "ball"', 1), r"line 25: \[object\] type: type must be one of"),
        (
            ("rpy = [0.0, 0.0, 1.5707963267948966]", "rpy = [0.0, 1.5707963267948966]", 1),
            r"line 12: \[\[arms\]\] #1 base: rpy \[rad\] must have shape \(3,\), got shape \(2,\)",
        ),
        (
            ("[scene]\n", '[scene]\nbuilder = "facing_arms"\n', 1),
            r"\[scene\] builder: a scene is either a builder's shorthand or described",
        ),
        (
            ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -9.81]\nrobot = 1", 1),
            r"\[scene\] robot: unknown key; without a builder",
        ),
    ],
)
def test_scene_file_errors_point_at_the_entry_and_line(tmp_path: Path, change: tuple[str, str, int], message: str) -> None:
    old, new, nth = change
    text = (EXAMPLES / "two_ur5s.toml").read_text(encoding="utf-8")
    at = -1
    for _ in range(nth):
        at = text.index(old, at + 1)
    path = tmp_path / "bad.toml"
    path.write_text(text[:at] + new + text[at + len(old) :], encoding="utf-8")
    with pytest.raises(SceneFileError, match=message):
        load(path)


def test_simulate_then_view_and_plot_what_it_wrote(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene_file = tmp_path / "slider.toml"
    text = (EXAMPLES / "slider_and_fixture.toml").read_text(encoding="utf-8")
    scene_file.write_text(text.replace("../../urdf/", f"{ROOT / 'urdf'}/").replace("duration = 1.0", "duration = 0.1"))
    out = tmp_path / "out"
    assert main(["simulate", str(scene_file), "--out", str(out)]) == 0
    assert "real-time factor" in capsys.readouterr().out
    assert tomllib.loads((out / "scene.toml").read_text())["output"]["folder"] == "."
    for target in (out / "scene.toml", out, out / "trajectory.npz"):  # the copy finds its results; so do the folder and file
        assert main(["view", str(target), "--html", str(tmp_path / "v.html"), "--fps", "10"]) == 0
        assert "MB)" in capsys.readouterr().out
    assert main(["plot", str(out), "--out", str(tmp_path / "p.png")]) == 0 and (tmp_path / "p.png").stat().st_size > 10_000
    assert main(["view", str(tmp_path)]) == 2
    assert f"{tmp_path} holds no trajectory.npz: run `coopdyn simulate` or `coopdyn demo` first" in capsys.readouterr().err
    reader_gone = subprocess.Popen(  # `coopdyn plot … | head -c0`: the pipe is closed before coopdyn writes
        [sys.executable, "-m", "coopdyn", "plot", str(out), "--out", str(tmp_path / "p2.png")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert reader_gone.stdout is not None
    reader_gone.stdout.close()
    _, err = reader_gone.communicate(timeout=120)
    assert reader_gone.returncode == 0 and b"Traceback" not in err and (tmp_path / "p2.png").is_file()


def test_the_command_line_describes_itself(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"coopdyn {cd.__version__}"
    for command in ("demo", "simulate", "view", "plot", "book", "bench"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        _, _, rest = capsys.readouterr().out.partition("\n\n")
        assert rest.split("\n\n")[0].strip() and not rest.startswith("positional") and not rest.startswith("options"), command
    with pytest.raises(SystemExit):
        main(["demo", "--integrator", "rk45"])
    assert "invalid choice: 'rk45' (choose from 'dop853', 'dopri5', 'exponential'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    assert "one of dop853, dopri5, exponential, generalized_alpha, implicit_euler," in " ".join(capsys.readouterr().out.split())


def test_a_divergence_names_the_mode_that_limits_the_step(pandas: cd.Scene) -> None:
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance

    task = GripLiftOscillate(start=cd.scenes.object_start(pandas))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EnergyBalanceWarning)
        with pytest.raises(DivergenceError) as caught:
            cd.simulate(pandas, 0.5, controller=ObjectImpedance(pandas, task), integrator="rk4", dt=5e-3, progress=False)
    text = str(caught.value)
    advice = caught.value.advice
    lam = advice.limiting_mode("rk4")
    limit = advice.max_stable_dt("rk4")
    assert f"|λ| = {abs(lam):.4g} 1/s" in text and f"dt ≤ {limit * 1e3:.4g} ms" in text and limit < 5e-3
    assert "max_speed = 10000 rad/s or m/s" in text and "stable at dt = 5 ms: implicit_euler, ros2" in text
    t_end = caught.value.result.t[-1]
    assert text == f"{caught.value.detail}. The trajectory up to t = {t_end:.6g} s is in this error's .result"
    with np.errstate(all="ignore"):  # the limiting mode is where rk4's |R(hλ)| first passes 1
        from coopdyn.integrators import get_integrator

        R = np.abs(get_integrator("rk4").stability_function(np.array([0.99, 1.01]) * limit * lam))
    assert R[0] <= 1.0 + 1e-6 < R[1]


def test_warnings_print_around_the_progress_bar_and_point_at_the_caller() -> None:
    calls: list[str] = []

    class Bar:
        def clear(self) -> None:
            calls.append("clear")

        def refresh(self) -> None:
            calls.append("refresh")

    with _progress.showing(Bar()), pytest.warns(UserWarning) as record:
        _progress.warn("hello", UserWarning)
    assert calls == ["clear", "refresh"] and record[0].filename == __file__
    scene = cd.scenes.facing_arms("panda")
    with pytest.warns(EnergyBalanceWarning) as record, pytest.raises(DivergenceError):  # through the bar, both loops
        cd.simulate(scene, 0.3, controller=GravityCompensationPD(scene, kp=4e4, kd=0.0), integrator="rk4", dt=4e-3, progress=True)
    assert {r.filename for r in record if r.category is EnergyBalanceWarning} == {__file__}


def test_facing_arms_takes_a_stiffness_per_axis() -> None:
    scene = cd.scenes.facing_arms("ur5", stiffness=[1e4, 2e4, 3e4], rotational_ratio=0.01)
    assert np.array_equal(np.diag(scene.links[1].element.K), [1e4, 2e4, 3e4, 100.0, 200.0, 300.0])
    with pytest.raises(SceneError, match=r"one positive value or three \(x, y, z of the tool frame\)"):
        cd.scenes.facing_arms("ur5", stiffness=[1e4, 2e4])


def test_the_version_is_the_project_s() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert cd.__version__ == project["version"]


def test_stl_meshes_get_normals_so_they_are_lit() -> None:
    from coopdyn.viz.viewer import _STL, stl_with_normals

    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [0, 0, 1], [1, 0, 0]]], dtype=np.float32)
    records = np.zeros(2, _STL)
    records["v"] = tri  # zero normals, as UR5's collision meshes have
    blank = b"\0" * 80 + (2).to_bytes(4, "little") + records.tobytes()
    fixed = np.frombuffer(stl_with_normals(blank), _STL, count=2, offset=84)
    assert np.array_equal(fixed["n"], [[0, 0, 1], [0, 1, 0]]) and np.array_equal(fixed["v"], tri)
    assert stl_with_normals(stl_with_normals(blank)) == stl_with_normals(blank)  # valid normals: the file as it is


def test_arrows_cameras_and_meshes_of_the_animation(tmp_path: Path, book: cd.Scene) -> None:
    from coopdyn.viz.viewer import ARROW_LENGTH, HEAD_LENGTH, _arrow, camera, force_scale, visual_model

    res = cd.simulate(book, 0.2, integrator="exponential", dt=1e-3, progress=False)
    scale, peak = force_scale(res)
    assert peak == pytest.approx(np.abs(res.wrenches()[..., 2]).max()) and scale * peak == pytest.approx(ARROW_LENGTH)
    parts = _arrow(np.zeros(3), np.array([0.0, 0.0, 0.2]))
    T, _ = parts[""]
    assert np.allclose(T[:3, 1], [0, 0, 1])  # along the force
    (T_shaft, ss), (Th, sh) = parts["/shaft"], parts["/head"]
    assert T_shaft[1, 3] == pytest.approx((0.2 - HEAD_LENGTH) / 2)
    assert (
        ss[1] + HEAD_LENGTH == pytest.approx(0.2)
        and np.array_equal(sh, np.ones(3))
        and Th[1, 3] == pytest.approx(0.2 - HEAD_LENGTH / 2)
    )
    lo, hi = np.array([-0.5, -0.3, 0.0]), np.array([0.5, 0.3, 0.9])
    eye, target = camera(lo, hi)
    forward = (target - eye) / np.linalg.norm(target - eye)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    angles = np.degrees(np.arccos(((corners - eye) @ forward) / np.linalg.norm(corners - eye, axis=1)))
    assert angles.max() < 75.0 / 2 * 4 / 3 and angles.max() > 15.0  # in view, and not a speck
    geom = visual_model(book)  # the book's slider URDF has visual geometry only: it is drawn, not left out
    assert {g.name.split("/")[0] for g in geom.geometryObjects} >= {"tip1", "tip2"}


def test_arms_of_two_robots_are_placed_by_inverse_kinematics_from_a_scene_file(tmp_path: Path) -> None:
    """[[arms]] tool_pose: a UR5 and a Panda start with their tool frames at the given world
    poses (to 1e-8 m and rad) on two faces of a box; an unreachable pose and q0 with tool_pose
    are refused with the arm's line."""
    text = """
[[arms]]
name = "left"
robot = "ur5"
tip_frame = "tool0"
base = { translation = [0.0, -0.5, 0.0], rpy = [0.0, 0.0, 1.5707963267948966] }
tool_pose = { translation = [0.0, -0.1, 0.7], rpy = [-1.5707963267948966, 0.0, 0.0] }

[[arms]]
name = "right"
robot = "panda"
base = { translation = [0.0, 0.6, 0.0], rpy = [0.0, 0.0, -1.5707963267948966] }
tool_pose = { translation = [0.0, 0.1, 0.7], rotation = [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]] }

[object]
type = "box"
mass = 1.0
size = [0.2, 0.2, 0.2]
pose = [0.0, 0.0, 0.7]

[[interconnections]]
arm = "left"
stiffness = [1e4, 1e4, 1e4, 100.0, 100.0, 100.0]

[[interconnections]]
arm = "right"
stiffness = [1e4, 1e4, 1e4, 100.0, 100.0, 100.0]

[simulation]
duration = 0.01
"""
    path = tmp_path / "ik.toml"
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error", cd.SceneWarning)  # placed on the box: no warning
        scene = load(path).scene
    data = scene.model.createData()
    pin.framesForwardKinematics(scene.model, data, scene.q0)
    targets = {
        "left": pin.SE3(pin.rpy.rpyToMatrix(-np.pi / 2, 0.0, 0.0), np.array([0.0, -0.1, 0.7])),
        "right": pin.SE3(np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]), np.array([0.0, 0.1, 0.7])),
    }
    for lk in scene.links:
        assert np.max(np.abs(pin.log6(data.oMf[lk.tip_frame].actInv(targets[lk.name])).vector)) < 1e-8
    # without tool_pose the arms start in their reference postures, away from the box: each grasp,
    # at its arm's tool frame, is named with its distance
    unplaced = "\n".join(line for line in text.splitlines() if not line.startswith("tool_pose"))
    path.write_text(unplaced)
    with pytest.warns(cd.SceneWarning) as warned:
        load(path)
    far = [str(w.message) for w in warned if "grasps the object" in str(w.message)]
    assert len(far) == 2 and all("more than its size (200 mm)" in m and "tool_pose" in m for m in far), far
    assert "'left'" in far[0] and "'right'" in far[1]
    path.write_text(text.replace("translation = [0.0, 0.1, 0.7]", "translation = [0.0, -2.0, 0.7]"))
    said = r"line 13: \[\[arms\]\] #2 tool_pose: inverse kinematics of arm 'right' did not reach"
    with pytest.raises(SceneFileError, match=said):
        load(path)
    path.write_text(text.replace('robot = "panda"', 'robot = "panda"\nq0 = [0.0, 0.0, 0.0, -1.5, 0.0, 1.5, 0.8]'))
    with pytest.raises(SceneFileError, match=r"give q0 or tool_pose .*, not both"):
        load(path)
