"""The held strip (examples/flexible_beam.py) at the step its modes need: the figures the
example, its docs and the CHANGELOG quote, from one command.

* the largest real part of the linearised closed loop's eigenvalues [1/s] at the start, and its
  least damped oscillating mode, for ObjectImpedance's default gains read at the tool frames
  (the example), the same without the internal moments, at the strip's middle node, and for the
  example's former gains at the middle node;
* the example's settings (trapezoid, 1 ms) against 50 µs: sag range, grasp-force peak, tracking;
  the same without the internal moments (``internal=(0, 0)``);
* the default gains at the middle node, resolved (trapezoid, 50 µs): how the unstable loop ends;
* the example's former gains (500 N/m, 30 N·s/m, middle node) resolved (trapezoid, 0.1 ms): the
  unstable swing;
* the example resolved over 12 s (trapezoid, 0.25 ms): the sag range in each 2 s window
  (it settles once the task ends at 4.25 s);
* the former setting under implicit Euler at 1 ms with the accuracy check on: the warning's
  force error and the span its reference covered;
* ``advise_model``'s CPU per simulated second for the elastic model against a measured run;
* the gains tried: the linearised closed loop's largest real part, read at the tool frames, over
  object stiffnesses 500 … 1e5 N/m (damping 0.06 s × stiffness, as the defaults), on the held
  strip and on the planar arms' beam;
* examples/planar_beam.py at its settings (trapezoid, 1 ms) against 0.1 ms and 50 µs (forces,
  sag), and its start transient: the sag's range over 0–0.1 s and over 0.4–0.5 s;
* with ``--memory``: the resident memory Pinocchio's ``createData`` adds for a 64-element strip
  (about 2 GB: its nv³ derivative tensors).

    .venv/bin/python benchmarks/flexible_beam_check.py [--memory]      # about 3 min
"""

from __future__ import annotations

import argparse
import resource
import sys
import warnings
from pathlib import Path

import numpy as np

import coopdyn as cd
from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
from coopdyn.scenes import held_beam, object_start

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import planar_beam
from flexible_beam import deflection

GAINS: dict = {}  # the example's: ObjectImpedance's defaults, read at the tool frames (its default for a strip)
AT_MIDDLE = {"measure": "object"}  # the same gains fed back at the strip's middle node
NO_INTERNAL = {"internal": (0.0, 0.0)}  # read at the tool frames, without the internal moments
FORMER = {"stiffness": (500.0, 10.0), "damping": (30.0, 0.5), "measure": "object"}  # the example's gains before


def _task(scene: cd.Scene) -> GripLiftOscillate:
    return GripLiftOscillate(start=object_start(scene), squeeze=5.0, amplitude=0.02, frequency=1.5, axis=(0.0, 0.0, 1.0))


def _run(gains: dict, integrator: str, dt: float, t_final: float = 5.0, check: str = "off") -> cd.Result:
    scene = held_beam()
    controller = ObjectImpedance(scene, _task(scene), **gains)
    return cd.simulate(
        scene, t_final, controller=controller, integrator=integrator, dt=dt, save_every=max(1, round(1e-2 / dt)),
        accuracy_check=check,
    )  # fmt: skip


def _line(label: str, res: cd.Result) -> str:
    sag = deflection(res)
    force = np.abs(res.wrenches()[..., :3]).max()
    track = res.tracking_error(_task(res.scene)).max()
    return (
        f"{label:44s} sag {sag.min() * 1e3:7.2f} … {sag.max() * 1e3:7.2f} mm, grasp force peak {force:7.2f} N, "
        f"tracking max {track * 1e3:6.1f} mm"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--memory", action="store_true", help="also measure createData of a 64-element strip (~2 GB)")
    args = parser.parse_args()
    scene = held_beam()
    cases = (
        ("defaults at the tool frames (example)", GAINS),
        ("the same without internal moments", NO_INTERNAL),
        ("defaults at the middle node", AT_MIDDLE),
        ("former gains at the middle node", FORMER),
    )
    for label, gains in cases:
        lam = cd.linearize(scene, controller=ObjectImpedance(scene, **gains)).eigenvalues
        top = lam[np.argmax(lam.real)]
        osc = lam[lam.imag > 1.0]
        low = osc[np.argmin(-osc.real / np.abs(osc))]
        print(
            f"closed loop at the start, {label:38s}: largest Re λ {top.real:8.3g} /s ({abs(top.imag) / (2 * np.pi):.0f} Hz); "
            f"least damped: {low.imag / (2 * np.pi):.0f} Hz, ζ = {-low.real / abs(low):.2%}"
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mine, fine = _run(GAINS, "trapezoid", 1e-3), _run(GAINS, "trapezoid", 5e-5)
        print(_line("example: trapezoid 1 ms", mine))
        print(_line("example gains: trapezoid 50 µs", fine))
        df = np.abs(mine.wrenches()[..., :3] - fine.wrenches()[..., :3]).max()
        dsag = np.abs(deflection(mine) - deflection(fine)).max()
        print(f"  1 ms against 50 µs: forces within {df:.3f} N, sag within {dsag * 1e3:.3f} mm")
        print(_line("without internal moments: trapezoid 1 ms", _run(NO_INTERNAL, "trapezoid", 1e-3)))
        try:
            print(_line("defaults at the middle node: trapezoid 50 µs", _run(AT_MIDDLE, "trapezoid", 5e-5)))
        except cd.DivergenceError as exc:
            print(f"{'defaults at the middle node: trapezoid 50 µs':44s} diverged: {str(exc)[:120]}")
        print(_line("former gains: trapezoid 0.1 ms (resolved)", _run(FORMER, "trapezoid", 1e-4)))
        long = _run(GAINS, "trapezoid", 2.5e-4, 12.0)
        sag = deflection(long)
        windows = ", ".join(f"{np.ptp(sag[(long.t >= a) & (long.t < a + 2)]) * 1e3:.3g}" for a in range(0, 12, 2))
        print(f"example gains over 12 s (trapezoid 0.25 ms): sag range per 2 s window [mm]: {windows}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        former = _run(FORMER, "implicit_euler", 1e-3, check="auto")
    print(_line("former setting: implicit Euler 1 ms", former))
    messages = [str(w.message) for w in caught if issubclass(w.category, cd.AccuracyWarning)]
    said = messages[0][:260] if messages else "none"
    print(f"  its force_error_estimate: {former.force_error_estimate:.4g} N; AccuracyWarning: {said}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        advice = cd.advise_model(held_beam(), bandwidth=15.0, dt=1e-3)
        elastic = next(c for c in advice.costs if c.model == "elastic")
        run = cd.simulate(held_beam(), 2.0, integrator="implicit_euler", dt=1e-3, accuracy_check="off", energy_check="off")
    print(
        f"advise_model, elastic: {elastic.cpu_per_second:.3g} s CPU per simulated s; a 2 s run measures {run.cpu_time / 2.0:.3g}"
    )
    for name, strip in (("held strip", held_beam()), ("planar arms' beam", cd.scenes.planar_arms_beam())):
        tops = []
        for k in (500.0, 2000.0, 1e4, 1e5):
            law = ObjectImpedance(strip, stiffness=(k, 0.05 * k), damping=(0.06 * k, 0.003 * k))
            tops.append(f"{k:g}: {cd.linearize(strip, controller=law).eigenvalues.real.max():.3g}")
        print(f"gains tried, {name}, read at the tool frames: object stiffness [N/m]: largest Re λ [1/s]: " + ", ".join(tops))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs = {dt: planar_beam.main(6.0, "/tmp/planar_beam_check", html=False, dt=dt) for dt in (1e-3, 1e-4, 5e-5)}
    fine = runs[5e-5]
    for dt in (1e-3, 1e-4):
        df = np.abs(runs[dt].wrenches()[..., :3] - fine.wrenches()[..., :3]).max()
        dsag = np.abs(cd.scenes.midspan_deflection(runs[dt]) - cd.scenes.midspan_deflection(fine)).max()
        print(f"planar example, trapezoid {dt * 1e3:g} ms vs 50 µs: forces within {df:.3g} N, sag within {dsag * 1e6:.3g} µm")
    sag, t = cd.scenes.midspan_deflection(runs[1e-3]), runs[1e-3].t
    early, later = np.ptp(sag[t < 0.1]), np.ptp(sag[(t >= 0.4) & (t < 0.5)])
    print(f"planar example, start transient: sag range {early * 1e3:.3g} mm over 0–0.1 s, {later * 1e3:.3g} mm over 0.4–0.5 s")
    if args.memory:
        scene = held_beam(n_elements=64)
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        scene.model.createData()
        after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        print(f"createData of a 64-element strip (nv = {scene.nv}): max resident memory +{(after - before) / 2**20:.2f} GB")


if __name__ == "__main__":
    main()
