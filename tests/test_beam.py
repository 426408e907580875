"""The elastic beam object (direct stiffness method): closed forms of a cantilever, the free
beam's six rigid-body modes, the scene's matrices against the assembly, energy conservation and
the compiled kernel against the Python elements."""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

import coopdyn as cd
from coopdyn.control import GravityCompensationPD
from coopdyn.errors import StepMatrixError
from coopdyn.integrators import GeneralizedAlpha, LinearlyImplicitEuler
from coopdyn.model.elements.beam import tip_stiffness

STEEL = {"E": 210e9, "rho": 7850.0}


def _clamped(beam: cd.Beam) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and lumped mass of the beam with node 0 clamped."""
    return beam.stiffness_matrix()[6:, 6:], beam.mass_matrix()[6:, 6:]


@pytest.mark.parametrize("timoshenko", [False, True])
def test_cantilever_tip_deflection_and_twist_are_the_closed_forms(timoshenko: bool) -> None:
    """A cantilever of 4 elements under a tip force P and torque T: v = PL³/(3EIz) (+ PL/(κGA)
    with shear), w = PL³/(3EIy) (+ the same), θx = TL/(GJ), u = PL/(EA) — exact for any mesh."""
    section = cd.Section.rectangle(0.02, 0.01, nu=0.3, timoshenko=timoshenko, **STEEL)
    L, P, T = 0.5, 10.0, 2.0
    K, _ = _clamped(cd.Beam(L, section, 4))
    shear = P * L / (section.shear_factor * section.G * section.A) if timoshenko else 0.0
    for dof, load, expected in (
        (0, P, P * L / (section.E * section.A)),
        (1, P, P * L**3 / (3 * section.E * section.Iz) + shear),
        (2, P, P * L**3 / (3 * section.E * section.Iy) + shear),
        (3, T, T * L / (section.G * section.J)),
    ):
        f = np.zeros(K.shape[0])
        f[-6 + dof] = load
        assert np.linalg.solve(K, f)[-6 + dof] == pytest.approx(expected, rel=1e-10)


def test_cantilever_frequencies_converge_to_the_closed_forms() -> None:
    """First bending ω = 1.8751² √(EI/(ρAL⁴)), torsion (π/2L) √(GJ/(ρJ₀)), axial (π/2L) √(E/ρ):
    the lumped-mass model converges at second order (error ratio ≈ 4 per mesh halving) and is
    within 0.5 % at 32 elements."""
    section = cd.Section.circle(0.02, nu=0.3, **STEEL)
    L = 1.0
    exact = {
        "bending": 1.8751040687**2 * np.sqrt(section.E * section.Iy / (section.rho * section.A * L**4)),
        "torsion": np.pi / (2 * L) * np.sqrt(section.G * section.J / (section.rho * (section.Iy + section.Iz))),
        "axial": np.pi / (2 * L) * np.sqrt(section.E / section.rho),
    }
    errors: dict[str, list[float]] = {k: [] for k in exact}
    for n in (8, 16, 32):
        K, M = _clamped(cd.Beam(L, section, n))
        w, modes = scipy.linalg.eigh(K, M)
        omega = np.sqrt(w)
        # kinetic energy of each mode by node coordinate, summed over nodes: axial u, bending
        # (v, θz), bending (w, θy), torsion θx
        energy = (np.diag(M)[:, None] * modes**2).reshape(n, 6, -1).sum(axis=0)
        groups = np.array([energy[0], energy[1] + energy[5], energy[2] + energy[4], energy[3]])
        kind = np.argmax(groups, axis=0)
        first = {"axial": omega[kind == 0][0], "bending": omega[kind == 1][0], "torsion": omega[kind == 3][0]}
        for k in exact:
            errors[k].append(abs(first[k] - exact[k]) / exact[k])
    for k, e in errors.items():
        assert e[-1] < 5e-3, (k, e)
        assert e[0] / e[1] == pytest.approx(4.0, rel=0.25) and e[1] / e[2] == pytest.approx(4.0, rel=0.25), (k, e)


def test_section_rotary_inertia_puts_the_first_three_bending_modes_within_half_a_percent() -> None:
    """A cantilever's first three bending modes, βL = 1.8751, 4.6941, 7.8548 (ω = β²√(EI/ρA)):
    with the nodes' rotary inertia the cross-section's own (``rotary_inertia="section"``) they
    converge at second order and are within 0.5 % at 32 elements; the slice's extra m·l²/12
    (the default) lowers them, mode 3 beyond 0.5 %. The fastest node rotation gets faster by
    at most √(1 + l²/12r²)."""
    section = cd.Section.circle(0.02, nu=0.3, **STEEL)
    L = 1.0
    beta_L = np.array([1.8751040687, 4.6940911330, 7.8547574382])
    exact = beta_L**2 * np.sqrt(section.E * section.Iy / (section.rho * section.A * L**4))
    errors: dict[str, list[np.ndarray]] = {"slice": [], "section": []}
    fastest: dict[str, float] = {}
    for rotary in errors:
        for n in (8, 16, 32):
            K, M = _clamped(cd.Beam(L, section, n, rotary_inertia=rotary))
            omega = np.sqrt(np.abs(scipy.linalg.eigvalsh(K, M)))
            errors[rotary].append(np.array([np.min(np.abs(omega - w)) / w for w in exact]))
            fastest[rotary] = float(omega.max())
    section_errors = np.array(errors["section"])
    assert np.all(section_errors[-1] < 5e-3), section_errors[-1]
    ratio = section_errors[1] / section_errors[2]  # order 2: → 4 (mode 3, less resolved, 3.2 from 16 to 32)
    assert np.all((ratio > 3.0) & (ratio < 4.5)), ratio
    assert np.all(section_errors < np.array(errors["slice"]))
    assert errors["slice"][-1][2] > 5e-3
    h, r = L / 32, np.sqrt(section.Iy / section.A)
    assert 1.0 < fastest["section"] / fastest["slice"] <= np.sqrt(1 + h**2 / (12 * r**2)) * (1 + 1e-9)


def test_rotary_inertia_is_checked_and_kept_by_scene_files() -> None:
    """A misspelt choice is refused with the choices; a scene description keeps it."""
    section = cd.Section.circle(0.02, nu=0.3, **STEEL)
    with pytest.raises(cd.SceneError, match=r"rotary_inertia must be one of \['slice', 'section'\], got 'rayleigh'"):
        cd.Beam(1.0, section, 8, rotary_inertia="rayleigh")
    beam = cd.Beam(1.0, section, 8, rotary_inertia="section")
    assert beam.describe()["rotary_inertia"] == "section"
    assert (
        cd.Beam.from_description(
            "beam", {k: v for k, v in beam.describe().items() if k not in ("type", "section")} | {"section": section}
        ).rotary_inertia
        == "section"
    )
    assert "rotary_inertia" not in cd.Beam(1.0, section, 8).describe()


@pytest.mark.parametrize("n", [1, 3, 8])
def test_a_free_beam_has_exactly_six_zero_modes(n: int) -> None:
    beam = cd.Beam(0.6, cd.Section.rectangle(0.03, 0.003, E=70e9, rho=2700.0, timoshenko=True), n)
    assert beam.zero_modes() == 6
    assert "rank K = " + str(6 * (n + 1) - 6) in beam.report()


def _floating(n: int = 4, beta: float = 0.0) -> cd.Scene:
    """A beam hung from the world by a soft spring at one end."""
    section = cd.Section.circle(0.01, E=1e8, rho=1000.0)  # a soft rod: slow modes
    beam = cd.Beam(0.4, section, n, pose=pin.SE3(pin.utils.rotate("y", 0.3), np.array([0.1, 0.0, 1.0])), damping=beta)
    K = cd.diagonal(1e-9, 1e-9)
    return cd.Scene([], beam, [cd.Interconnection(None, stiffness=K, grasp=[-0.2, 0.0, 0.0])], gravity=[0.0, 0.0, 0.0])


@pytest.mark.parametrize("backend", ["python", "native"])
def test_the_scene_matrices_are_the_direct_stiffness_assembly(backend: str) -> None:
    """At rest, the dynamics' K̃ and mass matrix over the beam's node coordinates are the
    assembled stiffness and the lumped mass (the node frames are the beam's axes)."""
    scene = _floating()
    M, K, _ = cd.Dynamics(scene, backend).stiffness(scene.q0, scene.v0)
    nodes = np.ix_(scene.object_v, scene.object_v)
    Kb = scene.object.stiffness_matrix()
    np.testing.assert_allclose(K[nodes], Kb, rtol=0, atol=1e-12 * np.abs(Kb).max())
    np.testing.assert_allclose(M[nodes], scene.object.mass_matrix(), rtol=0, atol=1e-15)


def test_energy_is_conserved_without_damping() -> None:
    """A free beam set spinning and vibrating (undamped): total energy stays constant to the
    integrator's accuracy (rk4, steps resolving the fastest mode)."""
    scene = _floating()
    rng = np.random.default_rng(5)
    v0 = 0.2 * rng.normal(size=scene.nv)
    M, K, _ = cd.Dynamics(scene).stiffness(scene.q0, v0)
    omega_max = np.sqrt(scipy.linalg.eigh(K, M, eigvals_only=True).max())
    drift = []
    for step in (0.2, 0.1):  # ω_max·dt: rk4 loses ~(ω dt)⁶/144 of the fastest mode's energy per step
        res = cd.simulate(scene, 0.1, integrator="rk4", dt=step / omega_max, save_every=100, v0=v0)
        total = res.energy().total
        drift.append(np.ptp(total) / total[0])
    assert drift[1] < 2e-6 and drift[0] / drift[1] > 20  # the integrator's, vanishing at order ≥ 5
    assert np.max(res.energy().elastic) > 1e-3 * total[0]  # it did deform


def test_beam_damping_dissipates() -> None:
    scene = _floating(beta=1e-3)
    v0 = 0.2 * np.random.default_rng(5).normal(size=scene.nv)
    res = cd.simulate(scene, 0.2, integrator="implicit_euler", dt=1e-4, save_every=100, v0=v0)
    assert np.all(np.diff(res.energy().total) < 1e-12)


@pytest.mark.parametrize(("n_elements", "damping"), [(4, 0.0), (7, 0.002)])
def test_kernel_and_python_agree_on_a_beam_held_by_two_pandas(n_elements: int, damping: float) -> None:
    """The beam elements run on the kernel's SE(3) twin with the beam's K and D: accelerations
    and implicit terms agree with the Python elements to round-off (the kernel assembles each
    element's K̃ and D̃ on its two nodes' columns only, and each grasp's on its arm's and node's:
    undamped and damped grasps)."""
    from coopdyn.dynamics import backend

    if not backend.native_available():
        pytest.skip("coopdyn._native is not built")
    scene = cd.scenes.held_beam(n_elements=n_elements, damping=damping)
    native, python = cd.Dynamics(scene, "native"), cd.Dynamics(scene, "python")
    rng = np.random.default_rng(2)
    for _ in range(3):
        q = pin.integrate(scene.model, scene.q0, 0.02 * rng.normal(size=scene.nv))
        v, tau = rng.normal(size=scene.nv), rng.normal(size=scene.n_actuated)
        a, b = native.acceleration(q, v, tau), python.acceleration(q, v, tau)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max())
        for x, y in zip(native.implicit_terms(q, v, tau), python.implicit_terms(q, v, tau), strict=True):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-9 * np.abs(y).max())


def _native_beam(n_elements: int) -> tuple[cd.Scene, cd.Dynamics, cd.Dynamics]:
    from coopdyn.dynamics import backend

    if not backend.native_available():
        pytest.skip("coopdyn._native is not built")
    scene = cd.scenes.held_beam(n_elements=n_elements, damping=0.002)
    return scene, cd.Dynamics(scene, "native"), cd.Dynamics(scene, "python")


def test_the_kernel_factors_a_beam_scene_s_step_matrix_sparse_as_the_dense_solve() -> None:
    """The step matrix of a beam held by two Pandas is sparse (the nodes hang on the world, each
    element joins two of them): the kernel factors it with a sparse Cholesky factor, and an
    implicit Euler update from it equals the Python backend's dense solve, and the kernel's own
    dense factor, to round-off."""
    scene, native, python = _native_beam(7)
    kernel = native._kernel  # type: ignore[attr-defined]
    assert kernel.sparse_step_matrix
    rng = np.random.default_rng(5)
    q = pin.integrate(scene.model, scene.q0, 0.02 * rng.normal(size=scene.nv))
    v, tau = rng.normal(size=scene.nv), rng.normal(size=scene.n_actuated)
    kp, kd = np.full(scene.n_actuated, 50.0), np.full(scene.n_actuated, 5.0)
    expected = python.implicit_euler_velocity(q, v, tau, 1e-3, kp, kd)
    sparse = native.implicit_euler_velocity(q, v, tau, 1e-3, kp, kd)
    kernel.sparse_step_matrix = False
    dense = native.implicit_euler_velocity(q, v, tau, 1e-3, kp, kd)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(sparse, expected, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(dense, expected, rtol=0, atol=1e-10 * scale)
    assert not kernel.sparse_step_matrix


def test_switching_the_factor_takes_effect_at_the_next_factorisation() -> None:
    """Setting ``sparse_step_matrix`` leaves the last factor and its solves as they were (a run in
    another thread keeps a consistent factor and solve); the next factorisation takes it."""
    scene, native, _ = _native_beam(7)
    kernel = native._kernel  # type: ignore[attr-defined]
    q, v, tau = scene.q0, np.full(scene.nv, 0.1), np.zeros(scene.n_actuated)
    kp = kd = np.zeros(scene.n_actuated)
    f, M, K, D = native.implicit_terms(q, v, tau)
    native.factor(M, K, D, 1e-3, kp, kd)
    before = native.solve(v, f)
    kernel.sparse_step_matrix = False
    kernel.sparse_step_matrix = True
    for x, y in zip(native.solve(v, f), before, strict=True):
        np.testing.assert_array_equal(x, y)


def test_the_sparse_step_matrix_says_when_it_is_not_positive_definite() -> None:
    """A gain that makes the beam scene's step matrix indefinite is a StepMatrixError from the
    sparse factor, as from the dense one."""
    scene, native, _ = _native_beam(7)
    assert native._kernel.sparse_step_matrix  # type: ignore[attr-defined]
    kp = np.full(scene.n_actuated, -1e12)
    with pytest.raises(StepMatrixError, match="not positive definite"):
        native.implicit_euler_velocity(scene.q0, scene.v0, np.zeros(scene.n_actuated), 1e-3, kp, np.zeros_like(kp))


@pytest.mark.parametrize(
    "method",
    [
        "implicit_euler",
        LinearlyImplicitEuler(jacobian_every=3),
        "trapezoid",
        GeneralizedAlpha(rho_inf=0.3),
        "ros2",
        "ros2_adaptive",
    ],
    ids=str,
)
def test_a_compiled_run_on_the_sparse_pattern_is_the_python_backends(method: object) -> None:
    """Every implicit method's compiled run on a damped beam held by two Pandas (its step matrix,
    the products with M and K̃ and the energy monitor's Δq̇ᵀD̃Δq̇ on the sparse pattern) gives the
    run of the Python backend — its own dense matrices and solves, in the Python loop — to
    round-off, with the same energy-balance warnings: none (the compiled monitor without its
    step's Δq̇ᵀD̃Δq̇ warns of a 0.6–425 J excess here)."""
    scene, native, _ = _native_beam(7)
    assert native._kernel.sparse_step_matrix  # type: ignore[attr-defined]
    v0 = 0.05 * np.random.default_rng(3).normal(size=scene.nv)
    kwargs = dict(controller=GravityCompensationPD(scene), integrator=method, dt=1e-3, v0=v0, accuracy_check="off")
    runs, said = [], []
    for loop, backend in (("python", "python"), ("compiled", "native")):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            runs.append(cd.simulate(scene, 0.01, loop=loop, backend=backend, energy_check="warn", **kwargs))  # type: ignore[arg-type]
        said.append([str(w.message) for w in caught if issubclass(w.category, cd.EnergyBalanceWarning)])
    py, co = runs
    assert (py.loop, co.loop) == ("python", "compiled")
    for name in ("q", "v", "tau"):
        a, b = getattr(py, name), getattr(co, name)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9 * max(1.0, np.abs(a).max()), err_msg=name)
    assert (co.n_steps, co.n_factor, co.n_rejected) == (py.n_steps, py.n_factor, py.n_rejected)
    assert said[1] == said[0]


@pytest.mark.parametrize("scene", ["beam", "box"])
def test_the_damping_form_is_the_quadratic_form_of_the_damping_matrix(scene: str) -> None:
    """Δq̇ᵀ D̃ Δq̇ (the energy monitor's dissipation of a linearly implicit step), summed on the
    sparse pattern of a beam scene and densely for two arms and a box, is the product with the
    D̃ the kernel returns."""
    from coopdyn.dynamics import backend

    if not backend.native_available():
        pytest.skip("coopdyn._native is not built")
    built = cd.scenes.held_beam(n_elements=7, damping=0.002) if scene == "beam" else cd.scenes.facing_arms("panda", damping=0.002)
    native = cd.Dynamics(built, "native")
    rng = np.random.default_rng(8)
    v, dv = rng.normal(size=built.nv), rng.normal(size=built.nv)
    D = native.implicit_terms(built.q0, v, np.zeros(built.n_actuated))[3]
    expected = dv @ D @ dv
    assert native._kernel.damping_form(dv) == pytest.approx(expected, rel=1e-12)  # type: ignore[attr-defined]


def test_small_scenes_keep_the_dense_step_matrix() -> None:
    """Two arms and a box (20 coordinates, a grasp reaches 13): the dense factor, as before."""
    from coopdyn.dynamics import backend

    if not backend.native_available():
        pytest.skip("coopdyn._native is not built")
    assert not cd.Dynamics(cd.scenes.facing_arms("panda"), "native")._kernel.sparse_step_matrix  # type: ignore[attr-defined]


def test_beam_element_refuses_what_is_not_a_beam() -> None:
    with pytest.raises(cd.SceneError, match="BeamSegment"):
        cd.Interconnection("a", stiffness=1e4, element="beam").law()
    with pytest.raises(cd.SceneError, match="length"):
        cd.Beam(-1.0, cd.Section.circle(0.01, **STEEL))
    with pytest.raises(cd.SceneError, match="E"):
        cd.Section.circle(0.01, E=-1.0, rho=1.0)
    assert tip_stiffness(cd.Section.circle(0.01, **STEEL), 1.0).shape == (6, 6)
    with pytest.raises(cd.SceneError, match="n_elements must be an integer"):
        cd.Beam(1.0, cd.Section.circle(0.01, **STEEL), 0)
    with pytest.raises(cd.SceneError, match="more than 500"):
        cd.Beam(1.0, cd.Section.circle(0.01, **STEEL), 10**7)
    with pytest.raises(cd.SceneError, match="E must be finite"):
        cd.Section(np.inf, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    with pytest.raises(cd.SceneError, match="Poisson"):
        cd.Section.rectangle(0.01, 0.01, E=1e9, rho=1.0, nu=0.7)
