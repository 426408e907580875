"""Type stub of the compiled kernel (src/native/kernel.cpp): the dynamics (coopdyn.dynamics.native)
and the step loop (coopdyn.compiled), and the MuJoCo callbacks (coopdyn.mujoco)."""

from typing import Any

import numpy as np

PINOCCHIO_VERSION: str
ELEMENTS: list[str]
STATUSES: tuple[str, ...]
METHODS: tuple[str, ...]
CONTROLLERS: tuple[str, ...]

class Kernel:
    def __init__(
        self,
        model: Any,
        data: Any,
        links: list[tuple[str, int, int, dict[str, Any]]],
        damping: np.ndarray,
        actuated: np.ndarray,
        object_frame: int,
        joint_springs: np.ndarray,
        link_model: Any,
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
    def elastic_energies(self, q: np.ndarray) -> np.ndarray: ...
    def spring_force(self, q: np.ndarray, v: np.ndarray) -> np.ndarray: ...
    def gravity(self, q: np.ndarray) -> np.ndarray: ...
    def element_states(self, q: np.ndarray, v: np.ndarray) -> list[tuple[Any, ...]]: ...
    def readouts(self, Q: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, ...]: ...
    def derivatives(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, wrench: np.ndarray | None) -> tuple[Any, ...]: ...
    def clear_rotation_alarm(self) -> None: ...
    def damping_form(self, dv: np.ndarray) -> float: ...
    @property
    def last_dissipation(self) -> float: ...
    @property
    def rotation_alarm(self) -> int: ...
    @property
    def rotation_alarm_angle(self) -> float: ...
    @property
    def sparse_step_matrix(self) -> bool: ...
    @sparse_step_matrix.setter
    def sparse_step_matrix(self, on: bool) -> None: ...

class Sensitivity:
    """Exact sensitivities of a method's steps, open loop or closed (src/native/sensitivity.hpp); see coopdyn.sensitivity."""

    def __init__(
        self,
        kernel: Kernel,
        A: list[list[float]],
        b: list[float],
        symplectic: bool,
        implicit: tuple[float, ...],
        charts: list[tuple[int, int]],
        parameters: list[Any],
    ) -> None: ...
    def run(
        self,
        q0: np.ndarray,
        v0: np.ndarray,
        U: np.ndarray,
        per: int,
        h: float,
        dq0: np.ndarray,
        dv0: np.ndarray,
        dU: np.ndarray,
        dP: np.ndarray,
        end_wrench: bool,
        max_speed: float,
        t0: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool, np.ndarray]: ...
    def set_controller(self, kernel: Kernel, controller: dict[str, Any]) -> None: ...
    def controller_gain(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

class Loop:
    """A compiled simulation run (src/native/loop.hpp); see coopdyn.compiled."""

    def advance(self, budget: int) -> int: ...
    def restart(self, q0: np.ndarray, v0: np.ndarray) -> None: ...
    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]: ...
    def take_samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    def take_events(self) -> list[tuple[int, float, float, float, float, float]]: ...
    def counters(self) -> tuple[int, int, int, int, int]: ...
    def failure(self) -> tuple[str, float, float, np.ndarray, np.ndarray]: ...
    @property
    def t(self) -> float: ...

def evaluate_element(
    kind: str, parameters: dict[str, Any], T_M_G: np.ndarray, xi: np.ndarray, jacobians: bool
) -> tuple[float, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray, float]: ...
def make_loop(kernel: Kernel, config: dict[str, Any]) -> Loop: ...

class MujocoBridge:
    """coopdyn's law as MuJoCo callbacks (src/native/mujoco_bridge.hpp); see coopdyn.mujoco."""

    @property
    def evaluations(self) -> int: ...
    def take_error(self) -> str: ...

def make_mujoco_bridge(
    kernel: Kernel,  # (kept alive by the bridge)
    controller: dict[str, Any] | None,
    layout: tuple[int, int, int, int, int],
    q_pin: np.ndarray,
    q_mj: np.ndarray,
    v_pin: np.ndarray,
    v_mj: np.ndarray,
    free: np.ndarray,
    motor_ctrl: np.ndarray,
    motor_tau: np.ndarray,
) -> MujocoBridge: ...
def install_mujoco_bridge(bridge: MujocoBridge | None) -> MujocoBridge | None: ...
def mujoco_passive_address() -> int: ...
def mujoco_control_address() -> int: ...
