"""Exact sensitivities of a step and of a trajectory (coopdyn.sensitivity).

Every derivative is checked against Richardson-extrapolated central differences (error O(h⁴))
of the library's own step (the Python loop's integrator step) or of compiled rollouts; the
book's linear system against the closed forms of rk4's and symplectic Euler's step matrices
(exact to round-off); the forward pass against the compiled loop's step to round-off.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from test_linearize import _rel, ball_pandas, richardson

import coopdyn as cd
from coopdyn.closed_loop import System
from coopdyn.dynamics import Dynamics
from coopdyn.dynamics.derivatives import MatrixDerivatives
from coopdyn.errors import KernelError, SceneError, SimulationError
from coopdyn.integrators import get_integrator
from coopdyn.model.elements.lie import dexp_inv_rate, jlog6_of_log
from coopdyn.parameters import parameters, with_parameters
from coopdyn.sensitivity import step_sensitivity, trajectory_sensitivity


def _damped_pandas() -> cd.Scene:
    return cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.01, joint_damping=0.5)


def _ball_pandas() -> cd.Scene:
    return ball_pandas((1e4, 1e4, 1e4))  # (isotropic: a k_linear parameter)


def _hardening_box() -> cd.Scene:
    box = cd.RigidObject.box(2.0, (0.2, 0.1, 0.3), pose=[0.1, -0.2, 1.0])
    K = cd.diagonal([1e3, 2e3, 3e3], [10.0, 20.0, 30.0])
    link = cd.Interconnection(
        None, stiffness=K, damping=0.01 * K, grasp=[0.0, 0.0, 0.15], element="hardening", parameters={"hardening": 1e6}
    )
    return cd.Scene([], box, [link])


def _elastic_joint_pandas() -> cd.Scene:
    base = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.01)
    joints = cd.JointElasticity(stiffness=1e4, motor_inertia=0.5, damping=5.0)
    return cd.Scene([arm.replace(elasticity=joints) for arm in base.arm_specs], base.object, base.interconnection_specs)


#: scene, the parameters differentiated, the step [s] (one that the scene's fastest mode allows
#: rk4), the start's spread
CASES: dict[str, tuple[Callable[[], cd.Scene], list[str], float, float]] = {
    "pandas, damped SE(3) grasps": (
        _damped_pandas,
        ["left.k_linear", "right.k_angular", "left.d_linear", "left.k_rz", "object.mass", "left.grasp_y", "right.grasp_z"],
        4e-3,
        1.0,
    ),
    "pandas, ball grasps": (_ball_pandas, ["left.k_linear", "right.d_y", "right.grasp_x"], 4e-3, 1.0),
    "box hung from a hardening fixture": (
        _hardening_box,
        ["fixture.k_z", "fixture.k_rx", "fixture.d_x", "object.mass", "fixture.grasp_z"],
        4e-3,
        1.0,
    ),
    "pandas on elastic joints": (_elastic_joint_pandas, ["left.k_linear", "object.mass"], 2e-3, 1.0),
    "a beam held by two pandas (its elements)": (
        lambda: cd.scenes.held_beam(n_elements=2, damping=1e-3),
        ["left.k_linear", "right.d_z"],
        2e-5,
        1e-2,
    ),
}


def _start(scene: cd.Scene, seed: int = 11, spread: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A state with loaded, turned and moving grasps (the object spinning at ~3 rad/s), and torques
    (``spread`` scales the state's: a beam's nodes take far less)."""
    rng = np.random.default_rng(seed)
    q = pin.integrate(scene.model, scene.q0, 0.05 * spread * rng.normal(size=scene.nv))
    v = 0.5 * spread * rng.normal(size=scene.nv)
    v[scene.object_v[3:6]] = spread * np.array([3.0, -2.0, 1.5])
    return q, v, 3.0 * rng.normal(size=scene.n_actuated)


def _step(p: Any, relative: float) -> float:
    """A difference step for parameter p: ``relative`` of its value, or of 0.1 m for a grasp
    position (near 0 on these scenes)."""
    return relative * (0.1 if p.position else p.value)


def _stepper(
    scene: cd.Scene, method: str, tau: np.ndarray, backend: str | None = None
) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """The library's own step (the Python loop's integrator on the System) under a constant τ."""
    system = System(Dynamics(scene, backend), lambda t, q, v: tau)
    integrator = get_integrator(method)
    return lambda q, v, h: integrator.step(system, 0.0, q, v, h, integrator.workspace(system))


@pytest.mark.parametrize(
    "method", ["rk4", "symplectic_euler", "dopri5", "dop853", "implicit_euler", "trapezoid", "ros2", "generalized_alpha"]
)
@pytest.mark.parametrize("name", CASES)
def test_the_step_sensitivity_is_the_derivative_of_the_step(name: str, method: str) -> None:
    make, names, h, spread = CASES[name]
    scene = make()
    q, v, tau = _start(scene, spread=spread)
    nv, model = scene.nv, scene.model
    s = step_sensitivity(scene, q, v, tau, h, integrator=method, parameters=names)
    step = _stepper(scene, method, tau)
    q1, v1 = step(q, v, h)
    np.testing.assert_allclose(s.q, q1, rtol=0, atol=1e-13)  # the forward pass is the library's step
    np.testing.assert_allclose(s.v, v1, rtol=0, atol=1e-11 * max(1.0, np.max(np.abs(v1))))

    def state(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
        return np.concatenate([pin.difference(model, s.q, qq), vv - s.v])

    for k in range(nv):
        e = np.eye(nv)[k]
        ref_q = richardson(lambda x, e=e: state(*step(pin.integrate(model, q, x * e), v, h)), 1e-4)
        ref_v = richardson(lambda x, e=e: state(*step(q, v + x * e, h)), 1e-4)
        floor = 1e-8 * np.max(np.abs(s.dx_dx))  # (the differences' own error, on a column far below the rest)
        assert _rel(s.dx_dx[:, k], ref_q) < 1e-7 or np.max(np.abs(s.dx_dx[:, k] - ref_q)) < floor
        assert _rel(s.dx_dx[:, nv + k], ref_v) < 1e-7 or np.max(np.abs(s.dx_dx[:, nv + k] - ref_v)) < floor
    for k in range(scene.n_actuated):
        e = np.eye(scene.n_actuated)[k]
        ref = richardson(lambda x, e=e: state(*_stepper(scene, method, tau + x * e)(q, v, h)), 1.0)
        assert _rel(s.dx_du[:, k], ref) < 1e-7
    for k, p in enumerate(s.parameters):  # (1e-2: smaller differences of one short step are round-off's)
        ref = richardson(
            lambda x, p=p: state(*_stepper(with_parameters(scene, {p.name: p.value + x}), method, tau)(q, v, h)), _step(p, 1e-2)
        )
        assert _rel(s.dx_dp[:, k], ref) < 1e-6, p.name


@pytest.mark.parametrize("name", CASES)
def test_the_gauss_newton_matrices_derivative_is_exact(name: str) -> None:
    """∂(M w_M + D̃ w_D + K̃ w_K)/∂(q, v) for fixed vectors, against extrapolated central
    differences of the dynamics' own implicit_terms (what an implicit step solves with)."""
    make, _, _, spread = CASES[name]
    scene = make()
    q, v, tau = _start(scene, spread=spread)
    dyn = Dynamics(scene, "python")
    w_M, w_D, w_K = np.random.default_rng(1).normal(size=(3, scene.nv))
    links = dyn.force_links
    matrices = MatrixDerivatives(scene.model, links, [element.has_damping for *_, element in links])
    assert matrices.exact

    def G(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
        _, M, K, D = dyn.implicit_terms(qq, vv, tau)
        return np.asarray(M @ w_M + D @ w_D + K @ w_K)

    dG_dq, dG_dv, _ = matrices(q, v, w_M, w_D, w_K)
    scale = np.max(np.abs(dG_dq))
    for k in range(scene.nv):
        e = np.eye(scene.nv)[k]
        ref_q = richardson(lambda x, e=e: G(pin.integrate(scene.model, q, x * e), v), 1e-4 * spread)
        ref_v = richardson(lambda x, e=e: G(q, v + x * e), 1e-4)
        assert np.max(np.abs(dG_dq[:, k] - ref_q)) < 1e-8 * scale
        assert np.max(np.abs(dG_dv[:, k] - ref_v)) < 1e-8 * scale


def test_the_chart_rate_and_its_derivative() -> None:
    rng = np.random.default_rng(2)
    for size in (6, 3):
        for scale in (1e-3, 0.2, 2.0):  # (the series branch, and the closed forms)
            delta, v = scale * rng.normal(size=size), rng.normal(size=size)
            rate, C, N = dexp_inv_rate(delta, v)
            e = delta if size == 6 else np.concatenate([np.zeros(3), delta])
            J = jlog6_of_log(e) if size == 6 else jlog6_of_log(e)[3:, 3:]
            np.testing.assert_allclose(rate, J @ v, rtol=0, atol=1e-15 * max(1.0, np.max(np.abs(J @ v))))
            np.testing.assert_allclose(C, J, rtol=0, atol=1e-15 * np.max(np.abs(J)))
            for k in range(size):
                d = np.eye(size)[k]
                ref = richardson(lambda x, d=d: dexp_inv_rate(delta + x * d, v)[0], 1e-3)
                np.testing.assert_allclose(N[:, k], ref, rtol=0, atol=1e-10 * max(1.0, np.max(np.abs(N))))
    # the rate is the chart velocity the integrators use: dIntegrate(q, δ)⁻¹ v on a free-flyer
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=1e3)])
    system = System(Dynamics(scene))
    delta, v = np.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6]), rng.normal(size=6)
    np.testing.assert_allclose(dexp_inv_rate(delta, v)[0], system.chart_velocity(scene.q0, delta, v), rtol=0, atol=1e-14)


def test_the_book_system_steps_are_their_closed_forms(book: cd.Scene) -> None:
    """On a linear system rk4's step matrix is the 4th-order Taylor polynomial of hA, and
    symplectic Euler's the partitioned matrix of its stability analysis — exactly."""
    lin = cd.linearize(book)
    A, B, h = lin.A, lin.B, 1e-2
    n, eye = len(A) // 2, np.eye(len(A))
    hA = h * A
    s = step_sensitivity(book, dt=h)
    R = eye + hA + hA @ hA / 2 + hA @ hA @ hA / 6 + hA @ hA @ hA @ hA / 24
    np.testing.assert_allclose(s.dx_dx, R, rtol=0, atol=1e-14 * np.max(np.abs(R)))
    RB = h * (eye + hA / 2 + hA @ hA / 6 + hA @ hA @ hA / 24) @ B
    np.testing.assert_allclose(s.dx_du, RB, rtol=0, atol=1e-14 * np.max(np.abs(RB)))
    s = step_sensitivity(book, dt=h, integrator="symplectic_euler")
    G = np.block([[np.eye(n) + h * h * A[n:, :n], h * (np.eye(n) + h * A[n:, n:])], [h * A[n:, :n], np.eye(n) + h * A[n:, n:]]])
    np.testing.assert_allclose(s.dx_dx, G, rtol=0, atol=1e-15 * np.max(np.abs(G)))
    s = step_sensitivity(book, dt=h, integrator="exponential")  # the exact flow: e^{hA} and ∫₀ʰ e^{sA} ds B
    E = scipy.linalg.expm(np.block([[hA, h * B], [np.zeros((B.shape[1], len(A) + B.shape[1]))]]))
    np.testing.assert_allclose(s.dx_dx, E[: len(A), : len(A)], rtol=0, atol=1e-14 * np.max(np.abs(R)))
    np.testing.assert_allclose(s.dx_du, E[: len(A), len(A) :], rtol=0, atol=1e-14 * np.max(np.abs(RB)))


def test_the_exponential_integrators_parameter_sensitivities_are_the_derivatives_of_its_rollouts(book: cd.Scene) -> None:
    """The book system's grasp stiffness, damping and the object's mass, through the Fréchet
    derivative of the step's matrix exponential, against differences of compiled rollouts."""
    names = ["tip1.k_z", "tip2.d_z", "object.mass"]
    U = 5.0 * np.random.default_rng(2).normal(size=(12, book.n_actuated))
    tr = trajectory_sensitivity(book, U, 1e-2, dt=5e-3, parameters=names, integrator="exponential", initial_state=True)
    assert tr.exact and tr.dx_dx0 is not None

    def run(s: cd.Scene, x0: np.ndarray | None = None) -> np.ndarray:
        x0 = np.zeros(2 * book.nv) if x0 is None else x0
        out = cd.rollout(
            s, U[None], period=1e-2, dt=5e-3, q0=book.q0 + x0[: book.nv], v0=x0[book.nv :], integrator="exponential", threads=1
        )
        return np.concatenate([out.q[0] - tr.q, out.v[0] - tr.v], axis=1)

    np.testing.assert_allclose(run(book), 0.0, atol=1e-13)
    for k, p in enumerate(tr.parameters):
        ref = richardson(lambda x, p=p: run(with_parameters(book, {p.name: p.value + x})), 1e-2 * p.value)
        assert _rel(tr.dx_dp[..., k], ref) < 1e-7, p.name
    for k in range(2 * book.nv):
        ref = richardson(lambda x, k=k: run(book, x * np.eye(2 * book.nv)[k]), 1e-3)
        assert _rel(tr.dx_dx0[..., k], ref) < 1e-7


@pytest.mark.parametrize("method", ["rk4", "symplectic_euler", "implicit_euler", "ros2", "trapezoid", "generalized_alpha"])
def test_one_step_is_the_compiled_loops_step(pandas: cd.Scene, method: str) -> None:
    q, v, tau = _start(pandas)
    s = step_sensitivity(pandas, q, v, tau, 1e-3, integrator=method)
    run = cd.rollout(pandas, tau[None, None], period=1e-3, q0=q, v0=v, integrator=method, threads=1)
    np.testing.assert_allclose(s.q, run.q[0, 1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(s.v, run.v[0, 1], rtol=0, atol=1e-11 * np.max(np.abs(s.v)))


@pytest.mark.parametrize(
    ("method", "stiffness", "dt"),
    [
        ("rk4", 1e4, 1e-3),
        ("implicit_euler", 1e7, 2e-3),
        ("trapezoid", 1e7, 2e-3),
        ("ros2", 1e7, 1e-3),
        ("generalized_alpha", 1e7, 5e-4),
    ],
)
def test_trajectory_sensitivities_are_the_derivatives_of_compiled_rollouts(method: str, stiffness: float, dt: float) -> None:
    """rk4 on soft grasps; the linearly implicit methods on grasps of 1e7 N/m at steps where rk4
    diverges (checked): what an MPC on a stiff grasp differentiates."""
    scene = cd.scenes.facing_arms("panda", stiffness=stiffness, damping=0.01, joint_damping=0.5)
    names = ["left.k_linear", "right.k_angular", "left.d_linear", "object.mass", "left.grasp_y"]
    rng = np.random.default_rng(4)
    g = pin.computeGeneralizedGravity(scene.model, scene.model.createData(), scene.q0)[scene.actuated]
    U = g + 2.0 * rng.normal(size=(15, scene.n_actuated))
    v0 = 0.2 * rng.normal(size=scene.nv)
    if method != "rk4":
        assert "diverged" in cd.rollout(scene, U[None], period=2e-3, dt=dt, v0=v0, integrator="rk4", threads=1).status[0]
    tr = trajectory_sensitivity(scene, U, 2e-3, dt=dt, v0=v0, parameters=names, initial_state=True, integrator=method)
    nv, model = scene.nv, scene.model
    assert tr.exact and tr.dx_dp.shape == (16, 2 * nv, 5) and tr.dx_dx0 is not None and tr.dx_dx0.shape == (16, 2 * nv, 2 * nv)

    def run(s: cd.Scene, q0: np.ndarray = scene.q0, v: np.ndarray = v0) -> np.ndarray:
        out = cd.rollout(s, U[None], period=2e-3, dt=dt, q0=q0, v0=v, integrator=method, threads=1)
        dyn = Dynamics(s)
        W = np.array([[e.G_f_G for e in dyn.element_states(a, b)] for a, b in zip(out.q[0], out.v[0], strict=True)])
        x = np.array(
            [
                np.concatenate([pin.difference(model, a, b), c - d])
                for a, b, c, d in zip(tr.q, out.q[0], out.v[0], tr.v, strict=True)
            ]
        )
        return np.concatenate([x.ravel(), W.ravel()])

    base = run(scene)
    n_x = tr.dx_dp[..., 0].size
    np.testing.assert_allclose(base[:n_x], 0.0, atol=1e-11)  # the samples are the rollout's
    np.testing.assert_allclose(tr.wrench.ravel(), base[n_x:], rtol=0, atol=1e-12 * np.max(np.abs(tr.wrench)))
    for k, p in enumerate(tr.parameters):  # (a step of 1 %: the stiff grasps' state moves little with them)
        ref = richardson(lambda x, p=p: run(with_parameters(scene, {p.name: p.value + x})), _step(p, 1e-2))
        assert _rel(tr.dx_dp[..., k].ravel(), ref[:n_x]) < 1e-6, p.name
        # the wrenches' differences carry their round-off (1e-11 of their size) over the step: on grasps of
        # 1e7 N/m their derivative along a stiffness is 1e-7 N per N/m and that floor shows
        floor = 1e-11 * np.max(np.abs(tr.wrench)) / _step(p, 1e-2)
        assert np.max(np.abs(tr.dwrench_dp[..., k].ravel() - ref[n_x:])) < 1e-6 * np.max(np.abs(ref[n_x:])) + floor, p.name
    for k in (0, 7, nv - 1, nv + 3, 2 * nv - 1):  # some start directions: an arm joint, the object
        e = np.eye(2 * nv)[k]
        ref = richardson(lambda x, e=e: run(scene, pin.integrate(model, scene.q0, x * e[:nv]), v0 + x * e[nv:])[:n_x], 1e-5)
        assert _rel(tr.dx_dx0[..., k].ravel(), ref) < 1e-6


@pytest.mark.parametrize(
    "method", ["rk4", "dop853", "symplectic_euler", "implicit_euler", "ros2", "trapezoid", "generalized_alpha"]
)
def test_both_backends_give_the_same_sensitivities(method: str) -> None:
    """The kernel's twin against the Python reference: a step, and a trajectory of three steps a
    period (generalized-α's carried acceleration), with the start's columns."""
    if not cd.backend.native_available():
        pytest.skip("coopdyn._native is not built")
    scene = _damped_pandas()
    q, v, tau = _start(scene)
    names = ["left.k_linear", "right.d_angular", "object.mass", "right.grasp_x"]
    a, b = (
        step_sensitivity(scene, q, v, tau, 2e-3, integrator=method, parameters=names, backend=x) for x in ("python", "native")
    )
    for x, y in ((a.dx_dx, b.dx_dx), (a.dx_du, b.dx_du), (a.dx_dp, b.dx_dp)):
        assert _rel(x, y) < 1e-10
    assert cd.Sensitivity(scene, method).native is not None  # (the native backend runs the twin)
    U = tau + np.random.default_rng(5).normal(size=(4, scene.n_actuated))
    a, b = (
        trajectory_sensitivity(scene, U, 3e-3, dt=1e-3, integrator=method, parameters=names, initial_state=True, backend=x)
        for x in ("python", "native")
    )
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-13)
    assert a.dx_dx0 is not None and b.dx_dx0 is not None
    for x, y in ((a.dx_dp, b.dx_dp), (a.dx_dx0, b.dx_dx0), (a.dwrench_dp, b.dwrench_dp)):
        assert _rel(x, y) < 1e-10


def test_with_parameters_changes_only_what_it_names(pandas: cd.Scene) -> None:
    same = with_parameters(pandas, {"left.k_linear": 1e4})
    q, v, tau = _start(pandas)
    np.testing.assert_allclose(
        Dynamics(same).acceleration(q, v, tau), Dynamics(pandas).acceleration(q, v, tau), rtol=0, atol=1e-9
    )
    other = with_parameters(pandas, {"left.k_linear": 2e4, "right.k_rz": 3.0, "object.mass": 3.0, "right.d_x": 7.0})
    K_left, K_right = other.links[0].element.K, other.links[1].element.K
    np.testing.assert_array_equal(np.diag(K_left), [2e4, 2e4, 2e4, 100.0, 100.0, 100.0])
    np.testing.assert_array_equal(np.diag(K_right), [1e4, 1e4, 1e4, 100.0, 100.0, 3.0])  # (both of its entries)
    np.testing.assert_array_equal(np.diag(other.links[1].element.D), [7.0, 0, 0, 0, 0, 0])
    assert other.object.mass == 3.0
    np.testing.assert_allclose(other.object.inertia, 1.5 * np.asarray(pandas.object.inertia))
    for a, b in zip(other.links, pandas.links, strict=True):  # the grasps stay where the scene put them
        np.testing.assert_allclose(
            other.model.frames[a.grasp_frame].placement.homogeneous,
            pandas.model.frames[b.grasp_frame].placement.homogeneous,
            atol=1e-15,
        )
    # a grasp position moves that grasp frame along the object frame's axis, its orientation and the rest kept
    y = parameters(pandas, ["left.grasp_y"])[0].value
    moved = with_parameters(pandas, {"left.grasp_y": y + 0.01})
    before, after = (s.model.frames[s.links[0].grasp_frame].placement for s in (pandas, moved))
    np.testing.assert_allclose(after.translation - before.translation, [0.0, 0.01, 0.0], atol=1e-15)
    np.testing.assert_array_equal(after.rotation, before.rotation)
    np.testing.assert_allclose(moved.q0, pandas.q0, atol=0)
    box = _hardening_box()  # a fixture placed at its grasp's start pose stays where it was
    z = parameters(box, ["fixture.grasp_z"])[0].value
    shifted = with_parameters(box, {"fixture.grasp_z": z + 0.02})

    def fixture_pose(s: cd.Scene) -> np.ndarray:
        data = s.model.createData()
        pin.framesForwardKinematics(s.model, data, s.q0)
        return np.asarray(data.oMf[s.links[0].tip_frame].homogeneous)

    np.testing.assert_allclose(fixture_pose(shifted), fixture_pose(box), atol=1e-15)
    with pytest.raises(SceneError, match="a grasp position is a parameter on a rigid object only"):
        parameters(cd.scenes.held_beam(n_elements=2), ["left.grasp_x"])


def test_bad_requests_are_refused_with_what_to_do(pandas: cd.Scene) -> None:
    class MyTrapezoid(cd.integrators.Trapezoid):
        pass

    class HalvedRK4(cd.integrators.INTEGRATORS["rk4"]):  # type: ignore[misc,valid-type]
        """An rk4 whose own step differs from its tableau's (it was differentiated as the tableau)."""

        def step(self, system: Any, t: float, q: np.ndarray, v: np.ndarray, h: float, ws: Any = None) -> Any:
            q1, v1 = super().step(system, t, q, v, h, ws)
            return q1, 0.5 * v1

    class NamedRK4(cd.integrators.INTEGRATORS["rk4"]):  # type: ignore[misc,valid-type]
        name = "my_rk4"  # (only a name: its step is the tableau's, differentiated)

    assert step_sensitivity(pandas, integrator=NamedRK4()).dx_dx.shape == (2 * pandas.nv, 2 * pandas.nv)
    with pytest.raises(SimulationError, match="the exponential integrator needs a linear scene; this one is not"):
        step_sensitivity(pandas, integrator="exponential")
    refused = {
        cd.integrators.LinearlyImplicitEuler(jacobian_every=2): r"LinearlyImplicitEuler\(jacobian_every=2\) is not .*"
        "reuses an earlier step's matrices.*use jacobian_every=1",
        "ros2_adaptive": "adapts its step in a run; 'ros2' is the same step at a fixed h",
        MyTrapezoid(): r"a subclass of a built-in method \(MyTrapezoid\)",
        HalvedRK4(): r"a subclass of a built-in method \(HalvedRK4\)",
        "scipy": "only the explicit Runge–Kutta methods, symplectic Euler and the linearly implicit methods",
    }
    for method, why in refused.items():
        with pytest.raises(SimulationError, match=f"{why}.*'rk4'.*'implicit_euler'"):
            step_sensitivity(pandas, integrator=method)
    for backend in ("python", "native"):
        message = r"sensitivities: diverged(.*the step matrix.*not finite.*t = 0 s| in the step from t = 0 s \(the step matrix)"
        with pytest.raises(SimulationError, match=message), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # (the Python reference's arithmetic on an infinite step)
            step_sensitivity(pandas, dt=1e300, integrator="implicit_euler", backend=backend)
    with pytest.raises(SceneError, match="rigid grasps"):
        step_sensitivity(cd.rigid_limit(pandas))
    with pytest.raises(SimulationError, match=r"tau \[N·m or N\] must have shape \(14,\)"):
        cd.Sensitivity(pandas).step(tau=np.zeros(3))
    closed = cd.Sensitivity(pandas, controller=cd.control.GravityCompensationPD(pandas))
    assert len(closed.trajectory(np.int64(2), 1e-3).t) == 3  # (a numpy integer is a number of periods too)
    with pytest.raises(SimulationError, match=r"one row per period, or the number of periods N \(an integer\)"):
        closed.trajectory(np.array(2.5), 1e-3)
    with pytest.raises(SimulationError, match="initial_state must be True or False"):
        closed.trajectory(2, 1e-3, initial_state="yes")
    with pytest.raises(SimulationError, match=r"1,000,000,000 steps, more than 2,000,000: take a larger dt, or split"):
        closed.trajectory(10**9, 1e-3)  # (refused before its torques are made: 112 GB)
    with pytest.raises(SimulationError, match=r"are 50,000,000 steps, more than 2,000,000"):
        cd.Sensitivity(pandas).trajectory(np.zeros((5, 14)), 1e-2, dt=1e-9)
    with pytest.raises(SimulationError, match=r"would take .* GB, more than 4 GB: split the trajectory"):
        cd.Sensitivity(pandas).transitions(np.zeros((200_000, 14)), 1e-3)
    with pytest.raises(SceneError, match=r"unknown parameter 'left\.k'.*'left\.<kind>'.*k_linear.*'object\.mass'"):
        parameters(pandas, ["left.k"])
    with pytest.raises(SceneError, match="repeated"):
        parameters(pandas, ["left.k_x", "left.k_x"])
    grips = [  # (a dot in a name)
        dataclasses.replace(spec, name=f"{link.name}.grip")
        for spec, link in zip(pandas.interconnection_specs, pandas.links, strict=True)
    ]
    named = ["left.grip.k_x", "right.grip.d_linear"]
    assert [p.name for p in parameters(cd.Scene(pandas.arm_specs, pandas.object, grips), named)] == named
    with pytest.raises(SceneError, match="non-empty list"):
        parameters(pandas, "left.k_x")
    with pytest.raises(SceneError, match="non-empty list"):
        cd.Sensitivity(pandas, parameters=3)  # type: ignore[arg-type]
    skewed = cd.Scene(
        pandas.arm_specs, pandas.object,
        [cd.Interconnection(ic.arm, stiffness=cd.diagonal([1e4, 2e4, 1e4], 100.0)) for ic in pandas.interconnection_specs],
    )  # fmt: skip
    with pytest.raises(SceneError, match=r"not isotropic.*\[10000.0, 20000.0, 10000.0\].*k_x, k_y"):
        parameters(skewed, ["left.k_linear"])
    assert parameters(skewed, ["left.k_y"])[0].value == 2e4
    with pytest.raises(SceneError, match="no rotational"):
        parameters(_ball_pandas(), ["left.k_rx"])
    beam = cd.scenes.held_beam(n_elements=2)
    with pytest.raises(SceneError, match="not one body on one joint"):
        parameters(beam, ["object.mass"])
    with pytest.raises(SimulationError, match="must divide the period"):
        trajectory_sensitivity(pandas, np.zeros((2, pandas.n_actuated)), 1e-3, dt=3e-4)
    with pytest.raises(SimulationError, match=r"torques must be \(N, 14\)"):
        trajectory_sensitivity(pandas, np.zeros((2, 3)), 1e-3)
    with pytest.raises(SimulationError, match="diverged"):
        trajectory_sensitivity(pandas, np.full((5, pandas.n_actuated), 1e6), 1e-2)


def _impedance(scene: cd.Scene) -> Any:
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance

    return ObjectImpedance(scene, GripLiftOscillate(start=cd.scenes.object_start(scene), squeeze=20.0))


@pytest.mark.parametrize(("method", "stiffness"), [("rk4", 1e4), ("trapezoid", 1e6)])
def test_a_closed_loops_sensitivities_are_the_derivatives_of_its_simulation(method: str, stiffness: float) -> None:
    """The demo's controller built for the nominal scene, sampled at 1 kHz, on twins of it: the
    trajectory is simulate's, its sensitivities are differences of simulate's, the backends agree."""
    scene = cd.scenes.facing_arms("panda", stiffness=stiffness, damping=0.002)
    controller = _impedance(scene)
    names = ["left.k_linear", "right.k_angular", "object.mass"]
    tr = trajectory_sensitivity(scene, 80, 1e-3, parameters=names, controller=controller, integrator=method)
    assert not tr.exact and tr.tau.shape == (80, scene.n_actuated)

    def run(s: cd.Scene) -> cd.Result:
        return cd.simulate(s, 0.08, controller, method, dt=1e-3, control_dt=1e-3, accuracy_check="off", energy_check="off")

    base = run(scene)
    np.testing.assert_allclose(tr.q, base.q, rtol=0, atol=1e-14)
    np.testing.assert_allclose(tr.tau, base.tau[:-1], rtol=0, atol=1e-11)
    model = scene.model
    for k, p in enumerate(tr.parameters):

        def x(value: float, p: Any = p) -> np.ndarray:
            r = run(with_parameters(scene, {p.name: p.value + value}))
            return np.array(
                [np.concatenate([pin.difference(model, a, b), c - d]) for a, b, c, d in zip(tr.q, r.q, r.v, tr.v, strict=True)]
            )

        assert _rel(tr.dx_dp[..., k], richardson(x, 1e-2 * p.value)) < 1e-6, p.name  # (a step of 1 %, as above)
    python = trajectory_sensitivity(scene, 30, 1e-3, parameters=names, controller=controller, backend="python", integrator=method)
    assert _rel(python.dx_dp, tr.dx_dp[:31]) < 1e-7
    np.testing.assert_allclose(python.q, tr.q[:31], rtol=0, atol=1e-13)
    with pytest.raises(SimulationError, match=r"open-loop step; a closed loop's: Sensitivity\.trajectory"):
        cd.sensitivity.Sensitivity(scene, controller=controller).step()


def test_a_controller_that_keeps_state_is_refused_by_a_closed_loops_derivative(book: cd.Scene) -> None:
    """A PI whose integral grows at every call: the probes of its derivative would change it (the
    trajectory was 0.16 m off the simulation's, and identify never moved); both backends refuse
    it and say why, and the fit by finite differences, which calls it once per sample, finds the
    true stiffness."""

    class PI:
        def __init__(self) -> None:
            self.integral = np.zeros(2)

        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            if t == 0.0:
                self.integral = np.zeros(2)
            error = 0.01 - q[:2]
            self.integral += 0.01 * error
            return 2000.0 * error + 20000.0 * self.integral - 50.0 * v[:2]

    run = cd.simulate(book, 0.2, PI(), "rk4", dt=1e-3, control_dt=1e-2, save_every=10, accuracy_check="off")
    for backend in ("native", "python"):
        with pytest.raises(SimulationError, match=r"answered the same call at t = 0\.01 s differently: it keeps state"):
            trajectory_sensitivity(book, 20, 1e-2, dt=1e-3, parameters=["tip1.k_z"], controller=PI(), backend=backend)
    measured, start = cd.Measurements.from_result(run), {"tip1.k_z": 1.5e4}
    with pytest.raises(SimulationError, match="keeps state between calls"):
        cd.identify(book, measured, ["tip1.k_z"], initial=start, controller=PI(), dt=1e-3)
    fit = cd.identify(book, measured, ["tip1.k_z"], initial=start, controller=PI(), dt=1e-3, jacobian="finite-differences")
    assert fit.estimate["tip1.k_z"] == pytest.approx(parameters(book, ["tip1.k_z"])[0].value, rel=1e-9)


def test_one_period_and_one_parameter_with_the_start_give_the_references_derivatives(pandas: cd.Scene) -> None:
    """(1, n) inputs to the kernel's twin: one period of torques, one parameter with the start's
    columns — eigenpy once mapped such arrays wrongly through an Eigen::Ref."""
    U = 3.0 * np.random.default_rng(0).normal(size=(1, pandas.n_actuated))
    for names, start in ((["left.k_linear"], True), (["left.k_linear", "object.mass"], False)):
        a, b = (
            trajectory_sensitivity(pandas, U, 2e-3, dt=1e-3, parameters=names, initial_state=start, backend=x)
            for x in ("native", "python")
        )
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-13)
        np.testing.assert_allclose(a.tau, U, rtol=0, atol=0)
        assert _rel(a.dx_dp, b.dx_dp) < 1e-10
        if start:
            assert a.dx_dx0 is not None and b.dx_dx0 is not None and _rel(a.dx_dx0, b.dx_dx0) < 1e-10


def test_a_python_law_in_an_implicit_step_crosses_into_python_and_is_not_exact(pandas: cd.Scene) -> None:
    """A user's SE(3) law with its own evaluate (no C++ twin): its tangents are the base class's
    differences, in both twins alike; the derivative is that of the step to the differences'
    accuracy, and says it is not exact."""
    from coopdyn.model.elements import SE3Spring

    class Mine(SE3Spring):
        kind = "mine_implicit_test"

        def evaluate(self, T_M_G: Any, xi: Any, jacobians: bool = False) -> Any:
            return super().evaluate(T_M_G, xi, jacobians)

    links = [
        cd.Interconnection(ic.arm, stiffness=1e4, damping=cd.diagonal(20.0, 0.2), element=Mine)
        for ic in pandas.interconnection_specs
    ]
    with warnings.catch_warnings():  # (no C++ twin: the kernel calls the Python law)
        warnings.simplefilter("ignore")
        scene = cd.Scene(pandas.arm_specs, pandas.object, links)
        q, v, tau = _start(scene)
        a, b = (step_sensitivity(scene, q, v, tau, 2e-3, integrator="trapezoid", backend=x) for x in ("python", "native"))
    assert not a.exact and not b.exact
    assert _rel(a.dx_dx, b.dx_dx) < 1e-9
    exact = step_sensitivity(pandas.__class__(pandas.arm_specs, pandas.object, [
        cd.Interconnection(ic.arm, stiffness=1e4, damping=cd.diagonal(20.0, 0.2)) for ic in pandas.interconnection_specs
    ]), q, v, tau, 2e-3, integrator="trapezoid")  # fmt: skip
    assert exact.exact and _rel(b.dx_dx, exact.dx_dx) < 1e-6


def test_ctrl_c_stops_the_kernels_twin_mid_run(book: cd.Scene) -> None:
    """A SIGINT while the twin runs in C++ stops it there (it checks for signals every step), not
    when the whole run is done: the interrupted run takes a small part of the whole one's time."""
    import os
    import subprocess
    import time

    sens = cd.Sensitivity(book, "trapezoid", parameters=["tip1.k_z"])
    assert sens.native is not None
    short = np.zeros((2000, book.n_actuated))
    t0 = time.perf_counter()
    sens.trajectory(short, 1e-3)
    per_period = (time.perf_counter() - t0) / len(short)
    # (from another process: a thread of this one would wait for the GIL the run holds)
    sender = subprocess.Popen(["sh", "-c", f"sleep 0.2; kill -INT {os.getpid()}"])
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        sens.trajectory(np.zeros((100 * len(short), book.n_actuated)), 1e-3)
    took = time.perf_counter() - t0
    sender.wait()
    assert took < 0.25 * 100 * len(short) * per_period  # (the whole run: 100× the short one)


def test_a_python_laws_own_error_in_its_matrix_tangent_reaches_the_user(pandas: cd.Scene) -> None:
    """What a user's law raises in matrix_tangent inside the kernel's twin is kept and re-raised,
    named, with the law's own exception as its cause (not a bare kernel message)."""
    from coopdyn.model.elements import SE3Spring

    class Broken(SE3Spring):
        kind = "broken_matrix_tangent_test"

        def evaluate(self, T_M_G: Any, xi: Any, jacobians: bool = False) -> Any:
            return super().evaluate(T_M_G, xi, jacobians)

        def matrix_tangent(self, T_M_G: Any, xi: Any, w_K: Any, w_D: Any) -> Any:
            raise ValueError("no matrix tangent today")

    links = [cd.Interconnection(ic.arm, stiffness=1e4, element=Broken) for ic in pandas.interconnection_specs]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cd.Scene(pandas.arm_specs, pandas.object, links)
        for backend in ("python", "native"):
            with pytest.raises((ValueError, KernelError), match="no matrix tangent today") as caught:
                step_sensitivity(scene, integrator="implicit_euler", backend=backend)
            assert "kernel stopped" not in str(caught.value)
            if backend == "native":
                assert "Broken raised ValueError" in str(caught.value) and isinstance(caught.value.__cause__, ValueError)


def test_a_python_elements_own_error_reaches_the_user_from_the_kernels_twin(pandas: cd.Scene) -> None:
    from coopdyn.model.elements import SE3Spring

    class Flaky(SE3Spring):
        kind = "flaky_test"
        calls = 0

        def evaluate(self, T_M_G: Any, xi: Any, jacobians: bool = False) -> Any:
            Flaky.calls += 1
            if Flaky.calls > 40:
                raise ValueError("flaky element gave up")
            return super().evaluate(T_M_G, xi, jacobians)

    links = [cd.Interconnection(ic.arm, stiffness=1e4, element=Flaky) for ic in pandas.interconnection_specs]
    with warnings.catch_warnings():  # (no C++ twin: the kernel calls the Python law)
        warnings.simplefilter("ignore")
        scene = cd.Scene(pandas.arm_specs, pandas.object, links)
        sens = cd.Sensitivity(scene, backend="native")
    with pytest.raises((ValueError, SimulationError), match="flaky element gave up") as caught:
        sens.trajectory(np.zeros((20, scene.n_actuated)), 1e-3)
    assert "diverged" not in str(caught.value)  # (the element's failure, named, not a divergence)


def test_parameters_refuse_laws_they_do_not_know_and_entries_set_twice(pandas: cd.Scene) -> None:
    from coopdyn.model.elements import SE3Spring

    class Doubled(SE3Spring):
        kind = "doubled_test"

        def evaluate(self, T_M_G: Any, xi: Any, jacobians: bool = False) -> Any:
            ev = super().evaluate(T_M_G, xi, jacobians)
            return ev._replace(G_f_G=2.0 * ev.G_f_G)

    links = [cd.Interconnection(ic.arm, stiffness=1e4, element=Doubled) for ic in pandas.interconnection_specs]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cd.Scene(pandas.arm_specs, pandas.object, links)
    with pytest.raises(SceneError, match="Doubled law is not known to be linear"):
        parameters(scene, ["left.k_linear"])
    with pytest.raises(SceneError, match=r"'left\.k_linear' and 'left\.k_x' both set entry x of that stiffness"):
        parameters(pandas, ["left.k_linear", "left.k_x"])
    assert len(parameters(pandas, ["left.k_linear", "left.d_x", "right.k_x"])) == 3


def test_transitions_are_the_periods_linearisation(book: cd.Scene, pandas: cd.Scene) -> None:
    """On the book system a period of k rk4 steps is R(hA)^k exactly; on two Pandas each period's
    A_k, B_k chain into what the trajectory's forward sensitivities say about the start and what
    one-step sensitivities give."""
    lin = cd.linearize(book)
    h, per = 1e-2, 3
    tr = cd.Sensitivity(book).transitions(np.zeros((2, book.n_actuated)), per * h, dt=h)
    hA = h * lin.A
    R = np.eye(len(hA)) + hA + hA @ hA / 2 + hA @ hA @ hA / 6 + hA @ hA @ hA @ hA / 24
    np.testing.assert_allclose(tr.A[1], np.linalg.matrix_power(R, per), rtol=0, atol=1e-13)
    U = 2.0 * np.random.default_rng(3).normal(size=(4, pandas.n_actuated))
    sens = cd.Sensitivity(pandas, parameters=["left.k_linear"])
    tr = sens.transitions(U, 2e-3, dt=1e-3)
    full = sens.trajectory(U, 2e-3, dt=1e-3, initial_state=True)
    assert full.dx_dx0 is not None
    np.testing.assert_allclose(tr.q, full.q, rtol=0, atol=0)
    chain = np.eye(2 * pandas.nv)
    for k in range(4):
        chain = tr.A[k] @ chain
        assert _rel(chain, full.dx_dx0[k + 1]) < 1e-12
    dp = np.zeros((2 * pandas.nv, 1))  # ∂x_k/∂p by the periods: P_k + A_k ∂x_{k-1}/∂p
    for k in range(4):
        dp = tr.A[k] @ dp + tr.P[k]
        assert _rel(dp, full.dx_dp[k + 1]) < 1e-12
    one = sens.step(tr.q[0], tr.v[0], U[0], 1e-3)
    two = sens.step(one.q, one.v, U[0], 1e-3)
    np.testing.assert_allclose(tr.B[0], two.dx_dx @ one.dx_du + two.dx_du, rtol=0, atol=1e-12 * np.max(np.abs(tr.B[0])))
    with pytest.raises(SimulationError, match="linearises an open loop"):
        cd.Sensitivity(pandas, controller=_impedance(pandas)).transitions(U, 2e-3)


@pytest.mark.parametrize("method", ["rk4", "trapezoid"])
def test_a_losss_gradient_by_the_backward_pass_is_the_derivative_of_rollouts(pandas: cd.Scene, method: str) -> None:
    """L = Σ_k w_k·δx_k over the samples (δx about the nominal trajectory): its gradient from
    Transitions.gradient (one backward pass) against central differences of compiled rollouts in
    the torques and the start, and of rollouts of with_parameters in the parameters."""
    model, nv, na = pandas.model, pandas.nv, pandas.n_actuated
    rng = np.random.default_rng(8)
    g = pin.computeGeneralizedGravity(model, model.createData(), pandas.q0)[pandas.actuated]
    N, period, dt = 5, 2e-3, 1e-3
    U = g + 2.0 * rng.normal(size=(N, na))
    names = ["left.k_linear", "right.grasp_z"]
    tr = cd.Sensitivity(pandas, method, parameters=names).transitions(U, period, dt=dt)
    w = rng.normal(size=(N + 1, 2 * nv))
    grad = tr.gradient(w)

    def loss(batch: np.ndarray, scene: cd.Scene = pandas, x0: np.ndarray | None = None) -> np.ndarray:
        x0 = np.zeros((len(batch), 2 * nv)) if x0 is None else x0
        q0 = np.array([pin.integrate(model, pandas.q0, x[:nv]) for x in x0])
        run = cd.rollout(scene, batch, period=period, dt=dt, q0=q0, v0=pandas.v0 + x0[:, nv:], integrator=method, threads=1)
        out = np.zeros(len(batch))
        for b in range(len(batch)):
            dx = [np.concatenate([pin.difference(model, tr.q[k], run.q[b, k]), run.v[b, k] - tr.v[k]]) for k in range(N + 1)]
            out[b] = float(np.sum(w * np.array(dx)))
        return out

    eps = 1e-3
    plus, minus = np.repeat(U[None], N * na, axis=0), np.repeat(U[None], N * na, axis=0)
    for j in range(N * na):
        plus[j].flat[j] += eps
        minus[j].flat[j] -= eps
    du = ((loss(plus) - loss(minus)) / (2 * eps)).reshape(N, na)
    assert _rel(grad.torques, du) < 1e-6
    e = 1e-5 * np.eye(2 * nv)
    dx0 = (loss(np.repeat(U[None], 2 * nv, axis=0), x0=e) - loss(np.repeat(U[None], 2 * nv, axis=0), x0=-e)) / 2e-5
    assert _rel(grad.start, dx0) < 1e-6
    for k, p in enumerate(tr.parameters):
        step = _step(p, 1e-2)
        dp = (
            loss(U[None], with_parameters(pandas, {p.name: p.value + step}))
            - loss(U[None], with_parameters(pandas, {p.name: p.value - step}))
        ) / (2 * step)
        assert abs(grad.parameters[k] - dp[0]) < 1e-5 * max(abs(dp[0]), 1e-300), p.name
    with pytest.raises(SimulationError, match=r"dloss_dx.*shape"):
        tr.gradient(w[:-1])


def test_a_diverging_run_is_stopped_at_its_first_fast_step_with_its_time() -> None:
    """rk4 at 20 ms on a 28 Hz box (|R| ≈ 3.8 a step): the speed passes 1e4 at a step of a later
    period; trajectory and transitions (which runs period by period) both stop there and name the
    same instant, on both backends."""
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
    spring = cd.Interconnection(None, stiffness=cd.diagonal(3e4, 1.0), grasp=[0.0, 0.0, 0.05])
    scene = cd.Scene([], box, [spring])
    v0 = np.zeros(6)
    v0[0] = 0.1
    messages = []
    for backend in ("native", "python"):
        sens = cd.Sensitivity(scene, backend=backend)
        for run in (
            lambda: sens.trajectory(np.zeros((20, 0)), 0.04, dt=0.02, v0=v0),
            lambda: sens.transitions(np.zeros((20, 0)), 0.04, dt=0.02, v0=v0),
        ):
            with pytest.raises(SimulationError, match=r"diverged.*above 10000.*after the step from t = ") as caught:
                run()
            messages.append(str(caught.value).split("after the step from t = ")[1].split(" s")[0])
    assert len(set(messages)) == 1 and float(messages[0]) >= 0.04, messages  # (a later period: transitions counts from the start)
