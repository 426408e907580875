"""Matplotlib figures of results (matplotlib is imported lazily)."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._files import write_atomically
from ..accuracy import UNSTABLE_AT_START
from ..errors import SweepError, UnstableLoopWarning
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
    """Write ``fig`` atomically (temporary file, then rename) and close it; the format from the
    file's ending (``.png``, ``.pdf``, ``.svg``, …)."""
    formats = {f".{f}" for f in fig.canvas.get_supported_filetypes()}
    kind = Path(path).suffix.lstrip(".").lower() if isinstance(path, str | os.PathLike) else ""
    try:
        return write_atomically(path, "the figure", lambda tmp: fig.savefig(tmp, dpi=110, format=kind or "png"), formats)
    finally:
        _pyplot().close(fig)


def result_figure(result: Result, reference: Any = None, path: str | os.PathLike[str] | None = None) -> Any:
    """The figure that suits ``result``: the book's Figure 11 for the book's linear system (two
    interconnections, three prismatic coordinates), :func:`cooperative_figure` otherwise."""
    scene = result.scene
    if len(scene.object_v) == 1 and len(scene.links) == 2 and scene.nv == 3:  # a 1-DOF object between two 1-DOF arms
        return book_figure(result, None, path)
    return cooperative_figure(result, reference, path)


#: line styles told apart at a glance, for up to 8 joints of an arm (then they repeat)
JOINT_STYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1, 1, 1)), (0, (1, 3)), (0, (8, 2)), (0, (3, 1, 1, 1)))
ARM_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
AXIS_COLOURS = {"x": "tab:red", "y": "tab:green", "z": "tab:blue"}
PHASE_COLOURS = ("#f2f2f2", "#e3eef9", "#fdf0e0", "#eaf5ea")


def _phases(axes: Any, reference: Any, t_end: float) -> None:
    """Shade the task's phases (``reference.phases()``) on every panel, named on the first."""
    phases = getattr(reference, "phases", None)
    if not callable(phases):
        return
    top = axes[0]
    lo, hi = top.get_ylim()
    top.set_ylim(lo - 0.12 * (hi - lo), hi)  # a strip below the data for the phases' names
    for k, (name, start, end) in enumerate(phases()):
        end = min(end, t_end)
        if end <= start:
            continue
        for ax in axes:
            ax.axvspan(start, end, color=PHASE_COLOURS[k % len(PHASE_COLOURS)], zorder=0, lw=0)
        top.text(
            (start + end) / 2, 0.03, name, transform=top.get_xaxis_transform(), ha="center", va="bottom", fontsize=9, color="0.35"
        )


def cooperative_figure(result: Result, reference: Any = None, path: str | os.PathLike[str] | None = None) -> Any:
    """Motion and forces of any result, one panel each: the object's displacement from its start
    [mm] (with the desired one), every interconnection's force on the object [N], the internal
    (squeeze) force [N] and the joint torques [N·m]. A colour per arm (per axis in the first panel),
    a line style per force component or joint, legends beside the panels; with ``reference(t)``
    (e.g. a :class:`coopdyn.cooperative.GripLiftOscillate`) the desired motion and squeeze are drawn
    and its phases shaded."""
    plt = _pyplot()
    t = result.t
    fig, axes = plt.subplots(4, 1, figsize=(11, 11), sharex=True, layout="constrained")
    obj = result.object_position()
    start = obj[0]
    wanted = [reference(float(s)) for s in t] if reference is not None else []  # one pass over the reference
    for k, c in enumerate("xyz"):
        axes[0].plot(t, (obj[:, k] - start[k]) * 1e3, color=AXIS_COLOURS[c], lw=1.4, label=f"object {c}")
        if wanted:
            desired = np.array([w.position[k] for w in wanted])
            axes[0].plot(t, (desired - start[k]) * 1e3, "--", color=AXIS_COLOURS[c], lw=1, label=f"desired {c}")
    axes[0].set_ylabel("displacement [mm]")
    axes[0].set_title("Object position, from its start [mm]", loc="left", fontsize=10)
    W = result.wrenches()
    colour = {lk.name: ARM_COLOURS[i % len(ARM_COLOURS)] for i, lk in enumerate(result.scene.links)}
    for i, lk in enumerate(result.scene.links):
        for k, c in enumerate("xyz"):
            axes[1].plot(t, W[:, i, k], JOINT_STYLES[k], color=colour[lk.name], lw=1.1, label=f"{lk.name} F{c}")
    axes[1].set_ylabel("force [N]")
    axes[1].set_title("Interconnection forces on the object, world axes [N]", loc="left", fontsize=10)
    sq = result.squeeze()
    for i, lk in enumerate(result.scene.links):
        axes[2].plot(t, sq[:, i], JOINT_STYLES[i % 2], color=colour[lk.name], lw=1.4, label=lk.name)  # equal ones stay visible
    if wanted:
        axes[2].plot(t, [w.squeeze for w in wanted], "k--", lw=1, label="commanded")
    axes[2].set_ylabel("squeeze [N]")
    axes[2].set_title("Internal (squeeze) force at each grasp, positive = compression [N]", loc="left", fontsize=10)
    v_names = result.scene.coordinates()[1]
    for a, arm in enumerate(result.scene.arms):
        c = ARM_COLOURS[a % len(ARM_COLOURS)]
        for j, drive in enumerate(arm.drive_index):
            column = int(np.flatnonzero(result.scene.actuated == drive)[0])  # (an elastic joint's: its motor's)
            joint = v_names[drive].split(" [")[0]
            axes[3].plot(t, result.tau[:, column], linestyle=JOINT_STYLES[j % len(JOINT_STYLES)], color=c, lw=1, label=joint)
    units = {v_names[i].rsplit("[", 1)[-1] for i in result.scene.actuated}
    what = {"rad/s]": "torque [N·m]", "m/s]": "force [N]"}.get(units.pop(), "") if len(units) == 1 else "torque [N·m], force [N]"
    axes[3].set_ylabel(what or "torque [N·m], force [N]")
    axes[3].set_title(
        f"Joint {what.split(' ')[0] or 'torques'}s, a colour per arm, a line style per joint", loc="left", fontsize=10
    )
    axes[3].set_xlabel("time [s]")
    _phases(axes, reference, float(t[-1]) if len(t) else 0.0)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        n = len(ax.get_legend_handles_labels()[1])
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, ncol=1 if n <= 8 else 2, frameon=False)
    arms = ", ".join(a.name for a in result.scene.arms) or "fixtures"
    fig.suptitle(f"{arms} holding the object — {result.integrator}, dt = {result.dt:g} s")
    if path is not None:
        save_figure(fig, path)
    return fig


#: a metric column's unit suffix → (label unit, scale to it)
_UNITS = {"_m": ("mm", 1e3), "_N": ("N", 1.0), "_s": ("s", 1.0), "_Nm": ("N·m", 1.0)}


def column_label(name: str) -> tuple[str, float]:
    """``"tracking_error_max_m"`` → ``("tracking error max [mm]", 1000.0)``: a sweep column's
    name as an axis label, and the factor to its unit."""
    for suffix, (unit, scale) in _UNITS.items():
        if name.endswith(suffix):
            return f"{name[: -len(suffix)].replace('_', ' ')} [{unit}]", scale
    return name.replace("_", " ").replace(".", " "), 1.0


def _tick(value: Any) -> str:
    if isinstance(value, list | tuple | np.ndarray):
        return "(" + ", ".join(_tick(v) for v in value) + ")"
    if isinstance(value, float | np.floating):
        return f"{value:g}"
    return str(value)


def sweep_heatmap(
    table: Any,
    x: str,
    y: str,
    values: Any,
    path: str | os.PathLike[str] | None = None,
    *,
    title: str | None = None,
    xlabel: str | None = None,
    ylabel: str | None = None,
    limits: Mapping[str, float] | None = None,
) -> Any:
    """One heat map per metric of a sweep table over two of its parameters (``x``, ``y``): each
    cell the mean over the cell's completed runs (several with seeds), written in the cell; a
    cell with no completed run is grey and names what happened (diverged, failed, …). A run
    whose loop was unstable from the start — it completed with an ``UnstableLoopWarning``, or
    its divergence says so — counts as an "unstable loop", not as a completed run: its figures
    are an instability's, and another step would give others. A cell
    whose completed runs include one that warned (a non-empty ``warnings`` column: an accuracy,
    energy or scene warning, or a note such as a metric not computed), or one whose |value| of
    any metric in ``limits`` (metric → largest sensible value, in the column's units) passes
    its bound, is hatched in every panel and says how many runs did: a completed run is not
    always a trustworthy one. Values spanning more than a factor 20 get a
    logarithmic colour scale. ``xlabel``/``ylabel`` name the axes (default: the column names)."""
    from matplotlib.colors import LogNorm

    plt = _pyplot()
    if not hasattr(table, "columns") or not hasattr(table, "groupby"):
        raise SweepError(f"sweep_heatmap takes a sweep table (a pandas DataFrame), got {type(table).__name__}")
    values = [values] if isinstance(values, str) else list(values) if isinstance(values, Iterable) else []
    if not values:
        raise SweepError("sweep_heatmap needs the name of at least one metric column in values")
    limits = dict(limits or {})
    for name in (x, y, *values, *limits):
        if name not in table.columns:
            raise SweepError(f"the table has no column {name!r}; columns: {list(table.columns)}")
    for name, bound in limits.items():
        if isinstance(bound, bool) or not isinstance(bound, int | float) or not np.isfinite(bound):
            raise SweepError(f"limits[{name!r}] must be a finite number (the largest sensible value), got {bound!r}")
    if not len(table):
        raise SweepError("the sweep table has no rows to draw")
    tx, ty = table[x].map(_tick), table[y].map(_tick)  # the cells, once for every metric
    xs, ys = list(dict.fromkeys(tx)), list(dict.fromkeys(ty))
    cells = table.groupby([tx, ty], sort=False).indices  # (x tick, y tick) → row positions
    statuses = np.where(_unstable(table), "unstable loop", table["status"].to_numpy())
    completed = statuses == "completed"
    # per cell: its rows, the completed ones, and the other statuses (the same for every metric)
    cell_rows = [[cells.get((xv, yv), np.empty(0, dtype=int)) for xv in xs] for yv in ys]
    notes = [[", ".join(sorted(set(statuses[rows]) - {"completed"})) for rows in row] for row in cell_rows]
    warned = table["warnings"].fillna("").astype(str).str.len().to_numpy() > 0 if "warnings" in table.columns else None
    # per cell: its completed runs that warned or pass a bound (the same in every panel)
    doubts = [[_doubts(table, rows[completed[rows]], warned, limits) for rows in row] for row in cell_rows]
    fig, axes = plt.subplots(
        1,
        len(values),
        figsize=(1.2 + 1.1 * len(xs) * len(values) + 1.6 * len(values), 1.8 + 0.75 * len(ys)),
        constrained_layout=True,
        squeeze=False,
    )
    x_label, y_label = xlabel or column_label(x)[0], ylabel or column_label(y)[0]
    for ax, name in zip(axes[0], values, strict=True):
        label, scale = column_label(name)
        grid = np.full((len(ys), len(xs)), np.nan)
        try:
            column = table[name].to_numpy(dtype=float, na_value=np.nan)
        except (TypeError, ValueError) as exc:
            raise SweepError(f"column {name!r} is not numeric: a heat map draws numbers") from exc
        for i, row in enumerate(cell_rows):
            for j, rows in enumerate(row):
                ok = rows[completed[rows]]
                if len(ok):
                    grid[i, j] = float(np.mean(column[ok])) * scale
        finite = grid[np.isfinite(grid)]
        log = finite.size > 1 and finite.min() > 0 and finite.max() > 20 * finite.min()
        norm = LogNorm(finite.min(), finite.max()) if log else None
        cmap = plt.get_cmap("viridis").with_extremes(bad="#d9d9d9")  # grey: no completed run
        image = ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, aspect="auto", origin="lower", norm=norm)
        for i in range(len(ys)):
            for j in range(len(xs)):
                text = f"{grid[i, j]:.3g}" if np.isfinite(grid[i, j]) else ""
                if notes[i][j]:
                    text = f"{text}\n({notes[i][j]})" if text else notes[i][j]
                if doubts[i][j]:
                    text = f"{text}\n{doubts[i][j]}"
                    ax.add_patch(_hatch(j, i))
                light = np.isfinite(grid[i, j]) and image.norm(grid[i, j]) < 0.5
                ax.text(j, i, text, ha="center", va="center", fontsize=8, color="white" if light else "black")
        ax.set_xticks(range(len(xs)), xs, rotation=30 if max(map(len, xs)) > 6 else 0)
        ax.set_yticks(range(len(ys)), ys)
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        ax.set_title(label, fontsize=10)
        fig.colorbar(image, ax=ax, label=label, shrink=0.9)
    if any(d for row in doubts for d in row):  # (a key to the hatching)
        bounds = ", ".join(f"{column_label(k)[0]} > {v * column_label(k)[1]:g}" for k, v in limits.items())
        fig.supxlabel(
            "hatched: completed runs that warned (the table's warnings column)" + (f" or exceed {bounds}" if bounds else ""),
            fontsize=8,
        )
    if title:
        fig.suptitle(title)
    if path is not None:
        save_figure(fig, path)
    return fig


def _unstable(table: Any) -> np.ndarray:
    """Which runs of a sweep table had a loop unstable from the start: a completed run with an
    UnstableLoopWarning in ``warnings``, or a divergence whose ``message`` says so."""
    rows = len(table)
    said = table["warnings"].fillna("").astype(str) if "warnings" in table.columns else None
    warned = said.str.contains(UnstableLoopWarning.__name__, regex=False).to_numpy() if said is not None else np.zeros(rows, bool)
    warned = warned & (table["status"] == "completed").to_numpy()  # (a run that failed afterwards stays "failed")
    message = table["message"].fillna("").astype(str) if "message" in table.columns else None
    diverged = (
        ((table["status"] == "diverged") & message.str.contains(UNSTABLE_AT_START, regex=False)).to_numpy()
        if message is not None
        else np.zeros(rows, bool)
    )
    return np.asarray(warned | diverged)


def _doubts(table: Any, rows: np.ndarray, warned: np.ndarray | None, limits: Mapping[str, float]) -> str:
    """What makes completed runs ``rows`` doubtful: how many warned, how many pass each bound."""
    n_warned = int(np.count_nonzero(warned[rows])) if warned is not None and len(rows) else 0
    beyond = np.zeros(len(rows), dtype=bool)
    for name, bound in limits.items():
        beyond |= np.abs(table[name].to_numpy(dtype=float, na_value=np.nan)[rows]) > bound
    n_beyond = int(np.count_nonzero(beyond))
    of = f"/{len(rows)} " if len(rows) > 1 else ""
    return "\n".join(
        [*([f"{n_warned if of else ''}{of}warned".strip()] if n_warned else []),
         *([f"{n_beyond if of else ''}{of}beyond bound".strip()] if n_beyond else [])]
    )  # fmt: skip


def _hatch(j: int, i: int) -> Any:
    """A hatched frame over cell (j, i) of an imshow grid."""
    from matplotlib.patches import Rectangle

    return Rectangle((j - 0.5, i - 0.5), 1.0, 1.0, fill=False, hatch="///", edgecolor="#d62728", linewidth=1.5)
