"""The SE(3) spring–damper: exact gradient of U, action = reaction, unloaded = no wrench."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.model.interconnection import spring


def _anisotropic(rng: np.random.Generator, scale_lin: float, scale_ang: float) -> np.ndarray:
    """A random symmetric positive definite 6x6 matrix with coupled blocks."""
    L = rng.normal(size=(6, 6)) * np.sqrt(np.r_[np.full(3, scale_lin), np.full(3, scale_ang)])[:, None]
    return L @ L.T + np.diag(np.r_[np.full(3, scale_lin), np.full(3, scale_ang)])


@pytest.fixture(scope="module")
def anisotropic_scene(pandas: cd.Scene) -> cd.Scene:
    rng = np.random.default_rng(7)
    links = [
        cd.Interconnection(ic.arm, stiffness=_anisotropic(rng, 1e4, 1e2), damping=_anisotropic(rng, 10.0, 0.1))
        for ic in pandas.interconnection_specs
    ]
    return cd.Scene(pandas.arm_specs, pandas.object, links, gravity=pandas.gravity)


def _energy(dyn: cd.Dynamics, q: np.ndarray) -> float:
    return float(np.sum(dyn.elastic_energy(q)))


@pytest.mark.parametrize("seed", range(5))
def test_generalized_force_is_minus_gradient_of_elastic_energy(anisotropic_scene: cd.Scene, seed: int) -> None:
    """Q = Σ J_Gᵀ f_G + J_Tᵀ f_T equals −∂U/∂q by central differences along pin.integrate."""
    scene = anisotropic_scene
    rng = np.random.default_rng(seed)
    dyn = cd.Dynamics(scene)
    q = pin.integrate(scene.model, scene.q0, rng.normal(size=scene.nv) * 0.15)  # loaded, finite rotations
    Q = dyn.generalized_spring_force(q, np.zeros(scene.nv))
    eps = 1e-6
    grad = np.empty(scene.nv)
    for i in range(scene.nv):
        dq = np.zeros(scene.nv)
        dq[i] = eps
        grad[i] = (_energy(dyn, pin.integrate(scene.model, q, dq)) - _energy(dyn, pin.integrate(scene.model, q, -dq))) / (2 * eps)
    assert np.linalg.norm(Q + grad) <= 1e-6 * np.linalg.norm(grad)


def test_spring_action_equals_reaction() -> None:
    """The wrenches on T and G, moved to one point in world axes, cancel exactly."""
    rng = np.random.default_rng(3)
    K, D = _anisotropic(rng, 1e4, 10.0), _anisotropic(rng, 50.0, 0.5)
    for _ in range(10):
        oMT, oMG = pin.SE3.Random(), pin.SE3.Random()
        s = spring(oMT, oMG, rng.normal(size=6), rng.normal(size=6), K, D)
        world_T = oMT.act(pin.Force(s.T_f_T)).vector
        world_G = oMG.act(pin.Force(s.G_f_G)).vector
        np.testing.assert_allclose(world_T + world_G, 0.0, atol=1e-9 * np.linalg.norm(world_G))


def test_spring_damping_is_the_rate_of_the_deformation() -> None:
    """ė = Jlog6 ξ agrees with a finite difference of e along the relative motion."""
    rng = np.random.default_rng(4)
    oMT, oMG = pin.SE3.Random(), pin.SE3.Random()
    vT, vG = rng.normal(size=6), rng.normal(size=6)
    s = spring(oMT, oMG, vT, vG, np.eye(6), np.zeros((6, 6)))
    h = 1e-6

    def e(t: float) -> np.ndarray:
        return pin.log6((oMT * pin.exp6(vT * t)).actInv(oMG * pin.exp6(vG * t))).vector

    np.testing.assert_allclose(s.e_dot, (e(h) - e(-h)) / (2 * h), rtol=1e-6, atol=1e-8)


def test_unloaded_interconnection_exerts_no_wrench(anisotropic_scene: cd.Scene) -> None:
    """At the initial state the tips sit on their grasp frames: zero wrench, zero energy."""
    dyn = cd.Dynamics(anisotropic_scene)
    for s in dyn.springs(anisotropic_scene.q0, anisotropic_scene.v0):
        assert np.max(np.abs(s.G_f_G)) < 1e-9 and np.max(np.abs(s.T_f_T)) < 1e-9
    assert _energy(dyn, anisotropic_scene.q0) < 1e-20


def test_common_rigid_motion_leaves_no_wrench() -> None:
    """Moving T and G together (same pose offset, same rigid velocity) changes nothing."""
    rng = np.random.default_rng(5)
    K, D = _anisotropic(rng, 1e4, 10.0), _anisotropic(rng, 50.0, 0.5)
    oMT = pin.SE3.Random()
    T_M_G = pin.SE3.Random()
    X = pin.SE3.Random()
    vT = rng.normal(size=6)
    vG = T_M_G.actInv(pin.Motion(vT)).vector  # G rigidly attached to T
    a = spring(oMT, oMT * T_M_G, vT, vG, K, D)
    b = spring(X * oMT, X * oMT * T_M_G, vT, vG, K, D)
    np.testing.assert_allclose(a.G_f_G, b.G_f_G, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(a.e_dot, 0.0, atol=1e-12)


def test_scene_rigid_motion_leaves_joint_trajectories_unchanged(pandas: cd.Scene) -> None:
    """Moving bases and object by one rigid motion (about the vertical, gravity-invariant) gives
    the same joint trajectories."""
    X = pin.SE3(pin.utils.rotate("z", 0.7), np.array([0.3, -1.2, 0.25]))
    arms = [a.replace(base=X * a.base, q0=pandas.q0[info.q_index]) for a, info in zip(pandas.arm_specs, pandas.arms, strict=True)]
    obj = pandas.object
    moved_obj = cd.RigidObject(obj.mass, obj.inertia, pose=X * pin.SE3(np.eye(3), np.asarray(obj.pose, dtype=float)))
    moved = cd.Scene(arms, moved_obj, pandas.interconnection_specs, gravity=pandas.gravity)
    rng = np.random.default_rng(2)
    v0 = rng.normal(size=pandas.nv) * 0.3
    arm_v = pandas.actuated
    res_a = cd.simulate(pandas, 0.1, integrator="rk4", dt=1e-4, v0=v0, save_every=100)
    # joint rates and the object's body-frame (LOCAL) twist are the same in both scenes
    res_b = cd.simulate(moved, 0.1, integrator="rk4", dt=1e-4, v0=v0, save_every=100)
    arm_q = np.concatenate([a.q_index for a in pandas.arms])
    np.testing.assert_allclose(res_a.q[:, arm_q], res_b.q[:, arm_q], atol=1e-9)
    np.testing.assert_allclose(res_a.v[:, arm_v], res_b.v[:, arm_v], atol=1e-8)
    np.testing.assert_allclose(res_b.object_position(), res_a.object_position() @ X.rotation.T + X.translation, atol=1e-9)
