"""Type stub of the compiled kernel (src/native/kernel.cpp); see coopdyn.dynamics.native."""

from typing import Any

import numpy as np

PINOCCHIO_VERSION: str
ELEMENTS: list[str]

class Kernel:
    def __init__(
        self,
        model: Any,
        data: Any,
        links: list[tuple[str, int, int, tuple[np.ndarray, ...]]],
        damping: np.ndarray,
        actuated: np.ndarray,
        object_frame: int,
    ) -> None: ...
    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, wrench: np.ndarray | None) -> np.ndarray: ...
    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, wrench: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    def factor(self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, kp: np.ndarray, kd: np.ndarray) -> None: ...
    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...
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
    def element_states(self, q: np.ndarray, v: np.ndarray) -> list[tuple[Any, ...]]: ...
    def readouts(self, Q: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, ...]: ...
    def clear_rotation_alarm(self) -> None: ...
    @property
    def last_dissipation(self) -> float: ...
    @property
    def rotation_alarm(self) -> int: ...
    @property
    def rotation_alarm_angle(self) -> float: ...
