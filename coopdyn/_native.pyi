"""Type stub of the compiled kernel (src/native/kernel.cpp); see coopdyn.backend."""

from typing import Any

import numpy as np

PINOCCHIO_VERSION: str

class Kernel:
    def __init__(
        self,
        model: Any,
        data: Any,
        links: list[tuple[int, int, np.ndarray, np.ndarray]],
        damping: np.ndarray,
        actuated: np.ndarray,
        object_frame: int,
    ) -> None: ...
    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, wrench: np.ndarray | None) -> np.ndarray: ...
    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, wrench: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    def implicit_euler_velocity(
        self,
        q: np.ndarray,
        v: np.ndarray,
        tau: np.ndarray,
        h: float,
        kp: np.ndarray,
        kd: np.ndarray,
        wrench: np.ndarray | None,
    ) -> np.ndarray: ...
    def elastic_energies(self) -> np.ndarray: ...
    @property
    def last_dissipation(self) -> float: ...
