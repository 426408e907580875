"""The saved trajectory of a run and its readouts (:class:`Result`), and saving a failed run's partial result."""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ._files import temporary
from ._validate import finite_array, positive
from ._validate import path as as_path
from ._version import __version__
from .dynamics import Dynamics, Energy
from .dynamics.dynamics import Readouts
from .errors import CoopdynError, OutputError, SimulationError
from .model.description import build, describe
from .model.scene import Scene

#: the largest magnitude a loaded sample may have (t [s], q, v, τ): far beyond any run (simulate
#: stops at max_speed), and small enough that the readouts' squares and products stay finite
MAX_SAMPLE = 1e100
RESULT_FORMAT = "coopdyn.result/1"  #: what a saved result's ``meta`` says it is
ARRAYS = ("t", "q", "v", "tau")  #: the fields a saved result keeps as arrays (the others go in ``meta``)
MAX_LOAD_BYTES = 4e9  #: [bytes] the most a result file's arrays may take in memory, checked before they are read


_READ_HEADER = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
_MAX_HEADER = 10_000  #: [bytes] numpy's own limit on an .npy header


def _npy_header(f: Any) -> tuple[tuple[int, ...], np.dtype[Any]]:
    """The shape and dtype of the ``.npy`` stream ``f``, from its header alone."""
    version = np.lib.format.read_magic(f)
    if version not in _READ_HEADER:
        raise ValueError(f"an .npy format version {version} this coopdyn does not read")
    shape, _, dtype = _READ_HEADER[version](f, max_header_size=_MAX_HEADER)
    return shape, dtype


def read_npz(path: Path, names: tuple[str, ...] | None = None, max_bytes: float = MAX_LOAD_BYTES) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file (those in ``names``, or all), no pickles: their sizes are
    read from the headers and checked against ``max_bytes`` before anything is decompressed.

    Raises:
        ValueError: not an npz file, or arrays larger than ``max_bytes`` (the message says so).
    """
    import zipfile

    with zipfile.ZipFile(path) as zf:
        members = {n.removesuffix(".npy"): n for n in zf.namelist() if n.endswith(".npy")}
        wanted = [k for k in members if names is None or k in names]
        total = 0
        for key in wanted:
            with zf.open(members[key]) as f:
                shape, dtype = _npy_header(f)
            if dtype.hasobject:
                raise ValueError(f"{key} holds Python objects, which a result never does")
            total += int(np.prod(shape, dtype=object)) * dtype.itemsize
        if total > max_bytes:
            raise ValueError(
                f"its arrays would take {total / 1e9:.3g} GB in memory, more than the {max_bytes / 1e9:.3g} GB allowed "
                "(max_bytes); a result of a long run is better streamed (simulate(..., stream_to=…))"
            )
    with np.load(path, allow_pickle=False) as z:
        return {k: np.asarray(z[k]) for k in wanted}


@dataclass(frozen=True, eq=False)
class Result:
    """A saved trajectory and its readouts.

    Attributes:
        scene: the simulated scene.
        t: sample times (n,) [s].
        q, v: configurations (n, nq) and velocities (n, nv).
        tau: controller output at the samples (n, n_actuated) [N·m or N].
        integrator: name of the method; dt: its step (adaptive: output interval) [s].
        n_rhs: right-hand-side evaluations; cpu_time: CPU time of the integration loop [s].
        n_jac, n_factor: Jacobian evaluations and factorisations (implicit methods).
        n_steps, n_rejected: accepted and rejected steps.
        force_error_estimate: the largest error of the interconnection forces [N] found by
            comparing this run with a reference run (dopri5, or ros2_adaptive on stiff scenes)
            of the same scene, controller and start, when the accuracy screen could not clear
            the run (:mod:`coopdyn.accuracy`), or when ``simulate(..., accuracy=)`` chose its
            step (against dopri5 at rtol 1e-9); ``None`` when
            it was not needed (every mode passed the screen, or an error-controlled or exact
            method), not possible, or ``accuracy_check`` was not ``"auto"``.
    """

    scene: Scene
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    integrator: str
    dt: float
    n_rhs: int
    cpu_time: float
    n_jac: int = 0
    n_factor: int = 0
    n_steps: int = 0
    n_rejected: int = 0
    #: "completed", "interrupted" (Ctrl-C), "diverged" or "stopped" (step budget, or a step below h_min)
    status: str = "completed"
    backend: str | None = None  #: the dynamics backend of the run; readouts use the same
    loop: str = "python"  #: the step loop that ran: "compiled" or "python" (see coopdyn.simulate)
    force_error_estimate: float | None = None  #: [N] (see above)

    @cached_property
    def _dynamics(self) -> Dynamics:
        return Dynamics(self.scene, self.backend)

    @cached_property
    def readouts(self) -> Readouts:
        """Every interconnection's readouts along the trajectory, from one pass through the
        elements on the run's backend (computed on first use, then kept)."""
        return self._dynamics.readouts(self.q, self.v, self.tau)

    def _link(self, i: int) -> int:
        n = len(self.scene.links)
        if isinstance(i, bool) or not isinstance(i, int | np.integer) or not -n <= i < n:
            raise SimulationError(f"interconnection index must be an integer in [{-n}, {n}), got {i!r}")
        return int(i) % n

    def wrench(self, i: int) -> np.ndarray:
        """Wrench of interconnection i on the object (n, 6) [N, N·m]: force, then moment about the
        grasp point, in world-aligned axes (for a rigid grasp: the constraint wrench)."""
        return self.readouts.object_wrench[:, self._link(i)]

    def arm_wrench(self, i: int) -> np.ndarray:
        """Wrench of interconnection i on its arm (or fixture) (n, 6) [N, N·m], about the tip
        point, world axes."""
        return self.readouts.arm_wrench[:, self._link(i)]

    def deformation(self, i: int) -> np.ndarray:
        """Deformation of interconnection i (n, size) in tip-frame axes: ``log6(T_M_G)`` (n, 6)
        [m, rad] for an SE(3) spring, the grasp point's offset (n, 3) [m] for a ball spring; for
        a rigid grasp the same measures are its drift from the constraint."""
        i = self._link(i)
        return self.readouts.deformation[:, i, : self.scene.links[i].element.deformation_size]

    def constraint_drift(self) -> tuple[np.ndarray, np.ndarray]:
        """How far the rigid grasps (:func:`coopdyn.rigid_limit`) drifted from their constraints:
        the norms of the drift's translation (n, R) [m] and rotation (n, R) [rad], one column per
        rigid interconnection in scene order (R = 0 for an elastic scene)."""
        d = self.readouts.deformation[:, list(self.scene.constraints)]
        return np.linalg.norm(d[..., :3], axis=-1), np.linalg.norm(d[..., 3:], axis=-1)

    def elastic_energy(self, i: int) -> np.ndarray:
        """Elastic energy of interconnection i (n,) [J]."""
        return self.readouts.energy[:, self._link(i)]

    def dissipated_power(self, i: int) -> np.ndarray:
        """Power dissipated by interconnection i's damping (n,) [W]."""
        return self.readouts.power[:, self._link(i)]

    def energy(self) -> Energy:
        """Kinetic, gravity and elastic energy along the trajectory, each (n,) [J]; elastic: the
        interconnections', the object's own elements' and the elastic joints' springs'."""
        r = self.readouts
        return Energy(r.kinetic, r.potential, r.energy.sum(axis=1) + self.scene.joint_springs.energy(self.q))

    def joint_deflection(self) -> np.ndarray:
        """Each elastic joint's deflection θ − q (n, m) [rad or m], in the order of
        ``scene.joint_springs`` (arm after arm, each arm's elastic joints in its joint order)."""
        return self.scene.joint_springs.deflection(self.q)

    def joint_spring_torque(self) -> np.ndarray:
        """The torque each elastic joint's transmission puts on its link, K(θ − q) + D(θ̇ − q̇)
        (n, m) [N·m or N] (on its motor: the opposite), ordered as :meth:`joint_deflection`."""
        return self.scene.joint_springs.torque(self.q, self.v)

    def frame_position(self, frame: str | int) -> np.ndarray:
        """World position of a frame of the scene model (n, 3) [m]."""
        model = self.scene.model
        if isinstance(frame, str):
            if not model.existFrame(frame):
                from .errors import did_you_mean

                raise SimulationError(f"no frame {frame!r} in the scene.{did_you_mean(frame, [f.name for f in model.frames])}")
            frame = int(model.getFrameId(frame))
        elif isinstance(frame, bool) or not isinstance(frame, int | np.integer) or not 0 <= frame < model.nframes:
            raise SimulationError(f"frame must be a frame name or an index in [0, {model.nframes}), got {frame!r}")
        data = model.createData()
        out = np.empty((len(self.t), 3))
        for k, q in enumerate(self.q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, frame).translation
        return out

    def grasp_points(self) -> np.ndarray:
        """World positions of the grasp frames (n, N, 3) [m]."""
        return self.readouts.grasp_position[:, : len(self.scene.links)]

    def wrenches(self) -> np.ndarray:
        """Every interconnection's wrench on the object (n, N, 6) [N, N·m] (see :meth:`wrench`)."""
        return self.readouts.object_wrench[:, : len(self.scene.links)]

    def wrench_split(self) -> tuple[np.ndarray, np.ndarray]:
        """The interconnection wrenches on the object split into the part that moves the object
        and the internal part (:func:`coopdyn.grasp.split`), each (n, N, 6) [N, N·m]."""
        from .grasp import grasp_matrix, split

        W, P = self.wrenches(), self.grasp_points()
        parts = [split(grasp_matrix(p), w) for p, w in zip(P, W, strict=True)]
        return np.array([s.moving for s in parts]), np.array([s.internal for s in parts])

    def squeeze(self) -> np.ndarray:
        """Internal (squeeze) force at each grasp (n, N) [N], positive = compression."""
        from .grasp import squeeze_forces

        return squeeze_forces(self.grasp_points(), self.wrenches())

    def __repr__(self) -> str:
        duration = float(self.t[-1] - self.t[0]) if len(self.t) else 0.0
        return (
            f"Result({self.status}, {len(self.t)} samples over {duration:g} s, {self.integrator} at dt = {self.dt:g} s, "
            f"CPU {self.cpu_time:.3g} s, scene: {len(self.scene.arms)} arms, {len(self.scene.links)} interconnections)"
        )

    def columns(self) -> dict[str, list[str]]:
        """Names of the saved columns, with units and frames: ``"t"``, ``"q"``, ``"v"``,
        ``"tau"`` (arm joints) and ``"wrench"`` (per interconnection, on the object: fx, fy, fz
        [N] and mx, my, mz [N·m] about the grasp point, world axes); a CSV column is named by
        both, e.g. ``"q left/panda_joint1 [rad]"``, ``"v object.vx [m/s; body axes]"``,
        ``"wrench left.fz [N; world axes]"``."""
        return _columns(self.scene)

    def to_dataframe(self) -> Any:
        """The run as a pandas DataFrame, one row per sample, every column named with its unit
        and frame:

        * ``t [s]``;
        * the object frame's pose in the world: ``object.x/y/z [m; world]``, its orientation as
          ``object.roll/pitch/yaw [rad; world]`` (Pinocchio's ``rpy``: R = Rz(yaw) Ry(pitch)
          Rx(roll)) and as a quaternion ``object.qx/qy/qz/qw [1; world]``;
        * its velocity in world axes at its origin: ``object.vx/vy/vz [m/s; world axes]``,
          ``object.wx/wy/wz [rad/s; world axes]``;
        * each grasp's squeeze ``{link}.squeeze [N; + = compression]`` and its wrench split
          (:meth:`wrench_split`) into the part that moves the object and the internal part,
          ``{link}.moving.fx … mz`` and ``{link}.internal.fx … mz`` [N; world axes] and
          [N·m; world axes; about the grasp], as the wrench columns;
        * every saved column of :meth:`columns` (q, v — a free flyer's in its body axes —, τ and
          the wrenches), named ``"q …"``, ``"v …"``, ``"tau …"``, ``"wrench …"`` as in the CSV.
        """
        import pandas as pd

        model = self.scene.model
        data = model.createData()
        frame = self.scene.object_frame
        n = len(self.t)
        pose, twist = np.empty((n, 10)), np.empty((n, 6))
        for k in range(n):
            pin.forwardKinematics(model, data, self.q[k], self.v[k])
            oMo = pin.updateFramePlacement(model, data, frame)
            x, y, z, w = pin.Quaternion(oMo.rotation).coeffs()
            pose[k] = (*oMo.translation, *pin.rpy.matrixToRpy(oMo.rotation), x, y, z, w)
            twist[k] = pin.getFrameVelocity(model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).vector
        table: dict[str, np.ndarray] = {"t [s]": np.asarray(self.t, dtype=float)}
        for i, c in enumerate(("x", "y", "z")):
            table[f"object.{c} [m; world]"] = pose[:, i]
        for i, c in enumerate(("roll", "pitch", "yaw")):
            table[f"object.{c} [rad; world]"] = pose[:, 3 + i]
        for i, c in enumerate(("qx", "qy", "qz", "qw")):
            table[f"object.{c} [1; world]"] = pose[:, 6 + i]
        for i, c in enumerate(("vx", "vy", "vz")):
            table[f"object.{c} [m/s; world axes]"] = twist[:, i]
        for i, c in enumerate(("wx", "wy", "wz")):
            table[f"object.{c} [rad/s; world axes]"] = twist[:, 3 + i]
        if len(self.scene.links) >= 2:
            squeeze = self.squeeze()
            for i, lk in enumerate(self.scene.links):
                table[f"{lk.name}.squeeze [N; + = compression]"] = squeeze[:, i]
            moving, internal = self.wrench_split()
            for part, values in (("moving", moving), ("internal", internal)):
                for i, lk in enumerate(self.scene.links):
                    for j, c in enumerate(("fx", "fy", "fz", "mx", "my", "mz")):
                        unit = "N; world axes" if c[0] == "f" else "N·m; world axes; about the grasp"
                        table[f"{lk.name}.{part}.{c} [{unit}]"] = values[:, i, j]
        W = self.wrenches().reshape(n, -1)
        saved = {"q": self.q, "v": self.v, "tau": self.tau, "wrench": W}
        for key, names in self.columns().items():
            if key != "t":
                for j, name in enumerate(names):
                    table[f"{key} {name}"] = saved[key][:, j]
        return pd.DataFrame(table)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the result atomically (temporary file, then rename) and return the path.

        ``.npz``: everything the result holds — arrays, counters, status and the scene's
        description — so that :meth:`load` gives it back with its readouts. ``.csv``: a table,
        one row per sample: time, q, v, tau and the interconnection wrenches on the object,
        columns named after joints and interconnections, with units (:meth:`columns`)."""
        path = as_path(path, "path (a file name ending in .npz or .csv)", SimulationError)
        if path.suffix not in (".npz", ".csv"):
            raise SimulationError(f"unknown result format {path.suffix!r}: use .npz (reloads) or .csv (a table)")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except (OSError, ValueError) as exc:
            reason = getattr(exc, "strerror", None) or exc
            raise OutputError(getattr(exc, "errno", None), f"cannot write {path}: {reason}", str(path)) from exc
        tmp = temporary(path)
        W = self.wrenches().reshape(len(self.t), -1)
        try:
            if path.suffix == ".npz":
                meta = json.dumps(self._meta(), allow_nan=False)
                with open(tmp, "wb") as f:
                    np.savez(f, **{k: getattr(self, k) for k in ARRAYS}, wrenches=W, meta=np.array(meta))
            else:
                names = [f"{k} {n}" if k != "t" else n for k, ns in self.columns().items() for n in ns]
                _write_csv(tmp, names, [self.t, *self.q.T, *self.v.T, *self.tau.T, *W.T])
            os.replace(tmp, path)
        except BaseException as exc:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)  # no .tmp left behind (disk full, read-only, Ctrl-C)
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                raise OutputError(exc.errno, f"cannot write {path}: {exc.strerror or exc}", str(path)) from exc
            raise
        return path

    def _meta(self) -> dict[str, Any]:
        fields = [f.name for f in dataclasses.fields(self) if f.name not in (*ARRAYS, "scene")]
        return {
            "format": RESULT_FORMAT,
            "coopdyn": __version__,
            **{k: getattr(self, k) for k in fields},
            "scene": describe(self.scene),
            "columns": self.columns(),
        }

    @classmethod
    def load(cls, path: str | os.PathLike[str], max_bytes: float = MAX_LOAD_BYTES) -> Result:
        """A result saved by :meth:`save` as ``.npz``: the arrays, counters and status, and its
        scene rebuilt from the saved description (its URDFs are read again from where they were
        — an example-robot-data name, or the absolute path saved). Arrays larger than
        ``max_bytes`` [bytes] are refused before they are read; non-finite samples are refused
        by name."""
        path = as_path(path, "path (a .npz file Result.save wrote)", SimulationError)
        max_bytes = positive(max_bytes, "max_bytes", "bytes", SimulationError)
        if path.suffix != ".npz":
            raise SimulationError(f"{path}: Result.load reads the .npz files Result.save writes (a .csv is a table only)")
        if not path.is_file():
            raise SimulationError(f"no saved result at {path}")
        try:
            arrays = read_npz(path, (*ARRAYS, "meta"), max_bytes)
        except Exception as exc:
            raise SimulationError(f"{path} is not a result coopdyn wrote ({type(exc).__name__}: {exc})") from exc
        missing = [k for k in ARRAYS if k not in arrays]
        if "meta" in arrays and missing:
            raise SimulationError(f"{path}: no {', '.join(missing)} in the file (a damaged file?)")
        if "meta" not in arrays:
            raise SimulationError(
                f"{path} has no description of its scene (saved by an older coopdyn, or not by coopdyn); "
                "run the simulation again to save a result that reloads"
            )
        writer = None  # the coopdyn version that wrote the file, once known
        try:
            meta = json.loads(str(arrays["meta"]))
            writer = meta.get("coopdyn") if isinstance(meta, dict) else None
            written = meta.pop("format", None)
            if written != RESULT_FORMAT:
                by = meta.get("coopdyn", "an unknown version")
                raise SimulationError(
                    f"{path} is in format {written!r}, written by coopdyn {by}; this coopdyn ({__version__}) reads "
                    f"{RESULT_FORMAT!r}: open it with the coopdyn that wrote it, or run the simulation again"
                )
            meta.pop("coopdyn")
            saved_columns = meta.pop("columns")
            _check_meta(meta)
            scene = build(meta.pop("scene"))
        except SimulationError:
            raise
        except CoopdynError as exc:
            raise SimulationError(f"{path}: its scene cannot be rebuilt: {exc}") from exc
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            by = f"written by coopdyn {writer}, " if writer is not None else ""
            raise SimulationError(
                f"{path}: not a result coopdyn wrote, or damaged ({by}read by coopdyn {__version__}; {type(exc).__name__}: {exc})"
            ) from exc
        t = arrays["t"]
        rebuilt = {key: names for key, names in _columns(scene).items() if key in ("q", "v", "tau")}
        if any(saved_columns.get(key) != names for key, names in rebuilt.items()):
            key = next(k for k, names in rebuilt.items() if saved_columns.get(k) != names)
            raise SimulationError(
                f"{path}: its {key} columns are not those its rebuilt scene has (saved by a coopdyn that ordered the "
                f"coordinates otherwise, e.g. elastic joints' motors before the object); run the simulation again"
            )
        if t.ndim != 1 or t.dtype.kind != "f":
            raise SimulationError(f"{path}: t must be a list of times [s], got {t.dtype} of shape {t.shape} (a damaged file?)")
        if np.any(np.diff(t) <= 0):
            raise SimulationError(f"{path}: its times t must increase from sample to sample (a damaged file?)")
        for key, shape in {"q": (len(t), scene.nq), "v": (len(t), scene.nv), "tau": (len(t), scene.n_actuated)}.items():
            if arrays[key].shape != shape or arrays[key].dtype.kind != "f":
                raise SimulationError(
                    f"{path}: {key} is {arrays[key].dtype} of shape {arrays[key].shape}; its scene and the {len(t)} samples "
                    f"need floats of shape {shape} (a damaged file?)"
                )
        for key in ARRAYS:
            arrays[key] = np.asarray(arrays[key], dtype=np.float64)  # (a float16 or float32 file: the readouts take doubles)
            finite = np.abs(arrays[key]) <= MAX_SAMPLE
            bad = np.flatnonzero(~(finite if finite.ndim == 1 else finite.all(axis=1)))
            if len(bad):
                raise SimulationError(
                    f"{path}: {key} is not finite or beyond ±{MAX_SAMPLE:g} at {len(bad)} sample(s), the first at index "
                    f"{bad[0]} (a damaged file, or one not written by coopdyn, which saves finite samples within "
                    "max_speed only)"
                )
        try:
            return cls(scene=scene, t=arrays["t"], q=arrays["q"], v=arrays["v"], tau=arrays["tau"], **meta)
        except TypeError as exc:
            raise SimulationError(f"{path}: not a result coopdyn wrote, or damaged ({exc})") from exc

    def tracking_error(self, reference: Callable[[float], Any]) -> np.ndarray:
        """Object position error ‖p − p_d‖ (n,) [m] against ``reference(t).position`` (e.g. a
        :class:`coopdyn.cooperative.GripLiftOscillate`) or ``reference(t)`` returning (3,)."""
        if not callable(reference):
            raise SimulationError(f"reference must be a callable reference(t), got {type(reference).__name__}")
        positions = getattr(reference, "positions", None)  # all samples at once (GripLiftOscillate)
        if callable(positions):
            return np.linalg.norm(self.object_position() - positions(self.t), axis=1)
        desired = []
        for t in self.t:
            try:
                ref = reference(float(t))
            except Exception as exc:
                raise SimulationError(f"reference({float(t):g}) raised {type(exc).__name__}: {exc}") from exc
            desired.append(
                finite_array(getattr(ref, "position", ref), f"reference({float(t):g}) position", (3,), SimulationError)
            )
        return np.linalg.norm(self.object_position() - np.array(desired), axis=1)

    def tip_position(self, arm: int | str) -> np.ndarray:
        """World position of an arm's tip frame (n, 3) [m]."""
        return self.frame_position(self.scene.arms[self.scene.arm_index(arm)].tip_frame)

    def object_position(self) -> np.ndarray:
        """World position of the object frame origin (n, 3) [m]."""
        return self.readouts.object_position


def _columns(scene: Scene) -> dict[str, list[str]]:
    """:meth:`Result.columns` of a scene's runs."""
    q_names, v_names = scene.coordinates()
    tau = [v_names[i].replace("[rad/s]", "[N·m]").replace("[m/s]", "[N]") for i in scene.actuated]
    wrench = [
        f"{lk.name}.{c} [{'N; world axes' if c[0] == 'f' else 'N·m; world axes; about the grasp'}]"
        for lk in scene.links
        for c in ("fx", "fy", "fz", "mx", "my", "mz")
    ]
    return {"t": ["t [s]"], "q": q_names, "v": v_names, "tau": tau, "wrench": wrench}


def _write_csv(path: Path, names: list[str], columns: list[np.ndarray]) -> None:
    """The ``columns`` (each (n,)) as CSV with ``names`` as header, each number the shortest
    decimal that reads back to the same double. Polars' writer (Rust, on every core), fed column
    by column (no (n, m) temporary): 5–7× the npz's time for the same run — the text is 2.6×
    the bytes — where pyarrow's took 8× and numpy's savetxt 20–70× (``benchmarks/save_cost.py``)."""
    import polars as pl

    pl.DataFrame([pl.Series(name, np.ascontiguousarray(c)) for name, c in zip(names, columns, strict=True)]).write_csv(path)


#: what a saved counter or setting may hold, by the annotation of its Result field
_META_TYPES: dict[str, tuple[type, ...]] = {
    "float": (int, float),
    "int": (int,),
    "str": (str,),
    "str | None": (str, type(None)),
    "float | None": (int, float, type(None)),
}


def _check_meta(meta: dict[str, Any]) -> None:
    """Raise ValueError unless the saved counters and settings have their fields' types."""
    for f in dataclasses.fields(Result):
        if f.name in meta and f.type in _META_TYPES:
            value = meta[f.name]
            if isinstance(value, bool) or not isinstance(value, _META_TYPES[str(f.type)]):
                raise ValueError(f"{f.name} = {value!r} is not of type {f.type}")
            if isinstance(value, float) and not np.isfinite(value):
                raise ValueError(f"{f.name} = {value!r} is not finite")
            if isinstance(value, int | float) and (value < 0 or (f.name == "dt" and value == 0)):
                raise ValueError(f"{f.name} = {value!r} must be {'> 0' if f.name == 'dt' else '>= 0'}")


class SampleFiles:
    """A run's samples streamed to ``.npy`` files in ``folder`` (``t``, ``q``, ``v``, ``tau``)
    instead of kept in memory: the files are made at their final size up front, their disk
    space reserved (so that a disk filling up during the run cannot hit them), and filled as the
    run goes; :meth:`arrays` maps them back read-only. A run that stops early leaves files cut
    to the samples it made.

    Args:
        folder: a new or empty folder. n: samples the run will save. nq, nv, na: sizes.
    """

    NAMES = ("t", "q", "v", "tau")

    def __init__(self, folder: str | os.PathLike[str], n: int, nq: int, nv: int, na: int) -> None:
        self.folder = as_path(folder, "stream_to (a folder)", SimulationError).absolute()
        if self.folder.exists() and (not self.folder.is_dir() or any(self.folder.iterdir())):
            raise SimulationError(f"stream_to: {self.folder} must be a new or empty folder")
        need = n * (1 + nq + nv + na) * 8
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            free = shutil.disk_usage(self.folder).free
            if need > free:
                raise OutputError(28, f"streaming needs {need / 1e9:.3g} GB, {self.folder} has {free / 1e9:.3g} GB free")
            shapes = {"t": (n,), "q": (n, nq), "v": (n, nv), "tau": (n, na)}
            self._files = {k: _reserved_npy(self.folder / f"{k}.npy", s) for k, s in shapes.items()}
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            with contextlib.suppress(OSError):
                for name in self.NAMES:
                    (self.folder / f"{name}.npy").unlink(missing_ok=True)
            raise OutputError(
                exc.errno, f"cannot stream to {self.folder}: {exc.strerror or exc} (needs {need / 1e9:.3g} GB)", str(self.folder)
            ) from exc
        self.size, self.n = n, 0

    def append(self, t: Any, q: Any, v: Any, tau: Any) -> None:
        """Write rows (m,), (m, nq), (m, nv), (m, na) after those written so far."""
        m = len(t)
        for name, rows in zip(self.NAMES, (t, q, v, tau), strict=True):
            self._files[name][self.n : self.n + m] = rows
        self.n += m

    def arrays(self) -> tuple[np.ndarray, ...]:
        """(t, q, v, tau), memory-mapped read-only; files longer than what was written are cut
        in place (their header rewritten, the rest truncated: no new disk space needed)."""
        for name, mm in self._files.items():
            mm.flush()
            if self.n < self.size:
                _cut_npy(self.folder / f"{name}.npy", (self.n, *mm.shape[1:]))
        self._files = {}
        return tuple(np.load(self.folder / f"{k}.npy", mmap_mode="r") for k in self.NAMES)


def _reserved_npy(path: Path, shape: tuple[int, ...]) -> np.memmap[Any, Any]:
    """A float ``.npy`` file of ``shape``, its blocks allocated on disk, memory-mapped for writing.
    Without the reservation a full disk would end the process with SIGBUS at the first write to
    a page it cannot back."""
    mm = np.lib.format.open_memmap(path, mode="w+", dtype=np.float64, shape=shape)
    size = path.stat().st_size
    if hasattr(os, "posix_fallocate") and size:
        fd = os.open(path, os.O_RDWR)
        try:
            os.posix_fallocate(fd, 0, size)
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):  # a file system without it: stream unreserved
                raise
        finally:
            os.close(fd)
    return mm


def _cut_npy(path: Path, shape: tuple[int, ...]) -> None:
    """Make the ``.npy`` file at ``path`` hold only its first ``shape[0]`` rows, in place: the
    header is rewritten at its own length (a shorter shape, padded) and the file truncated."""
    with open(path, "r+b") as f:
        version = np.lib.format.read_magic(f)
        _READ_HEADER[version](f, max_header_size=_MAX_HEADER)
        offset = f.tell()
        header = np.lib.format.header_data_from_array_1_0(np.empty((0,), np.float64))
        header["shape"] = shape
        text = repr(header).encode("latin1")
        prefix = 8 + (2 if version == (1, 0) else 4)
        room = offset - prefix - 1  # the header's length, less its closing newline
        f.seek(prefix)
        f.write(text.ljust(room) + b"\n")
        f.truncate(offset + int(np.prod(shape)) * 8)
