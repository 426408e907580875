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


def _series_internal_force(e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A free 2 kg box between two fixtures, K1 ≠ K2 anisotropic, the second fixture off by the
    pose error e = (translation [m], rotation [rad]): the wrench of each grasp on the box at rest,
    and K1 (K1 + K2)⁻¹ K2 e."""
    import pinocchio as pin

    from coopdyn.statics import equilibrium

    K1 = np.diag([1e4, 3e4, 5e4, 2e3, 3e3, 4e3])
    K2 = np.diag([2e4, 1e4, 8e4, 1.5e3, 5e3, 2.5e3])
    box = cd.RigidObject.box(2.0, [0.2, 0.2, 0.2], pose=[0.0, 0.0, 0.5])
    start = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.5]))
    links = [cd.Interconnection(None, stiffness=K1), cd.Interconnection(None, stiffness=K2, fixture=start * pin.exp6(e))]
    scene = cd.Scene([], box, links, gravity=[0.0, 0.0, 0.0])
    rest = equilibrium(scene, tol=1e-11)
    res = cd.Result(scene, np.zeros(1), rest.q[None], np.zeros((1, scene.nv)), np.zeros((1, 0)), "statics", 1.0, 0, 0.0)
    return res.wrench(0)[0], res.wrench(1)[0], K1 @ np.linalg.solve(K1 + K2, K2 @ e)


def test_two_grasps_in_series_share_a_grasp_error_by_the_series_spring_law() -> None:
    """How elasticity resolves the force uncertainty of a rigid grasp: a box held by two
    anisotropic grasps K1 ≠ K2, one off by a small pose error e, carries at rest the internal
    force f_int = K1 (K1 + K2)⁻¹ K2 e — the series-spring law, exact to first order in e. The
    odd part (f(e) − f(−e))/2, where the second-order geometry cancels, matches it to 1e-9
    relative; f(e) itself to O(|e|); the two grasps' wrenches balance."""
    direction = np.array([1.0, -2.0, 1.5, 0.5, -0.3, 0.8])
    e = 1e-5 * direction
    f1, f2, law = _series_internal_force(e)
    _, g2, _ = _series_internal_force(-e)
    np.testing.assert_allclose((f2 - g2) / 2, law, rtol=0, atol=1e-9 * np.abs(law).max())
    np.testing.assert_allclose(f1 + f2, 0.0, atol=1e-9 * np.abs(law).max())  # nothing else holds the box
    quadratic = []
    for scale in (1e-4, 1e-5):
        _, f2, law = _series_internal_force(scale * direction)
        quadratic.append(np.abs(f2 - law).max() / scale**2)
    assert quadratic[1] == pytest.approx(quadratic[0], rel=0.05)  # f(e) misses the law by O(|e|²)
