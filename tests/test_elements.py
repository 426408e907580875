"""Interconnection elements: each law is the exact gradient of its energy, obeys action =
reaction, vanishes unloaded and under a common rigid motion; the SE(3) logarithm is accurate at
every angle; the C++ twins agree with their laws; a toy element defined here runs through the whole
pipeline, called from the compiled kernel."""

from __future__ import annotations

import warnings
from typing import Any, ClassVar

import mpmath as mp
import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.errors import NativeBackendWarning
from coopdyn.model.elements import (
    ELEMENTS,
    BallSpring,
    BeamElement,
    BeamSegment,
    Element,
    ElementEval,
    HardeningSpring,
    SE3Spring,
    register,
)
from coopdyn.model.elements.lie import jlog6, log6


@pytest.fixture(autouse=True)
def _seeded_pinocchio() -> None:
    """pin.SE3.Random draws from Pinocchio's own generator, which numpy's seed does not reach: seed
    it, so that each test sees the same poses on every run (unseeded, one draw in CI put a beam
    element's wrench 1.04e-10 off in one component of a 3.9e8 N vector, over the 1e-10 bound)."""
    pin.seed(0)


def _spd(rng: np.random.Generator, n: int, scale: np.ndarray) -> np.ndarray:
    """A random symmetric positive definite n×n matrix with coupled entries, scaled per row/column."""
    L = rng.normal(size=(n, n)) * np.sqrt(scale)[:, None]
    return L @ L.T + np.diag(scale)


def _element(kind: str, rng: np.random.Generator) -> Element:
    if kind == "se3":
        scale = np.r_[np.full(3, 1e4), np.full(3, 1e2)]
        return SE3Spring(_spd(rng, 6, scale), _spd(rng, 6, scale * 1e-3))
    if kind == "beam":
        return BeamElement(BeamSegment(cd.Section.rectangle(0.03, 0.01, E=70e9, rho=2700.0, timoshenko=True), 0.1), 1e-4)
    if kind == "ball":
        return BallSpring(_spd(rng, 3, np.full(3, 1e4)), _spd(rng, 3, np.full(3, 10.0)))
    if kind == "hardening":  # κ|p|² ≈ k at a 10 cm stretch
        scale = np.r_[np.full(3, 1e4), np.full(3, 1e2)]
        return HardeningSpring(_spd(rng, 6, scale), _spd(rng, 6, scale * 1e-3), hardening=1e6)
    raise ValueError(f"no test instance for element kind {kind!r}: add one here (a new element is tested as itself)")


def _undamped(el: Element) -> Element:
    """The same element without its damping."""
    return (
        BeamElement(el.segment, None)
        if isinstance(el, BeamElement)
        else type(el)(el.K, None, "undamped", **el.parameter_values())
    )


def _evaluate(element: Element, oMT: pin.SE3, oMG: pin.SE3, vT: np.ndarray, vG: np.ndarray) -> tuple[ElementEval, np.ndarray]:
    """The element's evaluation and the reaction wrench on T (in T) for frame poses and LOCAL twists."""
    T_M_G = oMT.actInv(oMG)
    ev = element.evaluate(T_M_G, vG - T_M_G.actInv(pin.Motion(vT)).vector, jacobians=True)
    return ev, -T_M_G.act(pin.Force(ev.G_f_G)).vector


KINDS = sorted(kind for kind, t in ELEMENTS.items() if t.python.constraint is None)  # force laws (constraints: test_rigid_limit)


@pytest.mark.parametrize("kind", KINDS)
def test_wrench_is_minus_gradient_of_energy(kind: str) -> None:
    """G_f_G = −∂U/∂δ for a body-frame perturbation δ of G (central differences), undamped. The
    poses come from the seeded generator (``pin.SE3.Random`` draws from a global state that other
    tests move: one draw put the deformation's rotation where the SE(3) logarithm bends sharply
    near π and the differences lost five digits, in one order of the suite), the deformation's
    rotation up to about 2 rad."""
    rng = np.random.default_rng(1)
    el = _element(kind, rng)
    el = _undamped(el)
    for _ in range(5):
        oMT = pin.exp6(rng.normal(size=6))
        oMG = oMT * pin.exp6(0.6 * rng.normal(size=6))
        ev, _ = _evaluate(el, oMT, oMG, np.zeros(6), np.zeros(6))
        grad = np.empty(6)
        for j in range(6):
            d = np.zeros(6)
            d[j] = 1e-6
            up = el.evaluate(oMT.actInv(oMG * pin.exp6(d)), np.zeros(6)).energy
            down = el.evaluate(oMT.actInv(oMG * pin.exp6(-d)), np.zeros(6)).energy
            grad[j] = (up - down) / 2e-6
        np.testing.assert_allclose(ev.G_f_G, -grad, rtol=1e-6, atol=1e-6 * np.abs(grad).max())


@pytest.mark.parametrize("kind", KINDS)
def test_action_equals_reaction(kind: str) -> None:
    """The wrenches on T and G, moved to one point in world axes, cancel exactly."""
    rng = np.random.default_rng(3)
    el = _element(kind, rng)
    for _ in range(10):
        oMT, oMG = pin.SE3.Random(), pin.SE3.Random()
        ev, T_f_T = _evaluate(el, oMT, oMG, rng.normal(size=6), rng.normal(size=6))
        world_T = oMT.act(pin.Force(T_f_T)).vector
        world_G = oMG.act(pin.Force(ev.G_f_G)).vector
        np.testing.assert_allclose(world_T + world_G, 0.0, atol=1e-9 * np.linalg.norm(world_G))


@pytest.mark.parametrize("kind", KINDS)
def test_dissipated_power_is_the_damping_force_times_the_relative_twist(kind: str) -> None:
    """P = −(damping part of G_f_G) · ξ ≥ 0, and ξᵀ S_D ξ = P (S_D is the damping in twist coordinates)."""
    rng = np.random.default_rng(4)
    el = _element(kind, rng)
    undamped = _undamped(el)
    for _ in range(5):  # (poses from the seeded generator: pin.SE3.Random's depends on the tests run before)
        T_M_G, xi = pin.exp6(rng.normal(size=6)), rng.normal(size=6)
        ev, ev0 = el.evaluate(T_M_G, xi, True), undamped.evaluate(T_M_G, xi)
        damping_force = ev.G_f_G - ev0.G_f_G  # (less the elastic part: its round-off, relative to that part, stays)
        assert ev.power > 0.0
        cancelled = 1e-13 * np.linalg.norm(ev0.G_f_G) * np.linalg.norm(xi)
        assert ev.power == pytest.approx(-damping_force @ xi, rel=1e-10, abs=cancelled)
        assert ev.power == pytest.approx(xi @ ev.S_D @ xi, rel=1e-10)


def test_se3_deformation_rate_is_jlog6_times_the_relative_twist() -> None:
    """ė = Jlog6 ξ agrees with a finite difference of e along the relative motion (poses from the
    seeded generator, as in test_wrench_is_minus_gradient_of_energy: near π differences fail)."""
    rng = np.random.default_rng(4)
    oMT = pin.exp6(rng.normal(size=6))
    oMG = oMT * pin.exp6(0.6 * rng.normal(size=6))
    vT, vG = rng.normal(size=6), rng.normal(size=6)
    T_M_G = oMT.actInv(oMG)
    e, theta = log6(T_M_G)
    xi = vG - T_M_G.actInv(pin.Motion(vT)).vector

    def e_at(t: float) -> np.ndarray:
        return log6((oMT * pin.exp6(vT * t)).actInv(oMG * pin.exp6(vG * t)))[0]

    np.testing.assert_allclose(jlog6(T_M_G, e, theta) @ xi, (e_at(1e-6) - e_at(-1e-6)) / 2e-6, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("kind", KINDS)
def test_common_rigid_motion_leaves_no_wrench(kind: str) -> None:
    """Moving T and G together (same pose offset, same rigid velocity) changes nothing."""
    rng = np.random.default_rng(5)
    el = _element(kind, rng)
    oMT, T_M_G, X = pin.SE3.Random(), pin.SE3.Random(), pin.SE3.Random()
    vT = rng.normal(size=6)
    vG = T_M_G.actInv(pin.Motion(vT)).vector  # G rigidly attached to T
    a, _ = _evaluate(el, oMT, oMT * T_M_G, vT, vG)
    b, _ = _evaluate(el, X * oMT, X * oMT * T_M_G, vT, vG)
    np.testing.assert_allclose(a.G_f_G, b.G_f_G, rtol=1e-10, atol=1e-8)
    assert a.power == pytest.approx(0.0, abs=1e-12)


def test_ball_spring_transmits_no_moment_about_the_grasp_point() -> None:
    rng = np.random.default_rng(6)
    el = _element("ball", rng)
    for _ in range(5):
        ev = el.evaluate(pin.SE3.Random(), rng.normal(size=6), True)
        np.testing.assert_array_equal(ev.G_f_G[3:], 0.0)
        np.testing.assert_array_equal(ev.S_K[3:], 0.0)


# -- the SE(3) logarithm ---------------------------------------------------------------------------
def _mp_log6(R: Any, p: Any) -> list[Any]:
    """log6 in 50-digit arithmetic (closed forms: at this precision they do not cancel)."""
    th = mp.acos(max(min((R[0, 0] + R[1, 1] + R[2, 2] - 1) / 2, 1), -1))
    w = mp.matrix([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) * (th / (2 * mp.sin(th)))
    a = th / 2 * mp.cot(th / 2)
    beta = (1 - a) / th**2
    wxp = mp.matrix([w[1] * p[2] - w[2] * p[1], w[2] * p[0] - w[0] * p[2], w[0] * p[1] - w[1] * p[0]])
    lin = a * p - wxp / 2 + beta * sum(w[i] * p[i] for i in range(3)) * w
    return [lin[0], lin[1], lin[2], w[0], w[1], w[2]]


def _mp_exp6(x: list[Any]) -> tuple[Any, Any]:
    v, w = mp.matrix(x[:3]), mp.matrix(x[3:])
    th = mp.sqrt(sum(t * t for t in w))
    if th == 0:
        return mp.eye(3), v
    K = mp.matrix([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    R = mp.eye(3) + mp.sin(th) / th * K + (1 - mp.cos(th)) / th**2 * K * K
    V = mp.eye(3) + (1 - mp.cos(th)) / th**2 * K + (th - mp.sin(th)) / th**3 * K * K
    return R, V * v


def _mp_jlog6(M: pin.SE3) -> np.ndarray:
    """d log6(M exp6(δ)) / dδ at 0 by central differences in 50-digit arithmetic (step 1e-22)."""
    with mp.workdps(50):
        R, p = mp.matrix(M.rotation.tolist()), mp.matrix(M.translation.tolist())
        h = mp.mpf("1e-22")
        J = np.empty((6, 6))
        for j in range(6):
            cols = []
            for sign in (1, -1):
                x = [mp.mpf(0)] * 6
                x[j] = sign * h
                dR, dp = _mp_exp6(x)
                cols.append(_mp_log6(R * dR, p + R * dp))
            J[:, j] = [float((cols[0][i] - cols[1][i]) / (2 * h)) for i in range(6)]
        return J


@pytest.mark.parametrize("theta", [1e-7, 1e-5, 1e-4, 3e-4, 1e-3, 1e-2, 0.2, 0.3, 1.0, 3.0])
def test_jlog6_is_accurate_at_every_angle(theta: float) -> None:
    """Against a 50-digit reference: ≤ 1e-13 relative at every angle, times the conditioning
    1/sin θ of the logarithm near π (Pinocchio 4.1's Jlog6 is off by up to ~1e-7 around 1e-3 rad;
    the series below 0.25 rad fix that)."""
    rng = np.random.default_rng(int(theta * 1e9) % 1000)
    n = rng.normal(size=3)
    M = pin.SE3(pin.exp3(theta * n / np.linalg.norm(n)), rng.normal(size=3))
    e, th = log6(M)
    ref = _mp_jlog6(M)
    assert np.abs(jlog6(M, e, th) - ref).max() <= 1e-13 * max(1.0, 1.0 / np.sin(theta)) * np.abs(ref).max()


def test_pinocchio_jlog6_is_what_the_series_fix() -> None:
    """Documents the edge: Pinocchio's own Jlog6 loses accuracy at 1e-3 rad (why lie.py exists)."""
    rng = np.random.default_rng(0)
    errors = []
    for _ in range(5):
        n = rng.normal(size=3)
        M = pin.SE3(pin.exp3(1e-3 * n / np.linalg.norm(n)), rng.normal(size=3))
        ref = _mp_jlog6(M)
        errors.append(np.abs(pin.Jlog6(M) - ref).max() / np.abs(ref).max())
    assert max(errors) > 1e-9


# -- a toy element, defined here, through the whole pipeline --------------------------------------
class ToyVerticalSpring(Element):
    """A spring on the vertical offset of G from T only: U = ½ k (ẑ·p_world)² with T's axes
    taken as world-aligned (fixtures); the wrench is the exact gradient, no damping."""

    kind: ClassVar[str] = "toy_vertical"
    deformation_size: ClassVar[int] = 1

    def __init__(self, stiffness: Any, damping: Any = None, name: str = "toy") -> None:
        self.k = float(stiffness)
        self.D = np.zeros(1)

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        R, p = T_M_G.rotation, T_M_G.translation
        z = p[2]
        f = np.zeros(6)
        f[:3] = -self.k * z * R[2]  # −∂U/∂(G-local translation) = −k z Rᵀ ẑ
        S_K = None
        if jacobians:
            S_K = np.zeros((6, 6))
            S_K[:3, :3] = self.k * np.outer(R[2], R[2])
        return ElementEval(0.5 * self.k * z * z, np.array([z]), f, 0.0, S_K, np.zeros((6, 6)) if jacobians else None, 0.0)


def test_a_toy_element_without_a_cpp_twin_runs_in_the_compiled_loop() -> None:
    """A box hung from the world by the toy spring bobs at ω = √(k/m) about its static sag m g / k.
    The toy has no C++ twin: the kernel calls its Python evaluate (one warning naming it) and the
    run stays in the compiled loop, equal to the all-Python run to round-off."""
    register(ToyVerticalSpring)
    try:
        m, k = 2.0, 800.0
        box = cd.RigidObject.box(m, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0], joint="prismatic", axis="z")
        scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=k, element="toy_vertical")])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = cd.simulate(scene, 1.0, integrator="rk4", dt=1e-3, save_every=10)
        assert (res.backend, res.loop) == ("native", "compiled")
        assert any("toy_vertical" in str(w.message) and "no C++ twin" in str(w.message) for w in caught)
        z = res.object_position()[:, 2] - 1.0
        sag, omega = m * 9.81 / k, np.sqrt(k / m)
        np.testing.assert_allclose(z, -sag * (1.0 - np.cos(omega * res.t)), atol=1e-8)
        np.testing.assert_allclose(res.wrench(0)[:, 2], -k * z, atol=1e-8)
        for method in ("trapezoid", "dopri5"):  # the implicit terms (S_K) and adaptive steps too
            runs = [
                cd.simulate(scene, 0.2, integrator=method, dt=1e-3, backend=b, accuracy_check="off") for b in ("native", "python")
            ]
            assert runs[0].n_steps == runs[1].n_steps
            np.testing.assert_allclose(runs[0].q, runs[1].q, rtol=0.0, atol=1e-12)
    finally:
        ELEMENTS.pop("toy_vertical", None)


def test_a_python_element_overflowing_in_a_short_run_leaks_no_numpy_warning() -> None:
    """The toy spring at k = 1e9 N/m, far beyond rk4's limit at 1 ms, with max_speed 1e300: its
    Python evaluate overflows inside the compiled loop's first chunk. A run without checks (on
    simulate's kept set-up) ends as the one set up from nothing, and numpy's overflow warnings
    stay inside (they once leaked: the short path entered numpy's errstate only for a Python
    controller)."""
    register(ToyVerticalSpring)
    try:
        box = cd.RigidObject.box(2.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0], joint="prismatic", axis="z")
        scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=1e9, element="toy_vertical")])
        settings: dict[str, Any] = dict(integrator="rk4", dt=1e-3, accuracy_check="off", energy_check="off", max_speed=1e300)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NativeBackendWarning)  # (the toy has no C++ twin: said once)
            warnings.simplefilter("error", RuntimeWarning)
            kept = cd.simulate(scene, 0.05, **settings)
            fresh = cd.simulate(scene, 0.05, loop="compiled", **settings)
        assert kept.status == fresh.status and np.array_equal(kept.q, fresh.q, equal_nan=True)
    finally:
        ELEMENTS.pop("toy_vertical", None)


def test_a_python_element_that_fails_stops_the_compiled_run_with_its_error() -> None:
    """An element whose evaluate raises, or returns the wrong shapes, inside the compiled loop:
    the run stops with a CoopdynError naming the element and what it did."""

    class Broken(ToyVerticalSpring):
        kind: ClassVar[str] = "toy_broken"
        fail_at = 0.05

        def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
            if T_M_G.translation[2] < -self.fail_at * 0.1:
                raise ZeroDivisionError("the toy broke")
            return super().evaluate(T_M_G, xi, jacobians)

    class WrongShape(ToyVerticalSpring):
        kind: ClassVar[str] = "toy_wrong"

        def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
            return super().evaluate(T_M_G, xi, jacobians)._replace(G_f_G=np.zeros(3))

    box = cd.RigidObject.box(2.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0], joint="prismatic", axis="z")
    for cls, message in ((Broken, "ZeroDivisionError: the toy broke"), (WrongShape, "G_f_G that is not 6 values")):
        register(cls)
        try:
            scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=800.0, element=cls.kind)])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                with pytest.raises(cd.CoopdynError, match=f"{cls.__name__}.*{message}"):
                    cd.simulate(scene, 0.5, integrator="rk4", dt=1e-3, loop="compiled")
        finally:
            ELEMENTS.pop(cls.kind, None)


def test_unknown_element_names_the_registered_ones() -> None:
    with pytest.raises(cd.SceneError, match=r"unknown interconnection element 'bal'.*Did you mean 'ball'"):
        cd.Interconnection("left", 1e3, element="bal").law()


@pytest.mark.parametrize("backend", ["native", "python"])
def test_a_box_spinning_through_pi_warns_once_naming_the_interconnection(backend: str) -> None:
    """A box on a soft rotational spring, spun about the vertical: the deformation's rotation
    passes 0.9π and the run says so once, with the interconnection's name and the time."""
    box = cd.RigidObject.box(1.0, (0.2, 0.2, 0.2), pose=[0.0, 0.0, 1.0])
    K = cd.diagonal(1e4, [1.0, 1.0, 0.01])
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=K, name="hook")], gravity=[0.0, 0.0, 0.0])
    v0 = np.zeros(6)
    v0[5] = 10.0  # rad/s about z: passes 0.9π ≈ 2.83 rad at t ≈ 0.28 s
    with pytest.warns(cd.errors.LogMapWarning, match=r"'hook' \(index 0\).*0\.9\dπ\) at t ≈ 0\.2[89]") as caught:
        cd.simulate(scene, 0.6, integrator="rk4", dt=1e-3, v0=v0, backend=backend, energy_check="off")
    assert len([w for w in caught if issubclass(w.category, cd.errors.LogMapWarning)]) == 1


def test_a_box_hung_from_the_world_settles_at_its_static_sag() -> None:
    """One damped SE(3) spring from a world fixture: the box settles where k·sag = m·g, on both backends."""
    m, k = 2.0, 2e3
    box = cd.RigidObject.box(m, (0.2, 0.2, 0.2), pose=[0.0, 0.0, 1.0])
    K = cd.diagonal(k, 50.0)
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=K, damping=0.02 * K, grasp=[0.0, 0.0, 0.1])])
    for backend in ("native", "python"):
        res = cd.simulate(scene, 3.0, integrator="implicit_euler", dt=1e-3, save_every=100, backend=backend)
        assert res.object_position()[-1, 2] == pytest.approx(1.0 - m * 9.81 / k, abs=1e-6)
        np.testing.assert_allclose(res.wrench(0)[-1], [0.0, 0.0, m * 9.81, 0.0, 0.0, 0.0], atol=1e-5)
        np.testing.assert_allclose(res.arm_wrench(0)[-1, :3], [0.0, 0.0, -m * 9.81], atol=1e-5)


def test_an_arm_with_every_joint_locked_holds_the_object_like_a_fixture(pandas: cd.Scene) -> None:
    """Locking all seven Panda joints leaves an arm with no DOF: the scene builds and simulates."""
    left, right = pandas.arm_specs
    held = {f"panda_joint{i}": float(x) for i, x in enumerate(left.q0, start=1)}  # where IK put them
    locked = left.replace(q0=None, locked_joints=held | {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0})
    scene = cd.Scene([locked, right], pandas.object, pandas.interconnection_specs, gravity=pandas.gravity)
    assert scene.arms[0].v_index.size == 0 and scene.n_actuated == 7
    ctrl = cd.control.GravityCompensationPD(scene, 50.0, 5.0)
    res = cd.simulate(scene, 0.05, controller=ctrl, integrator="implicit_euler", dt=1e-3)
    assert res.status == "completed" and np.all(np.isfinite(res.wrench(0)))
    assert np.max(np.abs(res.deformation(0)[0])) < 1e-9  # the locked tip sits on its grasp frame


# -- the C++ twins, and the parameters declared once -------------------------------------------


@pytest.mark.parametrize("kind", sorted(k for k, t in ELEMENTS.items() if t.native is not None))
def test_every_cpp_twin_evaluates_as_its_python_law(kind: str) -> None:
    """Built from the Python element's native_parameters() by name, the C++ twin gives the same
    energy, deformation, wrench, power, S_K, S_D and angle at random poses up to π − 1e-6."""
    from coopdyn import _native

    rng = np.random.default_rng(5)
    el = _element(kind, rng)
    for angle in (1e-8, 0.3, 2.0, np.pi - 1e-6):
        axis = rng.normal(size=3)
        R = pin.exp3(angle * axis / np.linalg.norm(axis))
        T_M_G = pin.SE3(R, 0.1 * rng.normal(size=3))
        xi = rng.normal(size=6)
        py = el.evaluate(T_M_G, xi, jacobians=True)
        cpp = list(_native.evaluate_element(ELEMENTS[kind].native, el.native_parameters(), T_M_G.homogeneous, xi, True))
        cpp[1] = cpp[1][: el.deformation_size]  # C++ pads the deformation to 6
        for a, b in zip(cpp, py, strict=True):
            scale = max(1.0, float(np.max(np.abs(b))))
            np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-11 * scale)


def test_the_cpp_twin_reads_every_parameter_by_name_and_no_other() -> None:
    """The parameters cross to C++ by name: a missing one and one the twin does not read are
    both refused, naming it."""
    from coopdyn import _native

    params = _element("hardening", np.random.default_rng(0)).native_parameters()
    pose, xi = np.eye(4), np.zeros(6)
    with pytest.raises(ValueError, match="missing parameter hardening"):
        _native.evaluate_element("hardening", {k: v for k, v in params.items() if k != "hardening"}, pose, xi, False)
    with pytest.raises(ValueError, match=r"does not read the parameter\(s\) hardening"):
        _native.evaluate_element("se3", params, pose, xi, False)
    with pytest.raises(ValueError, match="the kernel has no element 'toy'"):
        _native.evaluate_element("toy", params, pose, xi, False)


def test_the_hardening_spring_is_duffing_along_a_line() -> None:
    """Stretched by x along a unit vector u (no rotation): U = ½ k x² + ¼ κ x⁴ and the force on
    the object is −(k x + κ x³) u, no moment; S_K along u is k + 3 κ x², the force's derivative."""
    k, kappa = 2e3, 5e6
    el = HardeningSpring(np.r_[np.full(3, k), np.full(3, 50.0)], hardening=kappa)
    u = np.array([2.0, -1.0, 2.0]) / 3.0
    for x in (1e-3, 0.02, 0.1):
        ev = el.evaluate(pin.SE3(np.eye(3), x * u), np.zeros(6), jacobians=True)
        assert ev.energy == pytest.approx(0.5 * k * x**2 + 0.25 * kappa * x**4, rel=1e-12)
        np.testing.assert_allclose(ev.G_f_G[:3], -(k * x + kappa * x**3) * u, rtol=1e-12)
        np.testing.assert_allclose(ev.G_f_G[3:], 0.0, atol=1e-9 * (k * x + kappa * x**3))
        assert u @ ev.S_K[:3, :3] @ u == pytest.approx(k + 3.0 * kappa * x**2, rel=1e-12)


def test_a_box_hung_on_a_hardening_spring_rests_where_mg_is_kx_plus_kappa_x3() -> None:
    """A 2 kg box hung from a world fixture by a hardening spring at its centre of mass: its rest
    is the real root of k x + κ x³ = m g (cd.statics.equilibrium, both backends)."""
    m, k, kappa, g = 2.0, 1e3, 1e7, 9.81
    box = cd.RigidObject.box(m, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
    link = cd.Interconnection(None, stiffness=cd.diagonal(k, 10.0), element="hardening", parameters={"hardening": kappa})
    scene = cd.Scene([], box, [link])
    roots = np.roots([kappa, 0.0, k, -m * g])
    x = float(roots[np.abs(roots.imag) < 1e-12].real[0])
    assert 0.5 * m * g / k < x < m * g / k  # hardening: less than the linear spring's sag
    from coopdyn.statics import equilibrium

    data = scene.model.createData()
    for backend in ("native", "python"):
        rest = equilibrium(scene, backend=backend)
        pin.framesForwardKinematics(scene.model, data, rest.q)
        assert 1.0 - data.oMf[scene.object_frame].translation[2] == pytest.approx(x, rel=1e-9), backend


def test_an_element_parameter_is_checked_by_name_and_survives_describe_and_build(tmp_path: Any) -> None:
    """Interconnection.parameters: an unknown name is refused with the element's parameters and
    units; a described scene builds back with the same parameter; a scene file's table works."""
    from coopdyn.model.description import build, describe

    box = cd.RigidObject.box(2.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
    bad = cd.Interconnection(None, stiffness=1e3 * np.ones(6), element="hardening", parameters={"hardenin": 1.0})
    with pytest.raises(cd.SceneError, match=r"no parameter 'hardenin'. Did you mean 'hardening'.* hardening \[N/m³\]"):
        cd.Scene([], box, [bad])
    with pytest.raises(cd.SceneError, match="the 'se3' element has no parameter 'hardening'"):
        cd.Scene([], box, [cd.Interconnection(None, stiffness=1e3 * np.ones(6), parameters={"hardening": 1.0})])
    good = cd.Interconnection(None, stiffness=1e3 * np.ones(6), element="hardening", parameters={"hardening": 3e6})
    doc = describe(cd.Scene([], box, [good]))
    assert doc["interconnections"][0]["parameters"] == {"hardening": 3e6}
    assert build(doc).links[0].element.hardening == 3e6
    scene_file = tmp_path / "hung.toml"
    scene_file.write_text(
        "[object]\ntype = 'box'\nmass = 2.0\nsize = [0.1, 0.1, 0.1]\npose = [0, 0, 1]\n\n"
        "[[interconnections]]\nstiffness = 1000.0\nelement = 'hardening'\nparameters = { hardening = 3e6 }\n\n"
        "[simulation]\nduration = 0.01\nintegrator = 'trapezoid'\ndt = 1e-3\n",
        encoding="utf-8",
    )
    from coopdyn.io.scenefile import load

    assert load(scene_file).scene.links[0].element.hardening == 3e6


def test_ctrl_c_inside_a_python_element_stops_the_compiled_run_with_its_partial_result() -> None:
    """A Ctrl-C that lands inside a Python-only element's evaluate (called from the compiled
    kernel) is the user's interrupt: SimulationInterrupted with the samples so far, not a kernel
    error; the Python loop on the native dynamics says the same."""

    class Interrupted(ToyVerticalSpring):
        kind: ClassVar[str] = "toy_interrupted"

        def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
            if T_M_G.translation[2] < -0.005:  # about 0.03 s into the fall
                raise KeyboardInterrupt
            return super().evaluate(T_M_G, xi, jacobians)

    register(Interrupted)
    try:
        box = cd.RigidObject.box(2.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0], joint="prismatic", axis="z")
        scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=800.0, element=Interrupted.kind)])
        for loop in ("compiled", "python"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                with pytest.raises(cd.errors.SimulationInterrupted) as info:
                    cd.simulate(scene, 0.5, integrator="rk4", dt=1e-3, loop=loop, accuracy_check="off", progress=False)
            partial = info.value.result
            assert partial is not None and 0.02 < partial.t[-1] < 0.06, loop
    finally:
        ELEMENTS.pop(Interrupted.kind, None)
