"""The compiled kernel (``coopdyn._native``, src/native/) behind the :class:`Dynamics` interface.

Every call into the kernel goes through this class, which turns whatever the kernel raises into
a :class:`coopdyn.CoopdynError` subclass: :class:`~coopdyn.errors.StepMatrixError` (translated
in C++) and :class:`~coopdyn.errors.KernelError` for refused arguments.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from ..errors import CoopdynError, KernelError
from ..model.elements import ElementEval
from ..model.scene import Scene
from . import backend as _backend
from .derivatives import Derivatives
from .dynamics import KINDS, Dynamics, Readouts, step_coefficients


def _kernel_error(exc: Exception, what: str) -> KernelError:
    return KernelError(f"the compiled kernel refused {what}: {exc}")


class NativeDynamics(Dynamics):
    """The scene dynamics on the compiled kernel; the same results as :class:`PythonDynamics` to round-off."""

    backend = "native"

    def __init__(self, scene: Scene, backend: str | None = None) -> None:
        super().__init__(scene, backend)
        #: what a Python-only element raised inside the kernel (re-raised once the kernel returns)
        self.python_error: BaseException | None = None
        links = [
            (lk.native, lk.tip_frame, lk.grasp_frame, lk.element.native_parameters())
            if lk.native is not None
            else ("python", lk.tip_frame, lk.grasp_frame, {"element": lk.element, "evaluate": _ElementCallback(lk.element, self)})
            for lk in scene.elements
        ]
        actuated = np.asarray(scene.actuated, dtype=np.int32)
        kernel = _backend.kernel_module().Kernel
        springs = scene.joint_springs.native_table()
        self._kernel = self._call(
            "the scene",
            kernel,
            self.model,
            self.data,
            links,
            self._damping,
            actuated,
            scene.object_frame,
            springs,
            scene.link_model,
        )

    def _call(self, what: str, method: Any, *args: Any) -> Any:
        """``method(*args)`` on the kernel, what it raises turned into a :class:`CoopdynError`
        (ValueError for sizes, Boost.Python.ArgumentError for types, RuntimeError) — or, when a
        Python-only element raised inside it, that element's own exception (a Ctrl-C too)."""
        try:
            return method(*args)
        except CoopdynError:
            raise
        except Exception as exc:
            self.reraise_python_error()
            raise _kernel_error(exc, what) from exc

    def reraise_python_error(self) -> None:
        """Raise what a Python-only element raised inside the kernel, if it did (and forget it)."""
        error, self.python_error = self.python_error, None
        if error is not None:
            raise error

    @property
    def last_dissipation(self) -> float:
        return float(self._kernel.last_dissipation)

    def rotation_alarm(self) -> tuple[int, float] | None:
        link = self._kernel.rotation_alarm
        return None if link < 0 else (int(link), float(self._kernel.rotation_alarm_angle))

    def clear_rotation_alarm(self) -> None:
        self._kernel.clear_rotation_alarm()

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> np.ndarray:
        return self._call("acceleration(q, v, tau, object_wrench)", self._kernel.acceleration, q, v, tau, object_wrench)

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self._call("implicit_terms(q, v, tau, object_wrench)", self._kernel.implicit_terms, q, v, tau, object_wrench)

    def factor(
        self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, kp: np.ndarray, kd: np.ndarray, gh2: float | None = None
    ) -> None:
        gh, gh2 = step_coefficients(gh, gh2)
        self._call("factor(M, K, D, gh, kp, kd, gh2)", self._kernel.factor, M, K, D, gh, kp, kd, gh2)

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._call("solve(f_q, Mf_v)", self._kernel.solve, f_q, Mf_v)

    def implicit_euler_velocity(
        self,
        q: np.ndarray,
        v: np.ndarray,
        tau: np.ndarray,
        h: float,
        kp: np.ndarray,
        kd: np.ndarray,
        object_wrench: np.ndarray | None = None,
    ) -> np.ndarray:
        return self._call(
            "implicit_euler_velocity(q, v, tau, h, kp, kd, object_wrench)",
            self._kernel.implicit_euler_velocity,
            q,
            v,
            tau,
            h,
            kp,
            kd,
            object_wrench,
        )

    def generalized_spring_force(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return self._call("spring_force(q, v)", self._kernel.spring_force, q, v)

    def compiled_loop(self, config: dict[str, object]) -> object:
        """A compiled run of this scene (coopdyn.compiled writes ``config``); the kernel object
        it steps stays alive with it."""
        return self._call("the compiled loop's configuration", _backend.kernel_module().make_loop, self._kernel, config)

    def _derivatives(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None) -> Derivatives:
        raw = self._call("derivatives(q, v, tau, object_wrench)", self._kernel.derivatives, q, v, tau, object_wrench)
        a, da_dq, da_dv, da_dtau, W, dW_dq, dW_dv, exact = raw
        nv, L = self.scene.nv, len(self.scene.elements)  # reshape all: eigenpy returns a 1-row or 1-column matrix as a vector
        return Derivatives(
            a,
            da_dq.reshape(nv, nv),
            da_dv.reshape(nv, nv),
            da_dtau.reshape(nv, self.scene.n_actuated),
            W.reshape(L, 6),
            dW_dq.reshape(L, 6, nv),
            dW_dv.reshape(L, 6, nv),
            bool(exact),
        )

    def element_states(self, q: np.ndarray, v: np.ndarray) -> list[ElementEval]:
        raw = self._call("element_states(q, v)", self._kernel.element_states, q, v)
        out = []
        for (energy, e, f, power, S_K, S_D, theta), lk in zip(raw, self.scene.elements, strict=True):
            out.append(ElementEval(energy, e[: lk.element.deformation_size], f, power, S_K, S_D, theta))
        return out

    def _elastic(self, q: np.ndarray) -> np.ndarray:
        return self._call("elastic_energies(q)", self._kernel.elastic_energies, q)

    def readouts(self, Q: np.ndarray, V: np.ndarray, TAU: np.ndarray | None = None) -> Readouts:
        Q, V = np.asarray(Q, dtype=float), np.asarray(V, dtype=float)
        n = len(Q)
        if n == 1:  # eigenpy maps a writeable (1, nq) array with the row stride as the column stride
            Q, V = np.repeat(Q, 2, axis=0), np.repeat(V, 2, axis=0)  # (reading past its end): send two rows
        E, U, P, WG, WT, PG, PT, PO, KP = self._call("readouts(Q, V)", self._kernel.readouts, Q, V)
        m, L = len(Q), len(self.scene.elements)  # reshape all: eigenpy returns an (n, 1) matrix as a vector
        return Readouts(
            E.reshape(m, L, 6)[:n],
            U.reshape(m, L)[:n],
            P.reshape(m, L)[:n],
            WG.reshape(m, L, 6)[:n],
            WT.reshape(m, L, 6)[:n],
            PG.reshape(m, L, 3)[:n],
            PT.reshape(m, L, 3)[:n],
            PO.reshape(m, 3)[:n],
            KP.reshape(m, 2)[:n, 0].copy(),
            KP.reshape(m, 2)[:n, 1].copy(),
        )


KINDS["native"] = NativeDynamics

__all__ = ["NativeDynamics"]


class _ElementCallback:
    """A Python-only element as the kernel calls it (src/native/elements/python_element.hpp): its
    ``evaluate`` (calling the callback), ``tangent`` and ``matrix_tangent``, each returning the
    element's result, or None after keeping what it raised in the dynamics'
    :attr:`NativeDynamics.python_error`, for Python to re-raise once the kernel has returned."""

    def __init__(self, element: Any, dynamics: NativeDynamics) -> None:
        self.element = element
        self.dynamics = weakref.ref(dynamics)

    def __call__(self, T_M_G: Any, xi: np.ndarray, jacobians: bool) -> Any:
        return self._kept(self.element.evaluate, T_M_G, xi, jacobians)

    def tangent(self, T_M_G: Any, xi: np.ndarray) -> Any:
        return self._kept(self.element.tangent, T_M_G, xi)

    def matrix_tangent(self, T_M_G: Any, xi: np.ndarray, w_K: np.ndarray, w_D: np.ndarray) -> Any:
        return self._kept(self.element.matrix_tangent, T_M_G, xi, w_K, w_D)

    def _kept(self, method: Any, *args: Any) -> Any:
        try:
            return method(*args)
        except BaseException as exc:  # Ctrl-C and coopdyn's own errors as they are; the rest named
            if not isinstance(exc, KeyboardInterrupt | CoopdynError):
                named = KernelError(f"the Python element {type(self.element).__name__} raised {type(exc).__name__}: {exc}")
                named.__cause__ = exc
                exc = named
            dynamics = self.dynamics()
            if dynamics is not None and dynamics.python_error is None:
                dynamics.python_error = exc
            return None
