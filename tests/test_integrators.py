"""Integrators: convergence orders on the exact linear case and on two Pandas with a free-flying
box, the exponential integrator, adaptive methods, stability prediction vs measurement."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.closed_loop import System
from coopdyn.control import GravityCompensationPD
from coopdyn.errors import StepMatrixError
from coopdyn.integrators import INTEGRATORS, Exponential, GeneralizedAlpha, get_integrator
from coopdyn.reference import Drive, linear_book_exact

pytestmark = pytest.mark.filterwarnings("ignore::coopdyn.EnergyBalanceWarning")  # coarse steps on purpose

# (method, nominal order, step sizes in the asymptotic range) on the linear case over 1 s
LINEAR_ORDERS = {
    "symplectic_euler": (1, [4e-3, 2e-3, 1e-3]),
    "rk4": (4, [4e-3, 2e-3, 1e-3]),
    "implicit_euler": (1, [4e-3, 2e-3, 1e-3]),
    "ros2": (2, [1e-3, 5e-4, 2.5e-4]),
    "trapezoid": (2, [1e-3, 5e-4, 2.5e-4]),
    "generalized_alpha": (2, [1e-3, 5e-4, 2.5e-4]),
}


def _slope(dts: list[float], errors: list[float]) -> float:
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


@pytest.mark.parametrize("name", LINEAR_ORDERS)
def test_order_on_the_linear_case(book: cd.Scene, name: str) -> None:
    order, dts = LINEAR_ORDERS[name]
    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)
    errors = []
    for dt in dts:
        res = cd.simulate(book, 1.0, controller=ctrl, integrator=name, dt=dt)
        errors.append(np.max(np.abs(cd.scenes.book_positions(res.q, book) - linear_book_exact(res.t, d1, d2).Y)))
    assert _slope(dts, errors) == pytest.approx(order, abs=0.3)


def _fixed_steps(scene: cd.Scene, method: cd.integrators.Integrator, dt: float, v0: np.ndarray, t_final: float) -> np.ndarray:
    """Fixed steps of any method (adaptive ones without their step control); the final q."""
    system = System(cd.Dynamics(scene))
    q, v, t = scene.q0, v0, 0.0
    ws = method.workspace(system)  # generalized-α carries its algorithmic acceleration there
    for _ in range(round(t_final / dt)):
        q, v = method.step(system, t, q, v, dt, ws)
        t += dt
    return q


# (method, nominal order, step sizes) on two Pandas + free-flying box, k = 1e4 N/m, over 0.04 s
PANDA_ORDERS = {
    "symplectic_euler": (1, [4e-4, 2e-4, 1e-4]),
    "rk4": (4, [8e-4, 4e-4, 2e-4]),
    "dopri5": (5, [8e-4, 4e-4, 2e-4]),
    "dop853": (8, [5e-3, 4e-3, 2.5e-3]),  # (below 2.5 ms, 1e-11 and less, it is no longer one term's: not monotonic)
    "implicit_euler": (1, [4e-4, 2e-4, 1e-4]),
    "ros2": (2, [2e-4, 1e-4, 5e-5]),
    "trapezoid": (2, [2e-4, 1e-4, 5e-5]),
    "generalized_alpha": (2, [2e-4, 1e-4, 5e-5]),
}


@pytest.fixture(scope="module")
def panda_reference(pandas: cd.Scene) -> tuple[np.ndarray, np.ndarray]:
    """Initial velocity and the final q from RK4 at dt = 1e-5 (checked against Dormand–Prince)."""
    v0 = np.random.default_rng(3).normal(size=pandas.nv) * 0.5
    q_ref = _fixed_steps(pandas, get_integrator("rk4"), 1e-5, v0, 0.04)
    q_dp = _fixed_steps(pandas, get_integrator("dopri5"), 4e-5, v0, 0.04)
    assert np.max(np.abs(pin.difference(pandas.model, q_ref, q_dp))) < 1e-12  # two methods agree
    return v0, q_ref


@pytest.mark.parametrize("name", PANDA_ORDERS)
def test_order_on_two_pandas_with_a_free_flying_box(
    pandas: cd.Scene, panda_reference: tuple[np.ndarray, np.ndarray], name: str
) -> None:
    """Errors in the tangent space (pin.difference): the Lie-group chart keeps every order."""
    order, dts = PANDA_ORDERS[name]
    v0, q_ref = panda_reference
    method = get_integrator(name)
    errors = [np.max(np.abs(pin.difference(pandas.model, q_ref, _fixed_steps(pandas, method, dt, v0, 0.04)))) for dt in dts]
    assert _slope(dts, errors) == pytest.approx(order, abs=0.3)


def test_exponential_is_exact_for_a_held_controller(book: cd.Scene) -> None:
    """Zero-order hold: the torque is constant over each step, exactly what the exact solution
    with a piecewise-constant drive sees; agreement to round-off at any dt."""
    dt = 0.01
    values = np.random.default_rng(0).normal(300.0, 40.0, size=(100, 2))
    drives = [Drive([cd.reference.Segment(k * dt, values[k, i]) for k in range(100)]) for i in range(2)]

    def held(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        k = min(round(t / dt), 99)
        return values[k]

    res = cd.simulate(book, 1.0, controller=held, integrator=Exponential(hold="zoh"), dt=dt)
    exact = linear_book_exact(res.t, *drives)
    assert np.max(np.abs(cd.scenes.book_positions(res.q, book) - exact.Y)) < 1e-12
    assert np.max(np.abs(res.wrench(0)[:, 2] - exact.Fc1)) < 1e-8


@pytest.mark.parametrize(("hold", "order", "dts"), [("foh", 2, [2e-3, 1e-3, 5e-4]), ("cubic", 4, [5e-3, 2.5e-3, 1.25e-3])])
def test_exponential_hold_order(book: cd.Scene, hold: str, order: int, dts: list[float]) -> None:
    """Contact-force error vs dt; the drives' breakpoints (0.5, 1, 2, 2.25 s) are on these grids."""
    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)
    errors = []
    for dt in dts:
        res = cd.simulate(book, 3.0, controller=ctrl, integrator=Exponential(hold), dt=dt)
        exact = linear_book_exact(res.t, d1, d2)
        errors.append(max(np.max(np.abs(res.wrench(0)[:, 2] - exact.Fc1)), np.max(np.abs(res.wrench(1)[:, 2] - exact.Fc2))))
    assert _slope(dts, errors) == pytest.approx(order, abs=0.3)


def test_exponential_refuses_a_nonlinear_scene(pandas: cd.Scene) -> None:
    message = r"needs a linear scene; this one is not: 15 joints that are not prismatic .*left/panda_joint1.* and 12 more"
    with pytest.raises(cd.SimulationError, match=message):
        cd.simulate(pandas, 0.01, integrator="exponential")


def test_advise_detects_linearity(book: cd.Scene, pandas: cd.Scene) -> None:
    assert cd.advise(book).linear and "use 'exponential'" in cd.advise(book).recommendation
    advice = cd.advise(pandas)
    assert not advice.linear and not next(m for m in advice.methods if m.name == "exponential").applicable


@pytest.mark.parametrize("name", ["dopri5", "dop853", "ros2_adaptive"])
def test_adaptive_methods_meet_their_tolerance(book: cd.Scene, name: str) -> None:
    """The global error follows the tolerance, and outputs land on the save grid."""
    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)
    errors = []
    for rtol in (1e-3, 1e-5):
        method = INTEGRATORS[name](rtol=rtol, atol=rtol * 1e-3)  # type: ignore[call-arg]
        res = cd.simulate(book, 1.0, controller=ctrl, integrator=method, dt=0.1)  # (a grid its steps do not meet)
        np.testing.assert_allclose(res.t, np.linspace(0.0, 1.0, 11), atol=1e-12)
        errors.append(np.max(np.abs(cd.scenes.book_positions(res.q, book) - linear_book_exact(res.t, d1, d2).Y)))
        assert res.n_steps > 0
    assert errors[1] < errors[0] / 10.0
    assert errors[1] < 1e-5 * 0.3  # error in units of the tolerance x the solution scale (~0.3 m)


@pytest.mark.parametrize("k", [1e4, 1e5, 1e6])
@pytest.mark.parametrize("name", ["symplectic_euler", "rk4"])
def test_predicted_stable_dt_matches_measurement(k: float, name: str) -> None:
    """advise's linearised limit is within 25 % of the bisection on real simulations."""
    scene = cd.scenes.facing_arms("panda", stiffness=k)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)  # [N·m/rad], [N·m·s/rad]
    predicted = cd.advise(scene, controller=ctrl).max_stable_dt(name)
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.05
    measured = cd.measure_stable_dt(scene, name, controller=ctrl, guess=predicted, v0=v0, n_steps=2000)
    assert predicted == pytest.approx(measured, rel=0.25)


def test_implicit_methods_survive_stiffness_that_breaks_explicit_ones() -> None:
    """k = 1e7 N/m at dt = 1 ms: RK4 diverges with a diagnosis, the implicit methods hold."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e7, damping=1e-3)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    with pytest.raises(
        cd.DivergenceError,
        match=r"with rk4 at dt = 0.001 s.*stable at dt = 1 ms: implicit_euler, ros2, trapezoid, generalized_alpha\.",
    ):
        cd.simulate(scene, 0.5, controller=ctrl, integrator="rk4", dt=1e-3)
    for name in ("implicit_euler", "ros2", "generalized_alpha"):
        res = cd.simulate(scene, 0.5, controller=ctrl, integrator=name, dt=1e-3, energy_check="raise")
        assert np.all(np.isfinite(res.q)) and np.max(np.abs(res.v)) < 10.0


def test_energy_monitor_flags_unexplained_growth() -> None:
    """Symplectic Euler just beyond its limit: the monitor warns before anything is non-finite."""
    scene = cd.scenes.facing_arms("panda", stiffness=1e5)
    ctrl = GravityCompensationPD(scene, 50.0, 5.0)
    dt = 1.05 * cd.advise(scene, controller=ctrl).max_stable_dt("symplectic_euler")
    v0 = np.random.default_rng(0).normal(size=scene.nv) * 0.05
    advice = r"\(symplectic_euler\) is probably unstable or too coarse here: reduce dt, or use 'implicit_euler' or 'ros2'"
    backends = ("python", "native") if cd.backend.native_available() else ("python",)
    for backend in backends:  # the Python loop's monitor and the compiled loop's say the same
        with pytest.raises(cd.EnergyBalanceError, match=r"energy balance broken at t = (.|\n)*" + advice):
            cd.simulate(
                scene, 0.5, controller=ctrl, integrator="symplectic_euler", dt=dt, v0=v0, energy_check="raise", backend=backend
            )


def test_the_energy_warning_does_not_send_a_dissipative_method_to_itself() -> None:
    from coopdyn.monitor import violation_message

    for method in ("implicit_euler", "ros2"):
        message = violation_message(0.1, 1.0, 0.5, 0.5, 0.05, 2.0, method)
        assert f"({method})" in message and "'implicit_euler'" not in message and "'dopri5'" in message


def test_energy_monitor_is_quiet_on_a_good_run(pandas: cd.Scene) -> None:
    ctrl = GravityCompensationPD(pandas, 200.0, 20.0)
    v0 = np.random.default_rng(5).normal(size=pandas.nv) * 0.3
    cd.simulate(pandas, 0.3, controller=ctrl, integrator="rk4", dt=2e-4, v0=v0, energy_check="raise")


def test_implicit_euler_with_jacobian_reuse(book: cd.Scene) -> None:
    """Reusing M, K̃, D̃ for 10 steps keeps first order on the linear case and stability at
    k = 1e7 N/m, dt = 1 ms on the Panda scene."""
    from coopdyn.integrators import LinearlyImplicitEuler

    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)
    dts = [4e-3, 2e-3, 1e-3]
    errors = []
    for dt in dts:
        res = cd.simulate(book, 1.0, controller=ctrl, integrator=LinearlyImplicitEuler(jacobian_every=10), dt=dt)
        errors.append(np.max(np.abs(cd.scenes.book_positions(res.q, book) - linear_book_exact(res.t, d1, d2).Y)))
    assert _slope(dts, errors) == pytest.approx(1.0, abs=0.3)
    stiff = cd.scenes.facing_arms("panda", stiffness=1e7, damping=1e-3)
    res = cd.simulate(
        stiff,
        0.5,
        controller=GravityCompensationPD(stiff, 50.0, 5.0),
        integrator=LinearlyImplicitEuler(10),
        dt=1e-3,
        energy_check="raise",
    )
    assert res.n_jac == 50 and np.max(np.abs(res.v)) < 10.0
    with pytest.raises(cd.SimulationError, match=r"jacobian_every must be an integer >= 1, got 0"):
        LinearlyImplicitEuler(0)


def test_dopri5_fixed_step_order_on_the_linear_case(book: cd.Scene) -> None:
    """Dormand–Prince without its step control: fifth order against the exact solution."""
    d1, d2 = cd.scenes.book_task()
    method = get_integrator("dopri5")
    dts = [2.5e-3, 1.25e-3, 6.25e-4]  # the drives' breakpoints are on these grids
    errors = []
    for dt in dts:
        system = System(cd.Dynamics(book), cd.scenes.drives_controller(d1, d2))
        q, v, qs = book.q0, book.v0, [book.q0]
        for k in range(round(3.0 / dt)):
            q, v = method.step(system, k * dt, q, v, dt)
            qs.append(q)
        t = dt * np.arange(len(qs))
        errors.append(np.max(np.abs(cd.scenes.book_positions(np.array(qs), book) - linear_book_exact(t, d1, d2).Y)))
    assert _slope(dts, errors) == pytest.approx(5.0, abs=0.3)


@pytest.mark.parametrize(("weights", "local_order"), [("b", 9), ("b_hat", 6)])
def test_dop853_stability_function_matches_the_exponential_to_its_orders(weights: str, local_order: int) -> None:
    """On y' = λy a step is R(hλ): R(z) − eᶻ = O(z⁹) for the eighth-order solution, O(z⁶) for
    the fifth-order embedded one (``b_hat`` as the weights); the nonlinear order is tested on two
    Pandas (PANDA_ORDERS)."""
    tableau = get_integrator("dop853").tableau
    z = np.array([0.4, 0.2])
    gap = np.abs(cd.integrators.explicit._rk_stability(tableau, z, getattr(tableau, weights)) - np.exp(z))
    assert np.log2(gap[0] / gap[1]) == pytest.approx(local_order, abs=0.3), gap


def test_an_embedded_pair_must_end_on_its_solution() -> None:
    """The step takes the last stage as the solution: a pair whose last row is not b is refused."""
    rk4 = cd.integrators.RK4.tableau
    with pytest.raises(cd.SimulationError, match=r"Pair: an embedded pair's last stage must be its solution"):
        type("Pair", (cd.integrators.EmbeddedRungeKutta,), {"tableau": dataclasses.replace(rk4, b_hat=rk4.b), "error_order": 3})
    with pytest.raises(cd.SimulationError, match=r"Orderless: an embedded pair needs its error_order"):
        type("Orderless", (cd.integrators.EmbeddedRungeKutta,), {"tableau": get_integrator("dopri5").tableau})


def test_trapezoid_stability_function_is_the_cayley_map_and_rho_inf_sets_its_limit() -> None:
    """γ = ½ gives (1 + z/2)/(1 − z/2): |R(iω)| = 1 at every frequency; ρ∞ = |R(∞)|; ρ∞ = 0 is ROS2;
    A-stable (|R| ≤ 1 on the left half-plane) for every ρ∞ in [0, 1]."""
    z = np.concatenate([1j * np.logspace(-3, 6, 50), -np.logspace(-3, 6, 50) + 3j, [-1e12]])
    assert np.allclose(cd.integrators.Trapezoid().stability_function(z), (1 + z / 2) / (1 - z / 2), rtol=1e-12, atol=1e-12)
    assert np.allclose(np.abs(cd.integrators.Trapezoid().stability_function(1j * np.logspace(-3, 6, 50))), 1.0, atol=1e-12)
    for rho in (0.0, 0.3, 0.8, 1.0):
        method = cd.integrators.Trapezoid(rho)
        assert abs(method.stability_function(np.array([-1e12]))[0]) == pytest.approx(rho, abs=1e-9)
        assert np.all(np.abs(method.stability_function(z)) <= 1.0 + 1e-12)
    ros2 = get_integrator("ros2").stability_function(z)
    assert np.allclose(cd.integrators.Trapezoid(0.0).stability_function(z), ros2, rtol=1e-12, atol=1e-14)
    with pytest.raises(cd.SimulationError, match=r"rho_inf must be a number in \[0, 1\], got 1.5"):
        cd.integrators.Trapezoid(1.5)


def test_trapezoid_keeps_the_energy_that_ros2_dissipates(pandas: cd.Scene) -> None:
    """Undamped Pandas + box, τ = 0, perturbed: the trapezoid's energy error is second order
    (÷4 per halving of dt) and far below ROS2's numerical dissipation at the same step."""
    v0 = np.random.default_rng(11).normal(size=pandas.nv) * 0.2
    drift = {}
    for name, dt in (("trapezoid", 2e-3), ("trapezoid", 1e-3), ("ros2", 1e-3)):
        E = cd.simulate(pandas, 1.0, integrator=name, dt=dt, v0=v0).energy()
        drift[name, dt] = np.max(np.abs(E.total - E.total[0])) / E.kinetic.max()
    assert drift["trapezoid", 2e-3] / drift["trapezoid", 1e-3] == pytest.approx(4.0, rel=0.2)
    assert drift["trapezoid", 1e-3] < 0.005
    assert drift["ros2", 1e-3] > 5 * drift["trapezoid", 1e-3]


def test_generalized_alpha_at_rho_inf_1_is_newmark_average_acceleration() -> None:
    """ρ∞ = 1: the principal root is the trapezoid's Cayley map, which never damps (|R(iω)| = 1)."""

    z = np.concatenate([1j * np.logspace(-3, 6, 40), -np.logspace(-3, 4, 40) + 3j, -np.logspace(-2, 3, 20) * (1 + 1j)])
    assert np.allclose(GeneralizedAlpha(1.0).stability_function(z), (1 + z / 2) / (1 - z / 2), rtol=1e-9, atol=1e-9)
    assert np.allclose(np.abs(GeneralizedAlpha(1.0).stability_function(1j * np.logspace(-3, 6, 40))), 1.0, atol=1e-9)
    with pytest.raises(cd.SimulationError, match=r"rho_inf must be a number in \[0, 1\], got -0.1"):
        GeneralizedAlpha(-0.1)
    with pytest.raises(cd.SimulationError, match=r"rho_inf must be a number in \[0, 1\], got 1000000000"):
        GeneralizedAlpha(rho_inf=10**400)


def test_generalized_alpha_refuses_a_zero_step_and_a_state_that_is_not_finite(book: cd.Scene) -> None:
    system = System(cd.Dynamics(book), None)
    q, v = book.q0, np.zeros(book.nv)
    with pytest.raises(cd.SimulationError, match=r"needs a step h > 0, got 0\.0"):
        GeneralizedAlpha().step(system, 0.0, q, v, 0.0)
    with pytest.raises(StepMatrixError, match="not finite"):
        GeneralizedAlpha().step(system, 0.0, np.full_like(q, np.nan), v, 1e-3)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9, 1.0])
def test_generalized_alpha_is_second_order_stable_and_rho_inf_is_its_limit(rho: float) -> None:
    """On the mode with eigenvalues z, z̄ the principal root is e^z to third order (a second-order
    method); the step's spectral radius never exceeds 1 on lightly damped oscillators of any
    frequency (unconditionally stable) and tends to ρ∞ at high frequency."""

    method = GeneralizedAlpha(rho)
    small = np.array([1e-2j, -1e-2 + 1e-2j, 2e-2j])
    assert np.all(np.abs(method.stability_function(small) - np.exp(small)) < 2 * np.abs(small) ** 3)
    for omega in (1e-1, 1e1, 1e3):
        A = np.array([[0.0, 1.0], [-(omega**2), -0.02 * omega]])
        assert method.spectral_radius(A, 1.0) <= 1.0 + 1e-12
    A = np.array([[0.0, 1.0], [-1e16, 0.0]])
    assert method.spectral_radius(A, 1.0) == pytest.approx(rho, abs=1e-4)  # ρ∞ = 0: a triple root
    z = np.concatenate([1j * np.logspace(-3, 6, 40), -np.logspace(-3, 4, 40) + 3j])
    assert np.all(np.abs(method.stability_function(z)) <= 1.0 + 1e-9)


def test_generalized_alpha_spectral_radius_is_that_of_its_real_step(book: cd.Scene) -> None:
    """What advise uses is the step itself: on the book's linear system (no controller) the
    matrix one step applies to (q, v, a), built column by column from the integrator's own
    step, has the spectral radius ``spectral_radius(A, h)`` predicts; advise finds it stable at
    any step."""

    A = cd.stability.linearize(book)
    n = book.nv
    assert cd.advise(book).max_stable_dt("generalized_alpha") == float("inf")
    for rho, h in ((0.9, 1e-3), (0.5, 2e-2), (0.0, 0.5)):
        method = GeneralizedAlpha(rho)
        system = System(cd.Dynamics(book))
        q0, v0 = book.q0, np.zeros(n)
        a0 = system.acceleration(0.0, q0, v0)

        def step(dx: np.ndarray, method: GeneralizedAlpha = method, system: System = system) -> np.ndarray:
            ws = method.workspace(system)
            q, v = q0 + dx[:n], v0 + dx[n : 2 * n]
            ws.a, ws.q, ws.v = a0 + dx[2 * n :], q, v
            q1, v1 = method.step(system, 0.0, q, v, h, ws)
            return np.concatenate([q1, v1, ws.a])

        base = step(np.zeros(3 * n))
        T = np.column_stack([(step(1e-3 * e) - base) / 1e-3 for e in np.eye(3 * n)])
        assert np.max(np.abs(np.linalg.eigvals(T))) == pytest.approx(method.spectral_radius(A, h), rel=1e-6)


def test_generalized_alpha_keeps_the_energy_and_rho_inf_removes_only_high_frequencies(pandas: cd.Scene) -> None:
    """Undamped Pandas + box, τ = 0, perturbed: at ρ∞ = 1 the energy error is second order (÷4 per
    halving of dt) and far below ROS2's dissipation; ρ∞ = 0.9 at 1 ms stays within a few times
    the non-dissipative method's error (its damping is third order in ωh on resolved modes)."""

    v0 = np.random.default_rng(11).normal(size=pandas.nv) * 0.2
    drift = {}
    for label, method, dt in (
        ("1", GeneralizedAlpha(1.0), 2e-3),
        ("1", GeneralizedAlpha(1.0), 1e-3),
        ("0.9", GeneralizedAlpha(0.9), 1e-3),
        ("ros2", get_integrator("ros2"), 1e-3),
    ):
        E = cd.simulate(pandas, 1.0, integrator=method, dt=dt, v0=v0).energy()
        drift[label, dt] = np.max(np.abs(E.total - E.total[0])) / E.kinetic.max()
    assert drift["1", 2e-3] / drift["1", 1e-3] == pytest.approx(4.0, rel=0.2)
    assert drift["1", 1e-3] < 0.005
    assert drift["ros2", 1e-3] > 5 * drift["1", 1e-3]
    assert drift["0.9", 1e-3] < 3 * drift["1", 1e-3]


def test_ros2_adaptive_defaults_cost_steps_of_dopri5s_order() -> None:
    """Its defaults are set for a second-order method (steps ∝ rtol^-½): within 3× of dopri5's
    steps on the book system (dopri5's own 1e-6 took 59×), with a force error below 1 N."""
    scene = cd.scenes.linear_book()
    controller = cd.scenes.drives_controller(*cd.scenes.book_task())
    runs = {m: cd.simulate(scene, 0.1, controller=controller, integrator=m) for m in ("ros2_adaptive", "dopri5")}
    assert runs["ros2_adaptive"].n_steps <= 3 * runs["dopri5"].n_steps
    error = np.abs(runs["ros2_adaptive"].wrench(0) - runs["dopri5"].wrench(0)).max()
    assert error < 1.0


def test_the_advised_methods_are_the_registry_s_with_a_stability_function_of_their_own() -> None:
    """``advise`` reports on every registered method whose step has a spectral radius of its own
    (ros2_adaptive shares ros2's; scipy has none), in the registry's order."""
    import numpy as np

    from coopdyn.integrators import INTEGRATORS
    from coopdyn.stability import ADVISED

    expected = (
        "symplectic_euler",
        "rk4",
        "dopri5",
        "dop853",
        "implicit_euler",
        "ros2",
        "trapezoid",
        "generalized_alpha",
        "exponential",
    )
    assert ADVISED == expected
    oscillator = np.array([[0.0, 1.0], [-100.0, -0.1]])  # x'' + 0.1 x' + 100 x = 0
    for name in ADVISED:
        assert 0.0 < INTEGRATORS[name]().spectral_radius(oscillator, 1e-3) <= 1.0 + 1e-9, name


@pytest.mark.parametrize(
    ("tableau", "message"),
    [
        ({"A": ((), (0.5,)), "b": (0.5, 0.5), "c": (0.0, 0.4)}, r"rows of A sum to \[0.0, 0.5\], c is \[0.0, 0.4\]"),
        ({"A": ((1.0,),), "b": (1.0,), "c": (0.0,)}, "must be explicit"),
        ({"A": ((), (1.0,)), "b": (0.5, 0.6), "c": (0.0, 1.0)}, "b sums to 1.1, not 1"),
        ({"A": ((), (1.0,)), "b": (0.5, 0.5), "c": (0.0,)}, "one b, c .and b_hat. per row of A: 2 rows, 2 b, 1 c"),
    ],
)
def test_a_butcher_tableau_is_checked_when_it_is_made(tableau: dict[str, object], message: str) -> None:
    """Explicit, one coefficient per stage, consistent: checked in Python as the compiled loop does."""
    from coopdyn.integrators.explicit import ButcherTableau

    with pytest.raises(cd.SimulationError, match=message):
        ButcherTableau(**tableau)  # type: ignore[arg-type]


ADAPTIVE = sorted(n for n, c in INTEGRATORS.items() if c.adaptive)
BAD_TOLERANCES = [
    *(("rtol", bad) for bad in (0.0, -1e-6, math.nan, math.inf, 1.0, 1e300)),
    *(("atol", bad) for bad in (0.0, -1e-9, math.nan, math.inf, 1e-300)),
]


@pytest.mark.parametrize("name", ADAPTIVE)
@pytest.mark.parametrize(("setting", "bad"), BAD_TOLERANCES)
def test_adaptive_methods_refuse_tolerances_that_control_nothing(name: str, setting: str, bad: float) -> None:
    """rtol is a fraction of each coordinate's size: 0 < rtol < 1 (at 1 or more any error as large
    as the solution passes and the step grows unchecked); atol is at least 1e-30 (below, no double
    resolves it, and scipy's LSODA spun without end); both finite."""
    from coopdyn.errors import SimulationError

    with pytest.raises(SimulationError, match=setting):
        INTEGRATORS[name](**{setting: bad})


@pytest.mark.parametrize("name", ADAPTIVE)
def test_adaptive_methods_take_a_loose_tolerance_below_one(name: str) -> None:
    assert INTEGRATORS[name](rtol=0.5).rtol == 0.5


@pytest.mark.parametrize(("setting", "bad"), BAD_TOLERANCES)
def test_the_scipy_reference_refuses_the_same_tolerances(setting: str, bad: float) -> None:
    from coopdyn.errors import SimulationError
    from coopdyn.integrators.scipy_reference import ScipyReference

    with pytest.raises(SimulationError, match=setting):
        ScipyReference(**{setting: bad})


@pytest.mark.parametrize("loop", ["python", "auto"])
@pytest.mark.parametrize(("cls", "old", "new"), [(cd.integrators.Trapezoid, 1.0, 0.0), (GeneralizedAlpha, 0.9, 0.2)])
def test_a_setting_changed_on_the_instance_is_the_one_that_runs(
    book: cd.Scene, loop: str, cls: type[cd.integrators.Integrator], old: float, new: float
) -> None:
    """ρ∞ set after construction sets the method's γ (or α's) with it: the run is the one of a
    method built with that ρ∞, bit for bit, in both loops — before, the old γ ran while
    ``repr`` and the stability function said the new ρ∞."""
    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)

    def run(method: cd.integrators.Integrator) -> np.ndarray:
        return cd.simulate(book, 0.05, ctrl, method, 2e-3, loop=loop, accuracy_check="off").q

    changed = cls(old)  # type: ignore[call-arg]
    changed.rho_inf = new  # type: ignore[attr-defined]
    assert np.array_equal(run(changed), run(cls(new)))  # type: ignore[call-arg]
    assert not np.array_equal(run(changed), run(cls(old)))  # type: ignore[call-arg]
    z = np.array([-1e6 + 0j])
    assert np.allclose(changed.stability_function(z), cls(new).stability_function(z), rtol=0, atol=1e-15)  # type: ignore[call-arg]


BAD_SETTINGS = [("rtol", "1e-3"), ("rtol", -5.0), ("rtol", 2.0), ("atol", 1e-300), ("h_min", math.nan), ("h_min", -1.0)]


@pytest.mark.parametrize(("setting", "bad"), BAD_SETTINGS)
def test_settings_set_on_the_instance_are_checked_as_at_construction(setting: str, bad: object) -> None:
    """A bad value set on an instance is refused and leaves the setting as it was."""
    from coopdyn.errors import SimulationError

    dopri = INTEGRATORS["dopri5"]()
    with pytest.raises(SimulationError, match=setting):
        setattr(dopri, setting, bad)
    assert (dopri.rtol, dopri.atol, dopri.h_min) == (1e-6, 1e-9, 1e-12)


def test_settings_set_on_the_instance_are_floats_and_counts() -> None:
    from coopdyn.errors import SimulationError

    dopri = INTEGRATORS["dopri5"]()
    dopri.rtol = np.float64(1e-8)
    assert dopri.rtol == 1e-8 and type(dopri.rtol) is float
    assert INTEGRATORS["implicit_euler"](np.int64(3)).jacobian_every == 3
    with pytest.raises(SimulationError, match="rho_inf"):
        cd.integrators.Trapezoid().rho_inf = 1.5
    with pytest.raises(SimulationError, match="jacobian_every"):
        INTEGRATORS["implicit_euler"]().jacobian_every = 2.0
    with pytest.raises(SimulationError, match="at most 2"):
        INTEGRATORS["implicit_euler"](2**63)


@pytest.mark.parametrize("loop", ["python", "auto"])
@pytest.mark.parametrize("method", ["trapezoid", "generalized_alpha"])
def test_a_linear_scene_does_not_break_the_energy_balance_under_the_trapezoid(loop: str, method: str) -> None:
    """The book's linear system with grasps of 1e7 N/m and dampers of 2e5 N·s/m at 2 ms steps: an
    overdamped mode 30× faster than the step, which the trapezoid (R(−∞) = −1) and generalized-α
    (−0.9) keep alternating in sign from step to step. On a linear scene a trapezoid step
    changes the energy by exactly h (τ̄·q̇̄ − q̇̄ᵀ D q̇̄) — it cannot make energy —, yet the monitor,
    which credited the dampers' and the drives' power at the alternating end points, said the
    balance broke at the first check. It takes a linearly implicit step's work at its mean
    velocity and torque now: silent, in both loops."""
    scene = cd.scenes.linear_book(c_p=1e7, c_k=1e7, d_p=2e5, d_k=2e5)
    d1, d2 = cd.scenes.book_task()
    ctrl = cd.scenes.drives_controller(d1, d2)
    res = cd.simulate(scene, 1.0, ctrl, method, 2e-3, loop=loop, energy_check="raise", accuracy_check="off")
    assert res.status == "completed" and np.all(np.isfinite(res.q))


@pytest.mark.parametrize("rho_inf", [1.0, 0.9, 0.5])
def test_generalized_alpha_overshoot_on_a_stiff_damper_is_the_linear_methods(rho_inf: float) -> None:
    """On the book system with a stiff spring and a stiffer damper (k = 1e10 N/m, d = 1e6 N·s/m:
    relaxation rate 1e4 1/s, ten times 1/dt), a start velocity's effect over ten 1 ms steps is
    the linear generalized-α step matrix's from (0, v0, q̈(0, v0)) — the consistent start
    acceleration, carried as the algorithmic one: the overshoot docs/physics.md documents
    (6.2× the start velocity at ρ∞ = 0.5) is the method's, not the implementation's; and
    ``transient.start_transient``, what ``advise`` reports, is the runs' own figure."""
    from coopdyn.integrators.implicit import alpha_amplification
    from coopdyn.stability import linearize
    from coopdyn.transient import start_transient

    scene = cd.scenes.linear_book(c_p=1e10, c_k=1e10, d_p=1e6, d_k=1e6)
    v0 = 1e-5 * np.random.default_rng(0).standard_normal(scene.nv)
    kwargs = dict(integrator=GeneralizedAlpha(rho_inf=rho_inf), dt=1e-3, accuracy_check="off", energy_check="off")
    moved = cd.simulate(scene, 0.01, v0=v0, **kwargs)  # type: ignore[arg-type]
    rest = cd.simulate(scene, 0.01, **kwargs)  # type: ignore[arg-type]
    A, n = linearize(scene), scene.nv
    T = alpha_amplification(A[n:, :n], A[n:, n:], 1e-3, rho_inf)
    x, predicted = np.concatenate([np.zeros(n), v0, A[n:, n:] @ v0]), [v0]
    for _ in range(10):
        x = T @ x
        predicted.append(x[n : 2 * n])
    simulated = moved.v - rest.v
    np.testing.assert_allclose(simulated, np.array(predicted), rtol=0, atol=1e-6 * np.abs(simulated).max())
    measured = np.abs(simulated[1:]).max() / np.abs(v0).max()
    assert start_transient(A, 1e-3, rho_inf, v0, steps=10) == pytest.approx(measured, rel=1e-6)


def test_advise_names_generalized_alphas_start_transient() -> None:
    """``advise(dt=1 ms)`` on the 16-element held strip with the beam's damping (β = 1e-4 s, its
    fast element modes stiff and overdamped): generalized-α's start transient is ~23× the
    trapezoid's, past transient.LIMIT: the recommendation, the method's note and the divergence
    diagnosis say so and point to the trapezoid; for the run's own ρ∞ (``rho_inf=``), and not at
    all at ρ∞ = 1 (the trapezoid's own)."""
    from coopdyn import transient

    scene = cd.scenes.held_beam(n_elements=16, damping=0.002, beam_damping=1e-4)
    advice = cd.advise(scene, dt=1e-3)
    found = advice.alpha_transient
    diagnosis = advice.diagnosis("generalized_alpha", 1e-3)
    assert found is not None and (found.dt, found.rho_inf) == (1e-3, 0.9)
    assert found.amplification > transient.LIMIT * found.trapezoid and 300 < found.amplification < 600
    said = f"at ρ∞ = 0.9 it amplifies a start velocity up to {found.amplification:,.0f}× within 50 steps of 1 ms"
    assert said in advice.recommendation and said in diagnosis and "take the trapezoid or implicit_euler" in diagnosis
    assert "the blow-up is nonlinear" not in diagnosis
    assert "start velocity grows up to" in next(m.note for m in advice.methods if m.name == "generalized_alpha")
    assert cd.advise(scene, dt=1e-3, methods=["trapezoid"]).alpha_transient is None  # (not asked about)
    lower = cd.advise(scene, dt=1e-3, rho_inf=0.5).alpha_transient
    assert lower is not None and lower.rho_inf == 0.5 and lower.amplification > 10 * found.amplification
    assert cd.advise(scene, dt=1e-3, rho_inf=1.0).alpha_transient is None
    assert cd.advise(scene, dt=1e-3, rho_inf=0.0).alpha_transient is not None  # (ρ∞ = 0 is generalized-α's too)
    with pytest.raises(cd.SimulationError, match=r"rho_inf must be a number in \[0, 1\], got 1.5"):
        cd.advise(scene, dt=1e-3, rho_inf=1.5)  # (it once said nothing: the transient's own check was swallowed)


@pytest.mark.parametrize(
    ("scene", "dt"),
    [
        pytest.param(lambda: cd.scenes.held_beam(n_elements=16, damping=0.002, beam_damping=0.0), 1e-3, id="strip, β = 0"),
        pytest.param(lambda: cd.scenes.linear_book(c_p=1e10, c_k=1e10, d_p=1e6, d_k=1e6), 1e-3, id="book, stiff damper"),
        pytest.param(
            lambda: cd.scenes.held_beam(n_elements=40, damping=0.002, beam_damping=0.0), 5e-3, id="40 elements, β = 0, 5 ms"
        ),
    ],
)
def test_advise_says_nothing_of_a_transient_the_trapezoid_shares(scene: Callable[[], cd.Scene], dt: float) -> None:
    """Without the beam's damping generalized-α's start transient is level with the trapezoid's,
    and on the book's stiff damper 1.2×: nothing is said of it. On 40 undamped elements at 5 ms
    the trapezoid's own transient takes tens of steps to grow (12 within 10 steps, 41 within
    50): judged over ten, generalized-α's 137 looked 11× worse (a false alarm the review found)."""
    advice = cd.advise(scene(), dt=dt)
    diagnosis = advice.diagnosis("generalized_alpha", dt)
    assert advice.alpha_transient is None and "amplifies" not in advice.recommendation + diagnosis


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.zeros((3, 3)), 1e-3, 0.9), "finite \\(2n, 2n\\)"),
        ((np.full((4, 4), np.nan), 1e-3, 0.9), "finite \\(2n, 2n\\)"),
        ((np.zeros((4, 4)), 0.0, 0.9), "step h must be > 0"),
        ((np.zeros((4, 4)), math.nan, 0.9), "step h must be finite"),
        ((np.zeros((4, 4)), 1e-3, 1.5), "rho_inf must be a number in \\[0, 1\\]"),
        ((np.zeros((4, 4)), 1e-3, 0.9, np.zeros(2)), "non-zero finite start velocities"),
        ((np.zeros((4, 4)), 1e-3, 0.9, np.ones(3)), "non-zero finite start velocities"),
    ],
)
def test_start_transient_refuses_what_it_cannot_judge(args: tuple[Any, ...], match: str) -> None:
    from coopdyn.transient import start_transient

    with pytest.raises(cd.SimulationError, match=match):
        start_transient(*args)


def test_a_diverging_run_is_judged_at_its_own_rho_inf() -> None:
    """The divergence diagnosis of a generalized-α run names the transient at the run's ρ∞ — not
    the default instance's — and at ρ∞ = 1 (the trapezoid's own figures) says nothing of it; a
    step so long that the step matrix is singular leaves the advice without the transient
    instead of failing (the review found it raising LinAlgError)."""
    scene = cd.scenes.held_beam(n_elements=24, damping=0.002, beam_damping=1e-3)
    v0 = 0.05 * np.random.default_rng(0).standard_normal(scene.nv)
    said = []
    for rho_inf in (0.5, 1.0):  # (both diverge at 5 ms: ρ∞ = 0.5 in its first step, ρ∞ = 1 at 35 ms, as the trapezoid)
        with pytest.raises(cd.DivergenceError) as info, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cd.simulate(scene, 0.05, integrator=GeneralizedAlpha(rho_inf=rho_inf), dt=5e-3, v0=v0, accuracy_check="off")
        said.append(str(info.value))
    assert "at ρ∞ = 0.5 it amplifies a start velocity" in said[0] and "amplifies" not in said[1]
    stiff = cd.scenes.linear_book(c_p=1e12, c_k=1e12, d_p=1e8, d_k=1e8)
    assert cd.advise(stiff, dt=1e3).alpha_transient is None
