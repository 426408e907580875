"""Benchmark output: CSV files, charts and text tables."""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

from .cases import Row


def write_csv(rows: Sequence[Any], path: Path) -> Path:
    """Write dataclass rows or dicts as CSV, atomically."""
    dicts = [asdict(r) if hasattr(r, "__dataclass_fields__") else dict(r) for r in rows]
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(dicts[0]))
        writer.writeheader()
        writer.writerows(dicts)
    os.replace(tmp, path)
    return path


def read_csv(path: str | os.PathLike[str]) -> list[Row]:
    """Rows written by :func:`write_csv` (e.g. to re-plot a finished run)."""
    types = {f.name: f.type for f in fields(Row)}
    convert: dict[str, Callable[[str], Any]] = {"str": str, "float": float, "int": int, "bool": lambda x: x == "True"}
    with open(path, newline="") as f:
        return [Row(**{k: convert[str(types[k])](v) for k, v in d.items()}) for d in csv.DictReader(f)]


def _short(x: float) -> str:
    """1e4 for 10000.0, 2.5e5 for 250000.0: a stiffness as people write it."""
    mantissa, exponent = f"{x:.3e}".split("e")
    return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"


#: line and marker of each peer simulator's runs in the charts (coopdyn's are solid with dots)
_PEER_STYLES = {"mujoco": "x--", "drake": "s:", "exudyn": "^-."}


def plot_work_precision(rows: Sequence[Row], path: Path) -> Path:
    """Log–log wrench error vs CPU per simulated second, one panel per scene; × marks divergence."""
    from ..viz.plotting import _pyplot, save_figure

    plt = _pyplot()
    names = list(dict.fromkeys(r.scene for r in rows))
    methods = list(dict.fromkeys(r.method for r in rows))
    palette = (*plt.get_cmap("tab10").colors, "black", "#999999", "#b8860b", "#00ced1", "#8b008b")
    colour = {m: palette[i % len(palette)] for i, m in enumerate(methods)}  # one colour per method in every panel
    most = max((len({r.method for r in rows if r.scene == n and not r.stable}) for n in names), default=0)
    height = 4.2 + 0.1 * most  # (room for the divergence notes under the panels)
    fig, axes = plt.subplots(1, len(names), figsize=(5 * len(names), height), constrained_layout=True, squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        notes = []
        for method in dict.fromkeys(r.method for r in rows if r.scene == name):
            pts = [r for r in rows if r.scene == name and r.method == method and r.stable]
            if pts:
                style = _PEER_STYLES.get(method.split()[0], "o-")  # coopdyn solid; each peer its own line and marker
                if method.endswith("(Python callbacks)"):
                    style = "+:"  # a peer paying Python per evaluation: thin, dotted
                ax.loglog(
                    [r.cpu_per_sim_s for r in pts],
                    [max(r.wrench_error, 1e-16) for r in pts],
                    style,
                    label=method,
                    ms=4,
                    color=colour[method],
                )
            bad = [r for r in rows if r.scene == name and r.method == method and not r.stable]
            if bad:  # one line per method: how many of its settings diverged, from which step up
                steps = [r.dt for r in bad if r.setting.startswith("dt=")]
                where = f" (dt ≥ {min(steps):.3g} s)" if len(steps) == len(bad) else ""
                notes.append(f"× {method}: {len(bad)} of {len(bad) + len(pts)} settings diverged{where}")
        ax.set_title(re.sub(r"k=([0-9.eE+-]+)", lambda m: f"k = {_short(float(m.group(1)))} N/m", name))  # with units
        ax.set_xlabel("CPU s per simulated s")
        if notes:  # under the panel, not over its lower-left corner, where the tightest runs are drawn
            ax.annotate(
                "\n".join(notes),
                xy=(0.0, 0.0),
                xycoords=("axes fraction", ax.xaxis.label),
                xytext=(0, -4),
                textcoords="offset points",
                ha="left",
                va="top",
                fontsize=6,
                color="red",
            )
        ax.set_ylabel("max interconnection force error [N]")
        ax.grid(True, which="both", alpha=0.3)
    handles: dict[str, Any] = {}
    for ax in axes[0]:  # one legend for all panels: a method has one colour everywhere
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(label, handle)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncol=min(len(handles), 6), fontsize=8)
    return save_figure(fig, path)


def plot_stability(points: Sequence[dict[str, Any]], path: Path) -> Path:
    """Largest stable dt vs stiffness per method (predicted lines, measured markers)."""
    from ..viz.plotting import _pyplot, save_figure

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2), constrained_layout=True)
    for method in dict.fromkeys(p["method"] for p in points):
        pts = [p for p in points if p["method"] == method]
        ks = [p["k"] for p in pts]
        if all(math.isinf(p["predicted_dt"]) for p in pts):
            ax.loglog(ks, [p["measured_dt"] for p in pts], "s--", label=f"{method}: stable at every dt tried (≤ 5 ms)")
            continue
        (line,) = ax.loglog(ks, [p["predicted_dt"] for p in pts], "-", label=f"{method} predicted (advise)")
        ax.loglog(ks, [p["measured_dt"] for p in pts], "o", color=line.get_color(), label=f"{method} measured (bisection)")
    ax.set_xlabel("interconnection stiffness k [N/m] (rotational 0.01·k)")
    ax.set_ylabel("largest stable dt [s]")
    ax.set_title("Two Pandas + 2 kg box, joint PD 50/5")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)


def _best_to_reach(rows: Sequence[Row], tol: float) -> Row | None:
    """The cheapest stable row with a force error ≤ tol [N] that the energy monitor did not flag."""
    good = [r for r in rows if r.stable and not r.energy_flag and r.wrench_error <= tol]
    return min(good, key=lambda r: r.cpu_per_sim_s, default=None)


def format_rows(rows: Sequence[Row]) -> str:
    """The work–precision table as text."""
    head = (
        f"{'scene':<14} {'method':<17} {'setting':<13} {'pos err [m]':>11} {'force err [N]':>13} "
        f"{'CPU s/sim s':>11} {'RHS':>8} {'fact':>6}  ok"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        ok = "yes" if r.stable else "DIVERGED"
        if r.stable and r.energy_flag:
            ok = "energy!"
        lines.append(
            f"{r.scene:<14} {r.method:<17} {r.setting:<13} {r.position_error:>11.3e} {r.wrench_error:>13.3e} "
            f"{r.cpu_per_sim_s:>11.4f} {r.n_rhs:>8d} {r.n_factor:>6d}  {ok}"
        )
    return "\n".join(lines)


def format_peers(rows: Sequence[Row]) -> str:
    """What the peers reached on the linear case, next to coopdyn's best, at 1e-6 N and 1e-5 N."""
    from .peers import mujoco_available

    lines = []
    mine = [r for r in rows if r.scene == "linear" and not r.method.startswith("mujoco")]
    peers = [r for r in rows if r.scene == "linear" and r.method.startswith("mujoco")]
    if not peers:
        lines.append("peers: MuJoCo " + ("ran on no scene" if mujoco_available() else "is not installed (pip install mujoco)"))
    for tol in (1e-5, 1e-6):
        for who, pool in (("coopdyn", mine), ("MuJoCo", peers)):
            if not pool:
                continue
            best = _best_to_reach(pool, tol)
            lines.append(
                f"linear case, least CPU for a force error ≤ {tol:g} N over 3 s, {who}: "
                + (
                    f"{best.method} {best.setting}: {best.cpu_per_sim_s * 3.0 * 1e3:.1f} ms (error {best.wrench_error:.2e} N)"
                    if best
                    else "not reached in the sweep"
                )
            )
    lines.append("peers on the Panda scenes: coopdyn bench --peers")
    return "\n".join(lines)


def format_timing(timing: dict[str, dict[str, float]]) -> str:
    """The per-call costs of :func:`rhs_timing`, one column per backend, with the ratio."""
    names = list(timing)
    labels = {
        "rhs_us": "right-hand side",
        "implicit_terms_us": "implicit terms (f, M, K̃, D̃)",
        "implicit_euler_step_us": "implicit_euler step (incl. PD)",
    }
    head = f"{'two Pandas, nv = 20 [µs per call]':<36}" + "".join(f"{n:>10}" for n in names)
    if len(names) == 2:
        head += f"{'ratio':>8}"
    lines = [head, "-" * len(head)]
    for key, label in labels.items():
        line = f"{label:<36}" + "".join(f"{timing[n][key]:>10.1f}" for n in names)
        if len(names) == 2:
            line += f"{timing[names[0]][key] / timing[names[1]][key]:>7.1f}×"
        lines.append(line)
    lines.append("(medians of 7 blocks, backends interleaved)")
    return "\n".join(lines)


def format_implicit_cost(cost: dict[tuple[str, float, int], tuple[float, bool]]) -> str:
    """The whole-run costs of implicit_euler at dt = 1 ms, one line per backend and setting."""
    ks = sorted({k for _, k, _ in cost})
    head = f"{'implicit_euler, dt = 1 ms [CPU s / sim s]':<44}" + "".join(f"{f'k={k:.0e}':>10}" for k in ks)
    lines = [head, "-" * len(head)]
    for name, every in dict.fromkeys((b, e) for b, _, e in cost):
        label = f"{name}, Jacobian every {'step' if every == 1 else f'{every} steps'}"
        cells = []
        for k in ks:
            value, ok = cost[(name, k, every)]
            cells.append(f"{value:>9.4f}{' ' if ok else '!'}")
        lines.append(f"{label:<44}" + "".join(cells))
    lines.append("(PD controller and energy monitor included; median of 5 runs of 1 s; ! = unstable)")
    return "\n".join(lines)


def format_stability(points: Sequence[dict[str, Any]]) -> str:
    """The stability table as text."""
    lines = [f"{'k [N/m]':>8} {'method':<17} {'ω_max [rad/s]':>13} {'predicted dt':>13} {'measured dt':>12}"]
    for p in points:
        pred = "any" if math.isinf(p["predicted_dt"]) else f"{p['predicted_dt'] * 1e3:.4g} ms"
        meas = f"{p['measured_dt'] * 1e3:.4g} ms" + (" (max tried)" if math.isinf(p["predicted_dt"]) else "")
        lines.append(f"{p['k']:>8.0e} {p['method']:<17} {p['omega_max']:>13.4g} {pred:>13} {meas:>12}")
    return "\n".join(lines)
