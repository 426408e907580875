"""The package's structure: no import cycle anywhere, inside folders too (the layer contract in
pyproject.toml sees only the layers between them)."""

from __future__ import annotations


def test_no_module_imports_one_that_imports_it_back() -> None:
    import grimp

    graph = grimp.build_graph("coopdyn")
    cycles = sorted(
        {
            tuple(sorted((module, imported)))
            for module in graph.modules
            for imported in graph.find_modules_directly_imported_by(module)
            if graph.chain_exists(importer=imported, imported=module)
        }
    )
    assert cycles == []


def test_every_compiled_method_family_is_one_registry_entry_on_each_side() -> None:
    """The Python registry (INTEGRATORS) and the C++ one (src/native/methods/methods.hpp, exported
    as _native.METHODS) name the same families: every built-in's compiled_spec() names a family
    the kernel registered, and every registered family has a Python class that uses it."""
    from coopdyn import _native
    from coopdyn.integrators import INTEGRATORS

    used = {}
    for name, cls in INTEGRATORS.items():
        if "compiled_spec" in cls.__dict__:  # the built-ins with a compiled twin (scipy has none)
            used[name] = cls().compiled_spec().name
    assert set(used.values()) == set(_native.METHODS), used
    assert set(INTEGRATORS) - set(used) == {"scipy"}


def test_a_method_family_the_kernel_does_not_know_is_refused_by_name() -> None:
    """The compiled loop's registry refuses an unknown family, and each family checks its own
    settings when it is built (a Butcher tableau that is not explicit, a bad generalized-α)."""
    import pytest

    import coopdyn as cd
    from coopdyn.integrators import RK4, GeneralizedAlpha

    scene = cd.scenes.linear_book()
    kernel, config = _compiled_config(scene, RK4())
    with pytest.raises(ValueError, match="unknown method rk5"):
        _native_loop(kernel, {**config, "method": "rk5"})
    with pytest.raises(ValueError, match="the tableau must be explicit"):
        _native_loop(kernel, {**config, "A": [[0.0, 1.0], [0.5, 0.0]], "b": [0.5, 0.5], "c": [0.0, 0.5]})
    _, alpha = _compiled_config(scene, GeneralizedAlpha())
    with pytest.raises(ValueError, match="generalized-alpha needs"):
        _native_loop(kernel, {**alpha, "alpha": [1.0, 0.5, 0.5, 0.25]})


def _compiled_config(scene: object, method: object, controller: object = None) -> tuple[object, dict[str, object]]:
    """The kernel of ``scene`` and the compiled loop's settings for a 10-step run of ``method``."""
    import numpy as np

    import coopdyn as cd
    from coopdyn import compiled
    from coopdyn.closed_loop import System

    dyn = cd.Dynamics(scene, "native")  # type: ignore[arg-type]
    base = dict(q0=scene.q0, v0=np.zeros(scene.nv), dt=1e-3, t_final=0.01, n_steps=10, save_every=1, max_speed=1e4)  # type: ignore[attr-defined]
    config = compiled.plan(scene, System(dyn, controller), method, energy_check="off", **base).config  # type: ignore[arg-type]
    assert config is not None
    return dyn._kernel, config  # type: ignore[attr-defined]


def _native_loop(kernel: object, config: dict[str, object]) -> object:
    from coopdyn import _native

    return _native.make_loop(kernel, config)


def test_every_compiled_controller_is_one_registry_entry_on_each_side() -> None:
    """The built-in controllers' compiled_spec() kinds (and "none" for no controller) are the
    kinds the kernel's controller registry (src/native/controllers/) holds, no more, no less."""
    import numpy as np

    import coopdyn as cd
    from coopdyn import _native
    from coopdyn.control import ComputedTorque, GravityCompensationPD, MotorPD, TorqueSequence
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.scenes import object_start

    pandas = cd.scenes.facing_arms("panda", stiffness=1e4)
    elastic = cd.Scene(
        [a.replace(elasticity=cd.JointElasticity(1e4, 0.5)) for a in pandas.arm_specs],
        pandas.object,
        pandas.interconnection_specs,
    )
    book = cd.scenes.linear_book()
    built_in = [
        (GravityCompensationPD(pandas), pandas),
        (MotorPD(elastic), elastic),
        (TorqueSequence(pandas, np.zeros((2, pandas.n_actuated)), 0.01), pandas),
        (ComputedTorque(pandas), pandas),
        (ObjectImpedance(pandas), pandas),
        (ObjectImpedance(pandas, GripLiftOscillate(start=object_start(pandas))), pandas),
        (cd.scenes.drives_controller(*cd.scenes.book_task()), book),
    ]
    kinds = {"none", "python"} | {ctrl.compiled_spec(scene).name for ctrl, scene in built_in}  # python: any other callable
    assert kinds == set(_native.CONTROLLERS)


def test_every_setting_crosses_to_cpp_by_name_and_a_setting_it_does_not_read_is_refused() -> None:
    """The round trip of the parameter hand-over: every built-in method's and controller's
    compiled config is read field by field (the compiled-loop tests would fail otherwise), and a
    field the kernel does not read — misspelled, or added in Python only — is refused by name,
    in the loop's settings, a controller's and a nested task's."""
    import numpy as np
    import pytest

    import coopdyn as cd
    from coopdyn import _native
    from coopdyn.cooperative import GripLiftOscillate, ObjectImpedance
    from coopdyn.integrators import Trapezoid
    from coopdyn.scenes import object_start

    scene = cd.scenes.facing_arms("panda", stiffness=1e4)
    kernel, config = _compiled_config(scene, Trapezoid(), ObjectImpedance(scene, GripLiftOscillate(start=object_start(scene))))
    _native.make_loop(kernel, config)  # as written: every field read
    with pytest.raises(ValueError, match=r"compiled loop: the kernel does not read the setting\(s\) gama"):
        _native.make_loop(kernel, {**config, "gama": 0.5})
    controller = config["controller"]
    with pytest.raises(ValueError, match=r"controller 'object_impedance': the kernel does not read the setting\(s\) Kq"):
        _native.make_loop(kernel, {**config, "controller": {**controller, "Kq": np.ones(3)}})
    with pytest.raises(ValueError, match=r"controller 'object_impedance': task: the kernel does not read the setting\(s\) lft"):
        _native.make_loop(kernel, {**config, "controller": {**controller, "task": {**controller["task"], "lft": 0.1}}})
    with pytest.raises(ValueError, match="controller 'object_impedance': missing setting null_k"):
        _native.make_loop(kernel, {**config, "controller": {k: v for k, v in controller.items() if k != "null_k"}})


def test_a_compiled_spec_is_a_typed_spec_and_a_dict_is_refused_by_name() -> None:
    """compiled_spec returns a dataclass of coopdyn._spec (its fields are what C++ reads, checked
    both ways by make_loop); a user's class returning a plain dict is told so."""
    import dataclasses

    import numpy as np
    import pytest

    import coopdyn as cd
    from coopdyn import _spec
    from coopdyn.control import GravityCompensationPD

    spec = GravityCompensationPD(cd.scenes.linear_book()).compiled_spec(cd.scenes.linear_book())
    assert spec is None  # another scene: not this controller's
    book = cd.scenes.linear_book()
    spec = GravityCompensationPD(book).compiled_spec(book)
    assert isinstance(spec, _spec.GravityPDSpec) and dataclasses.is_dataclass(spec)
    assert set(spec.fields()) == {"kind", "kp", "kd", "q_des"}

    class DictSpec(GravityCompensationPD):
        def compiled_spec(self, scene: cd.Scene) -> dict[str, object]:  # type: ignore[override]
            return {"kind": "gravity_pd", "kp": self.kp, "kd": self.kd, "q_des": self.q_des}

    with pytest.raises(cd.errors.ControllerError, match=r"DictSpec\.compiled_spec returned dict; it must return a typed spec"):
        cd.simulate(book, 0.01, controller=DictSpec(book), integrator="rk4", dt=1e-3, loop="compiled", v0=np.zeros(book.nv))


def test_an_integrator_whose_compiled_spec_fails_is_a_simulation_error_not_a_controller_error() -> None:
    import pytest

    import coopdyn as cd
    from coopdyn.integrators import RK4

    class Broken(RK4):
        def compiled_spec(self) -> dict[str, object]:  # type: ignore[override]
            return {"method": "rk"}

    with pytest.raises(cd.SimulationError, match=r"Broken\.compiled_spec returned dict") as info:
        cd.simulate(cd.scenes.linear_book(), 0.01, integrator=Broken(), dt=1e-3, loop="compiled")
    assert not isinstance(info.value, cd.errors.ControllerError)


def test_the_compiled_loop_refuses_an_inconsistent_tableau_as_python_does() -> None:
    """A tableau whose rows do not sum to c (or weights to 1) is refused by the C++ reader too."""
    import pytest

    import coopdyn as cd
    from coopdyn import _native
    from coopdyn.integrators import RK4

    kernel, config = _compiled_config(cd.scenes.linear_book(), RK4())
    with pytest.raises(ValueError, match=r"inconsistent tableau \(a row of A does not sum to c\)"):
        _native.make_loop(kernel, {**config, "c": [0.0, 0.4, 0.5, 1.0]})
    with pytest.raises(ValueError, match=r"inconsistent tableau \(weights do not sum to 1\)"):
        _native.make_loop(kernel, {**config, "b": [0.2, 0.3, 0.3, 0.1]})


def test_a_setting_of_the_wrong_type_or_an_unknown_name_is_refused_naming_it() -> None:
    """The C++ readers name the field whose value has the wrong type, and an unknown method,
    controller or element comes with the registered names."""
    import numpy as np
    import pytest

    import coopdyn as cd
    from coopdyn import _native
    from coopdyn.integrators import RK4

    with pytest.raises(ValueError, match="element 'se3': parameter K must be a matrix of numbers"):
        _native.evaluate_element("se3", {"K": "stiff", "D": np.eye(6)}, np.eye(4), np.zeros(6), False)
    with pytest.raises(ValueError, match=r"no element 'toy' \(registered: ball, hardening, python, se3\)"):
        _native.evaluate_element("toy", {}, np.eye(4), np.zeros(6), False)
    kernel, config = _compiled_config(cd.scenes.linear_book(), RK4())
    with pytest.raises(ValueError, match="compiled loop: setting dt has the wrong type"):
        _native.make_loop(kernel, {**config, "dt": "fast"})
    with pytest.raises(ValueError, match=r"unknown method rk5 \(registered: exponential, generalized_alpha, implicit_euler, rk,"):
        _native.make_loop(kernel, {**config, "method": "rk5"})
    with pytest.raises(ValueError, match=r"unknown controller kind pid \(registered: computed_torque, drives, gravity_pd,"):
        _native.make_loop(kernel, {**config, "controller": {"kind": "pid"}})
