"""What users look at: the demo, plots, the HTML animation in a real browser, scene files."""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

import coopdyn as cd
from coopdyn.__main__ import main
from coopdyn.io.scenefile import SceneFileError, load, load_result
from coopdyn.viz.viewer import export_html

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def test_demo_writes_everything(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--out", str(tmp_path), "--t-final", "0.3"]) == 0
    out = capsys.readouterr().out
    for text in ("object tracking error: max", "internal force: peak", "real-time factor", "output folder:"):
        assert text in out
    for name in ("trajectory.npz", "trajectory.csv", "demo.png", "demo.html"):
        assert (tmp_path / name).stat().st_size > 1000
    with np.load(tmp_path / "trajectory.npz") as z:
        assert z["q"].shape == (31, 21) and z["wrenches"].shape == (31, 12)
    header = (tmp_path / "trajectory.csv").read_text().splitlines()[0]
    assert header.startswith("t [s],q left/panda_joint1 [rad],") and "v object.wz [rad/s; body axes]" in header
    assert "tau left/panda_joint1 [N·m]" in header and header.endswith("wrench right.mz [N·m; world axes; about the grasp]")


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def _headless(page: Path, profile: Path, *, budget_ms: int, screenshot: Path | None = None) -> str:
    """Open ``page`` in headless Chromium (software WebGL) for ``budget_ms`` of virtual time:
    write an 800 × 600 ``screenshot``, or return the page's DOM then."""
    output = [f"--screenshot={screenshot}"] if screenshot is not None else ["--dump-dom"]
    return subprocess.run(
        [
            str(_chromium()), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            f"--user-data-dir={profile}", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
            "--window-size=800,600", f"--virtual-time-budget={budget_ms}", *output, page.resolve().as_uri(),
        ],
        check=True, timeout=120, capture_output=True, text=True,
    ).stdout  # fmt: skip


@pytest.mark.skipif(_chromium() is None, reason="needs Chromium (Debian package 'chromium'; .ci/run installs it)")
def test_html_animation_shows_the_robots_in_a_browser(tmp_path: Path, pandas: cd.Scene) -> None:
    """Headless Chromium renders the exported file: the arms (light grey), the box (orange) and
    the interconnection force arrows (red) are on the screenshot, not a blank page."""
    ctrl = cd.control.GravityCompensationPD(pandas, 200.0, 20.0)  # the box hangs on the springs: ~10 N each
    run = cd.simulate(pandas, 0.3, controller=ctrl, integrator="implicit_euler", dt=1e-3, save_every=20)
    # keep the samples where the springs carry the box, so that every animation frame has arrows
    loaded = run.t >= 0.1
    res = dataclasses.replace(run, t=run.t[loaded] - run.t[loaded][0], q=run.q[loaded], v=run.v[loaded], tau=run.tau[loaded])
    assert np.all(np.linalg.norm(res.wrenches()[:, :, :3], axis=2) > 5.0)
    html = export_html(res, tmp_path / "anim.html")
    shot = tmp_path / "shot.png"
    _headless(html, tmp_path / "profile", budget_ms=8000, screenshot=shot)
    img = matplotlib.image.imread(shot)[..., :3]
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    orange = (r > 0.6) & (g > 0.3) & (g < 0.7) & (b < 0.35)
    grey = (np.abs(r - g) < 0.05) & (np.abs(g - b) < 0.05) & (r > 0.6)
    assert orange.sum() > 200, "the box is not on the screenshot"
    assert grey.sum() > 2000, "the arms are not on the screenshot"
    # red hue, antialiased edges included (orange has g well above b): the arrows are drawn over
    # the hands and the box (318 pixels here; 38–43 when the hands hid most of them)
    red = (r > 0.5) & (g < 0.45 * r) & (b < 0.45 * r) & (np.abs(g - b) < 0.12)
    assert red.sum() > 150, f"the force arrows are not on the screenshot ({red.sum()} red pixels)"
    # the page's clock: seeking to 0.1 s shows that time, and the button toggles play / pause
    probe = tmp_path / "probe.html"
    probe.write_text(
        html.read_text().replace(
            "</body>",
            "<script>setTimeout(() => { const s = document.getElementById('seek'); s.value = 0.1; s.oninput(); "
            "document.body.dataset.after = viewer.animator.playing + ' ' + viewer.animator.time; "
            "setTimeout(() => { document.body.dataset.shown = document.getElementById('time').textContent; "
            "document.getElementById('play').onclick(); document.body.dataset.toggled = String(viewer.animator.playing); "
            "}, 200); }, 1500);</script></body>",
        )
    )
    dom = _headless(probe, tmp_path / "profile2", budget_ms=4000)
    assert 'data-after="false 0.1"' in dom and 'data-toggled="true"' in dom, "seeking pauses at 0.1 s, the button plays"
    assert 'data-shown="t = 0.100 s"' in dom and f"/ {res.t[-1]:g} s" in dom, "the clock shows the simulated time"


@pytest.mark.skipif(_chromium() is None, reason="needs Chromium (Debian package 'chromium'; .ci/run installs it)")
def test_the_live_viewer_is_framed_with_its_legend(tmp_path: Path, pandas: cd.Scene) -> None:
    """What the live viewer is sent (recorded, rendered headless): the box in the middle of the
    window, not off to one side where meshcat's camera looks by default, and the arrows' legend
    on a white card above the scene."""
    from coopdyn.viz import viewer

    ctrl = cd.control.GravityCompensationPD(pandas, 200.0, 20.0)
    res = cd.simulate(pandas, 0.2, controller=ctrl, integrator="implicit_euler", dt=1e-3, save_every=20)
    window = viewer.RecordingWindow()
    vis = viewer._meshcat().Visualizer(window=window)
    scale, peak = viewer.force_scale(res)
    animator = viewer._Animator(pandas, vis, "collision", scale=scale)
    wrenches = res.wrenches()
    for name, T, s in animator.poses(res.q[-1], wrenches[-1]):
        vis[name].set_transform(viewer._scaled(T, s))
    viewer.frame_live(vis, *animator.box(res.q, wrenches), viewer._legend(scale, peak))
    page = tmp_path / "live.html"
    page.write_text(window.get_scene())
    shot = tmp_path / "live.png"
    _headless(page, tmp_path / "profile", budget_ms=6000, screenshot=shot)
    img = matplotlib.image.imread(shot)[..., :3]
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    rows, cols = np.nonzero((r > 0.6) & (g > 0.3) & (g < 0.7) & (b < 0.35))  # the orange box
    assert len(cols) > 200 and abs(cols.mean() - 400) < 80, f"the box is not in the middle (x = {cols.mean():.0f} of 800)"
    # (the arms reach below it: 218 of 600 here; 106, at the top edge, with meshcat's default camera)
    assert 160 < rows.mean() < 400, f"the box is not in the window's middle height (y = {rows.mean():.0f} of 600)"
    white_rows = np.nonzero(((r > 0.97) & (g > 0.97) & (b > 0.97)).sum(axis=1) > 200)[0]  # the legend card
    assert len(white_rows) > 5 and white_rows.mean() < rows.mean(), "no legend card above the scene"


@pytest.mark.parametrize("name", ["two_pandas.toml", "linear_book.toml"])
def test_example_scene_files_load(name: str) -> None:
    run = load(EXAMPLES / name)
    assert run.duration > 0 and run.scene.nv > 0


def test_simulate_a_scene_file_and_view_its_result(tmp_path: Path) -> None:
    scene_file = tmp_path / "book.toml"
    scene_file.write_text((EXAMPLES / "linear_book.toml").read_text().replace("duration = 3.0", "duration = 0.2"))
    assert main(["simulate", str(scene_file), "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "plot.png").is_file() and (tmp_path / "out" / "scene.toml").is_file()
    run = load(scene_file)
    result = load_result(run, tmp_path / "out" / "trajectory.npz")
    assert result.q.shape[1] == run.scene.nq
    assert (
        main(["view", str(scene_file), "--result", str(tmp_path / "out" / "trajectory.npz"), "--html", str(tmp_path / "v.html")])
        == 0
    )


GOOD = """
[scene]
builder = "linear_book"
m = 25.0

[simulation]
duration = 0.1
dt = 1e-3
"""


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (GOOD.replace("m = 25.0", "mass = 25.0"), r"bad.toml, line 4: \[scene\] mass: unknown key; valid keys: \['Y10'"),
        (GOOD.replace("m = 25.0", 'm = "heavy"'), r"line 4: \[scene\] m: must be a finite number, got 'heavy'"),
        (GOOD.replace("duration = 0.1\n", ""), r"\[simulation\]: missing required key 'duration' \[s\]"),
        (
            GOOD.replace("dt = 1e-3", "dt = 1e-3\nstep = 2"),
            r"line 9: \[simulation\] step: unknown key; valid keys: \['accuracy', 'control_dt', 'dt', 'duration'",
        ),
        (GOOD + "\n[physics]\ng = 9.81\n", r"line 10: \[physics\]: unknown table; valid tables: \['scene', 'arms', 'object'"),
        (
            GOOD.replace('builder = "linear_book"', 'builder = "book"'),
            r"\[scene\] builder: must be one of \['facing_arms', 'linear_book'\]",
        ),
        (GOOD + '\n[controller]\ntype = "pid"\n', r"\[controller\] type: must be one of \['book_drives', 'computed_torque'"),
        (
            GOOD.replace("dt = 1e-3", 'dt = 1e-3\nintegrator = "rk45"'),
            r"\[simulation\] integrator: unknown integrator 'rk45'; valid: \[",
        ),
        (GOOD.replace("m = 25.0", "m = -1.0"), r"\[scene\]: linear book parameter m must be > 0 \[kg\], got -1.0"),
        (
            GOOD.replace("[simulation]", "[simulaton]"),
            r"line 6: \[simulaton\]: unknown table; valid tables: .* Did you mean 'simulation'\?$",
        ),
        (
            GOOD + '\n[[arm]]\nname = "left"\n',
            r"line 10: \[\[arm\]\] #1: unknown array of tables; valid: .* Did you mean '\[\[arms\]\]'\?$",
        ),
        (GOOD.replace("duration = 0.1", "duration = -1"), r"line 7: \[simulation\] duration: must be >= 0 \[s\], got -1"),
        (GOOD.replace("dt = 1e-3", "dt = 1e-3\nsave_every = 0"), r"line 9: \[simulation\] save_every: must be >= 1 .*, got 0"),
        ("[scene\nbuilder =", r"bad.toml: not valid TOML"),
        (GOOD.replace("[scene]", "[scene]\n[simulation]"), r"bad.toml: not valid TOML"),
    ],
)
def test_scene_file_errors_name_the_file_key_and_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SceneFileError, match=message):
        load(path)


def test_missing_scene_file(tmp_path: Path) -> None:
    with pytest.raises(SceneFileError, match=r"scene file not found: .*nope.toml"):
        load(tmp_path / "nope.toml")


@pytest.mark.parametrize("fps", [0.0, -5.0, float("nan"), "30"])
def test_a_bad_frame_rate_is_refused_before_any_viewer_starts(tmp_path: Path, book: cd.Scene, fps: object) -> None:
    from coopdyn.viz.viewer import view

    res = cd.simulate(book, 0.05, integrator="rk4", dt=1e-3)
    for show in (lambda: view(res, fps=fps, loops=1), lambda: export_html(res, tmp_path / "a.html", fps=fps)):  # type: ignore[arg-type]
        with pytest.raises(cd.ViewerError, match="fps"):
            show()


def test_a_result_as_a_dataframe_names_its_units_and_frames(tmp_path: Path) -> None:
    """Result.to_dataframe: the object pose in the world (position, rpy and quaternion giving the
    same rotation), its velocity in world axes (R times Pinocchio's body-axes v), the squeeze,
    and every CSV column under the CSV's own name, with the same numbers; every name carries its
    unit, and the frame where one applies."""
    import pandas as pd
    import pinocchio as pin

    from coopdyn.control import GravityCompensationPD

    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.3
    res = cd.simulate(scene, 0.05, controller=GravityCompensationPD(scene), v0=v0, save_every=5, accuracy_check="off")
    df = res.to_dataframe()
    assert len(df) == len(res.t) and all("[" in c for c in df.columns)
    assert np.allclose(df[[f"object.{c} [m; world]" for c in "xyz"]].to_numpy(), res.object_position(), atol=1e-12)
    k = len(res.t) - 1
    joint = scene.model.joints[scene.model.frames[scene.object_frame].parentJoint]
    quat = df.loc[k, [f"object.{c} [1; world]" for c in ("qx", "qy", "qz", "qw")]].to_numpy(dtype=float)
    R = pin.Quaternion(quat[3], *quat[:3]).matrix()
    rpy = df.loc[k, [f"object.{c} [rad; world]" for c in ("roll", "pitch", "yaw")]].to_numpy(dtype=float)
    assert np.allclose(pin.rpy.rpyToMatrix(*rpy), R, atol=1e-12)
    v_body = res.v[k, joint.idx_v : joint.idx_v + 6]
    v_world = df.loc[k, [f"object.{c} [m/s; world axes]" for c in ("vx", "vy", "vz")]].to_numpy(dtype=float)
    w_world = df.loc[k, [f"object.{c} [rad/s; world axes]" for c in ("wx", "wy", "wz")]].to_numpy(dtype=float)
    assert np.allclose(v_world, R @ v_body[:3], atol=1e-12) and np.allclose(w_world, R @ v_body[3:], atol=1e-12)
    assert np.allclose(df["left.squeeze [N; + = compression]"], res.squeeze()[:, 0])
    # the wrench split: moving + internal = the wrench; the internal parts put no net wrench on the object
    from coopdyn.grasp import grasp_matrix

    parts = {
        part: np.array([[df.loc[k, f"{lk.name}.{part}.{c} [{unit}]"] for c, unit in zip(("fx", "fy", "fz", "mx", "my", "mz"),
                        ["N; world axes"] * 3 + ["N·m; world axes; about the grasp"] * 3, strict=True)] for lk in scene.links])
        for part in ("moving", "internal")
    }  # fmt: skip
    assert np.allclose(parts["moving"] + parts["internal"], res.wrenches()[k], atol=1e-9)
    assert np.abs(grasp_matrix(res.grasp_points()[k]) @ parts["internal"].reshape(-1)).max() < 1e-9
    assert np.abs(parts["internal"]).max() > 1e-3  # (a squeeze to split off)
    csv = pd.read_csv(res.save(tmp_path / "run.csv"))
    shared = [c for c in csv.columns if c in df.columns]
    assert len(shared) == len(csv.columns)  # (every CSV column is in the frame, under its name)
    assert np.allclose(csv[shared].to_numpy(), df[shared].to_numpy(), rtol=0, atol=0)
    assert "v object.vx [m/s; body axes]" in csv.columns and "wrench left.fz [N; world axes]" in csv.columns
