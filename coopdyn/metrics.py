"""The numbers a run is judged by, under one set of names at every front door: the summary of
``coopdyn demo`` (and its JSON), of ``coopdyn simulate`` on a scene file, and the columns of a
sweep table.

Each name carries its unit: ``_m`` metres, ``_N`` newtons.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from .result import Result

#: the metrics of a completed run, in the order they are printed and tabled (the tracking ones
#: need the object's reference; the internal-force ones two or more interconnections; the force
#: error a run the accuracy screen could not clear)
METRICS = (
    "tracking_error_max_m",
    "tracking_error_rms_m",
    "peak_internal_force_N",
    "internal_force_end_N",
    "peak_interconnection_force_N",
    "force_error_estimate_N",
)


class Metrics(NamedTuple):
    """What :func:`run_metrics` found (unpacks as ``values, notes``)."""

    values: dict[str, float]  #: by the names of :data:`METRICS`; those that could not be computed absent
    notes: list[str]  #: why an absent one is absent


def run_metrics(result: Result, reference: Callable[[float], Any] | None = None) -> Metrics:
    """The metrics of ``result`` (and notes on those that could not be computed): object
    tracking error [m] against ``reference(t)`` (max and rms over the samples), peak and final
    internal (squeeze) force [N] with two or more interconnections (the final one the mean over
    the grasps), the peak interconnection force [N], and for a checked run the force error found
    against its reference run [N] (``Result.force_error_estimate``)."""
    out: dict[str, float] = {}
    notes: list[str] = []
    scene = result.scene
    if callable(reference):
        try:
            e = result.tracking_error(reference)
            out["tracking_error_max_m"] = float(e.max())
            out["tracking_error_rms_m"] = float(np.sqrt(np.mean(e**2)))
        except Exception as exc:
            notes.append(f"tracking error not computed: {type(exc).__name__}: {exc}")
    try:
        if len(scene.links) > 1:
            squeeze = result.squeeze()
            out["peak_internal_force_N"] = float(np.max(np.abs(squeeze)))
            out["internal_force_end_N"] = float(np.mean(squeeze[-1]))
        if scene.links:
            out["peak_interconnection_force_N"] = float(np.max(np.linalg.norm(result.wrenches()[..., :3], axis=-1)))
    except Exception as exc:
        notes.append(f"force metrics not computed: {type(exc).__name__}: {exc}")
    if result.force_error_estimate is not None:
        out["force_error_estimate_N"] = float(result.force_error_estimate)
    return Metrics(out, notes)


def metric_lines(metrics: dict[str, Any], commanded_squeeze: float | None = None) -> list[str]:
    """The metrics as the CLI prints them (indented lines; those absent are left out)."""
    lines = []
    if "tracking_error_max_m" in metrics:
        lines.append(
            f"  object tracking error: max {metrics['tracking_error_max_m'] * 1e3:.2f} mm, "
            f"rms {metrics['tracking_error_rms_m'] * 1e3:.2f} mm"
        )
    if "internal_force_end_N" in metrics:
        commanded = f" (commanded {commanded_squeeze:g} N)" if commanded_squeeze is not None else ""
        lines.append(
            f"  internal force: peak {metrics['peak_internal_force_N']:.2f} N, at the end "
            f"{metrics['internal_force_end_N']:.3f} N{commanded}"
        )
    if "peak_interconnection_force_N" in metrics:
        lines.append(f"  peak interconnection force: {metrics['peak_interconnection_force_N']:.2f} N")
    if "force_error_estimate_N" in metrics and metrics["force_error_estimate_N"] is not None:
        lines.append(f"  interconnection force error against the reference run: max {metrics['force_error_estimate_N']:.3g} N")
    return lines


__all__ = ["METRICS", "Metrics", "metric_lines", "run_metrics"]
