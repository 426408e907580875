"""The compiled kernel (``coopdyn._native``, src/native/) behind the :class:`Dynamics` interface.

Every call into the kernel goes through this class, which turns whatever the kernel raises into
a :class:`coopdyn.CoopdynError` subclass: :class:`~coopdyn.errors.StepMatrixError` (translated
in C++) and :class:`~coopdyn.errors.KernelError` for refused arguments.
"""

from __future__ import annotations

import numpy as np

from ..errors import CoopdynError, KernelError
from ..model.elements import ElementEval
from ..model.scene import Scene
from . import backend as _backend
from .dynamics import Dynamics, Readouts


def _kernel_error(exc: Exception, what: str) -> KernelError:
    return KernelError(f"the compiled kernel refused {what}: {exc}")


class NativeDynamics(Dynamics):
    """The scene dynamics on the compiled kernel; the same results as :class:`PythonDynamics` to round-off."""

    backend = "native"

    def __init__(self, scene: Scene, backend: str | None = None) -> None:
        super().__init__(scene, backend)
        links = [(lk.native, lk.tip_frame, lk.grasp_frame, tuple(lk.element.native_parameters())) for lk in scene.links]
        try:
            self._kernel = _backend.kernel_module().Kernel(
                self.model, self.data, links, self._damping, np.asarray(scene.actuated, dtype=np.int32), scene.object_frame
            )
        except CoopdynError:
            raise
        except Exception as exc:
            raise _kernel_error(exc, "the scene") from exc

    @property
    def last_dissipation(self) -> float:
        return float(self._kernel.last_dissipation)

    def rotation_alarm(self) -> tuple[int, float] | None:
        link = self._kernel.rotation_alarm
        return None if link < 0 else (int(link), float(self._kernel.rotation_alarm_angle))

    def clear_rotation_alarm(self) -> None:
        self._kernel.clear_rotation_alarm()

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None) -> np.ndarray:
        try:
            return self._kernel.acceleration(q, v, tau, object_wrench)
        except CoopdynError:
            raise
        except Exception as exc:  # ValueError (sizes), Boost.Python.ArgumentError (types), RuntimeError
            raise _kernel_error(exc, "acceleration(q, v, tau, object_wrench)") from exc

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        try:
            return self._kernel.implicit_terms(q, v, tau, object_wrench)
        except CoopdynError:
            raise
        except Exception as exc:
            raise _kernel_error(exc, "implicit_terms(q, v, tau, object_wrench)") from exc

    def factor(self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, kp: np.ndarray, kd: np.ndarray) -> None:
        try:
            self._kernel.factor(M, K, D, gh, kp, kd)
        except CoopdynError:
            raise
        except Exception as exc:
            raise _kernel_error(exc, "factor(M, K, D, gh, kp, kd)") from exc

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        try:
            return self._kernel.solve(f_q, Mf_v)
        except CoopdynError:
            raise
        except Exception as exc:
            raise _kernel_error(exc, "solve(f_q, Mf_v)") from exc

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
        try:
            return self._kernel.implicit_euler_velocity(q, v, tau, h, kp, kd, object_wrench)
        except CoopdynError:
            raise
        except Exception as exc:
            raise _kernel_error(exc, "implicit_euler_velocity(q, v, tau, h, kp, kd, object_wrench)") from exc

    def generalized_spring_force(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        try:
            return self._kernel.spring_force(q, v)
        except Exception as exc:
            raise _kernel_error(exc, "spring_force(q, v)") from exc

    def compiled_loop(self, config: dict[str, object]) -> object:
        """A compiled run of this scene (coopdyn.compiled writes ``config``); the kernel object
        it steps stays alive with it."""
        try:
            return _backend.kernel_module().make_loop(self._kernel, config)
        except CoopdynError:
            raise
        except Exception as exc:
            raise _kernel_error(exc, "the compiled loop's configuration") from exc

    def element_states(self, q: np.ndarray, v: np.ndarray) -> list[ElementEval]:
        try:
            raw = self._kernel.element_states(q, v)
        except Exception as exc:
            raise _kernel_error(exc, "element_states(q, v)") from exc
        out = []
        for (energy, e, f, power, S_K, S_D, theta), lk in zip(raw, self.scene.links, strict=True):
            out.append(ElementEval(energy, e[: lk.element.deformation_size], f, power, S_K, S_D, theta))
        return out

    def _elastic(self) -> np.ndarray:
        return self._kernel.elastic_energies()

    def readouts(self, Q: np.ndarray, V: np.ndarray) -> Readouts:
        try:
            E, U, P, WG, WT, PG, PT, PO, KP = self._kernel.readouts(np.asarray(Q, dtype=float), np.asarray(V, dtype=float))
        except Exception as exc:
            raise _kernel_error(exc, "readouts(Q, V)") from exc
        n, L = len(Q), len(self.scene.links)  # reshape all: eigenpy returns an (n, 1) matrix as a vector
        return Readouts(
            E.reshape(n, L, 6),
            U.reshape(n, L),
            P.reshape(n, L),
            WG.reshape(n, L, 6),
            WT.reshape(n, L, 6),
            PG.reshape(n, L, 3),
            PT.reshape(n, L, 3),
            PO.reshape(n, 3),
            KP.reshape(n, 2)[:, 0].copy(),
            KP.reshape(n, 2)[:, 1].copy(),
        )


__all__ = ["NativeDynamics"]
