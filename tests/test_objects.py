"""The object protocol (coopdyn/model/objects.py): a new elastic object, defined here and nowhere
else in the package, builds into a scene, runs (compiled), oscillates at its closed-form
frequencies, describes itself as data and builds back once registered; and no module outside
the object modules asks which kind of object a scene holds."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin
import pytest

import coopdyn as cd
from coopdyn import _validate
from coopdyn.model import object_types
from coopdyn.model.description import build, describe
from coopdyn.model.elements import SE3Spring
from coopdyn.model.fields import Field, pose_data
from coopdyn.model.objects import InternalLink, Placement, SceneObject, Shape

PACKAGE = Path(cd.__file__).parent


@dataclass(frozen=True, eq=False)
class Dumbbell(SceneObject):
    """Two point-like masses m [kg] a distance ``gap`` [m] apart along x, joined by an internal
    spring of axial stiffness k [N/m] (stiff in the other directions): the smallest elastic object."""

    mass_each: float
    k: float
    gap: float = 0.2
    pose: Any = None
    name: str = "dumbbell"

    description_types: ClassVar[dict[str, dict[str, Field]]] = {
        "dumbbell": {
            "mass_each": Field("number", "each mass [kg]", True),
            "k": Field("number", "the axial stiffness between them [N/m]", True),
            "gap": Field("number", "their distance [m]"),
            "pose": Field("pose", "pose of the first mass [m]"),
            "name": Field("string", "prefix of its joints"),
        }
    }

    @property
    def joint_label(self) -> str:
        return "two free masses"

    @classmethod
    def from_description(cls, type_name: str, values: dict[str, Any]) -> Dumbbell:
        return cls(**values)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "dumbbell", "mass_each": self.mass_each, "k": self.k, "gap": self.gap, "name": self.name}
        if self.pose is not None:
            out["pose"] = pose_data(self.pose)
        return out

    def mass_and_com(self) -> tuple[float, np.ndarray]:
        return 2 * self.mass_each, np.array([self.gap / 2, 0.0, 0.0])

    def spatial_inertia(self) -> pin.Inertia:
        m, c = self.mass_and_com()
        return pin.Inertia(
            m, c, np.diag([1e-4, 1e-4 + self.mass_each * self.gap**2 / 2, 1e-4 + self.mass_each * self.gap**2 / 2])
        )

    def _body(self) -> pin.Inertia:
        return pin.Inertia(self.mass_each, np.zeros(3), 1e-4 * np.eye(3))

    def add_to(self, model: pin.Model) -> Placement:
        oMa = pin.SE3.Identity() if self.pose is None else _validate.se3(self.pose, "dumbbell pose")
        joints, q = [], []
        for i, x in enumerate((0.0, self.gap)):
            j = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), f"{self.name}/mass{i}")
            model.appendBodyToJoint(j, self._body(), pin.SE3.Identity())
            model.addBodyFrame(f"{self.name}/mass{i}", j, pin.SE3.Identity(), 0)
            joints.append(j)
            q.append(pin.SE3ToXYZQUAT(oMa * pin.SE3(np.eye(3), np.array([x, 0.0, 0.0]))))
        model.addFrame(pin.Frame(self.name, joints[0], pin.SE3.Identity(), pin.FrameType.OP_FRAME))
        return Placement(joints[0], tuple(joints), np.concatenate(q))

    def grasp_joint(self, placement: Placement, o_M_G: pin.SE3) -> tuple[int, pin.SE3]:
        k = int(o_M_G.translation[0] > self.gap / 2)
        return placement.joints[k], pin.SE3(np.eye(3), np.array([-self.gap * k, 0.0, 0.0])) * o_M_G

    def internal_links(self, model: pin.Model, placement: Placement) -> list[InternalLink]:
        t = model.addFrame(
            pin.Frame(
                f"{self.name}/T", placement.joints[0], pin.SE3(np.eye(3), np.array([self.gap, 0, 0])), pin.FrameType.OP_FRAME
            )
        )
        g = model.addFrame(pin.Frame(f"{self.name}/G", placement.joints[1], pin.SE3.Identity(), pin.FrameType.OP_FRAME))
        spring = SE3Spring(np.r_[self.k, 1e3 * self.k, 1e3 * self.k, 10.0, 10.0, 10.0], name=f"{self.name} spring")
        return [InternalLink(f"{self.name}/spring", int(t), int(g), spring, "se3")]

    def shapes(self, model: pin.Model) -> list[Shape]:
        out = []
        for i in range(2):
            joint, frame = model.getJointId(f"{self.name}/mass{i}"), model.getFrameId(f"{self.name}/mass{i}")
            out.append(Shape(f"{self.name}/box{i}", joint, frame, pin.SE3.Identity(), (0.04, 0.04, 0.04)))
        return out

    def lowest_frequency(self) -> float:
        return float(np.sqrt(2 * self.k / self.mass_each) / (2 * np.pi))


def _held_dumbbell(m: float = 0.5, k: float = 2e3, k_fix: float = 5e3) -> tuple[cd.Scene, Dumbbell]:
    """The dumbbell with its first mass held by a world fixture (axial k_fix, stiff otherwise), no gravity."""
    obj = Dumbbell(m, k, pose=[0.0, 0.0, 1.0])
    fixture = cd.Interconnection(None, stiffness=np.r_[k_fix, 1e3 * k_fix, 1e3 * k_fix, 10.0, 10.0, 10.0], grasp=[0.0, 0.0, 0.0])
    return cd.Scene([], obj, [fixture], gravity=[0.0, 0.0, 0.0]), obj


def test_a_new_elastic_object_runs_at_its_closed_form_frequencies() -> None:
    """Fixture k_f on mass A, spring k between A and B, masses m: ω² are the eigenvalues of
    [[k_f + k, −k], [−k, k]] / m. Stretch B by 1 mm and run compiled (trapezoid at 0.1 ms): the
    motion of B along x is the two modes' sum, and the scene and the run never ask its kind."""
    m, k, k_fix = 0.5, 2e3, 5e3
    scene, _ = _held_dumbbell(m, k, k_fix)
    assert scene.elements[-1].name == "dumbbell/spring" and "two free masses" in str(scene)
    w2, modes = np.linalg.eigh(np.array([[k_fix + k, -k], [-k, k]]) / m)
    omega = np.sqrt(w2)
    q0 = scene.q0.copy()
    x0 = np.array([0.0, 1e-3])  # B stretched by 1 mm
    q0[7] += x0[1]  # B's x (second free flyer: q[7:14])
    res = cd.simulate(scene, 0.2, q0=q0, integrator="trapezoid", dt=1e-4, accuracy_check="off", progress=False)
    assert res.loop == "compiled"
    a = modes.T @ x0  # modal amplitudes, released at rest
    xB = (modes[1] * a) @ np.cos(np.outer(omega, res.t))
    np.testing.assert_allclose(res.q[:, 7] - scene.q0[7], xB, atol=2e-3 * 1e-3)  # 0.2 % of the stretch


def test_a_registered_object_describes_itself_and_builds_back_and_is_drawn(monkeypatch: pytest.MonkeyPatch) -> None:
    """One registry line (object_types.OBJECTS) makes the dumbbell a description type: described
    as data, built back to the same scene; the viewer draws its two boxes; the advisor sees its
    own elastic mode."""
    monkeypatch.setattr(object_types, "OBJECTS", (*object_types.OBJECTS, Dumbbell))
    scene, obj = _held_dumbbell()
    doc = describe(scene)
    assert doc["object"]["type"] == "dumbbell"
    back = build(doc)
    assert isinstance(back.object, Dumbbell) and back.object.k == obj.k and back.nv == scene.nv == 12
    np.testing.assert_array_equal(back.q0, scene.q0)
    from coopdyn.viz.viewer import visual_model

    assert {g.name for g in visual_model(scene).geometryObjects} == {"dumbbell/box0", "dumbbell/box1"}
    assert obj.lowest_frequency() == pytest.approx(np.sqrt(2 * 2e3 / 0.5) / (2 * np.pi))


def test_no_module_outside_the_object_modules_asks_which_object_a_scene_holds() -> None:
    """isinstance(..., Beam) or isinstance(..., RigidObject) only in the object modules: every
    other module goes through the protocol."""
    allowed = {"model/body.py", "model/beam.py", "model/objects.py", "model/object_types.py"}
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel in allowed:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "isinstance" and len(node.args) == 2:
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                names |= {n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)}
                if names & {"Beam", "RigidObject"}:
                    found.append(f"{rel}:{node.lineno}")
    assert found == []


def _example(cls: type[SceneObject]) -> SceneObject:
    """An instance of each registered object class (a new one must add its own here)."""
    if cls is cd.RigidObject:
        return cd.RigidObject.box(2.0, (0.2, 0.1, 0.1), pose=[0.0, 0.0, 1.0])
    if cls is cd.Beam:
        return cd.Beam(0.6, cd.Section.rectangle(0.03, 0.01, E=70e9, rho=2700.0), n_elements=4, pose=[0.0, 0.0, 1.0])
    raise ValueError(f"no example of the object {cls.__name__}: add one here (a new object is tested as itself)")


@pytest.mark.parametrize("cls", object_types.OBJECTS, ids=lambda c: c.__name__)
def test_every_registered_object_builds_describes_and_builds_back(cls: type[SceneObject]) -> None:
    """Held by a world fixture: the scene builds, describes itself as data and builds back to the
    same model and start; its mass is the same through both of the protocol's mass methods; the
    viewer has something to draw."""
    obj = _example(cls)
    scene = cd.Scene([], obj, [cd.Interconnection(None, stiffness=1e4 * np.ones(6))])
    back = build(describe(scene))
    assert type(back.object) is cls and back.nv == scene.nv
    np.testing.assert_array_equal(back.q0, scene.q0)
    assert describe(back) == describe(scene)
    mass, com = obj.mass_and_com()
    inertia = obj.spatial_inertia()
    assert inertia.mass == pytest.approx(mass, rel=1e-12)
    np.testing.assert_allclose(inertia.lever, com, atol=1e-12)
    assert obj.shapes(scene.model)
