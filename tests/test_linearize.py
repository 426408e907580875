"""The exact linearisation: the elements' second derivatives and ∂q̈/∂(q, v, τ) of the coupled system.

Every element's :meth:`tangent` is compared with Richardson-extrapolated central differences of
its own law (error O(h⁴)) at small and large rotations; :func:`coopdyn.linearize` with the same
differences of :meth:`Dynamics.acceleration` on scenes that exercise every built-in element,
damping, an external wrench, a fixture and a beam; the book's linear system with its closed-form
state matrices; the tangent-coordinate drift of a spinning free-flyer with the flow it describes.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.dynamics import Dynamics
from coopdyn.model.elements import BallSpring, Element, ElementEval, HardeningSpring, SE3Spring
from coopdyn.model.elements.lie import jlog6, jlog6_of_log, log6
from coopdyn.reference import BookParameters


def richardson(f: Callable[[float], np.ndarray], h: float) -> np.ndarray:
    """df/ds at s = 0 from central differences at h and h/2, extrapolated (error O(h⁴))."""

    def central(step: float) -> np.ndarray:
        return (f(step) - f(-step)) / (2.0 * step)

    return (4.0 * central(h / 2) - central(h)) / 3.0


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _elements() -> dict[str, Element]:
    rng = np.random.default_rng(5)
    L = rng.normal(size=(6, 6))
    K_full = L @ L.T * 2e3 + np.diag([1e4, 2e4, 3e4, 50.0, 60.0, 70.0])
    K = cd.diagonal([1e4, 2e4, 3e4], [50.0, 60.0, 70.0])
    D = cd.diagonal([10.0, 20.0, 30.0], [0.1, 0.2, 0.3])
    M = rng.normal(size=(3, 3))
    return {
        "se3 (full K, damped)": SE3Spring(K_full, D),
        "se3 undamped": SE3Spring(K),
        "hardening": HardeningSpring(K, D, hardening=1e7),
        "ball": BallSpring(M @ M.T * 1e3 + np.eye(3) * 1e4, np.diag([5.0, 6.0, 7.0])),
    }


ELEMENTS = _elements()


@pytest.mark.parametrize("theta", [0.0, 1e-4, 0.2, 0.26, 1.0, 2.8])
@pytest.mark.parametrize("name", ELEMENTS)
def test_element_tangent_is_the_derivative_of_its_wrench(name: str, theta: float) -> None:
    element = ELEMENTS[name]
    rng = np.random.default_rng(int(theta * 1000) + len(name))
    axis = rng.normal(size=3)
    X = pin.SE3(pin.exp3(theta * axis / np.linalg.norm(axis)), 0.05 * rng.normal(size=3))
    xi = rng.normal(size=6)
    F_d, F_x = element.tangent(X, xi)
    for k in range(6):
        e = np.zeros(6)
        e[k] = 1.0
        ref_d = richardson(lambda s, e=e: element.evaluate(X * pin.exp6(s * e), xi).G_f_G, 1e-3)
        ref_x = richardson(lambda s, e=e: element.evaluate(X, xi + s * e).G_f_G, 1e-3)
        scale = max(np.max(np.abs(F_d)), 1.0)
        np.testing.assert_allclose(F_d[:, k], ref_d, rtol=0.0, atol=1e-8 * scale)
        np.testing.assert_allclose(F_x[:, k], ref_x, rtol=0.0, atol=1e-8 * max(np.max(np.abs(F_x)), 1.0))
    assert element.exact_tangent


@pytest.mark.parametrize("theta", [0.0, 1e-4, 0.26, 2.8])
@pytest.mark.parametrize("name", ELEMENTS)
def test_element_matrix_tangent_is_the_derivative_of_its_gauss_newton_matrices(name: str, theta: float) -> None:
    """∂(S_K w_K + S_D w_D)/∂(δ, ξ) for fixed twists (an implicit step's derivative needs it)."""
    element = ELEMENTS[name]
    rng = np.random.default_rng(int(theta * 1000) + 7 * len(name))
    axis = rng.normal(size=3)
    X = pin.SE3(pin.exp3(theta * axis / np.linalg.norm(axis)), 0.05 * rng.normal(size=3))
    xi, w_K, w_D = rng.normal(size=(3, 6))

    def applied(pose: pin.SE3, twist: np.ndarray) -> np.ndarray:
        ev = element.evaluate(pose, twist, True)
        return np.asarray(ev.S_K @ w_K + ev.S_D @ w_D)

    G_d, G_x = element.matrix_tangent(X, xi, w_K, w_D)
    scale = max(np.max(np.abs(G_d)), 1.0)
    for k in range(6):
        e = np.eye(6)[k]
        ref_d = richardson(lambda s, e=e: applied(X * pin.exp6(s * e), xi), 1e-3)
        ref_x = richardson(lambda s, e=e: applied(X, xi + s * e), 1e-3)
        np.testing.assert_allclose(G_d[:, k], ref_d, rtol=0.0, atol=1e-8 * scale)
        np.testing.assert_allclose(G_x[:, k], ref_x, rtol=0.0, atol=1e-8 * scale)
    # a user's law gets the base class's differences, which agree
    for a, b in zip(Element.matrix_tangent(element, X, xi, w_K, w_D), (G_d, G_x), strict=True):
        assert np.max(np.abs(a - b)) < 1e-7 * scale


class _HardBall(BallSpring):
    """A user's ball law with a cubic term: its own evaluate, no derivatives of its own."""

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        ev = super().evaluate(T_M_G, xi, jacobians)
        p = T_M_G.translation
        f = ev.G_f_G.copy()
        f[:3] -= T_M_G.rotation.T @ (1e6 * (p @ p) * p)
        S_K = None if ev.S_K is None else ev.S_K + np.diag([1e6 * 3 * (p @ p)] * 3 + [0.0] * 3)
        return ev._replace(G_f_G=f, S_K=S_K)


class _MismatchedHessian(SE3Spring):
    """A user's SE(3) law whose hessian is not the Hessian its S_K is built from."""

    def hessian(self, e: np.ndarray) -> np.ndarray:
        return np.asarray(self.K) * 2.0


def test_user_laws_get_differences_or_a_clear_error_not_the_built_ins_closed_forms() -> None:
    X = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.5])), np.array([0.02, -0.01, 0.03]))
    xi, w_K, w_D = np.random.default_rng(3).normal(size=(3, 6))
    ball = _HardBall(np.diag([1e4, 2e4, 3e4]), np.eye(3))
    assert not ball.exact_tangent and type(ball).matrix_tangent is Element.matrix_tangent
    ref = richardson(lambda s: ball.evaluate(X * pin.exp6(s * np.eye(6)[0]), xi).G_f_G, 1e-3)
    assert _rel(ball.tangent(X, xi)[0][:, 0], ref) < 1e-7
    with pytest.raises(cd.SceneError, match=r"_MismatchedHessian: its Gauss–Newton stiffness S_K is not Jlog6ᵀ·hessian"):
        _MismatchedHessian(cd.diagonal(1e4, 50.0)).matrix_tangent(X, xi, w_K, w_D)


def test_the_logarithm_jacobian_as_a_function_of_the_logarithm_is_jlog6() -> None:
    rng = np.random.default_rng(2)
    for theta in (0.0, 1e-7, 0.1, 0.249, 0.251, 1.5, 3.0):
        axis = rng.normal(size=3)
        X = pin.SE3(pin.exp3(theta * axis / np.linalg.norm(axis)), rng.normal(size=3))
        e, th = log6(X)
        np.testing.assert_allclose(jlog6_of_log(e), jlog6(X, e, th), rtol=0.0, atol=1e-14 * max(1.0, np.max(np.abs(e))))


class _PlainSE3(Element):
    """A user element with the SE(3) law and no tangent of its own: the default differences."""

    kind = "plain_se3_for_linearize"
    deformation_size = 6

    def __init__(self, stiffness: object, damping: object = None, name: str = "interconnection") -> None:
        self._law = SE3Spring(stiffness, damping, name)

    def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
        return self._law.evaluate(T_M_G, xi, jacobians)


def test_an_element_without_a_tangent_gets_central_differences_and_says_so() -> None:
    K, D = cd.diagonal(1e4, 50.0), cd.diagonal(10.0, 0.1)
    exact, plain = SE3Spring(K, D), _PlainSE3(K, D)
    X = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.5])), np.array([0.02, -0.01, 0.03]))
    xi = np.array([0.1, -0.2, 0.3, 1.0, -0.5, 0.2])
    for a, b in zip(plain.tangent(X, xi), exact.tangent(X, xi), strict=True):
        assert _rel(a, b) < 1e-7
    assert not plain.exact_tangent
    box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=K, damping=D, element=_PlainSE3, grasp=[0.0, 0.0, 0.05])])
    assert not cd.linearize(scene, backend="python").exact


def ball_pandas(stiffness: tuple[float, float, float] = (1e4, 2e4, 3e4)) -> cd.Scene:
    """The two Pandas on ball grasps of diagonal ``stiffness`` [N/m] (tip axes), damping 20 N·s/m."""
    base = cd.scenes.facing_arms("panda", stiffness=1e4)
    K = np.diag(stiffness)
    links = [
        cd.Interconnection(ic.arm, stiffness=K, damping=np.eye(3) * 20.0, element="ball") for ic in base.interconnection_specs
    ]
    return cd.Scene(base.arm_specs, base.object, links, gravity=base.gravity)


def _hardening_pandas() -> cd.Scene:
    base = cd.scenes.facing_arms("panda", stiffness=1e4)
    K = cd.diagonal(1e4, 100.0)
    links = [
        cd.Interconnection(ic.arm, stiffness=K, damping=0.002 * K, element="hardening", parameters={"hardening": 1e8})
        for ic in base.interconnection_specs
    ]
    return cd.Scene(base.arm_specs, base.object, links, gravity=base.gravity)


def _hung_box() -> cd.Scene:
    box = cd.RigidObject.box(2.0, (0.2, 0.1, 0.3), pose=[0.1, -0.2, 1.0])
    K = cd.diagonal([1e3, 2e3, 3e3], [10.0, 20.0, 30.0])
    return cd.Scene([], box, [cd.Interconnection(None, stiffness=K, damping=0.01 * K, grasp=[0.0, 0.0, 0.15])])


SCENES: dict[str, Callable[[], cd.Scene]] = {
    "pandas, damped SE(3) grasps and joints": lambda: cd.scenes.facing_arms(
        "panda", stiffness=1e5, damping=30.0, joint_damping=0.5
    ),
    "pandas, ball grasps": ball_pandas,
    "pandas, hardening grasps": _hardening_pandas,
    "box hung from a fixture": _hung_box,
    "beam held by two pandas": lambda: cd.scenes.held_beam(n_elements=2, damping=5.0),
    "book": cd.scenes.linear_book,
}


@pytest.mark.parametrize("backend", ["python", "native"])
@pytest.mark.parametrize("name", SCENES)
def test_linearize_is_the_derivative_of_the_acceleration(name: str, backend: str) -> None:
    """Each backend's A and B against differences of its Dynamics.acceleration in Pinocchio's
    tangent coordinates, at a state with loaded, turned and moving grasps, torques and a
    world-fixed wrench on the object."""
    if backend == "native" and not cd.backend.native_available():
        pytest.skip("coopdyn._native is not built")
    scene = SCENES[name]()
    rng = np.random.default_rng(11)
    nv, model = scene.nv, scene.model
    q = pin.integrate(model, scene.q0, 0.05 * rng.normal(size=nv))
    v, tau = 0.5 * rng.normal(size=nv), 3.0 * rng.normal(size=scene.n_actuated)
    wrench = np.array([3.0, -2.0, 5.0, 0.4, -0.1, 0.2])
    lin = cd.linearize(scene, q, v, tau, object_wrench=wrench, backend=backend)
    dyn = Dynamics(scene, backend)
    a = dyn.acceleration(q, v, tau, wrench)
    np.testing.assert_allclose(lin.acceleration, a, rtol=0.0, atol=1e-9 * np.max(np.abs(a)))
    da_dq, da_dv, da_dtau = lin.A[nv:, :nv], lin.A[nv:, nv:], lin.B[nv:]
    for k in range(nv):
        e = np.zeros(nv)
        e[k] = 1.0
        ref_q = richardson(lambda s, e=e: dyn.acceleration(pin.integrate(model, q, s * e), v, tau, wrench), 1e-4)
        ref_v = richardson(lambda s, e=e: dyn.acceleration(q, v + s * e, tau, wrench), 1e-4)
        np.testing.assert_allclose(da_dq[:, k], ref_q, rtol=0.0, atol=1e-7 * np.max(np.abs(da_dq)))
        np.testing.assert_allclose(da_dv[:, k], ref_v, rtol=0.0, atol=1e-7 * max(np.max(np.abs(da_dv)), 1.0))
    for k in range(scene.n_actuated):
        e = np.zeros(scene.n_actuated)
        e[k] = 1.0
        ref_t = richardson(lambda s, e=e: dyn.acceleration(q, v, tau + s * e, wrench), 1.0)
        np.testing.assert_allclose(da_dtau[:, k], ref_t, rtol=0.0, atol=1e-9 * np.max(np.abs(da_dtau)))
    assert lin.exact


@pytest.mark.parametrize("name", [*SCENES, "user element"])
def test_the_kernel_twin_linearises_as_the_python_reference(name: str) -> None:
    """Dynamics(scene, "native").derivatives — Pinocchio's C++ derivatives and the elements' C++
    tangents (complex step in C++ too) — equal the Python reference to round-off; a user element
    without a twin is differentiated through its Python tangent from the kernel."""
    if not cd.backend.native_available():
        pytest.skip("coopdyn._native is not built")
    if name == "user element":
        box = cd.RigidObject.box(1.0, (0.1, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
        link = cd.Interconnection(None, stiffness=cd.diagonal(1e4, 50.0), damping=cd.diagonal(10.0, 0.1), element=_PlainSE3)
        scene = cd.Scene([], box, [link])
    else:
        scene = SCENES[name]()
    rng = np.random.default_rng(3)
    q = pin.integrate(scene.model, scene.q0, 0.2 * rng.normal(size=scene.nv))  # rotations beyond the series switch
    v, tau = rng.normal(size=scene.nv), rng.normal(size=scene.n_actuated)
    wrench = np.array([1.0, 2.0, -3.0, 0.1, 0.2, -0.3])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cd.backend.NativeBackendWarning)
        native = cd.linearize(scene, q, v, tau, object_wrench=wrench, backend="native")
    python = cd.linearize(scene, q, v, tau, object_wrench=wrench, backend="python")
    pairs = ((native.A, python.A), (native.B, python.B), (native.dwrench_dx, python.dwrench_dx), (native.wrench, python.wrench))
    for a, b in pairs:
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12 * max(np.max(np.abs(b), initial=0.0), 1.0))
    assert native.exact == python.exact == (name != "user element")


def test_grasp_wrench_derivatives_match_differences() -> None:
    scene = SCENES["pandas, damped SE(3) grasps and joints"]()
    rng = np.random.default_rng(4)
    nv, model = scene.nv, scene.model
    q, v = pin.integrate(model, scene.q0, 0.05 * rng.normal(size=nv)), 0.5 * rng.normal(size=nv)
    lin = cd.linearize(scene, q, v)
    dyn = Dynamics(scene, "python")

    def wrenches(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
        return np.array([ev.G_f_G for ev in dyn.element_states(qq, vv)])

    np.testing.assert_allclose(lin.wrench, wrenches(q, v), rtol=0.0, atol=1e-12 * np.max(np.abs(lin.wrench)))
    for k in range(2 * nv):
        e = np.zeros(nv)
        e[k % nv] = 1.0
        if k < nv:
            ref = richardson(lambda s, e=e: wrenches(pin.integrate(model, q, s * e), v), 1e-4)
        else:
            ref = richardson(lambda s, e=e: wrenches(q, v + s * e), 1e-4)
        np.testing.assert_allclose(lin.dwrench_dx[:, :, k], ref, rtol=0.0, atol=1e-7 * np.max(np.abs(lin.dwrench_dx)))


def test_book_linearisation_is_its_closed_form_state_matrix() -> None:
    """The book's system is linear: A and B are its state matrices exactly, at any state."""
    params = BookParameters(c_p=3e4, d_k=700.0)
    scene = cd.scenes.linear_book(c_p=3e4, d_k=700.0)
    A_ref, B_ref, _ = params.state_matrices()
    rng = np.random.default_rng(0)
    lin = cd.linearize(scene, scene.q0 + 0.01 * rng.normal(size=3), rng.normal(size=3), rng.normal(size=2))
    order = [scene.arms[0].v_index[0], scene.object_v[0], scene.arms[1].v_index[0]]
    perm = order + [3 + i for i in order]
    np.testing.assert_allclose(lin.A[np.ix_(perm, perm)], A_ref, rtol=1e-12, atol=1e-9)
    columns = [list(scene.actuated).index(order[0]), list(scene.actuated).index(order[2])]
    np.testing.assert_allclose(lin.B[perm][:, columns], B_ref, rtol=1e-12, atol=1e-15)


def test_tangent_coordinates_of_a_spinning_object_drift_as_omega_says() -> None:
    """Ω(v) = −ad(v) on a free-flyer: the rate of δ = difference(q̄(t), q(t)) between two free
    motions, differentiated with respect to δ at δ = 0, equals A's upper-left block."""
    scene = _hung_box()
    model, nv = scene.model, scene.nv
    q_ref, v_ref = scene.q0, np.array([0.3, -0.2, 0.1, 2.0, -1.0, 3.0])
    omega = cd.linearize(scene, q_ref, v_ref).A[:nv, :nv]

    def drift(delta: np.ndarray) -> np.ndarray:  # d/dt difference(q̄ ⊕ t v̄, (q̄ ⊕ δ) ⊕ t v̄) at t = 0
        q = pin.integrate(model, q_ref, delta)

        def apart(t: float) -> np.ndarray:
            return pin.difference(model, pin.integrate(model, q_ref, t * v_ref), pin.integrate(model, q, t * v_ref))

        return richardson(apart, 1e-3)

    for k in range(nv):
        e = np.zeros(nv)
        e[k] = 1.0
        np.testing.assert_allclose(omega[:, k], richardson(lambda s, e=e: drift(s * e), 1e-3), rtol=0.0, atol=1e-8)
    assert np.any(omega)


def test_a_held_box_has_the_modes_of_its_stiffness_and_mass() -> None:
    """A box hung by one undamped spring, without gravity, at rest: the eigenvalues of A are
    ±i·ω with ω² the eigenvalues of M⁻¹K (K = Ad-transported stiffness at the grasp)."""
    box = cd.RigidObject.box(2.0, (0.2, 0.1, 0.3), pose=[0.0, 0.0, 1.0])
    K = cd.diagonal([1e3, 2e3, 3e3], [10.0, 20.0, 30.0])
    scene = cd.Scene([], box, [cd.Interconnection(None, stiffness=K, grasp=[0.0, 0.0, 0.0])], gravity=[0.0, 0.0, 0.0])
    lam = cd.linearize(scene).eigenvalues
    mass = np.diag([2.0, 2.0, 2.0])
    inertia = np.diag(box.inertia)  # a box's principal moments, about its centre
    w2 = np.concatenate([np.diag(K)[:3] / np.diag(mass), np.diag(K)[3:] / inertia])
    np.testing.assert_allclose(np.sort(lam.imag[lam.imag > 0]), np.sort(np.sqrt(w2)), rtol=1e-12)
    np.testing.assert_allclose(lam.real, 0.0, atol=1e-9)


def test_linearize_refuses_what_it_cannot_do() -> None:
    scene = cd.scenes.linear_book()
    with pytest.raises(cd.SceneError, match=r"tau \[N·m or N\] must have shape \(2,\)"):
        cd.linearize(scene, tau=[1.0])
    with pytest.raises(cd.SceneError, match="v \\(a velocity\\) must have shape"):
        cd.linearize(scene, v=[0.0])
    with pytest.raises(cd.SceneError, match=r"object_wrench .* must be finite"):
        cd.linearize(scene, object_wrench=[np.nan, 0, 0, 0, 0, 0])
    with pytest.raises(cd.SceneError, match="rigid grasps"):
        cd.linearize(cd.rigid_limit(cd.scenes.facing_arms("panda", stiffness=1e4)))
    with pytest.raises(cd.SceneError, match=r"must be a coopdyn\.Scene"):
        cd.linearize("scene.toml")  # type: ignore[arg-type]


def test_the_exact_jacobian_variant_equals_gauss_newton_where_the_law_is_linear() -> None:
    """On the book's prismatic system the Gauss–Newton K̃, D̃ are exact: the measurement variant's
    −M ∂q̈/∂q, −M ∂q̈/∂v equal them; on two Pandas they differ (geometry, gravity, Coriolis)."""
    from coopdyn.bench.exact_jacobian import ExactJacobian, jacobian

    for scene, same in ((cd.scenes.linear_book(), True), (SCENES["pandas, damped SE(3) grasps and joints"](), False)):
        rng = np.random.default_rng(1)
        q = pin.integrate(scene.model, scene.q0, 0.05 * rng.normal(size=scene.nv))
        v, tau = rng.normal(size=scene.nv), rng.normal(size=scene.n_actuated)
        _, _, K, D = Dynamics(scene, "python").implicit_terms(q, v, tau)
        with jacobian("exact"):
            exact = Dynamics(scene, "python")
        assert isinstance(exact, ExactJacobian)
        _, _, K_x, D_x = exact.implicit_terms(q, v, tau)
        assert (_rel(K_x, K) < 1e-12 and _rel(D_x, D) < 1e-12) == same
    assert type(Dynamics(scene, "python")) is not ExactJacobian  # the block restored the backend


def test_the_closed_loop_adds_the_controllers_gain() -> None:
    """A joint PD without gravity: ∂τ/∂x is −Kp on the actuated joints' positions and −Kd on
    their velocities, and the closed loop's A is the open loop's plus B times it."""
    from coopdyn.control import GravityCompensationPD

    scene = cd.scenes.facing_arms("panda", stiffness=1e4, gravity=(0.0, 0.0, 0.0))
    pd = GravityCompensationPD(scene, 40.0, 4.0)
    closed = cd.linearize(scene, controller=pd)
    gain = np.zeros((scene.n_actuated, 2 * scene.nv))
    gain[np.arange(scene.n_actuated), scene.actuated] = -40.0
    gain[np.arange(scene.n_actuated), scene.nv + scene.actuated] = -4.0
    assert closed.controller_gain is not None and not closed.exact
    np.testing.assert_allclose(closed.controller_gain, gain, atol=1e-6)
    open_loop = cd.linearize(scene, tau=closed.tau)
    expected = open_loop.A + open_loop.B @ closed.controller_gain
    np.testing.assert_allclose(closed.A, expected, rtol=0.0, atol=1e-9 * np.max(np.abs(closed.A)))
    with pytest.raises(cd.SceneError, match="controller must be a callable"):
        cd.linearize(scene, controller="pd")  # type: ignore[arg-type]


def test_the_compiled_twins_gain_is_the_python_twins() -> None:
    """coopdyn.compiled.controller_gain (the loop check's, through the kernel) gives a built-in
    controller's ∂τ/∂x as linearize.controller_gain does — the same central differences on its
    compiled twin — for the PD with gravity compensation and ObjectImpedance; a user's Python
    controller, or the Python backend, gets None (the Python differences then)."""
    from coopdyn.closed_loop import System
    from coopdyn.compiled import controller_gain as compiled_gain
    from coopdyn.control import GravityCompensationPD
    from coopdyn.cooperative import ObjectImpedance
    from coopdyn.linearize import controller_gain

    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    q = pin.integrate(scene.model, scene.q0, 0.05 * np.random.default_rng(2).normal(size=scene.nv))
    v = 0.3 * np.random.default_rng(3).normal(size=scene.nv)
    for controller in (GravityCompensationPD(scene, 60.0, 6.0), ObjectImpedance(scene)):
        system = System(Dynamics(scene, "native"), controller)
        compiled, python = compiled_gain(system, 0.1, q, v), controller_gain(system, 0.1, q, v)
        assert compiled is not None and compiled.shape == python.shape == (scene.n_actuated, 2 * scene.nv)
        np.testing.assert_allclose(compiled, python, rtol=0.0, atol=1e-6 * np.max(np.abs(python)))
    pd = GravityCompensationPD(scene)
    assert compiled_gain(System(Dynamics(scene, "native"), lambda t, q, v: pd(t, q, v)), 0.0, q, v) is None
    assert compiled_gain(System(Dynamics(scene, "python"), pd), 0.0, q, v) is None


def test_a_subclass_that_changes_the_se3_law_loses_its_exact_tangent() -> None:
    """An SE3Spring subclass with its own evaluate and no gradient or tangent of its own is
    differentiated by central differences (and says so), not with the parent's exact tangent;
    the hardening spring, which brings its gradient, keeps an exact one."""

    class Stiffer(SE3Spring):
        kind = "stiffer_for_linearize"

        def evaluate(self, T_M_G: pin.SE3, xi: np.ndarray, jacobians: bool = False) -> ElementEval:
            ev = super().evaluate(T_M_G, xi, jacobians)
            return ev._replace(G_f_G=2.0 * ev.G_f_G)

    element = Stiffer(cd.diagonal(1e4, 50.0))
    X = pin.SE3(pin.exp3(np.array([0.2, -0.1, 0.3])), np.array([0.01, 0.02, -0.01]))
    F_d, _ = element.tangent(X, np.zeros(6))
    exact, _ = SE3Spring(cd.diagonal(1e4, 50.0)).tangent(X, np.zeros(6))
    assert not Stiffer.exact_tangent and HardeningSpring.exact_tangent and SE3Spring.exact_tangent
    np.testing.assert_allclose(F_d, 2.0 * exact, rtol=0.0, atol=1e-6 * np.max(np.abs(exact)))


@pytest.mark.parametrize("backend", ["native", "python"])
def test_a_runs_loop_diagnosis_linearises_on_its_own_dynamics_as_linearize_does(backend: str) -> None:
    """The loop check and the divergence diagnosis (``accuracy.start_loop``) linearise on the run's
    own dynamics (``linearize.open_loop``: a beam's Pinocchio data is not built once more); their
    closed loop is ``cd.linearize(scene, q, v, controller=…)``'s to the last bit, after the
    dynamics stepped elsewhere; rigid grasps still give no loop."""
    from coopdyn.accuracy import start_loop
    from coopdyn.closed_loop import System
    from coopdyn.control import GravityCompensationPD

    scene = cd.scenes.facing_arms("panda", stiffness=1e4, damping=0.002)
    pd = GravityCompensationPD(scene, 60.0, 6.0)
    q = pin.integrate(scene.model, scene.q0, 0.05 * np.random.default_rng(5).normal(size=scene.nv))
    v = 0.3 * np.random.default_rng(6).normal(size=scene.nv)
    system = System(Dynamics(scene, backend), pd)
    system.dynamics.acceleration(scene.q0, np.zeros(scene.nv), np.zeros(scene.n_actuated))  # (elsewhere first)
    loop = start_loop(system, q, v)
    public = cd.linearize(scene, q, v, controller=pd, backend=backend)
    assert loop is not None and public.controller_gain is not None
    assert np.array_equal(loop.A + loop.B @ loop.G, public.A) and np.array_equal(loop.G, public.controller_gain)
    rigid = cd.rigid_limit(scene)
    assert start_loop(System(Dynamics(rigid, "python"), GravityCompensationPD(rigid)), rigid.q0, rigid.v0) is None
