"""The compiled step loop (src/native/loop.hpp): :func:`coopdyn.simulate` runs a simulation there
when the native dynamics, a built-in integrator and no ``object_wrench`` callable allow it — a
built-in controller as its C++ twin, any other controller called back — and through the Python
loop otherwise.
Both loops take the same steps with the same operations; results agree to round-off
(tests/test_compiled_loop.py).

The compiled loop runs in chunks of steps with the GIL released; between chunks Python updates
the progress bar, issues the warnings the chunk reported, and can be interrupted (Ctrl-C).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from . import accuracy
from ._spec import CompiledSpec, ExponentialSpec, NoControllerSpec, PythonControllerSpec
from .accuracy import StartLoop
from .closed_loop import System
from .dynamics.backend import kernel_module
from .errors import ControllerError, CoopdynError, GraspGeometryError, SimulationError
from .integrators import Integrator
from .model.scene import Scene
from .monitor import ENERGY_RTOL

#: what a chunk reports, by name (src/native/loop.hpp: Status; the kernel exports the names)
STATUS_NAMES = ("running", "done", "diverged", "step_matrix", "energy", "h_min", "controller", "failed", "scene")
RUNNING, DONE, DIVERGED, STEP_MATRIX, ENERGY, H_MIN, CONTROLLER, FAILED, SCENE = range(len(STATUS_NAMES))
BUDGET = -1  #: set in Python between chunks: an adaptive run used up its step budget
#: the kinds of event a chunk reports (src/native/loop.hpp: Event)
ROTATION_ALARM, ENERGY_BALANCE = 0, 1
#: wall time of one chunk [s]: how often Python looks (progress bar, warnings, Ctrl-C)
CHUNK_SECONDS = 0.05
#: steps (adaptive: attempts) of the first chunk; later chunks are sized to CHUNK_SECONDS
FIRST_CHUNK = 64
_ENERGY_MODES = {"off": 0, "warn": 1, "raise": 2}


def _own_spec(obj: Any, *args: Any, error: type[CoopdynError] = ControllerError) -> CompiledSpec | None:
    """``obj.compiled_spec(*args)`` when obj's own class defines it (a subclass that changes the
    behaviour runs in Python), else None; ``error``: what a failing hook raises."""
    spec = type(obj).__dict__.get("compiled_spec")
    if spec is None:
        return None
    try:
        out = spec(obj, *args)
    except (CoopdynError, KeyboardInterrupt):
        raise
    except Exception as exc:  # a user's class: say whose hook failed
        raise error(f"{type(obj).__name__}.compiled_spec raised {type(exc).__name__}: {exc}") from exc
    if out is not None and not isinstance(out, CompiledSpec):
        raise error(
            f"{type(obj).__name__}.compiled_spec returned {type(out).__name__}; it must return a typed spec (a subclass of "
            "coopdyn._spec.CompiledSpec, see docs/extending.md), or None"
        )
    return out


class PythonCallback:
    """A Python controller as the compiled loop calls it (src/native/controllers/python_controller.hpp).

    The loop calls :attr:`controller` itself with read-only q and v and takes a finite float64
    vector of the right size as it is; any other output goes through :meth:`check` (the
    conversions and messages of ``System.torque``) and what the controller raises through
    :meth:`raised`. Either keeps the error a run raises in :attr:`error` (None returned to the
    loop), so that the loop stops and :func:`coopdyn.simulate` re-raises it."""

    def __init__(self, system: System) -> None:
        self.system = system
        self.controller = system.controller
        self.error: BaseException | None = None

    def raised(self, t: float, exc: BaseException) -> bool:
        """The controller raised ``exc`` at t: keep what the run raises for it (what naming it
        raises, when it does: as in the Python loop) and return False — or return True for a
        :class:`~coopdyn.errors.GraspGeometryError`, which the loop handles as the compiled
        controllers' (an adaptive method's rejected attempt)."""
        if isinstance(exc, GraspGeometryError):
            return True
        try:
            self.error = self.system.controller_failure(t, exc)
        except BaseException as failure:  # e.g. an exception whose str() raises
            self.error = failure
        return False

    def check(self, t: float, q: np.ndarray, v: np.ndarray, out: object) -> np.ndarray | None:
        """The controller's output ``out`` at (t, q, v), converted and checked; None (the error
        kept) when it is refused."""
        try:
            return self.system.checked_output(out, t, q, v)
        except BaseException as exc:  # Ctrl-C too: re-raised by simulate once the loop has stopped
            self.error = exc
            return None


class Plan(NamedTuple):
    """The compiled loop's configuration, or None and why the run stays in Python."""

    config: dict[str, Any] | None
    why: str


def plan(
    scene: Scene,
    system: System,
    method: Integrator,
    *,
    q0: np.ndarray,
    v0: np.ndarray,
    dt: float,
    t_final: float,
    n_steps: int,
    save_every: int,
    max_speed: float,
    energy_check: str,
    controller: dict[str, Any] | None = None,
) -> Plan:
    """The compiled loop's configuration for this run, or None and why it cannot run compiled
    (``controller``: :func:`controller_settings`, when the caller has them already)."""
    if system.dynamics.backend != "native":
        return Plan(None, "the dynamics run on the Python backend")
    if system.has_object_wrench:
        return Plan(None, "an object_wrench callable is Python code")
    spec = _own_spec(method, error=SimulationError)
    if spec is None:
        return Plan(None, f"the integrator {method!r} has no compiled version")
    if controller is None:
        controller = controller_settings(scene, system)
    if isinstance(spec, ExponentialSpec):  # discretised here, once per step size the run takes
        ws = method.workspace(system)
        last = {k for k in (0, n_steps - 2, n_steps - 1) if 0 <= k < n_steps}
        steps = sorted({min(dt, t_final - k * dt) for k in last})
        discretisations = [(h, *method.discretisation(system, h, ws)) for h in steps]  # type: ignore[attr-defined]
        spec = dataclasses.replace(spec, discretisations=discretisations, n_factor=system.n_factor)
    kp, kd = system.matrix_gains  # (none under a control_dt hold)
    config = {
        **spec.fields(),  # the method family's name and settings, read by its header in src/native/methods/
        "controller": controller,
        "kp": np.asarray(kp, dtype=float),
        "kd": np.asarray(kd, dtype=float),
        "q0": np.asarray(q0, dtype=float),
        "v0": np.asarray(v0, dtype=float),
        "dt": float(dt),
        "t_final": float(t_final),
        "n_steps": int(n_steps),
        "save_every": int(save_every),
        "max_speed": float(max_speed),
        "energy_mode": _ENERGY_MODES[energy_check],
        "energy_every": max(1, round(5e-3 / dt)),
        "energy_rtol": ENERGY_RTOL,
        "rtol": float(getattr(method, "rtol", 0.0)),
        "atol": float(getattr(method, "atol", 0.0)),
        "h_min": float(getattr(method, "h_min", 0.0)),
        "control_dt": 0.0 if system.control_dt is None else float(system.control_dt),
    }
    return Plan(config, "")


def same(a: Any, b: Any) -> bool:
    """Whether two settings are equal to the bit — numbers, strings, arrays (by their bytes: a
    few µs less than ``np.array_equal``), and dicts, lists and tuples of them; any other object
    only to itself (a Python controller's callback). coopdyn.Simulator restarts its last loop
    when the settings of a run are the same as that loop's."""
    kind = type(a)
    if kind is not type(b):
        return False
    if kind in _SCALARS:
        return bool(a == b)
    if kind is np.ndarray:
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if kind is dict:  # (loops, not all() over a generator: 1.5 µs less a run, benchmarks/fixed_cost.py)
        if a.keys() != b.keys():
            return False
        for k, x in a.items():
            if not same(x, b[k]):
                return False
        return True
    if kind is list or kind is tuple:
        if len(a) != len(b):
            return False
        for x, y in zip(a, b, strict=True):
            if not same(x, y):
                return False
        return True
    return a is b


_SCALARS = frozenset((float, int, str, bool))


def controller_settings(scene: Scene, system: System) -> dict[str, Any]:
    """The controller's part of the configuration: its compiled twin's settings, or a callback
    (a controller without a compiled version for this run — Python code, a Python reference or
    drive, or one built for a scene of other arms or frames — is called back from the compiled
    loop). A built-in controller built for a twin of the scene (:func:`twin_scenes`: the same arms,
    joints and frames, other interconnection or object parameters) runs compiled with its own
    settings, as its Python law would: it keeps its own model of the object."""
    controller = system.controller
    spec = NoControllerSpec() if controller is None else _own_spec(controller, scene)
    own = getattr(controller, "scene", None)
    if spec is None and isinstance(own, Scene) and own is not scene and twin_scenes(own, scene):
        spec = _own_spec(controller, own)
    if spec is None:
        spec = PythonControllerSpec(callback=PythonCallback(system))
    return spec.fields()


def controller_gain(system: System, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """∂τ/∂x (n_actuated, 2nv) of the system's controller at (t, q, v) through its compiled twin —
    the steps of :func:`coopdyn.linearize.controller_gain`, equal to it to about 1e-9 of a gain,
    in microseconds where the Python twin takes milliseconds — or None: the Python backend, or a
    controller that would be called back (Python code)."""
    kernel = getattr(system.dynamics, "_kernel", None)
    if kernel is None or system.controller is None:
        return None
    settings = controller_settings(system.dynamics.scene, system)
    if "callback" in settings:
        return None
    probe = kernel_module().Sensitivity(kernel, [], [], True, (), [], [])  # (a symplectic stub: only its controller is used)
    probe.set_controller(kernel, settings)
    return np.asarray(probe.controller_gain(float(t), q, v)[1])


def start_loop(system: System, q: np.ndarray, v: np.ndarray, t: float = 0.0) -> StartLoop | None:
    """:func:`coopdyn.accuracy.start_loop` with the controller's gain from its compiled twin when it
    has one (:func:`controller_gain`), from its Python differences otherwise — what every loop
    diagnosis (a run's loop check, a divergence's, a sensitivity's) takes."""
    try:
        gain = controller_gain(system, t, q, v)
    except Exception:  # (the compiled probe failed: the Python one says so, or gives no loop — never an error)
        gain = None
    return accuracy.start_loop(system, q, v, t, gain=gain)


def twin_scenes(a: Scene, b: Scene) -> bool:
    """Whether two scenes differ only in their interconnections' laws and the object's inertia: the
    same joints and frames, placed alike (every frame's placement equal to 1e-12 m at the start
    and at three other configurations), the same arm bodies, armature and gravity — what a
    controller's kinematics and arm model read."""
    ma, mb = a.model, b.model
    if (ma.nq, ma.nv, ma.njoints, ma.nframes) != (mb.nq, mb.nv, mb.njoints, mb.nframes) or list(ma.names) != list(mb.names):
        return False
    if [f.name for f in ma.frames] != [f.name for f in mb.frames] or [j.shortname() for j in ma.joints] != [
        j.shortname() for j in mb.joints
    ]:
        return False
    da, db = ma.createData(), mb.createData()
    rng = np.random.default_rng(0)
    for q in (a.q0, *(pin.integrate(ma, a.q0, 0.3 * rng.normal(size=ma.nv)) for _ in range(3))):
        pin.framesForwardKinematics(ma, da, q)
        pin.framesForwardKinematics(mb, db, q)
        if any(not np.allclose(x.homogeneous, y.homogeneous, rtol=0, atol=1e-12) for x, y in zip(da.oMf, db.oMf, strict=True)):
            return False
    skip = a.object_joint
    same_bodies = all(
        j == skip or np.array_equal(ia.toDynamicParameters(), ib.toDynamicParameters())
        for j, (ia, ib) in enumerate(zip(ma.inertias, mb.inertias, strict=True))
    )
    return same_bodies and np.array_equal(ma.armature, mb.armature) and np.array_equal(a.gravity, b.gravity)


def next_chunk(steps: int, seconds: float) -> int:
    """The size of the next chunk after one of ``steps`` steps took ``seconds`` of wall time."""
    per_step = seconds / max(steps, 1)
    return int(min(max(CHUNK_SECONDS / max(per_step, 1e-9), 16), 1 << 20))


class Samples(NamedTuple):
    """What a compiled run saved, with its work counters."""

    t: np.ndarray  #: (n,) [s]
    q: np.ndarray  #: (n, nq)
    v: np.ndarray  #: (n, nv)
    tau: np.ndarray  #: (n, n_actuated)
    pending: bool  #: the last sample's torque is not known yet (no step taken from it)
    n_rhs: int
    n_jac: int
    n_factor: int
    n_accepted: int
    n_rejected: int


def samples(loop: Any, scene: Scene) -> Samples:
    """The samples and counters of a compiled run so far."""
    t, Q, V, TAU, pending = loop.samples()
    n_rhs, n_jac, n_factor, n_accepted, n_rejected = (int(c) for c in loop.counters())
    return Samples(
        *rows(t, Q, V, TAU, scene),
        bool(pending),
        n_rhs,
        n_jac,
        n_factor,
        n_accepted,
        n_rejected,
    )


def take_samples(loop: Any, scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, Q, V, TAU) of the samples a compiled run finished since the last take, all but the
    last (whose torque may be pending); the loop forgets them."""
    t, Q, V, TAU = loop.take_samples()
    return rows(t, Q, V, TAU, scene)


def rows(t: Any, Q: Any, V: Any, TAU: Any, scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's sample arrays as (n,), (n, nq), (n, nv), (n, n_actuated) floats (eigenpy
    returns one-row or one-column matrices as vectors)."""
    t = np.asarray(t, dtype=float).reshape(-1)
    n = t.shape[0]
    return (
        t,
        np.asarray(Q, dtype=float).reshape(n, scene.nq),
        np.asarray(V, dtype=float).reshape(n, scene.nv),
        np.asarray(TAU, dtype=float).reshape(n, scene.n_actuated),
    )


__all__ = ["Plan", "Samples", "controller_settings", "next_chunk", "plan", "rows", "same", "samples", "take_samples"]
