"""The compiled kernel computes the same physics as the Python reference, to round-off.

Each quantity — dynamics, implicit terms, every element's evaluation and every trajectory
readout — is compared on scenes that exercise every element and every branch of the kernel:
free-flying box with two Pandas (SE(3) springs, interconnection and joint damping, an external
wrench), the same with ball springs, three arms, a box hung from the world by one spring (a
fixture, no arm), and the book's prismatic linear case (1-D springs, no free-flyer).
"""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn.dynamics import Dynamics, backend
from coopdyn.errors import KernelError, StepMatrixError

pytestmark = pytest.mark.skipif(not backend.native_available(), reason="coopdyn._native is not built")


def _ball_pandas() -> cd.Scene:
    base = cd.scenes.facing_arms("panda", stiffness=1e4)
    rng = np.random.default_rng(3)
    links = []
    for ic in base.interconnection_specs:
        L = rng.normal(size=(3, 3))
        links.append(
            cd.Interconnection(ic.arm, stiffness=L @ L.T * 1e3 + np.eye(3) * 1e4, damping=np.eye(3) * 20.0, element="ball")
        )
    return cd.Scene(base.arm_specs, base.object, links, gravity=base.gravity)


def _hung_box() -> cd.Scene:
    box = cd.RigidObject.box(2.0, (0.2, 0.1, 0.3), pose=[0.1, -0.2, 1.0])
    K = cd.diagonal([1e3, 2e3, 3e3], [10.0, 20.0, 30.0])
    return cd.Scene([], box, [cd.Interconnection(None, stiffness=K, damping=0.01 * K, grasp=[0.0, 0.0, 0.15])])


def _scenes() -> dict[str, cd.Scene]:
    return {
        "pandas_damped": cd.scenes.facing_arms("panda", stiffness=1e5, damping=30.0, joint_damping=0.5),
        "pandas_ball": _ball_pandas(),
        "three_pandas": cd.scenes.facing_arms("panda", stiffness=1e4, n_arms=3),
        "hung_box": _hung_box(),
        "book": cd.scenes.linear_book(),
    }


SCENES = _scenes()


def _pair(scene: cd.Scene) -> tuple[Dynamics, Dynamics]:
    return Dynamics(scene, backend="native"), Dynamics(scene, backend="python")


def _states(scene: cd.Scene, n: int = 4) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Random states around q0 (springs loaded) and torques."""
    rng = np.random.default_rng(7)
    out = []
    for _ in range(n):
        q = pin.integrate(scene.model, scene.q0, 0.05 * rng.normal(size=scene.nv))
        out.append((q, rng.normal(size=scene.nv), 5.0 * rng.normal(size=scene.n_actuated)))
    return out


def _close(a: np.ndarray, b: np.ndarray) -> None:
    scale = max(1.0, float(np.max(np.abs(b))))
    np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-11 * scale)


@pytest.mark.parametrize("name", SCENES)
def test_acceleration_and_dissipation_match_python(name: str) -> None:
    scene = SCENES[name]
    nat, py = _pair(scene)
    wrench = np.array([3.0, -2.0, 5.0, 0.4, -0.1, 0.2])
    for q, v, tau in _states(scene):
        for w in (None, wrench):
            _close(nat.acceleration(q, v, tau, w), py.acceleration(q, v, tau, w))
            assert nat.last_dissipation == pytest.approx(py.last_dissipation, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("name", ["pandas_damped", "three_pandas", "book"])
def test_gravity_read_off_the_kinematics_is_pinocchios(name: str) -> None:
    """The compiled GravityCompensationPD takes g(q) from the kernel's kinematics pass (subtree
    masses and first moments against each joint axis): Pinocchio's generalized gravity on the
    actuated joints, revolute (Pandas) and prismatic (book)."""
    scene = SCENES[name]
    nat, _ = _pair(scene)
    data = scene.model.createData()
    for q, _, _ in _states(scene):
        g = pin.computeGeneralizedGravity(scene.model, data, q)[scene.actuated]
        assert np.max(np.abs(g)) > 1.0
        _close(nat._kernel.gravity(q), g)


def _every_joint_kind_arm(multi_dof: bool = False) -> tuple[pin.Model, np.ndarray, int, int, int]:
    """A chain with every joint kind ``Kernel.gravity`` takes (unaligned, unbounded, helical,
    prismatic; a side branch), random placements and inertias, and a free-flying object with a
    tip–grasp pair and an object frame: (model, actuated, tip, grasp, object frame). With
    ``multi_dof``, also the joints of more than one degree of freedom (spherical, ZYX, planar,
    translation, universal, a composite) and a rotor armature on every joint."""
    rng = np.random.default_rng(0)

    def placement() -> pin.SE3:
        return pin.SE3(pin.exp3(rng.normal(size=3)), 0.3 * rng.normal(size=3))

    def inertia() -> pin.Inertia:
        return pin.Inertia(rng.uniform(0.5, 2.0), 0.2 * rng.normal(size=3), np.diag(rng.uniform(0.01, 0.1, 3)))

    def axis() -> np.ndarray:
        a = rng.normal(size=3)
        return a / np.linalg.norm(a)

    kinds = [
        pin.JointModelRevoluteUnaligned(axis()),
        pin.JointModelRUBX(),
        pin.JointModelRevoluteUnboundedUnaligned(),
        pin.JointModelHelicalUnaligned(axis(), 0.3),
        pin.JointModelPrismaticUnaligned(axis()),
        pin.JointModelHZ(0.1),
        pin.JointModelRY(),
        pin.JointModelPX(),
    ]
    if multi_dof:
        composite = pin.JointModelComposite(pin.JointModelRX())
        composite.addJoint(pin.JointModelPY(), placement())
        kinds += [
            pin.JointModelSpherical(),
            pin.JointModelSphericalZYX(),
            pin.JointModelPlanar(),
            pin.JointModelTranslation(),
            pin.JointModelUniversal(axis(), axis()),
            composite,
        ]
    model, parent = pin.Model(), 0
    for i, kind in enumerate(kinds):
        parent = model.addJoint(parent, kind, placement(), f"j{i}")
        model.appendBodyToJoint(parent, inertia(), placement())
        if i == 2:
            branch = model.addJoint(parent, pin.JointModelRZ(), placement(), "branch")
            model.appendBodyToJoint(branch, inertia(), pin.SE3.Identity())
    obj = model.addJoint(0, pin.JointModelFreeFlyer(), placement(), "object")
    model.appendBodyToJoint(obj, inertia(), pin.SE3.Identity())
    tip = model.addFrame(pin.Frame("tip", parent, 0, placement(), pin.FrameType.OP_FRAME))
    grasp = model.addFrame(pin.Frame("grasp", obj, 0, placement(), pin.FrameType.OP_FRAME))
    frame = model.addFrame(pin.Frame("object_frame", obj, 0, placement(), pin.FrameType.OP_FRAME))
    actuated = np.array([model.joints[j].idx_v for j in range(1, model.njoints) if model.names[j] != "object"], dtype=np.int32)
    if multi_dof:
        model.armature = rng.uniform(0.0, 0.05, model.nv)
    return model, actuated, tip, grasp, frame


def test_gravity_and_external_forces_are_right_for_every_joint_kind() -> None:
    """On every joint kind the kinematic g(q) takes, it is Pinocchio's generalized gravity; and the
    right-hand side with the element's wrench as ABA's external forces is M⁻¹ f of the implicit
    terms, which map the same wrench through the frame Jacobians (with an object wrench too)."""
    model, actuated, tip, grasp, frame = _every_joint_kind_arm()
    kernel = _se3_kernel(model, actuated, tip, grasp, frame)
    rng, data = np.random.default_rng(1), model.createData()
    for _ in range(10):
        q = pin.integrate(model, pin.neutral(model), rng.normal(size=model.nv))
        v, tau = rng.normal(size=model.nv), rng.normal(size=actuated.size)
        g = pin.computeGeneralizedGravity(model, data, q)[actuated]
        _close(kernel.gravity(q), g)
        for w in (None, rng.normal(size=6)):
            f, M, _, _ = kernel.implicit_terms(q, v, tau, w)
            _close(kernel.acceleration(q, v, tau, w), np.linalg.solve(M, f))


def _se3_kernel(model: pin.Model, actuated: np.ndarray, tip: int, grasp: int, frame: int) -> object:
    """A kernel of ``model`` (no elastic joints) with one damped SE(3) spring between tip and grasp."""
    K, D = np.diag([300.0, 500.0, 700.0, 20.0, 30.0, 40.0]), np.diag([2.0, 3.0, 4.0, 0.1, 0.2, 0.3])
    links = [("se3", tip, grasp, {"K": K, "D": D})]
    return backend.kernel_module().Kernel(
        model, model.createData(), links, np.zeros(model.nv), actuated, frame, np.zeros(0), model
    )


@pytest.mark.parametrize("seed", range(5))
def test_the_articulated_body_pass_is_pinocchios_aba(seed: int) -> None:
    """The kernel's articulated-body pass, which starts from its kinematics pass instead of
    redoing it, gives pinocchio.aba's q̈ for the same joint torques and the same external forces
    (the element's wrench on the joints carrying G and T), on every joint kind, with rotor armature:
    the same operations in the same order, so the same bits."""
    model, actuated, tip, grasp, frame = _every_joint_kind_arm(multi_dof=True)
    kernel = _se3_kernel(model, actuated, tip, grasp, frame)
    rng, data = np.random.default_rng(seed), model.createData()
    G, T = model.frames[grasp], model.frames[tip]
    q = pin.integrate(model, pin.neutral(model), rng.normal(size=model.nv))
    v, tau = rng.normal(size=model.nv), rng.normal(size=actuated.size)
    f_G = pin.Force(kernel.element_states(q, v)[0][2])
    assert np.linalg.norm(f_G.vector) > 1.0
    pin.framesForwardKinematics(model, data, q)
    T_M_G = data.oMf[tip].actInv(data.oMf[grasp])
    fext = [pin.Force.Zero() for _ in range(model.njoints)]
    fext[G.parentJoint] += G.placement.act(f_G)
    fext[T.parentJoint] -= T.placement.act(T_M_G.act(f_G))
    tau_full = np.zeros(model.nv)
    tau_full[actuated] = tau
    expected = pin.aba(model, data, q, v, tau_full, fext)
    if platform.machine() in ("x86_64", "AMD64"):  # the kernel and the pin wheels compiled alike (no FMA)
        np.testing.assert_array_equal(kernel.acceleration(q, v, tau, None), expected)
    else:  # elsewhere a compiler may fuse multiply-adds differently in the two builds
        _close(kernel.acceleration(q, v, tau, None), expected)


def test_gravity_refuses_joints_it_cannot_read() -> None:
    """A spherical actuated joint has three degrees of freedom: the kernel says what it takes (the
    compiled GravityCompensationPD then uses Pinocchio's RNEA)."""
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.appendBodyToJoint(j, pin.Inertia.FromSphere(1.0, 0.1), pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])))
    kernel = backend.kernel_module().Kernel(
        model, model.createData(), [], np.zeros(3), np.arange(3, dtype=np.int32), 0, np.zeros(0), model
    )
    with pytest.raises(ValueError, match="revolute, prismatic or helical"):
        kernel.gravity(pin.neutral(model))


def test_dissipation_is_counted_where_there_is_damping() -> None:
    """Guards the comparison above against comparing two zeros."""
    scene = SCENES["pandas_damped"]
    nat, _ = _pair(scene)
    q, v, tau = _states(scene)[0]
    nat.acceleration(q, v, tau)
    assert nat.last_dissipation > 1.0


@pytest.mark.parametrize("name", SCENES)
def test_implicit_terms_match_python(name: str) -> None:
    scene = SCENES[name]
    nat, py = _pair(scene)
    for q, v, tau in _states(scene):
        for a, b in zip(nat.implicit_terms(q, v, tau), py.implicit_terms(q, v, tau), strict=True):
            _close(a, b)


@pytest.mark.parametrize("name", SCENES)
def test_generalized_spring_force_matches_python(name: str) -> None:
    """Q = Σ Jrᵀ f: the kernel's own evaluation (used by the MuJoCo peer) and the Python one."""
    scene = SCENES[name]
    nat, py = _pair(scene)
    for q, v, _ in _states(scene):
        Q = nat.generalized_spring_force(q, v)
        assert np.max(np.abs(Q)) > 0.1  # the interconnections do work here
        _close(Q, py.generalized_spring_force(q, v))


@pytest.mark.parametrize("name", SCENES)
def test_implicit_euler_velocity_matches_python(name: str) -> None:
    scene = SCENES[name]
    nat, py = _pair(scene)
    kp, kd = np.full(scene.n_actuated, 80.0), np.full(scene.n_actuated, 4.0)
    act = scene.actuated
    for q, v, tau in _states(scene):
        _, M, K, D = py.implicit_terms(q, v, tau)
        K[act, act] += kp
        D[act, act] += kd
        for h in (1e-4, 1e-3, 1e-2):
            # Two Cholesky solves (Eigen vs numpy) agree to the conditioning times round-off.
            kappa = np.linalg.cond(M + h * D + h * h * K)
            a = nat.implicit_euler_velocity(q, v, tau, h, kp, kd)
            b = py.implicit_euler_velocity(q, v, tau, h, kp, kd)
            np.testing.assert_allclose(a, b, rtol=0.0, atol=10.0 * kappa * np.finfo(float).eps * np.max(np.abs(b)))


@pytest.mark.parametrize("name", SCENES)
def test_energies_match_python(name: str) -> None:
    scene = SCENES[name]
    nat, py = _pair(scene)
    for q, v, _ in _states(scene):
        e_nat, e_py = nat.energy(q, v), py.energy(q, v)
        assert e_nat.elastic > 0.0
        assert e_nat.total == pytest.approx(e_py.total, rel=1e-12)
        _close(nat.elastic_energy(q), py.elastic_energy(q))


def test_kernel_leaves_the_same_kinematics_in_data(pandas: cd.Scene) -> None:
    """Readers of Dynamics.data after a right-hand side (object power, wrenches) see the state it was
    evaluated at, whichever backend ran."""
    nat, py = _pair(pandas)
    q, v, tau = _states(pandas)[1]
    nat.acceleration(q, v, tau)
    py.acceleration(q, v, tau)
    f = pandas.object_frame
    for d in (nat, py):
        pin.updateFramePlacement(pandas.model, d.data, f)
    np.testing.assert_allclose(nat.data.oMf[f].homogeneous, py.data.oMf[f].homogeneous, atol=1e-14)
    V = [pin.getFrameVelocity(pandas.model, d.data, f, pin.ReferenceFrame.LOCAL).vector for d in (nat, py)]
    np.testing.assert_allclose(V[0], V[1], atol=1e-13)


def test_implicit_euler_runs_agree_across_backends(pandas: cd.Scene) -> None:
    """A whole closed-loop run (PD controller, energy monitor) gives the same trajectory."""
    ctrl = cd.control.GravityCompensationPD(pandas, 50.0, 5.0)
    v0 = np.random.default_rng(0).normal(size=pandas.nv) * 0.3
    runs = []
    for name in ("native", "python"):
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("COOPDYN_BACKEND", name)
            runs.append(cd.simulate(pandas, 0.2, controller=ctrl, integrator="implicit_euler", dt=1e-3, v0=v0))
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-10)
    np.testing.assert_allclose(runs[0].wrench(0), runs[1].wrench(0), atol=1e-6)


def test_what_the_kernel_refuses_reaches_the_user_as_a_coopdyn_error(pandas: cd.Scene) -> None:
    nat = Dynamics(pandas, backend="native")
    q, v, tau = pandas.q0, np.zeros(pandas.nv), np.zeros(pandas.n_actuated)
    with pytest.raises(KernelError, match="tau has 3 entries, expected 14"):
        nat.acceleration(q, v, np.zeros(3))
    with pytest.raises(KernelError, match="v has 4 entries"):
        nat.acceleration(q, np.zeros(4), tau)
    with pytest.raises(KernelError, match="q has"):
        nat.acceleration(q[:-1], v, tau)
    with pytest.raises(KernelError, match="object wrench must have 6 entries"):
        nat.acceleration(q, v, tau, np.zeros(5))
    with pytest.raises(KernelError, match="kp has"):
        nat.implicit_euler_velocity(q, v, tau, 1e-3, np.zeros(2), np.zeros(pandas.n_actuated))
    with pytest.raises(KernelError, match="refused acceleration"):  # Boost.Python.ArgumentError inside
        nat.acceleration("abc", v, tau)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["native", "python"])
def test_factor_coefficients_that_are_not_real_numbers_are_refused_on_both_backends(pandas: cd.Scene, name: str) -> None:
    dyn = Dynamics(pandas, backend=name)
    _, M, K, D = dyn.implicit_terms(pandas.q0, np.zeros(pandas.nv), np.zeros(pandas.n_actuated))
    gains = np.full(pandas.n_actuated, 10.0)
    for gh, gh2 in (("x", None), ([], None), (1e-3, 1j), (10**400, None)):
        with pytest.raises(KernelError, match="gh and gh2 must be real numbers"):
            dyn.factor(M, K, D, gh, gains, gains, gh2)  # type: ignore[arg-type]
    dyn.factor(M, K, D, np.float32(1e-3), gains, gains)  # a numpy float is a real number


@pytest.mark.parametrize("name", ["native", "python"])
def test_a_step_matrix_that_is_not_positive_definite_raises_on_both_backends(pandas: cd.Scene, name: str) -> None:
    dyn = Dynamics(pandas, backend=name)
    q, v, tau = pandas.q0, np.zeros(pandas.nv), np.zeros(pandas.n_actuated)
    with pytest.raises(StepMatrixError, match="not positive definite"):
        dyn.implicit_euler_velocity(q, v, tau, 1e-2, np.full(pandas.n_actuated, -1e6), np.zeros(pandas.n_actuated))
    nv = pandas.nv
    with pytest.raises(StepMatrixError, match="not finite"):
        dyn.factor(np.full((nv, nv), np.nan), np.zeros((nv, nv)), np.zeros((nv, nv)), 1e-3, tau, tau)


def test_simulate_names_the_time_and_the_method_when_the_step_matrix_fails(pandas: cd.Scene) -> None:
    class NegativeGains:
        def __call__(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            return np.zeros(pandas.n_actuated)

        def gains(self) -> tuple[np.ndarray, np.ndarray]:
            return np.full(pandas.n_actuated, -1e6), np.zeros(pandas.n_actuated)

    for method in ("implicit_euler", "ros2"):
        with pytest.raises(StepMatrixError, match=rf"at t = 0 s \({method}, dt = 0.01 s\).*controller's gains") as info:
            cd.simulate(pandas, 0.1, controller=NegativeGains(), integrator=method, dt=1e-2)
        assert info.value.result is not None and info.value.result.status == "diverged"


@pytest.mark.parametrize("name", SCENES)
def test_element_states_match_python(name: str) -> None:
    """Every element's evaluation (energy, deformation, wrench, power, S_K, S_D) on both backends."""
    scene = SCENES[name]
    nat, py = _pair(scene)
    for q, v, _ in _states(scene):
        for a, b in zip(nat.element_states(q, v), py.element_states(q, v), strict=True):
            for x, y in zip(a, b, strict=True):
                _close(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("name", SCENES)
def test_readouts_match_python(name: str) -> None:
    """The trajectory readouts (wrenches on object and arm, deformations, energies, positions)."""
    scene = SCENES[name]
    nat, py = _pair(scene)
    states = _states(scene, 6)
    Q, V = np.array([s[0] for s in states]), np.array([s[1] for s in states])
    for a, b in zip(nat.readouts(Q, V), py.readouts(Q, V), strict=True):
        _close(a, b)
    assert np.max(np.abs(py.readouts(Q, V).object_wrench)) > 1.0  # not comparing zeros


def test_backend_choice(monkeypatch: pytest.MonkeyPatch, pandas: cd.Scene) -> None:
    assert Dynamics(pandas, backend="python").backend == "python"
    monkeypatch.setenv("COOPDYN_BACKEND", "python")
    assert Dynamics(pandas).backend == "python"
    monkeypatch.setenv("COOPDYN_BACKEND", "auto")
    assert Dynamics(pandas).backend == "native"
    with pytest.raises(backend.BackendError, match="backend must be one of auto, native, python, got 'fortran'"):
        Dynamics(pandas, backend="fortran")


def test_missing_kernel_warns_and_falls_back(monkeypatch: pytest.MonkeyPatch, pandas: cd.Scene) -> None:
    why = "coopdyn._native was built against Pinocchio 0.0.1 but Pinocchio 4.1.0 is installed"
    monkeypatch.delenv("COOPDYN_BACKEND", raising=False)
    monkeypatch.setattr(backend, "_load", lambda: (None, why))
    backend._warn_once.cache_clear()
    with pytest.warns(backend.NativeBackendWarning, match=r"built against Pinocchio 0\.0\.1"):
        assert Dynamics(pandas).backend == "python"
    with pytest.raises(backend.BackendError, match=r"native backend was requested but coopdyn\._native was built"):
        Dynamics(pandas, backend="native")


def test_the_type_stub_matches_the_compiled_module() -> None:
    """coopdyn/_native.pyi names what the kernel exports, member by member, and nothing else
    (the module also carries eigenpy's registrations, which are not coopdyn's)."""
    import ast

    import coopdyn._native as native

    stub = ast.parse((Path(cd.__file__).parent / "_native.pyi").read_text(encoding="utf-8"))
    declared: dict[str, set[str] | None] = {}
    for node in stub.body:
        if isinstance(node, ast.ClassDef):
            declared[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef) and not n.name.startswith("_")}
        elif isinstance(node, ast.FunctionDef):
            declared[node.name] = None
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            declared[node.target.id] = None
    eigenpy = {"boost_type_index", "std_type_index", "seed", "sharedMemory"}
    exported = {name for name in dir(native) if not name.startswith("_")} - eigenpy
    assert set(declared) == exported
    for name, members in declared.items():
        if members is not None:
            assert members == {m for m in dir(getattr(native, name)) if not m.startswith("_")}, name


@pytest.mark.parametrize("angle", [1e-8, 1e-6, 1e-4, 1e-2, 0.5, 2.0, 3.0, np.pi - 1e-3, np.pi - 1e-6])
def test_the_compiled_lie_algebra_matches_lie_py_from_tiny_angles_to_pi(angle: float) -> None:
    """lie.hpp against lie.py through the SE(3) spring: the object turned by ``angle`` about an
    oblique axis and shifted, every output of the element (energy, deformation, wrench, power,
    S_K, S_D) on both backends — the series near 0 and the branch near π included."""
    scene = _hung_box()
    nat, py = _pair(scene)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    q = scene.q0.copy()
    placement = pin.XYZQUATToSE3(q[:7]) * pin.SE3(pin.exp3(angle * axis), np.array([0.01, -0.02, 0.005]))
    q[:7] = pin.SE3ToXYZQUAT(placement)
    v = np.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
    for a, b in zip(nat.element_states(q, v), py.element_states(q, v), strict=True):
        for x, y in zip(a, b, strict=True):
            _close(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("backend", ["python", "native"])
@pytest.mark.parametrize("fault", ["a wrong size", "not finite"])
def test_a_failed_factor_leaves_nothing_to_solve_with(pandas: cd.Scene, backend: str, fault: str) -> None:
    """After a good factor, one that fails (M of the wrong size, or NaN in it) is refused, and a
    solve then says it needs a successful factor instead of solving with the old one."""
    dynamics = cd.Dynamics(pandas, backend)
    nv, zero = pandas.nv, np.zeros(pandas.n_actuated)
    f, M, K, D = dynamics.implicit_terms(pandas.q0, pandas.v0, zero)
    dynamics.factor(M, K, D, 1e-3, zero, zero)
    bad = M[:-1, :-1] if fault == "a wrong size" else np.where(np.eye(nv) > 0, np.nan, M)
    with pytest.raises((KernelError, StepMatrixError), match=r"nv x nv|not finite"):
        dynamics.factor(bad, K, D, 1e-3, zero, zero)
    with pytest.raises(KernelError, match="successful factor"):
        dynamics.solve(np.zeros(nv), f)
