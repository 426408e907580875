"""The book's linear cooperative system (Figure 11): grip, lift, oscillate, against the exact solution."""

from __future__ import annotations

import sys

import numpy as np

import coopdyn as cd
from coopdyn.viz.plotting import book_figure

T_FINAL = 3.0  # [s]
DT = 1e-4  # [s]
SQUEEZE = 100.0  # internal force to grip with [N]
OUT = "out/linear_book.png"


def main(t_final: float = T_FINAL, out: str = OUT) -> float:
    """Simulate, compare with the exact solution, plot; return max |ΔY| [m]."""
    params = cd.reference.BookParameters()  # the book's values: m = 25 kg, c_p = 2e4 N/m, ...
    scene = cd.scenes.linear_book()
    drive1, drive2 = cd.scenes.book_task(params, squeeze=SQUEEZE)
    res = cd.simulate(scene, t_final, controller=cd.scenes.drives_controller(drive1, drive2), dt=DT, save_every=10)
    exact = cd.reference.linear_book_exact(res.t, drive1, drive2, params)
    error = float(np.max(np.abs(cd.scenes.book_positions(res.q, scene) - exact.Y)))
    print(f"max |Y - Y_exact| = {error:.2e} m; internal force at the end = {0.5 * (exact.Fc1[-1] - exact.Fc2[-1]):.2f} N")
    book_figure(res, exact, out)
    print(f"wrote {out}")
    return error


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
