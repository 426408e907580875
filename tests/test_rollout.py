"""coopdyn.rollout: batched open-loop trajectories in threads — each equal to its own serial
run, the threads' result equal to one thread's, a failing trajectory isolated, bad input named."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.control import TorqueSequence
from coopdyn.errors import SceneError, SimulationError


@pytest.fixture(scope="module")
def pandas() -> cd.Scene:
    return cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)


def torques(scene: cd.Scene, B: int, N: int, seed: int = 0) -> np.ndarray:
    """Gravity compensation at the start plus random torques, (B, N, n_actuated) [N·m]."""
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    return g + np.random.default_rng(seed).normal(scale=2.0, size=(B, N, scene.n_actuated))


def test_each_rollout_is_its_own_serial_run_and_threads_change_nothing(pandas: cd.Scene) -> None:
    U = torques(pandas, 4, 20)
    v0 = np.random.default_rng(1).normal(scale=0.1, size=(4, pandas.nv))
    one = cd.rollout(pandas, U, period=0.01, dt=1e-3, v0=v0, threads=1)
    two = cd.rollout(pandas, U, period=0.01, dt=1e-3, v0=v0, threads=2)
    np.testing.assert_array_equal(one.q, two.q)
    np.testing.assert_array_equal(one.v, two.v)
    assert one.status == ("done",) * 4 and one.t.shape == (21,) and one.q.shape == (4, 21, pandas.nq)
    for b in (0, 3):
        run = cd.simulate(
            pandas, 0.2, TorqueSequence(pandas, U[b], 0.01), "implicit_euler", dt=1e-3, save_every=10, v0=v0[b], control_dt=0.01,
            energy_check="off", accuracy_check="off",
        )  # fmt: skip
        np.testing.assert_array_equal(one.q[b], run.q)
        np.testing.assert_allclose(one.t, run.t, rtol=0, atol=1e-12)


def test_the_torque_sequence_holds_each_row_for_its_period_in_both_loops(pandas: cd.Scene) -> None:
    U = torques(pandas, 1, 5)[0]
    seq = TorqueSequence(pandas, U, 0.01)
    assert np.array_equal(seq(0.0, pandas.q0, pandas.v0), U[0]) and np.array_equal(seq(0.0199, pandas.q0, pandas.v0), U[1])
    assert np.array_equal(seq(1.0, pandas.q0, pandas.v0), U[-1])  # (the last row to the end)
    runs = [cd.simulate(pandas, 0.05, seq, "rk4", dt=1e-3, loop=loop, accuracy_check="off") for loop in ("python", "compiled")]
    np.testing.assert_array_equal(runs[0].tau, runs[1].tau)
    np.testing.assert_allclose(runs[0].q, runs[1].q, rtol=0, atol=1e-13)


def test_a_rollout_holds_each_row_over_every_stage_of_its_period(pandas: cd.Scene) -> None:
    # rk4's last stage sits on the period's end: it must still read row k, not row k + 1
    U = torques(pandas, 1, 2)[0]
    U[1] += 50.0
    both = cd.rollout(pandas, U[None], period=1e-3, integrator="rk4", threads=1)
    first = cd.rollout(pandas, U[None, [0, 0]], period=1e-3, integrator="rk4", threads=1)
    np.testing.assert_array_equal(both.q[0, 1], first.q[0, 1])
    np.testing.assert_array_equal(both.v[0, 1], first.v[0, 1])
    assert not np.array_equal(both.v[0, 2], first.v[0, 2])  # (row 1 does act on the next period)


def test_an_instant_a_rounding_short_of_a_boundary_is_the_next_period(pandas: cd.Scene) -> None:
    U = torques(pandas, 1, 10)[0]
    seq = TorqueSequence(pandas, U, 0.1)
    assert 0.7 / 0.1 < 7.0  # (6.999999999999999)
    assert np.array_equal(seq(0.7, pandas.q0, pandas.v0), U[7])
    assert np.array_equal(seq(0.7 - 1e-6, pandas.q0, pandas.v0), U[6])


@pytest.mark.filterwarnings("ignore::coopdyn.errors.LogMapWarning")  # (the kicked trajectory twists its grasp)
def test_a_diverging_rollout_is_one_status_and_nans(pandas: cd.Scene) -> None:
    U = torques(pandas, 3, 10)
    U[1] *= 1e4  # (kicked off at 1e4 N·m)
    out = cd.rollout(pandas, U, period=0.01, dt=1e-3, integrator="rk4", threads=2)
    assert out.status[0] == out.status[2] == "done" and "diverged" in out.status[1]
    assert np.isnan(out.q[1, -1]).all() and not np.isnan(out.q[[0, 2]]).any()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"torques": np.zeros((2, 3))}, r"torques must be \(B, N, 14\)"),
        ({"period": 0.0}, "period"),
        ({"dt": 3e-3}, "must divide the period"),
        ({"q0": np.zeros(3)}, r"q0 must be \(21,\) or \(2, 21\)"),
        ({"threads": 0}, "threads must be a positive integer"),
        ({"torques": np.full((2, 3, 14), np.nan)}, "torques"),
        # what stops every trajectory alike is an error, not B statuses
        ({"dt": 1e-9}, r"30,000,000 steps a trajectory, more than 2,000,000: take a larger dt or fewer periods"),
        ({"integrator": "exponential"}, "rollout: the exponential integrator needs a linear scene"),
    ],
)
def test_bad_input_is_named(pandas: cd.Scene, kwargs: dict, message: str) -> None:
    args = {"torques": np.zeros((2, 3, 14)), "period": 0.01, "dt": 1e-3, **kwargs}
    with pytest.raises(SimulationError, match=message):
        cd.rollout(pandas, args.pop("torques"), **args)


def test_a_shared_start_that_is_no_state_is_refused(pandas: cd.Scene) -> None:
    q0 = pandas.q0.copy()
    q0[-4:] *= 2.0  # (the box's quaternion, no longer of unit norm)
    with pytest.raises(cd.SceneError, match="not a valid configuration"):
        cd.rollout(pandas, np.zeros((2, 3, 14)), period=0.01, q0=q0)


def test_the_torque_sequence_refuses_a_wrong_table(pandas: cd.Scene) -> None:
    with pytest.raises(
        SceneError, match=r"torques must be \(N, 14\): one row of the 14 arm torques per period, got shape \(3, 2\)$"
    ):
        TorqueSequence(pandas, np.zeros((3, 2)), 0.01)
