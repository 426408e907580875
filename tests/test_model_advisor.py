"""The quasi-static condensation and the model advisor (coopdyn.quasi_static, coopdyn.advise_model)."""

from __future__ import annotations

import numpy as np
import pytest

import coopdyn as cd

STEEL = {"E": 210e9, "rho": 7850.0}


def test_condensed_grasp_compliance_is_the_spring_plus_the_half_beam_cantilever() -> None:
    """Static condensation of a beam held at its ends by fixtures: each condensed spring's
    compliance is the grasp spring's plus that of a cantilever of half the beam clamped at the
    reference node: v/P = 1/k + (L/2)³/(3EIz), w/P = 1/k + (L/2)³/(3EIy), u/P = 1/k + (L/2)/(EA)."""
    section = cd.Section.rectangle(0.02, 0.01, **STEEL)
    L, k = 0.8, 1e6
    beam = cd.Beam(L, section, 6)
    K = cd.diagonal(k, 1e3)
    links = [cd.Interconnection(None, stiffness=K, grasp=[x, 0.0, 0.0]) for x in (-L / 2, L / 2)]
    scene = cd.Scene([], beam, links)
    qs = cd.quasi_static(scene)
    assert isinstance(qs.object, cd.RigidObject) and qs.object.mass == pytest.approx(beam.mass)
    for lk in qs.links:
        C = np.linalg.inv(lk.element.K)
        half = L / 2
        assert C[0, 0] == pytest.approx(1 / k + half / (section.E * section.A), rel=1e-9)
        assert C[1, 1] == pytest.approx(1 / k + half**3 / (3 * section.E * section.Iz), rel=1e-9)
        assert C[2, 2] == pytest.approx(1 / k + half**3 / (3 * section.E * section.Iy), rel=1e-9)


def test_grasps_on_one_side_of_the_reference_node_are_refused() -> None:
    beam = cd.Beam(0.8, cd.Section.circle(0.01, **STEEL), 4)
    links = [cd.Interconnection(None, stiffness=cd.diagonal(1e4, 10.0), grasp=[x, 0.0, 0.0]) for x in (-0.4, -0.2)]
    with pytest.raises(cd.SceneError, match="same side"):
        cd.quasi_static(cd.Scene([], beam, links))


def test_a_rigid_object_scene_is_its_own_quasi_static_model(pandas: cd.Scene) -> None:
    assert cd.quasi_static(pandas) is pandas


def test_advice_follows_the_bandwidth() -> None:
    """Two Pandas holding a flexible strip (first internal mode ≈ 23 Hz): at 15 Hz of bandwidth
    the drives reach its modes (elastic); at 1 Hz they do not (quasi-static: the grasps' modes
    are still within reach). The costs are measured for all three models."""
    scene = cd.scenes.held_beam(n_elements=4)
    fast = cd.advise_model(scene, bandwidth=15.0, measure=0.01)
    assert fast.recommendation == "elastic" and 15.0 < fast.object_mode_hz < 40.0
    assert [c.model for c in fast.costs] == ["rigid", "quasi-static", "elastic"]
    assert all(c.cpu_per_second > 0 for c in fast.costs)
    assert fast.costs[2].states > fast.costs[1].states
    slow = cd.advise_model(scene, bandwidth=1.0, measure=0.01)
    assert slow.recommendation == "quasi-static"
    assert "quasi-static" in str(slow) and "Hz" in str(slow)


def test_stiff_grasps_on_a_rigid_box_need_only_the_rigid_model() -> None:
    box = cd.RigidObject.box(2.0, [0.2, 0.2, 0.2], pose=[0.0, 0.0, 0.5])
    links = [cd.Interconnection(None, stiffness=cd.diagonal(1e7, 1e5), grasp=[0.0, y, 0.0]) for y in (-0.1, 0.1)]
    advice = cd.advise_model(cd.Scene([], box, links), bandwidth=15.0, measure=0.01)
    assert advice.recommendation == "rigid" and advice.grasp_mode_hz > 75.0
    assert advice.object_mode_hz is None
    with pytest.raises(cd.SimulationError, match="bandwidth"):
        cd.advise_model(cd.Scene([], box, links), bandwidth=-1.0)
    with pytest.raises(cd.SimulationError, match="bandwidth must be finite"):
        cd.advise_model(cd.Scene([], box, links), bandwidth=float("nan"))


def test_advise_model_refuses_a_rigid_scene_and_its_rk4_limit_is_rk4s() -> None:
    """The advisor derives the rigid limit itself, so a rigid scene is refused by name; its rk4
    limit on the undamped modes is where rk4's stability function leaves the unit disc."""
    from coopdyn.advisor import EXPLICIT_LIMIT
    from coopdyn.integrators import RK4

    with pytest.raises(cd.SimulationError, match="this one is rigid already"):
        cd.advise_model(cd.rigid_limit(cd.scenes.linear_book()))
    R = np.abs(RK4().stability_function(np.array([0.999, 1.001]) * EXPLICIT_LIMIT * 1j))
    assert R[0] <= 1.0 < R[1]
