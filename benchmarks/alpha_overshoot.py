"""How much a start velocity is amplified by each implicit method on stiff, overdamped modes.

A mode with a stiff spring k and a stiff damper d relaxes at the rate k/d; when k/d is far above
1/dt, generalized-α with ρ∞ < 1 overshoots in velocity for a few steps (more the smaller ρ∞),
where the trapezoid (generalized-α at ρ∞ = 1) and implicit Euler do not. A beam's
stiffness-proportional damping (β, so d = βk on every element mode) gives all its fast modes the
rate 1/β: 1e4 1/s at the scenes' default β = 1e-4 s, ten times 1/dt at 1 ms.

For each scene, from a small random start velocity v0 (and from rest), 10 ms at dt = 1 ms:
the largest change of any velocity against the same method's run from rest, per unit of the
largest start velocity (a linear response: the script checks it at three sizes, and prints the
figure the linear generalized-α step matrix predicts from the consistent start acceleration, which
explains it: q̈(0, v0) = −M⁻¹D v0 is huge on a stiff damper, and the method carries it as its
algorithmic acceleration, whose mode decays by only −ρ∞ per step). Cases: the book's three
masses with k = 1e10 N/m and d = 1e6 N·s/m (k/d = 1e4 1/s), the same undamped, and two Pandas
holding the 16- and 40-element strip (``coopdyn.scenes.held_beam``) with β = 1e-4 s and β = 0.

    .venv/bin/python benchmarks/alpha_overshoot.py
"""

from __future__ import annotations

import warnings

import numpy as np

import coopdyn as cd
from coopdyn.integrators import GeneralizedAlpha
from coopdyn.stability import linearize
from coopdyn.transient import start_transient

METHODS = {
    "trapezoid": "trapezoid",
    "generalized_alpha ρ∞=0.9": GeneralizedAlpha(rho_inf=0.9),
    "generalized_alpha ρ∞=0.5": GeneralizedAlpha(rho_inf=0.5),
    "implicit_euler": "implicit_euler",
}


def scenes() -> dict[str, cd.Scene]:
    return {
        "book, k = 1e10, d = 1e6": cd.scenes.linear_book(c_p=1e10, c_k=1e10, d_p=1e6, d_k=1e6),
        "book, k = 1e10, d = 0": cd.scenes.linear_book(c_p=1e10, c_k=1e10, d_p=0.0, d_k=0.0),
        "strip, 16 elements, β = 1e-4 s": cd.scenes.held_beam(n_elements=16, damping=0.002, beam_damping=1e-4),
        "strip, 16 elements, β = 0": cd.scenes.held_beam(n_elements=16, damping=0.002, beam_damping=0.0),
        "strip, 40 elements, β = 1e-4 s": cd.scenes.held_beam(n_elements=40, damping=0.002, beam_damping=1e-4),
    }


def amplification(scene: cd.Scene, method: object, size: float = 1e-5) -> float:
    """max |v(t) − v_rest(t)| / max |v0| over 10 ms at 1 ms, for a random v0 of ``size`` (m/s, rad/s)."""
    v0 = size * np.random.default_rng(0).standard_normal(scene.nv)
    kwargs = dict(integrator=method, dt=1e-3, accuracy_check="off", energy_check="off")
    rest = cd.simulate(scene, 0.01, **kwargs)  # type: ignore[arg-type]
    moved = cd.simulate(scene, 0.01, v0=v0, **kwargs)  # type: ignore[arg-type]
    return float(np.abs(moved.v - rest.v).max() / np.abs(v0).max())


def linear_prediction(scene: cd.Scene, rho_inf: float, size: float = 1e-5) -> float:
    """The same figure from the linear generalized-α step matrix of the scene linearised at its start
    (``alpha_amplification``), started from (0, v0, q̈(0, v0)): the consistent start acceleration,
    which the method carries as its algorithmic one."""
    v0 = size * np.random.default_rng(0).standard_normal(scene.nv)
    return start_transient(linearize(scene), 1e-3, rho_inf, v0, steps=10)  # (what coopdyn.advise judges, over 10 ms)


def divergence(scene: cd.Scene, method: object, size: float) -> str:
    """What a run of 20 ms from a random start velocity of ``size`` says."""
    v0 = size * np.random.default_rng(0).standard_normal(scene.nv)
    try:
        result = cd.simulate(scene, 0.02, integrator=method, dt=1e-3, v0=v0, accuracy_check="off")
    except cd.DivergenceError as exc:
        return str(exc).split("; largest stable dt")[0] + " …"  # (up to the stability diagnosis)
    return f"completed, largest velocity {np.abs(result.v).max():.3g}"


def main() -> None:
    names = list(METHODS)
    print("largest velocity change per unit start velocity, 10 ms at dt = 1 ms (1: the start velocity itself)")
    print(f"{'scene':34s}" + "".join(f"{n:>27s}" for n in names))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (every run here leaves its fast modes unresolved, on purpose)
        built = scenes()
        for label, scene in built.items():
            print(f"{label:34s}" + "".join(f"{amplification(scene, METHODS[n]):27.3g}" for n in names), flush=True)
        print("the linear generalized-α step matrix from (0, v0, q̈(0, v0)), ρ∞ = 1 (the trapezoid's figures), 0.9 and 0.5:")
        for label, scene in built.items():
            print(f"{label:34s}" + "".join(f"{linear_prediction(scene, rho):27.3g}" for rho in (1.0, 0.9, 0.5)), flush=True)
        strip = cd.scenes.held_beam(n_elements=16, damping=0.002, beam_damping=1e-4)
        alpha = METHODS["generalized_alpha ρ∞=0.9"]
        linear = [amplification(strip, alpha, size) for size in (1e-6, 1e-5, 1e-4)]
        sizes = "from 1e-6, 1e-5, 1e-4"
        print(f"linearity: the 16-element strip, generalized_alpha ρ∞=0.9, {sizes}:", *(f"{x:.4g}" for x in linear))
        big = cd.scenes.held_beam(n_elements=40, damping=0.002, beam_damping=1e-4)
        print(f"40-element strip, generalized_alpha ρ∞=0.9, start velocity 0.05 (random): {divergence(big, alpha, 0.05)}")


if __name__ == "__main__":
    main()
