"""meshcat visualisation: a self-contained HTML animation of a result (arms with their URDF
meshes, the object, interconnection force arrows) and live viewing in a meshcat server.

The HTML is written without any server: a recording stand-in for meshcat's connection keeps the
scene tree and packs it with meshcat's own viewer script, as ``meshcat-server`` does for
``Visualizer.static_html()``. The file plays offline in a browser.
"""

from __future__ import annotations

import base64
import html
import logging
import os
import re
import time
import warnings
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._files import write_atomically
from .._signals import sigterm_as_interrupt
from .._validate import positive
from ..errors import ViewerError
from ..model.arm import load_arm
from ..model.scene import Scene
from ..result import Result
from .meshcat_server import LOOPBACK, check_host, is_loopback
from .meshcat_server import start as start_server

FORCE_SCALE = 0.01  #: arrow length per newton [m/N]

_log = logging.getLogger(__name__)


def _meshcat() -> Any:
    from .._optional import require

    require("meshcat.geometry", "meshcat visualisation", "meshcat")
    return require("meshcat", "meshcat visualisation", "meshcat")


class RecordingWindow:
    """Stands in for meshcat's server connection: records the scene tree (objects, transforms,
    properties, animation) so that :meth:`get_scene` can write a standalone HTML page."""

    def __init__(self) -> None:
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()

    def send(self, command: Any) -> None:
        import umsgpack
        from meshcat.servers.tree import SceneTree, find_node

        data = command.lower()
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        kind = data["type"]
        if kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                if path[-1] in parent:
                    del parent[path[-1]]
            else:
                self.tree = SceneTree()
            return
        node = find_node(self.tree, path)
        if kind == "set_object":
            node.object, node.properties = packed, []
        elif kind == "set_transform":
            node.transform = packed
        elif kind == "set_property":
            node.properties.append(packed)
        elif kind == "set_animation":
            node.animation = packed

    def get_scene(self, extra_js: str = "", legend: str = "") -> str:
        """The recorded scene as a standalone HTML page: meshcat's viewer script inlined, the
        commands gzip-compressed (the page inflates them; meshes are mostly text) and sent in order
        with the animations last (sent first, an animated scale can stay at its static value);
        ``extra_js`` runs after them, ``legend`` is shown in a corner."""
        import gzip

        from meshcat.servers.tree import walk
        from meshcat.servers.zmqserver import VIEWER_ROOT

        commands: list[bytes] = []
        animations: list[bytes] = []
        for node in walk(self.tree):
            commands.extend(b for b in [node.object, *node.properties, node.transform] if b is not None)
            if node.animation is not None:
                animations.append(node.animation)
        stream = b"".join(len(c).to_bytes(4, "little") + c for c in commands + animations)
        payload = base64.b64encode(gzip.compress(stream, 6)).decode()
        js = Path(VIEWER_ROOT, "main.min.js").read_text()
        return (
            _HTML.replace("{js}", js)
            .replace("{payload}", payload)
            .replace("{extra}", extra_js)
            .replace("{legend}", html.escape(legend))
        )

    def url(self) -> str:
        return "(recording: no server)"


_HTML = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>coopdyn</title>
<style>body { margin: 0; } #meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }
#legend { position: absolute; left: 12px; bottom: 12px; font: 13px sans-serif; color: #222;
  background: rgba(255, 255, 255, 0.8); padding: 4px 8px; border-radius: 4px; pointer-events: none; }
#clock { position: absolute; left: 12px; top: 12px; font: 14px sans-serif; color: #222;
  background: rgba(255, 255, 255, 0.85); padding: 6px 10px; border-radius: 4px; }
#clock button { font: 13px sans-serif; width: 4.5em; } #clock input { width: 22em; vertical-align: middle; }
#time { display: inline-block; width: 7.5em; text-align: right; font-variant-numeric: tabular-nums; }</style></head>
<body>
<div id="meshcat-pane"></div>
<div id="legend">{legend}</div>
<script>{js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(async function () {
  const packed = Uint8Array.from(atob("{payload}"), c => c.charCodeAt(0));
  const inflated = new Blob([packed]).stream().pipeThrough(new DecompressionStream("gzip"));
  const buf = new Uint8Array(await new Response(inflated).arrayBuffer());
  const view = new DataView(buf.buffer);
  for (let o = 0; o < buf.length;) {
    const n = view.getUint32(o, true);
    viewer.handle_command_bytearray(buf.slice(o + 4, o + 4 + n));
    o += 4 + n;
  }
  {extra}
})();
</script>
</body>
</html>
"""


def visual_model(
    scene: Scene, meshes: str = "collision", *, arms: Collection[str] | None = None, with_object: bool = True
) -> pin.GeometryModel:
    """Display geometry of the whole scene on ``scene.model``: every arm's URDF ``meshes``
    ("collision": compact, the default — an arm whose URDF has none shows its visual meshes;
    "visual": the full meshes, several MB of HTML per arm) and a box for the object
    (its own boxes: ``SceneObject.shapes``); only the arms named in ``arms`` when given, and no
    object without ``with_object``."""
    import coal

    geom = pin.GeometryModel()
    model = scene.model
    for spec, info in zip(scene.arm_specs, scene.arms, strict=True):
        if arms is not None and info.name not in arms:
            continue
        la = load_arm(spec, meshes=meshes)
        if la.visual is not None and la.visual.ngeoms == 0 and meshes == "collision":  # a URDF with visual geometry only
            la = load_arm(spec, meshes="visual")
        visual = la.visual
        assert visual is not None
        base = la.base
        for g in visual.geometryObjects:
            joint_name = la.model.names[g.parentJoint]
            frame_name = la.model.frames[g.parentFrame].name
            copy = pin.GeometryObject(g)
            if g.parentJoint == 0:  # fixed to the arm's base
                copy.parentJoint, copy.placement = 0, base * g.placement
            else:
                copy.parentJoint = model.getJointId(joint_name)
            copy.parentFrame = model.getFrameId(frame_name) if model.existFrame(frame_name) else 0
            geom.addGeometryObject(copy)
    for shape in scene.object.shapes(model) if with_object else ():  # the object draws itself (a beam: one box per node)
        box = pin.GeometryObject(shape.name, shape.joint, shape.frame, shape.placement, coal.Box(*shape.size))
        box.meshColor = np.array([0.85, 0.55, 0.2, 1.0])
        geom.addGeometryObject(box)
    return geom


ARROW_LENGTH = 0.25  #: length of a result's largest force arrow [m]; the scale [m/N] follows from it
GHOST_COLOR = (0.2, 0.45, 0.95, 0.35)  #: the motors' ghost arms (elastic joints): translucent blue
GHOST_DEFLECTION = 0.15  #: [rad] a run's largest joint deflection θ − q as the ghost arms draw it
HEAD_LENGTH, HEAD_RADIUS, SHAFT_RADIUS = 0.03, 0.013, 0.005  #: an arrow's head and shaft [m]

_STL = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def stl_with_normals(data: bytes) -> bytes:
    """A binary STL of the file's triangles whose facet normals are valid: the file itself when
    they are; else the normals computed (right-hand rule). Some exporters write zero normals
    (UR5's collision meshes), which the browser takes as they are: the mesh renders black."""
    n = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if len(data) == 84 + 50 * n:
        records = np.frombuffer(data, _STL, count=n, offset=84)
        if np.all(np.abs(np.linalg.norm(records["n"], axis=1) - 1.0) < 1e-2):
            return data
        triangles = records["v"].astype(np.float64)
    else:  # ASCII
        found = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
        triangles = np.array(found, dtype=np.float64).reshape(-1, 3, 3)
    out = np.zeros(len(triangles), _STL)
    out["v"] = triangles
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    norm = np.linalg.norm(cross, axis=1, keepdims=True)
    out["n"] = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
    return b"coopdyn: normals computed".ljust(80, b"\0") + len(triangles).to_bytes(4, "little") + out.tobytes()


def _visualizer_class() -> Any:
    """Pinocchio's meshcat visualizer, with STL meshes sent with valid normals."""
    import meshcat.geometry as mg
    import umsgpack
    from pinocchio.visualize import MeshcatVisualizer

    class Visualizer(MeshcatVisualizer):
        def loadMeshFromFile(self, geometry_object: Any) -> Any:
            if Path(geometry_object.meshPath).suffix.lower() == ".stl":
                data = stl_with_normals(Path(geometry_object.meshPath).read_bytes())
                return mg.MeshGeometry(umsgpack.Ext(0x12, data), "stl")  # 0x12: meshcat's byte-array extension
            return super().loadMeshFromFile(geometry_object)

    return Visualizer


def force_scale(result: Result) -> tuple[float, float]:
    """(arrow length per newton [m/N], the peak interconnection force [N]): the largest force of
    the run is drawn :data:`ARROW_LENGTH` long."""
    W = result.wrenches()
    peak = float(np.max(np.linalg.norm(W[..., :3], axis=-1))) if W.size else 0.0
    return (ARROW_LENGTH / peak if peak > 0 else 0.01), peak


def deflection_scale(result: Result) -> float:
    """How many times the ghost arms magnify the elastic joints' deflections θ − q: the run's
    largest is drawn :data:`GHOST_DEFLECTION` rad, never less than its true size (×1); 1 for a
    run without elastic joints or without a deflection."""
    if result.scene.joint_springs.size == 0:
        return 1.0
    peak = float(np.max(np.abs(result.joint_deflection()), initial=0.0))
    return max(1.0, GHOST_DEFLECTION / peak) if peak > 0 else 1.0


class _Animator:
    """Loads a scene into a meshcat visualizer and writes poses of one result frame. With elastic
    joints, a translucent ghost of each elastic arm shows it at its motor angles θ (each
    deflection θ − q magnified ``deflection`` times)."""

    def __init__(
        self,
        scene: Scene,
        viewer: Any,
        meshes: str = "collision",
        root: str = "coopdyn",
        scale: float = 0.01,
        deflection: float = 1.0,
    ) -> None:
        meshcat = _meshcat()

        self.scene = scene
        self.geom = visual_model(scene, meshes)
        self.viz = _visualizer_class()(scene.model, None, self.geom)
        self.viz.initViewer(viewer=viewer)
        self.viz.loadViewerModel(rootNodeName=root)
        self.viewer = viewer
        self.scale = scale
        self.data = scene.model.createData()
        self.gdata = self.geom.createData()
        self.arrows = [f"{root}/forces/link{i}" for i in range(len(scene.links))]
        g = meshcat.geometry
        for name in self.arrows:
            # drawn over everything (after the opaque pass, no depth test): an arrow along an arm's
            # approach lies inside its hand, and the push on a box starts inside the fingers
            red = g.MeshLambertMaterial(color=0xD62728, transparent=True, depthTest=False)
            viewer[f"{name}/shaft"].set_object(g.Cylinder(1.0, SHAFT_RADIUS), red)
            viewer[f"{name}/head"].set_object(g.Cylinder(HEAD_LENGTH, radiusTop=0.0, radiusBottom=HEAD_RADIUS), red)
        self.arrow_nodes = {f"{a}{part}" for a in self.arrows for part in ("", "/shaft", "/head")}
        self.nodes = [
            (self.viz.getViewerNodeName(g, pin.GeometryType.VISUAL), i, g.meshScale)
            for i, g in enumerate(self.geom.geometryObjects)
        ]
        self.springs, self.deflection = scene.joint_springs, deflection
        self.ghost_nodes: list[tuple[str, int, np.ndarray]] = []
        if self.springs.size:
            elastic = {info.name for info in scene.arms if info.elastic.size}
            self.ghost = visual_model(scene, meshes, arms=elastic, with_object=False)
            for g in self.ghost.geometryObjects:
                g.meshColor, g.overrideMaterial = np.array(GHOST_COLOR), True
            ghost_viz = _visualizer_class()(scene.model, None, self.ghost)
            ghost_viz.initViewer(viewer=viewer)
            ghost_viz.loadViewerModel(rootNodeName=f"{root}/motors", visual_color=list(GHOST_COLOR))
            self.ghost_data, self.ghost_gdata = scene.model.createData(), self.ghost.createData()
            self.ghost_nodes = [
                (ghost_viz.getViewerNodeName(g, pin.GeometryType.VISUAL), i, g.meshScale)
                for i, g in enumerate(self.ghost.geometryObjects)
            ]

    def poses(self, q: np.ndarray, wrenches: np.ndarray) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
        """(node, rigid 4x4 transform, scale (3,)) of every visual and force arrow at q.

        meshcat animations carry position and orientation only, so the scale goes separately
        (as an animated ``scale`` property; a static transform may fold it in)."""
        model, data = self.scene.model, self.data
        pin.framesForwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, self.geom, self.gdata)
        for name, i, scale in self.nodes:
            yield name, self.gdata.oMg[i].homogeneous, scale
        for name, lk, w in zip(self.arrows, self.scene.links, wrenches, strict=True):
            vec = w[:3] * self.scale  # drawn ending at the grasp point: the push, from outside the object
            for part, (T, scale) in _arrow(data.oMf[lk.grasp_frame].translation - vec, vec).items():
                yield f"{name}{part}", T, scale
        if self.ghost_nodes:  # the elastic arms at their motor angles: q + deflection·(θ − q) on the links
            turn = np.zeros(model.nv)
            turn[self.springs.link_v] = self.deflection * self.springs.deflection(q)
            at_motors = pin.integrate(model, q, turn)
            pin.forwardKinematics(model, self.ghost_data, at_motors)
            pin.updateGeometryPlacements(model, self.ghost_data, self.ghost, self.ghost_gdata)
            for name, i, scale in self.ghost_nodes:
                yield name, self.ghost_gdata.oMg[i].homogeneous, scale

    def box(self, qs: Any, wrenches: Any) -> tuple[np.ndarray, np.ndarray]:
        """The world box (lower, upper corners) [m] that every geometry and force arrow stays in
        over the configurations ``qs`` with interconnection ``wrenches``, at least 0.3 m wide."""
        model, data, geom, gdata = self.scene.model, self.data, self.geom, self.gdata
        corners = []
        for g in geom.geometryObjects:
            g.geometry.computeLocalAABB()
            lo = np.asarray(g.geometry.aabb_local.min_) * g.meshScale
            hi = np.asarray(g.geometry.aabb_local.max_) * g.meshScale
            corners.append(np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]))
        points = []
        for q, W in zip(qs, wrenches, strict=True):
            pin.framesForwardKinematics(model, data, q)
            pin.updateGeometryPlacements(model, data, geom, gdata)
            points += [c @ M.rotation.T + M.translation for M, c in zip(gdata.oMg, corners, strict=True)]
            points += [
                np.array([data.oMf[lk.grasp_frame].translation - w[:3] * self.scale])
                for lk, w in zip(self.scene.links, W, strict=True)
            ]
        stacked = np.concatenate(points)
        centre, half = (stacked.min(axis=0) + stacked.max(axis=0)) / 2, (stacked.max(axis=0) - stacked.min(axis=0)) / 2
        half = np.maximum(half, 0.15)
        return centre - half, centre + half


def _arrow(tail: np.ndarray, vec: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{"": the arrow's rigid pose, "/shaft", "/head": their poses in it} with scales (3,): the
    arrow from ``tail`` along ``vec`` (+y of the pose), a head of fixed size (an arrow shorter
    than two heads shrinks as a whole) on a unit cylinder stretched to the rest."""
    length = float(np.linalg.norm(vec))
    T = np.eye(4)
    T[:3, 3] = tail
    if length < 1e-9:
        return {"": (T, np.full(3, 1e-6)), "/shaft": (np.eye(4), np.ones(3)), "/head": (np.eye(4), np.ones(3))}
    y = vec / length
    a = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(y, a)
    x /= np.linalg.norm(x)
    T[:3, :3] = np.column_stack([x, y, np.cross(x, y)])
    s = min(1.0, length / (2 * HEAD_LENGTH))
    head, shaft = HEAD_LENGTH * s, length - HEAD_LENGTH * s
    T_shaft, T_head = np.eye(4), np.eye(4)
    T_shaft[1, 3], T_head[1, 3] = shaft / 2, shaft + head / 2
    return {"": (T, np.ones(3)), "/shaft": (T_shaft, np.array([s, max(shaft, 1e-6), s])), "/head": (T_head, np.full(3, s))}


def camera(lo: np.ndarray, hi: np.ndarray, azimuth: float = -35.0, elevation: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) [m]: looking at the centre of the box (lo, hi) from ``azimuth`` (from +x
    towards +y) and ``elevation`` [deg], at the distance where its eight corners fit meshcat's
    default camera (75° vertical field of view) in a 4:3 window, with a 5 % margin."""
    centre = (lo + hi) / 2
    az, el = np.radians(azimuth), np.radians(elevation)
    u = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])  # from the target to the eye
    right = np.cross(-u, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -u)
    tan_v = np.tan(np.radians(75.0) / 2) * 0.95
    tan_h = tan_v * 4 / 3
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - centre
    distance = max(np.max(corners @ u + np.abs(corners @ right) / tan_h), np.max(corners @ u + np.abs(corners @ up) / tan_v))
    return centre + distance * u, centre


def _yup(p: np.ndarray) -> list[float]:
    """A world point (z up) in the coordinates of meshcat's camera (three.js, y up)."""
    return [float(p[0]), float(p[2]), float(-p[1])]


def _scaled(T: np.ndarray, scale: np.ndarray) -> np.ndarray:
    out = T.copy()
    out[:3, :3] = T[:3, :3] @ np.diag(scale)
    return out


MAX_FPS = 1000.0  #: frames per second an animation may ask for


def _fps(fps: Any) -> float:
    fps = positive(fps, "fps", "frames per second", ViewerError)
    if fps > MAX_FPS:
        raise ViewerError(f"fps must be at most {MAX_FPS:g} frames per second, got {fps:g}")
    return fps


def _frames(result: Result, fps: float) -> np.ndarray:
    """The sample shown at each frame, 1/fps apart in simulated time — a sample held over
    several frames when they are sparser than that, so that an animation's time (the page's
    clock, the live viewer's pace) is the simulated time."""
    times = np.arange(0.0, result.t[-1] + 1e-12, 1.0 / fps)
    return np.clip(np.searchsorted(result.t, times), 0, len(result.t) - 1)


def export_html(result: Result, path: str | os.PathLike[str], *, fps: float = 30.0, meshes: str = "collision") -> Path:
    """Write a self-contained HTML animation of ``result`` (plays offline in a browser),
    atomically; ``meshes`` as in :func:`visual_model`. The camera frames the arms and the object
    over the whole run; red arrows, drawn over everything else and ending at the grasp they push
    on, show the interconnection forces on the object, the largest :data:`ARROW_LENGTH` long (the
    scale is in the page's corner); with elastic joints, translucent blue ghost arms at the motor
    angles show the joints' deflections, magnified as the corner says; a bar at the top has play / pause (also the space bar), the
    simulated time and a slider to seek."""
    meshcat = _meshcat()
    from meshcat.animation import Animation

    fps = _fps(fps)
    window = RecordingWindow()
    vis = meshcat.Visualizer(window=window)
    animator, legend = _loaded(result, vis, meshes)
    idx = _frames(result, fps)
    wrenches = result.wrenches()
    for name, T, s in animator.poses(result.q[0], wrenches[0]):
        vis[name].set_transform(_scaled(T, s))
    anim = Animation(default_framerate=fps)
    for frame, k in enumerate(idx):
        with anim.at_frame(vis, frame) as f:
            for name, T, s in animator.poses(result.q[k], wrenches[k]):
                f[name].set_transform(T)
                if name in animator.arrow_nodes:
                    f[name].set_property("scale", "vector3", s.tolist())
    vis.set_animation(anim, play=True, repetitions=1000)
    sampled = idx[:: max(1, len(idx) // 20)]
    eye, target = camera(*animator.box(result.q[sampled], wrenches[sampled]))
    vis["/Cameras/default/rotated/<object>"].set_property("position", _yup(eye))
    x, y, z = _yup(target)  # meshcat has no command for the orbit target: set it in the page
    look = f"viewer.controls.target.set({x:.6g}, {y:.6g}, {z:.6g}); viewer.controls.update(); viewer.set_dirty();"
    page = window.get_scene(look + _clock(float(result.t[-1])), f"{legend} · {result.integrator}, {result.t[-1]:g} s")
    return write_atomically(path, "the HTML animation", lambda tmp: tmp.write_text(page, encoding="utf-8"), {".html", ".htm"})


def _loaded(result: Result, vis: Any, meshes: str) -> tuple[_Animator, str]:
    """``result``'s scene loaded into ``vis``, its force arrows and (elastic joints) its ghost arms
    scaled for the run, and the legend that says both scales."""
    scale, peak = force_scale(result)
    deflection = deflection_scale(result)
    animator = _Animator(result.scene, vis, meshes, scale=scale, deflection=deflection)
    return animator, _legend(scale, peak, deflection if animator.ghost_nodes else None)


def _legend(scale: float, peak: float, deflection: float | None = None) -> str:
    """What the red arrows mean, at ``scale`` [m/N] for a run whose largest force is ``peak`` [N];
    and with elastic joints what the ghost arms mean (``deflection``: their magnification)."""
    if peak <= 0:
        text = "no interconnection force in this run"
    else:
        text = f"red arrows: interconnection forces on the object, 1 cm = {0.01 / scale:.3g} N (peak {peak:.3g} N)"
    if deflection is not None:
        text += f" · blue ghost: the arms at their motor angles, deflection θ − q drawn ×{deflection:.3g}"
    return text


def frame_live(vis: Any, lo: np.ndarray, hi: np.ndarray, legend: str) -> None:
    """Frame a live viewer on the world box (lo, hi) [m] as :func:`export_html` frames its page,
    and show ``legend`` on a card above it. meshcat's commands cannot move the camera's orbit
    target (the world origin), so the scene — the coopdyn root, meshcat's grid and axes — is
    moved by −target instead, and the camera put at eye − target."""
    meshcat = _meshcat()
    g = meshcat.geometry
    eye, target = camera(lo, hi)
    shift = np.eye(4)
    shift[:3, 3] = -target
    for node in ("coopdyn", "/Grid", "/Axes"):
        vis[node].set_transform(shift)
    vis["/Cameras/default/rotated/<object>"].set_property("position", _yup(eye - target))
    u = (eye - target) / np.linalg.norm(eye - target)  # towards the eye
    right = np.cross(-u, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -u)
    extent = np.abs(np.asarray(hi) - np.asarray(lo))  # (the box's extent across and up the view)
    width = 0.9 * float(extent @ np.abs(right))
    png, aspect = _text_png(legend)
    card = np.eye(4)
    card[:3, :3] = np.column_stack([right, up, u])  # the card's face (+z) towards the eye, its text upright
    card[:3, 3] = up * (0.5 * float(extent @ np.abs(up)) + 0.6 * width / aspect)
    texture = g.ImageTexture(image=g.PngImage(png))
    vis["legend"].set_object(g.Box([width, width / aspect, 1e-4]), g.MeshBasicMaterial(map=texture))
    vis["legend"].set_transform(card)


def _text_png(text: str) -> tuple[bytes, float]:
    """``text`` on a white card as PNG bytes, and the card's width / height."""
    import io

    from matplotlib.figure import Figure

    width, height = max(0.085 * len(text), 2.0), 0.26  # [in]
    fig = Figure(figsize=(width, height), dpi=200)
    fig.patch.set_facecolor("white")
    fig.text(0.5, 0.5, text, ha="center", va="center", fontsize=11, color="#222222")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", facecolor="white")
    return buffer.getvalue(), width / height


def _clock(duration: float) -> str:
    """The page's clock: a play/pause button, the simulated time and a slider to seek (meshcat's
    own are in its controls' Animations folder). The animation's time is the simulated time: its
    frames are the result's samples at 1/fps apart."""
    return (
        """
  const bar = document.createElement("div");
  bar.id = "clock";
  bar.innerHTML = '<button id="play" title="play / pause (space)">pause</button> '
    + '<input id="seek" type="range" min="0" max="DURATION" step="0.001" value="0"> '
    + '<span id="time">t = 0.000 s</span> / DURATION s';
  document.body.appendChild(bar);
  const anim = viewer.animator, play = document.getElementById("play"),
    seek = document.getElementById("seek"), shown = document.getElementById("time");
  function toggle() {
    if (anim.playing) { anim.pause(); } else { anim.play(); }
  }
  play.onclick = toggle;
  document.addEventListener("keydown", e => { if (e.code === "Space") { e.preventDefault(); toggle(); } });
  seek.oninput = () => { anim.pause(); anim.seek(Number(seek.value)); anim.display_progress(Number(seek.value));
    viewer.set_dirty(); };
  setInterval(() => {
    play.textContent = anim.playing ? "pause" : "play";
    shown.textContent = "t = " + anim.time.toFixed(3) + " s";
    if (anim.playing) { seek.value = anim.time; }
  }, 50);
"""
    ).replace("DURATION", f"{duration:.6g}")


def view(
    result: Result,
    *,
    fps: float = 30.0,
    loops: int | None = None,
    zmq_url: str | None = None,
    meshes: str = "visual",
    host: str = LOOPBACK,
) -> str:
    """Play ``result`` in a live meshcat viewer and return the viewer's URL. Plays ``loops`` times
    (``None``: until Ctrl-C or SIGTERM). The camera frames the arms and the object over the run,
    and a card above them says what the red force arrows mean (:func:`frame_live`).

    Unless ``zmq_url`` names a running meshcat server, it starts one serving on ``host`` (default
    127.0.0.1: this machine only; any other address warns, since anyone who can reach it sees the
    scene) and stops it however the viewing ends (Ctrl-C, SIGTERM, an error, or this process
    dying)."""
    meshcat = _meshcat()
    fps = _fps(fps)  # before a server starts
    host = check_host(host)
    server = None
    try:
        if zmq_url is None:
            if not is_loopback(host):
                warnings.warn(
                    f"serving the viewer on {host}: anyone who can reach this address can watch it; "
                    "use the default host 127.0.0.1 to keep it on this machine",
                    UserWarning,
                    stacklevel=2,
                )
            server = start_server(host)
            zmq_url = server.zmq_url
        with sigterm_as_interrupt():
            vis = meshcat.Visualizer(zmq_url=zmq_url)
            animator, legend = _loaded(result, vis, meshes)
            idx = _frames(result, fps)
            wrenches = result.wrenches()
            sampled = idx[:: max(1, len(idx) // 20)]
            frame_live(vis, *animator.box(result.q[sampled], wrenches[sampled]), legend)
            url = server.web_url if server is not None else vis.url()
            _log.info("meshcat viewer at %s (Ctrl-C to stop)", url)
            n = 0
            try:
                while loops is None or n < loops:
                    for k in idx:
                        t0 = time.perf_counter()
                        for name, T, stretch in animator.poses(result.q[k], wrenches[k]):
                            vis[name].set_transform(_scaled(T, stretch))
                        time.sleep(max(0.0, 1.0 / fps - (time.perf_counter() - t0)))
                    n += 1
            except KeyboardInterrupt:
                pass
    finally:
        if server is not None:
            server.stop()
    return str(url)
