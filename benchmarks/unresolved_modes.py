"""Force error of stable methods against |λ|·dt: where a step stops resolving a mode.

The book's linear system with undamped interconnections (d_k = 0) at three stiffnesses, driven
by the book's grip / lift / oscillate task over 3 s, against its exact solution. Prints, per
method and step, |λ|·dt of the fastest oscillatory mode and the largest interconnection-force
error. It sets ``coopdyn.stability.RESOLVE_LIMIT``: from |λ|·dt ≈ 1 on, the error no longer
falls with dt — it is the mode's whole force swing.

Run: ``.venv/bin/python benchmarks/unresolved_modes.py``
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

import coopdyn as cd
from coopdyn import scenes
from coopdyn.problems.linear_book import BookParameters, linear_book_exact


def main() -> None:
    warnings.simplefilter("ignore", cd.AccuracyWarning)
    base = BookParameters()
    print(f"{'c_k [N/m]':>10} {'|λ| [1/s]':>10} {'dt [s]':>8} {'|λ|·dt':>7} {'method':>15} {'force error [N]':>16}")
    for c_k in (base.c_k, base.c_k * 100, base.c_k * 1e4):
        p = dataclasses.replace(base, c_k=c_k, d_k=0.0)
        scene = scenes.linear_book(**{f.name: getattr(p, f.name) for f in dataclasses.fields(p)})
        d1, d2 = scenes.book_task(p)
        controller = scenes.drives_controller(d1, d2)
        rate = cd.advise(scene).oscillation.rate
        for dt in (1e-4, 3e-4, 1e-3, 3e-3, 1e-2):
            for method in ("implicit_euler", "trapezoid"):
                res = cd.simulate(
                    scene, 3.0, controller=controller, integrator=method, dt=dt, save_every=max(1, round(0.01 / dt))
                )
                exact = linear_book_exact(res.t, d1, d2, p)
                error = max(np.max(np.abs(res.wrench(0)[:, 2] - exact.Fc1)), np.max(np.abs(res.wrench(1)[:, 2] - exact.Fc2)))
                print(f"{c_k:10.0e} {rate:10.4g} {dt:8.0e} {rate * dt:7.2f} {method:>15} {error:16.3g}")


if __name__ == "__main__":
    main()
