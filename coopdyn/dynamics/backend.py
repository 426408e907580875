"""Which implementation runs the dynamics' hot path.

* ``"native"`` — the compiled kernel ``coopdyn._native`` (C++ on Pinocchio's C++ API, built when
  coopdyn is installed): the right-hand side, the implicit-method terms and the implicit Euler
  solve in one call each.
* ``"python"`` — the same equations with Pinocchio's Python bindings (:mod:`coopdyn.dynamics.dynamics`);
  the reference the kernel is tested against, and the fallback when the kernel is missing.

The default (``"auto"``) takes the kernel when it imports and was built against the installed
Pinocchio, else Python with a one-time warning saying why. An interconnection element without
a C++ twin does not send the scene to Python: the kernel calls that element's Python
``evaluate`` (one warning), and everything else stays compiled. Choose per object with
``Dynamics(scene, backend=...)``, or for the process with the environment variable
``COOPDYN_BACKEND=native|python|auto``.
"""

from __future__ import annotations

import importlib
import os
from functools import cache
from types import ModuleType

import pinocchio as pin

from .. import _progress, _validate
from ..errors import BackendError, NativeBackendWarning
from ..model.scene import Scene

BACKENDS = ("auto", "native", "python")


@cache
def _load() -> tuple[ModuleType | None, str]:
    """(the kernel module or None, why not)."""
    try:
        _native = importlib.import_module("coopdyn._native")  # the compiled leaf (imports only coopdyn.errors)
    except ImportError as exc:
        return None, f"coopdyn._native did not import ({exc}); reinstall coopdyn with a C++17 compiler available"
    built = getattr(_native, "PINOCCHIO_VERSION", "?")
    if built != pin.__version__:
        return None, (
            f"coopdyn._native was built against Pinocchio {built} but Pinocchio {pin.__version__} is installed "
            "(their C++ ABIs need not match); reinstall coopdyn to rebuild it"
        )
    return _native, ""


def native_available() -> bool:
    """True when the compiled kernel can be used."""
    return _load()[0] is not None


def resolve(backend: str | None = None, scene: Scene | None = None) -> str:
    """The backend that runs for a request: ``None`` reads ``COOPDYN_BACKEND`` (default ``"auto"``).

    With a ``scene``, an interconnection element without a C++ twin (see
    :data:`coopdyn.model.elements.ELEMENTS`) sends ``"auto"`` to Python with one warning.

    Raises:
        BackendError: for an unknown name, or ``"native"`` when the kernel is unavailable or
            lacks an element of the scene.
    """
    if scene is not None and not isinstance(scene, Scene):
        raise BackendError(f"dynamics need a coopdyn.Scene, got {type(scene).__name__}")
    name = os.environ.get("COOPDYN_BACKEND", "auto") if backend is None else backend
    if not isinstance(name, str) or name not in BACKENDS:
        raise BackendError(f"backend must be one of {', '.join(BACKENDS)}, got {_validate._short(name)}")
    module, why = _load()
    if name == "python":
        return "python"
    if module is None:
        if name == "native":
            raise BackendError(f"the native backend was requested but {why}")
        _warn_once(why)
        return "python"
    if scene is not None and scene.constraints:
        if name == "native":  # the rigid limit: Pinocchio's constraintDynamics, called from Python
            raise BackendError(
                "a scene with rigid grasps runs on the Python dynamics (constraints); use backend='python' or 'auto'"
            )
        return "python"
    if scene is not None:
        known = set(getattr(module, "ELEMENTS", ()))
        lost = sorted({lk.element.kind for lk in scene.elements if lk.native is not None and lk.native not in known})
        if lost:  # registered with a twin this build of the kernel lacks
            why = f"the kernel lacks the C++ twin of the interconnection element(s) {lost}"
            if name == "native":
                raise BackendError(f"the native backend was requested but {why}; use backend='python'")
            _warn_once(f"{why}; this scene runs on the Python dynamics")
            return "python"
        python_only = sorted({lk.element.kind for lk in scene.elements if lk.native is None})
        if python_only:
            _warn_python_elements(tuple(python_only))
    return "native"


def kernel_module() -> ModuleType:
    """The compiled kernel module (only after :func:`resolve` returned ``"native"``)."""
    module, why = _load()
    if module is None:
        raise BackendError(why)
    return module


@cache
def _warn_python_elements(kinds: tuple[str, ...]) -> None:
    _progress.warn(
        f"the interconnection element(s) {list(kinds)} have no C++ twin: the compiled kernel calls their Python "
        "evaluate once per evaluation (the rest of the scene and the step loop stay compiled)",
        NativeBackendWarning,
        stacklevel=None,
    )


@cache
def _warn_once(why: str) -> None:
    _progress.warn(f"using the Python dynamics (several times slower): {why}", NativeBackendWarning, stacklevel=None)
