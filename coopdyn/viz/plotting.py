"""Matplotlib figures of results (matplotlib is imported lazily)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..problems.linear_book import BookSolution
from ..result import Result


def _pyplot() -> Any:
    from .._optional import require

    require("matplotlib", "plotting", "matplotlib").use("Agg")
    return require("matplotlib.pyplot", "plotting", "matplotlib")


def book_figure(result: Result, exact: BookSolution | None = None, path: str | os.PathLike[str] | None = None) -> Any:
    """The book's Figure 11 for a linear-book result: Y1, Y2, Y3; Fc1, Fc2; τ1, τ2 against time.

    With ``exact`` (the solution at ``result.t``) a fourth panel shows the pipeline's deviation
    from it. Returns the figure; writes a PNG when ``path`` is given.
    """
    from ..problems.linear_book import book_positions

    plt = _pyplot()
    n = 4 if exact is not None else 3
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.6 * n), sharex=True, constrained_layout=True)
    t = result.t
    Y = book_positions(result.q, result.scene)
    for i, label in enumerate(("Y1 (tip 1)", "Y2 (object)", "Y3 (tip 2)")):
        axes[0].plot(t, Y[:, i], label=label)
    axes[0].set_ylabel("position [m]")
    Fc1, Fc2 = result.wrench(0)[:, 2], result.wrench(1)[:, 2]
    axes[1].plot(t, Fc1, label="Fc1 (spring p on object)")
    axes[1].plot(t, Fc2, label="Fc2 (spring k on object)")
    axes[1].plot(t, 0.5 * (Fc1 - Fc2), "--", label="internal (squeeze) ½(Fc1 − Fc2)")
    axes[1].set_ylabel("contact force [N]")
    axes[2].plot(t, result.tau[:, 0], label="τ1")
    axes[2].plot(t, result.tau[:, 1], label="τ2")
    axes[2].set_ylabel("drive [N]")
    if exact is not None:
        axes[3].semilogy(t, np.maximum(np.max(np.abs(Y - exact.Y), axis=1), 1e-18), label="max |ΔY| [m]")
        dF = np.maximum(np.abs(Fc1 - exact.Fc1), np.abs(Fc2 - exact.Fc2))
        axes[3].semilogy(t, np.maximum(dF, 1e-18), label="max |ΔFc| [N]")
        axes[3].set_ylabel("vs exact solution")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"Linear cooperative system (book eq. 45/46): {result.integrator}, dt = {result.dt:g} s")
    if path is not None:
        save_figure(fig, path)
    return fig


def save_figure(fig: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``fig`` atomically (temporary file, then rename) and close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    os.replace(tmp, path)
    _pyplot().close(fig)
    return path


def result_figure(result: Result, reference: Any = None, path: str | os.PathLike[str] | None = None) -> Any:
    """The figure that suits ``result``: the book's Figure 11 for the book's linear system (two
    interconnections, three prismatic coordinates), :func:`cooperative_figure` otherwise."""
    scene = result.scene
    if scene.object.joint == "prismatic" and len(scene.links) == 2 and scene.nv == 3:
        return book_figure(result, None, path)
    return cooperative_figure(result, reference, path)


def cooperative_figure(result: Result, reference: Any = None, path: str | os.PathLike[str] | None = None) -> Any:
    """Figure-11-style plot of any result: object and tool positions, interconnection forces,
    internal (squeeze) force, joint torques against time. ``reference(t)`` (e.g. a
    :class:`coopdyn.cooperative.GripLiftOscillate`) adds the desired object position."""
    plt = _pyplot()
    t = result.t
    fig, axes = plt.subplots(4, 1, figsize=(9, 11), sharex=True, constrained_layout=True)
    obj = result.object_position()
    for k, c in enumerate("xyz"):
        (line,) = axes[0].plot(t, obj[:, k], label=f"object {c}")
        if reference is not None:
            axes[0].plot(t, [reference(s).position[k] for s in t], "--", color=line.get_color(), lw=1, label=f"desired {c}")
    for arm in result.scene.arms:
        axes[0].plot(t, result.tip_position(arm.name)[:, 2], ":", label=f"{arm.name} tool z")
    axes[0].set_ylabel("position [m]")
    W = result.wrenches()
    for i, lk in enumerate(result.scene.links):
        name = lk.name
        for k, c in enumerate("xyz"):
            axes[1].plot(t, W[:, i, k], label=f"{name} F{c}")
    axes[1].set_ylabel("interconnection force\non the object [N]")
    sq = result.squeeze()
    for i, lk in enumerate(result.scene.links):
        axes[2].plot(t, sq[:, i], label=lk.name)
    if reference is not None:
        axes[2].plot(t, [reference(s).squeeze for s in t], "k--", lw=1, label="commanded")
    axes[2].set_ylabel("internal (squeeze)\nforce [N]")
    joints = [n for a in result.scene.arms for n in a.joint_names]
    for j in range(result.tau.shape[1]):
        axes[3].plot(t, result.tau[:, j], lw=0.8, label=joints[j] if j < len(joints) else str(j))
    axes[3].set_ylabel("joint torque [N·m]")
    axes[3].set_xlabel("time [s]")
    for ax in axes[:3]:
        ax.legend(loc="best", fontsize=7, ncol=3)
    axes[3].legend(loc="upper left", fontsize=5, ncol=7)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"{', '.join(a.name for a in result.scene.arms)} holding the object: {result.integrator}, dt = {result.dt:g} s")
    if path is not None:
        save_figure(fig, path)
    return fig
