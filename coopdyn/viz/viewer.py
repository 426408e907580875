"""meshcat visualisation: a self-contained HTML animation of a result (arms with their URDF
meshes, the object, interconnection force arrows) and live viewing in a meshcat server.

The HTML is written without any server: a recording stand-in for meshcat's connection keeps the
scene tree and packs it with meshcat's own viewer script, as ``meshcat-server`` does for
``Visualizer.static_html()``. The file plays offline in a browser.
"""

from __future__ import annotations

import base64
import logging
import os
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._signals import sigterm_as_interrupt
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

    def get_scene(self) -> str:
        """The recorded scene as a standalone HTML page (meshcat's viewer script inlined)."""
        from meshcat.servers.tree import walk
        from meshcat.servers.zmqserver import VIEWER_ROOT

        commands: list[bytes] = []
        for node in walk(self.tree):
            blobs = [node.object, *node.properties, node.transform, node.animation]
            commands.extend(b for b in blobs if b is not None)
        js = Path(VIEWER_ROOT, "main.min.js").read_text()
        # decode synchronously, in order (fetch() of data URLs may resolve out of order)
        calls = "\n".join(f'viewer.handle_command_bytearray(b64("{base64.b64encode(c).decode()}"));' for c in commands)
        return _HTML.format(js=js, commands=calls)

    def url(self) -> str:
        return "(recording: no server)"


_HTML = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>coopdyn</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}</style></head>
<body>
<div id="meshcat-pane"></div>
<script>{js}</script>
<script>
function b64(s) {{
  const bin = atob(s); const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
  return out;
}}
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
{commands}
</script>
</body>
</html>
"""


def visual_model(scene: Scene, meshes: str = "collision") -> pin.GeometryModel:
    """Display geometry of the whole scene on ``scene.model``: every arm's URDF ``meshes``
    ("collision": compact, the default; "visual": the full meshes, ~30 MB of HTML for two
    Pandas) and a box for the object (``RigidObject.size``, or a 5 cm cube)."""
    import coal

    geom = pin.GeometryModel()
    model = scene.model
    for spec, info in zip(scene.arm_specs, scene.arms, strict=True):
        la = load_arm(spec, meshes=meshes)
        assert la.visual is not None
        base = la.base
        for g in la.visual.geometryObjects:
            joint_name = la.model.names[g.parentJoint]
            frame_name = la.model.frames[g.parentFrame].name
            copy = pin.GeometryObject(g)
            if g.parentJoint == 0:  # fixed to the arm's base
                copy.parentJoint, copy.placement = 0, base * g.placement
            else:
                copy.parentJoint = model.getJointId(joint_name)
            copy.parentFrame = model.getFrameId(frame_name) if model.existFrame(frame_name) else 0
            geom.addGeometryObject(copy)
        del info
    from ..model.beam import Beam

    obj = scene.object
    if isinstance(obj, Beam):  # one segment per node, an element long: the chain bends with the nodes
        h, width = obj.element_length, max(np.sqrt(12 * obj.section.Iz / obj.section.A), 0.005)
        height = max(np.sqrt(12 * obj.section.Iy / obj.section.A), 0.005)
        for k in range(obj.n_nodes):
            joint = model.getJointId(f"{obj.name}/node{k}")
            length = h if 0 < k < obj.n_elements else h / 2
            shift = 0.0 if 0 < k < obj.n_elements else (h / 4 if k == 0 else -h / 4)
            segment = pin.GeometryObject(
                f"{obj.name}/segment{k}",
                joint,
                model.getFrameId(f"{obj.name}/node{k}"),
                pin.SE3(np.eye(3), np.array([shift, 0.0, 0.0])),
                coal.Box(length * 0.96, width, height),
            )
            segment.meshColor = np.array([0.85, 0.55, 0.2, 1.0])
            geom.addGeometryObject(segment)
        return geom
    size = obj.size if obj.size is not None else (0.05, 0.05, 0.05)
    box = pin.GeometryObject(f"{obj.name}/box", scene.object_joint, scene.object_frame, pin.SE3.Identity(), coal.Box(*size))
    box.meshColor = np.array([0.85, 0.55, 0.2, 1.0])
    geom.addGeometryObject(box)
    return geom


class _Animator:
    """Loads a scene into a meshcat visualizer and writes poses of one result frame."""

    def __init__(self, scene: Scene, viewer: Any, meshes: str = "collision", root: str = "coopdyn") -> None:
        meshcat = _meshcat()
        from pinocchio.visualize import MeshcatVisualizer

        self.scene = scene
        self.geom = visual_model(scene, meshes)
        self.viz = MeshcatVisualizer(scene.model, None, self.geom)
        self.viz.initViewer(viewer=viewer)
        self.viz.loadViewerModel(rootNodeName=root)
        self.viewer = viewer
        self.data = scene.model.createData()
        self.gdata = self.geom.createData()
        self.arrows = [f"{root}/forces/link{i}" for i in range(len(scene.links))]
        for name in self.arrows:
            red = meshcat.geometry.MeshLambertMaterial(color=0xD62728)
            viewer[name].set_object(meshcat.geometry.Cylinder(1.0, 0.006), red)
        self.nodes = [
            (self.viz.getViewerNodeName(g, pin.GeometryType.VISUAL), i, g.meshScale)
            for i, g in enumerate(self.geom.geometryObjects)
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
            vec = w[:3] * FORCE_SCALE  # drawn ending at the grasp point: the push, from outside the object
            yield name, *_arrow(data.oMf[lk.grasp_frame].translation - vec, vec)


def _arrow(origin: np.ndarray, vec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rigid transform, scale) turning meshcat's unit cylinder (along y, centred) into a bar
    from ``origin`` along ``vec``."""
    length = float(np.linalg.norm(vec))
    T = np.eye(4)
    T[:3, 3] = origin + 0.5 * vec
    if length < 1e-9:
        return T, np.array([1e-6, 1e-6, 1e-6])
    y = vec / length
    a = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(y, a)
    x /= np.linalg.norm(x)
    T[:3, :3] = np.column_stack([x, y, np.cross(x, y)])
    return T, np.array([1.0, length, 1.0])


def _scaled(T: np.ndarray, scale: np.ndarray) -> np.ndarray:
    out = T.copy()
    out[:3, :3] = T[:3, :3] @ np.diag(scale)
    return out


def _frames(result: Result, fps: float) -> np.ndarray:
    times = np.arange(0.0, result.t[-1] + 1e-12, 1.0 / fps)
    return np.unique(np.clip(np.searchsorted(result.t, times), 0, len(result.t) - 1))


def export_html(result: Result, path: str | os.PathLike[str], *, fps: float = 30.0, meshes: str = "collision") -> Path:
    """Write a self-contained HTML animation of ``result`` (plays offline in a browser),
    atomically; ``meshes`` as in :func:`visual_model`."""
    meshcat = _meshcat()
    from meshcat.animation import Animation

    window = RecordingWindow()
    vis = meshcat.Visualizer(window=window)
    animator = _Animator(result.scene, vis, meshes)
    idx = _frames(result, fps)
    wrenches = result.wrenches()
    for name, T, scale in animator.poses(result.q[0], wrenches[0]):
        vis[name].set_transform(_scaled(T, scale))
    anim = Animation(default_framerate=fps)
    for frame, k in enumerate(idx):
        with anim.at_frame(vis, frame) as f:
            for name, T, scale in animator.poses(result.q[k], wrenches[k]):
                f[name].set_transform(T)
                if name in animator.arrows:
                    f[name].set_property("scale", "vector3", scale.tolist())
    vis.set_animation(anim, play=True, repetitions=1000)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(window.get_scene())
    os.replace(tmp, path)
    return path


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
    (``None``: until Ctrl-C or SIGTERM).

    Unless ``zmq_url`` names a running meshcat server, it starts one serving on ``host`` (default
    127.0.0.1: this machine only; any other address warns, since anyone who can reach it sees the
    scene) and stops it however the viewing ends (Ctrl-C, SIGTERM, an error, or this process
    dying)."""
    meshcat = _meshcat()
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
            animator = _Animator(result.scene, vis, meshes)
            idx = _frames(result, fps)
            wrenches = result.wrenches()
            url = server.web_url if server is not None else vis.url()
            _log.info("meshcat viewer at %s (Ctrl-C to stop)", url)
            n = 0
            try:
                while loops is None or n < loops:
                    for k in idx:
                        t0 = time.perf_counter()
                        for name, T, scale in animator.poses(result.q[k], wrenches[k]):
                            vis[name].set_transform(_scaled(T, scale))
                        time.sleep(max(0.0, 1.0 / fps - (time.perf_counter() - t0)))
                    n += 1
            except KeyboardInterrupt:
                pass
    finally:
        if server is not None:
            server.stop()
    return str(url)
