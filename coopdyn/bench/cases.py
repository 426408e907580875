"""Benchmark cases: scenes with their controllers and reference trajectories, and the row type
of the work–precision table."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from ..control import GravityCompensationPD, GripLiftOscillate, ObjectImpedance
from ..errors import SimulationError
from ..integrators import INTEGRATORS
from ..model.elastic_joints import JointElasticity
from ..model.scene import Scene
from ..problems.facing_arms import facing_arms, object_start
from ..problems.linear_book import BookParameters, Drive, book_task, drives_controller, linear_book, linear_book_exact
from ..result import Result
from ..simulate import simulate

OUTPUT_INTERVAL = 0.01  #: errors are compared on this output grid [s]


@dataclass(frozen=True)
class Case:
    """A benchmark scene with its controller and its reference trajectory."""

    name: str
    scene: Scene
    controller: Callable[[float, np.ndarray, np.ndarray], np.ndarray]
    t_final: float
    v0: np.ndarray
    reference: Callable[[Result], tuple[np.ndarray, np.ndarray]]  #: (object positions, wrench forces) on res.t
    reference_note: str
    book: tuple[BookParameters, Drive, Drive] | None = None  #: the linear case's parameters and drives (for peers)


@dataclass(frozen=True)
class Row:
    """One point of the work–precision chart."""

    scene: str
    method: str
    setting: str  #: "dt=…" or "rtol=…"
    dt: float
    rtol: float
    position_error: float  #: max |Δ object position| over the output grid [m] (inf: diverged)
    wrench_error: float  #: max |Δ interconnection force| over the output grid [N]
    cpu_per_sim_s: float  #: median CPU seconds per simulated second
    n_rhs: int
    n_factor: int
    stable: bool
    energy_flag: bool  #: the energy monitor warned


def _forces(res: Result) -> np.ndarray:
    return np.stack([res.wrench(i)[:, :3] for i in range(len(res.scene.links))], axis=1)


def linear_case(t_final: float = 3.0) -> Case:
    """The book's linear system with the grip/lift/oscillate drives; exact reference."""
    params = BookParameters()
    scene = linear_book(**asdict(params))
    d1, d2 = book_task(params)

    def reference(res: Result) -> tuple[np.ndarray, np.ndarray]:
        ex = linear_book_exact(res.t, d1, d2, params)
        forces = np.zeros((res.t.size, 2, 3))
        forces[:, 0, 2], forces[:, 1, 2] = ex.Fc1, ex.Fc2
        return np.column_stack([np.zeros_like(ex.t), np.zeros_like(ex.t), ex.Y[:, 1]]), forces

    return Case("linear", scene, drives_controller(d1, d2), t_final, scene.v0, reference, "exact (expm)", (params, d1, d2))


def panda_case(stiffness: float, t_final: float = 0.2, reference_rtol: float = 1e-11, n_arms: int = 2) -> Case:
    """Two Pandas (``n_arms``; one: a 7-link revolute chain the box hangs from) holding a 2 kg
    box, joint PD 50/5 + gravity compensation, perturbed start; reference: Dormand–Prince at a
    tight tolerance."""
    scene = facing_arms("panda", stiffness=stiffness, n_arms=n_arms)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.3
    reference = _tight_reference(scene, ctrl, t_final, v0, reference_rtol)
    note = f"dopri5 rtol={reference_rtol:g}"
    name = f"pandas k={stiffness:.0e}" if n_arms == 2 else f"{n_arms} panda{'s' * (n_arms > 1)} k={stiffness:.0e}"
    return Case(name, scene, ctrl, t_final, v0, reference, note)


def _tight_reference(
    scene: Scene, ctrl: Callable[..., np.ndarray], t_final: float, v0: np.ndarray, rtol: float
) -> Callable[[Result], tuple[np.ndarray, np.ndarray]]:
    """A case's reference: Dormand–Prince at ``rtol`` on the output grid; returns what
    :attr:`Case.reference` gives a run (object positions, wrench forces), refusing another grid."""
    ref = simulate(
        scene,
        t_final,
        controller=ctrl,
        integrator=INTEGRATORS["dopri5"](rtol=rtol, atol=rtol * 1e-2),  # type: ignore[call-arg]
        dt=OUTPUT_INTERVAL,
        v0=v0,
        energy_check="off",
        max_steps=None,
    )
    ref_pos, ref_forces = ref.object_position(), _forces(ref)

    def reference(res: Result) -> tuple[np.ndarray, np.ndarray]:
        if res.t.size != ref.t.size or np.max(np.abs(res.t - ref.t)) > 1e-9:
            raise SimulationError("benchmark runs must save on the reference's output grid")
        return ref_pos, ref_forces

    return reference


#: the task benchmark's pace: the demo's grip, lift and oscillation compressed into 1.2 s
TASK_PACE = dict(squeeze=20.0, t_grip=0.2, t_lift=0.3, lift_duration=0.4, t_osc=0.7, frequency=2.0, cycles=1.0)
#: the task benchmark's interconnection damping, as the demo's: D = 0.002 s · K
TASK_DAMPING = 0.002


#: the elastic joints of the task benchmark's elastic variant (examples/elastic_joints.py's)
ELASTIC_JOINTS = JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0)


def task_case(
    stiffness: float, t_final: float = 1.25, reference_rtol: float = 1e-11, joints: JointElasticity | None = None
) -> Case:
    """The demo's task as a benchmark: two Pandas grip a 2 kg box (20 N squeeze), lift it 0.1 m
    and oscillate it one cycle at 2 Hz (:data:`TASK_PACE`, 1.2 s), damped interconnections
    (D = 0.002 s · K) at ``stiffness`` [N/m], ObjectImpedance, from rest at the scene's start:
    the realistic regime, where the spring modes are excited only weakly; reference:
    Dormand–Prince at a tight tolerance. ``joints``: every joint of both arms elastic
    (:class:`coopdyn.JointElasticity`), the same task through the motors."""
    scene = facing_arms("panda", stiffness=stiffness, damping=TASK_DAMPING)
    if joints is not None:
        scene = Scene([a.replace(elasticity=joints) for a in scene.arm_specs], scene.object, scene.interconnection_specs)
    ctrl = ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene), **TASK_PACE))
    v0 = np.zeros(scene.nv)
    reference = _tight_reference(scene, ctrl, t_final, v0, reference_rtol)
    name = f"task k={stiffness:.0e}" + (", elastic joints" if joints is not None else "")
    return Case(name, scene, ctrl, t_final, v0, reference, f"dopri5 rtol={reference_rtol:g}")
