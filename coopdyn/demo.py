"""The main job: two Pandas grip, lift and oscillate a box (``coopdyn demo``)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from . import _validate
from .cooperative import GripLiftOscillate, ObjectImpedance
from .errors import DivergenceError, SimulationError, SimulationInterrupted, StepBudgetError
from .metrics import metric_lines, run_metrics
from .outputs import check_folder, save_partial, write_outputs
from .problems.facing_arms import facing_arms, object_start
from .simulate import simulate
from .stepping import MIN_DT
from .viz.plotting import cooperative_figure

STIFFNESS = 1e4  #: interconnection stiffness [N/m]; rotational 1e2 [N·m/rad]
DAMPING = 0.002  #: interconnection damping / stiffness [s]
SQUEEZE = 20.0  #: commanded internal force [N]


def run_demo(
    out: str | os.PathLike[str] = "out/demo",
    *,
    t_final: float = 5.0,
    dt: float = 1e-3,
    integrator: str = "trapezoid",
    html: bool = True,
    progress: bool = True,
) -> dict[str, Any]:
    """Simulate, write plot / HTML / trajectory to ``out``; return the summary (figures and the
    files written; :func:`format_summary` makes it text). On a divergence or Ctrl-C the
    trajectory so far is written and the error re-raised with those paths in ``saved``."""
    out_dir = check_folder(out)  # before the run: a refusal costs nothing yet
    dt = _validate.positive(dt, "dt", "s", SimulationError)
    if dt < MIN_DT:
        raise SimulationError(f"dt must be >= {MIN_DT:g} [s], got {dt!r}")
    scene = facing_arms("panda", stiffness=STIFFNESS, damping=DAMPING)
    task = GripLiftOscillate(start=object_start(scene), squeeze=SQUEEZE)
    controller = ObjectImpedance(scene, task)
    wall0 = time.perf_counter()
    try:
        res = simulate(
            scene,
            t_final,
            controller=controller,
            integrator=integrator,
            dt=dt,
            save_every=max(1, round(0.01 / dt)),  # 100 samples per second
            progress=progress,
        )
    except (DivergenceError, SimulationInterrupted, StepBudgetError) as exc:
        exc.saved = save_partial(exc, out_dir)  # type: ignore[union-attr]
        raise
    wall = time.perf_counter() - wall0
    metrics, notes = run_metrics(res, task)  # the names sweep tables and scene-file runs use
    summary = {
        "duration_s": t_final,
        "integrator": res.integrator,
        "dt_s": dt,
        **metrics,
        "commanded_internal_force_N": SQUEEZE,
        "cpu_s": res.cpu_time,
        "real_time_factor": t_final / wall,
        "wall_s": wall,
        "rhs_evaluations": res.n_rhs,
        "notes": notes,
    }

    def figure(folder: Path) -> Path:
        cooperative_figure(res, task, folder / "demo.png")
        return folder / "demo.png"

    def animation(folder: Path) -> Path:
        from .viz.viewer import export_html

        return export_html(res, folder / "demo.html")

    written = write_outputs(
        out_dir,
        [("trajectory", lambda folder: [res.save(folder / "trajectory.npz"), res.save(folder / "trajectory.csv")])],
        [("plot", figure), *([("animation", animation)] if html else [])],
    )
    summary["files"] = [str(f) for f in written.files]
    summary["problems"] = list(written.problems)
    summary["output_folder"] = str(written.folder)
    return summary


def format_summary(summary: dict[str, Any]) -> str:
    """The demo's summary as the lines ``coopdyn demo`` prints."""
    lines = [
        f"two Pandas, {STIFFNESS:g} N/m interconnections, {summary['integrator']} at dt = {summary['dt_s']:g} s, "
        f"{summary['duration_s']:g} s simulated",
        *metric_lines(summary, commanded_squeeze=SQUEEZE),
        *[f"  {note}" for note in summary.get("notes", ())],
        f"  CPU {summary['cpu_s']:.2f} s, wall {summary['wall_s']:.2f} s: real-time factor {summary['real_time_factor']:.2f}",
    ]
    lines += [f"output folder: {summary['output_folder']}"]
    lines += [f"  wrote {f}" for f in summary["files"]]
    lines += [f"  not written: {p}" for p in summary.get("problems", ())]
    return "\n".join(lines)
