"""The MuJoCo peer model of the book's linear case is the same system: it converges to the
exact solution at RK4's order (a wrong sign, rest length or mass would leave an error floor)."""

from __future__ import annotations

import numpy as np
import pytest

from coopdyn import bench, scenes
from coopdyn.bench.peers import mujoco_linear_book
from coopdyn.reference import BookParameters, linear_book_exact

pytest.importorskip("mujoco")


def _force_error(p: BookParameters, dt: float, integrator: str, t_final: float = 1.5) -> float:
    drives = scenes.book_task(p)
    run = mujoco_linear_book(p, drives, t_final, dt, integrator, save_every=round(0.01 / dt))
    exact = linear_book_exact(run.t, *drives, params=p)
    np.testing.assert_allclose(run.t, np.arange(run.t.size) * 0.01, atol=1e-12)
    F1, F2 = run.contact_forces(p)
    return float(max(np.max(np.abs(F1 - exact.Fc1)), np.max(np.abs(F2 - exact.Fc2))))


@pytest.mark.parametrize("p", [BookParameters(), BookParameters(m1=5.0, m2=20.0, c_k=4e4, s3=0.03)], ids=["book", "asymmetric"])
def test_mujoco_rk4_converges_to_the_exact_solution_at_order_4(p: BookParameters) -> None:
    dts = [2.5e-3, 1.25e-3, 6.25e-4]
    errors = [_force_error(p, dt, "RK4") for dt in dts]
    order = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert abs(order - 4.0) < 0.3, (errors, order)
    assert errors[-1] < 1e-3  # newtons, out of forces of ~100-400 N


def test_mujoco_euler_is_first_order() -> None:
    p = BookParameters()
    errors = [_force_error(p, dt, "Euler") for dt in (2.5e-3, 1.25e-3)]
    assert np.log2(errors[0] / errors[1]) == pytest.approx(1.0, abs=0.3)


def test_bench_peer_rows_and_summary() -> None:
    rows = bench.peer_rows(bench.linear_case(3.0), quick=True, repeats=1, progress=False)
    assert {r.method for r in rows} == {"mujoco Euler", "mujoco implicitfast", "mujoco RK4"}
    assert all(r.stable and r.cpu_per_sim_s > 0 for r in rows)
    text = bench.format_peers(rows)
    assert "least CPU for a force error ≤ 1e-05 N over 3 s, MuJoCo" in text
    assert bench.peer_rows(bench.panda_case(1e4), quick=True, progress=False) == []


@pytest.mark.parametrize("compiled", [True, False], ids=["C callbacks", "Python callbacks"])
def test_mujoco_panda_scene_is_coopdyns_scene(compiled: bool) -> None:
    """The Panda scene rebuilt in MuJoCo from coopdyn's model, with coopdyn's law as passive
    forces and its controller (as C callbacks of coopdyn's kernel, or from Python): the same
    accelerations at random states (round-off), and RK4 in
    both simulators converges to the same trajectory (the difference falls at order 4)."""
    import pinocchio as pin

    from coopdyn.bench.mujoco_scene import MujocoScene
    from coopdyn.control import GravityCompensationPD

    scene = scenes.facing_arms("panda", stiffness=1e4, damping=0.002, joint_damping=0.5)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    assert MujocoScene(scene, ctrl, "RK4", 1e-3, compiled=compiled).check(n=5) < 1e-12
    v0 = np.random.default_rng(4).normal(size=scene.nv) * 0.3
    ref = __import__("coopdyn").simulate(scene, 0.05, controller=ctrl, integrator="rk4", dt=1e-5, v0=v0, save_every=1000)
    errors = []
    for dt in (2e-3, 1e-3, 5e-4):
        _, Q, _, _, _ = MujocoScene(scene, ctrl, "RK4", dt, compiled=compiled).run(scene.q0, v0, 0.05, round(0.01 / dt))
        errors.append(max(np.max(np.abs(pin.difference(scene.model, Q[i], ref.q[i]))) for i in range(len(Q))))
    order = np.polyfit(np.log([2e-3, 1e-3, 5e-4]), np.log(errors), 1)[0]
    assert abs(order - 4.0) < 0.3, (errors, order)


def test_exudyn_panda_scene_is_coopdyns_scene_up_to_its_spring_law() -> None:
    """The Panda scene rebuilt in Exudyn (kinematic tree, rigid box, Exudyn's own intrinsic
    SE(3) spring-dampers, coopdyn's controller): RK44 there and coopdyn's rk4 at the same small
    step follow the same motion; the gap is the spring laws' second-order difference, not a
    modelling error: 4.6e-6 rad against 0.037 rad of motion over 0.1 s here, where a wrong inertia,
    placement or axis moves things by a good fraction of the motion."""
    pytest.importorskip("exudyn")
    import pinocchio as pin

    from coopdyn.bench.exudyn_scene import ExudynScene
    from coopdyn.control import GravityCompensationPD

    scene = scenes.facing_arms("panda", stiffness=1e4)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    v0 = np.random.default_rng(4).normal(size=scene.nv) * 0.3
    ref = __import__("coopdyn").simulate(scene, 0.1, controller=ctrl, integrator="rk4", dt=1e-4, v0=v0, save_every=100)
    t, Q, _, _ = ExudynScene(scene, ctrl).run(scene.q0, v0, 0.1, 1e-4, "RK44")
    np.testing.assert_allclose(t, ref.t, atol=1e-12)
    gap = max(np.max(np.abs(pin.difference(scene.model, Q[i], ref.q[i]))) for i in range(len(t)))
    motion = max(np.max(np.abs(pin.difference(scene.model, ref.q[0], ref.q[i]))) for i in range(len(t)))
    assert gap < 1e-3 * motion, (gap, motion)
