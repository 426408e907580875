"""Two Pandas holding a 2 kg box: energy conservation and dissipation, static load sharing."""

from __future__ import annotations

import numpy as np
import pytest

import coopdyn as cd
from coopdyn.control import GravityCompensationPD


def test_energy_is_conserved_without_damping(pandas: cd.Scene) -> None:
    """D = 0, no joint damping, τ = 0, perturbed start: total energy drift ≤ 1e-6 relative over 1 s.

    The drift is measured relative to the largest kinetic energy of the run (the energy that
    actually moves around), not to the arbitrary gravity-potential offset.
    """
    rng = np.random.default_rng(11)
    v0 = rng.normal(size=pandas.nv) * 0.2
    res = cd.simulate(pandas, 1.0, integrator="rk4", dt=1e-4, v0=v0, save_every=50)
    E = res.energy()
    assert E.elastic.max() > 1.0 and E.kinetic.max() > 1.0  # the springs and the arms really work
    drift = np.max(np.abs(E.total - E.total[0]))
    assert drift <= 1e-6 * E.kinetic.max()
    assert drift <= 1e-6 * abs(E.total[0])


def test_energy_never_increases_with_damping(pandas: cd.Scene) -> None:
    """Interconnection and joint damping only dissipate: E(t) is non-increasing at every step."""
    damped = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002, joint_damping="urdf")
    assert np.any(damped.arms[0].damping > 0)
    rng = np.random.default_rng(12)
    res = cd.simulate(damped, 0.5, integrator="rk4", dt=1e-4, v0=rng.normal(size=damped.nv) * 0.2, save_every=1)
    total = res.energy().total
    increase = np.diff(total)
    assert np.max(increase) <= 1e-9 * np.max(np.abs(total))
    assert total[-1] < total[0] - 0.1  # and it does dissipate [J]


def test_held_box_weight_is_carried_half_by_each_arm() -> None:
    """Gravity compensation + joint PD: the interconnection forces on the box settle to its
    weight (≤ 1e-6 N), each arm of the mirror-symmetric scene carrying half."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.005)
    ctrl = GravityCompensationPD(scene, kp=200.0, kd=20.0)  # [N·m/rad], [N·m·s/rad]
    res = cd.simulate(scene, 3.0, controller=ctrl, integrator="rk4", dt=5e-4, save_every=100)
    weight = scene.object.mass * -scene.gravity
    f0, f1 = res.wrench(0)[-1, :3], res.wrench(1)[-1, :3]
    assert np.max(np.abs(f0 + f1 - weight)) <= 1e-6
    assert f0[2] == pytest.approx(weight[2] / 2, abs=1e-6)
    assert f1[2] == pytest.approx(weight[2] / 2, abs=1e-6)
