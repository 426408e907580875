"""The Drake peer of the Panda scenes is coopdyn's scene: built from coopdyn's model, it has the
same accelerations, and its integrators converge to coopdyn's trajectory."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn import scenes
from coopdyn.bench.drake_scene import DrakeScene
from coopdyn.control import GravityCompensationPD

pytest.importorskip("pydrake")


def test_drake_panda_scene_is_coopdyns_scene() -> None:
    """The Panda scene rebuilt as a Drake MultibodyPlant from coopdyn's model, with coopdyn's law
    and controller as its applied generalized force: the same accelerations at random states
    (round-off); Drake's error-controlled RK3 approaches coopdyn's trajectory as its accuracy is
    tightened, and its discrete plant converges at first order in its step."""
    scene = scenes.facing_arms("panda", stiffness=1e4, damping=0.002, joint_damping=0.5)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    assert DrakeScene(scene, ctrl).check(n=5) < 1e-12
    v0 = np.random.default_rng(4).normal(size=scene.nv) * 0.3
    ref = cd.simulate(scene, 0.05, controller=ctrl, integrator="rk4", dt=1e-5, v0=v0, save_every=1000)

    def gap(Q: np.ndarray) -> float:
        assert len(Q) == len(ref.q)
        return max(float(np.max(np.abs(pin.difference(scene.model, Q[i], ref.q[i])))) for i in range(len(Q)))

    loose, tight = (gap(DrakeScene(scene, ctrl).run(scene.q0, v0, 0.05, 0.01, "runge_kutta3", a)[1]) for a in (1e-3, 1e-7))
    assert tight < 1e-6 and tight < 1e-2 * loose, (loose, tight)
    coarse, fine = (gap(DrakeScene(scene, ctrl, time_step=dt).run(scene.q0, v0, 0.05, 0.01)[1]) for dt in (1e-3, 5e-4))
    assert np.log2(coarse / fine) == pytest.approx(1.0, abs=0.3), (coarse, fine)


def test_drake_peer_refuses_bad_steps_and_passes_coopdyn_errors_on() -> None:
    """A bad time step is refused up front; a controller that fails inside Drake's loop raises
    its own error instead of passing for a diverged run."""
    scene = scenes.facing_arms("panda", stiffness=1e4)
    with pytest.raises(cd.SimulationError, match=r"takes a coopdyn\.Scene"):
        DrakeScene("scene", None)  # type: ignore[arg-type]
    for bad, match in (
        (-1e-3, "time_step must be >= 0"),
        (float("nan"), "must be finite"),
        ("1ms", "numeric"),
        (True, "numeric"),
    ):
        with pytest.raises(cd.SimulationError, match=match):
            DrakeScene(scene, None, time_step=bad)  # type: ignore[arg-type]
    peer, q0, v0 = DrakeScene(scene, None, time_step=1e-3), scene.q0, np.zeros(scene.nv)
    for args, match in (
        ((q0[:3], v0, 0.02, 0.01), r"q0 must have shape \(21,\)"),
        ((np.full(scene.nq, np.nan), v0, 0.02, 0.01), "q0 must be finite"),
        ((q0, v0, 0.0, 0.01), r"t_final must be > 0 \[s\]"),
        ((q0, v0, 0.02, float("nan")), "output_interval must be finite"),
        ((q0, v0, 0.02, 0.01, None, -1.0), "accuracy must be > 0"),
    ):
        with pytest.raises(cd.SimulationError, match=match):
            peer.run(*args)  # type: ignore[arg-type]

    def failing(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        if t > 2e-3:
            raise cd.ControllerError("the controller gave up")
        return np.zeros(scene.n_actuated)

    with pytest.raises(cd.ControllerError, match="the controller gave up"):
        DrakeScene(scene, failing, time_step=1e-3).run(scene.q0, np.zeros(scene.nv), 0.02, 0.01)


def test_drake_peer_runs_again_from_the_start() -> None:
    """The benchmark times each point in several rounds: a second run of the same peer starts
    afresh and gives the same trajectory."""
    scene = scenes.facing_arms("panda", stiffness=1e4)
    peer = DrakeScene(scene, GravityCompensationPD(scene, 50.0, 5.0), time_step=1e-3)
    v0 = np.random.default_rng(1).normal(size=scene.nv) * 0.3
    first, second = (peer.run(scene.q0, v0, 0.02, 0.01) for _ in range(2))
    np.testing.assert_array_equal(first[1], second[1])
