"""Matplotlib figures of results (matplotlib is imported lazily)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .reference import BookSolution
from .simulate import Result


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def book_figure(result: Result, exact: BookSolution | None = None, path: str | os.PathLike[str] | None = None) -> Any:
    """The book's Figure 11 for a linear-book result: Y1, Y2, Y3; Fc1, Fc2; τ1, τ2 against time.

    With ``exact`` (the solution at ``result.t``) a fourth panel shows the pipeline's deviation
    from it. Returns the figure; writes a PNG when ``path`` is given.
    """
    from .scenes import book_positions

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
