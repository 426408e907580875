"""Heavier sweeps, not run by default: bash run.sh test -m slow."""

from __future__ import annotations

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.control import GravityCompensationPD

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("k", [1e4, 1e5, 1e6, 1e7])
@pytest.mark.parametrize("name", ["symplectic_euler", "rk4"])
@pytest.mark.parametrize("n_arms", [2, 3])
def test_predicted_stable_dt_matches_measurement_sweep(k: float, name: str, n_arms: int) -> None:
    """advise vs bisection on longer runs, up to 1e7 N/m and for three arms: within 10 %."""
    scene = cd.scenes.facing_arms("panda", stiffness=k, n_arms=n_arms)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    predicted = cd.advise(scene, controller=ctrl).max_stable_dt(name)
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.05
    measured = cd.measure_stable_dt(scene, name, controller=ctrl, guess=predicted, v0=v0, n_steps=3000)
    assert predicted == pytest.approx(measured, rel=0.1)
