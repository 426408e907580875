"""The energy-balance monitor: the change of total energy must equal the work of the joint
torques minus the energy dissipated by dampers. Growth that no input power explains means the
integrator is unstable or too coarse for the scene — even when the trajectory looks plausible.
"""

from __future__ import annotations

import numpy as np

from . import _progress
from .closed_loop import System
from .errors import EnergyBalanceError, EnergyBalanceWarning

ENERGY_RTOL = 0.05  #: default tolerance of the balance, relative to the energy in play


class EnergyMonitor:
    """Checks ``E(t) − E(0) ≤ W_in(t) − W_diss(t) + tolerance`` along a run.

    The net power ``τ·q̇ − dissipation`` is taken at every step's start (reused from the
    integrator's own evaluation there) and integrated by the third-order rule
    ``h/12 (5 P₊ + 8 P − P₋)`` on equal steps (trapezoidal otherwise; under a ``control_dt``
    hold, each hold's integral ends on the power before the next sample's jump and the rule
    does not reach across it); the energy is evaluated
    every ``every`` steps. The tolerance is ``rtol`` times the energy in play (the largest
    kinetic + elastic energy seen, plus ∫|P| dt), plus the quadrature's own error estimate,
    plus round-off.

    A linearly implicit step (one that forms the damping matrix D̃: the trapezoid,
    generalized-α, ROS2) dissipates at its mean velocity, not at its end points: on a linear
    scene the trapezoid's energy changes by exactly ``h (τ̄·q̇̄ − q̇̄ᵀ D̃ q̇̄)`` a step. Its work is
    taken so — the point rule's plus ``h/4 (Δq̇ᵀ D̃ Δq̇ − Δτ·Δq̇)``. A mode it does not resolve
    alternates from step to step (|R(−∞)| near 1); at the points its dampers and the
    controller's damping then seem to dissipate far more than the step does, and the energy
    looked as if it grew where the method only kept it (a linear scene, which the trapezoid
    cannot make gain energy, was flagged, and so were runs of the task at k = 1e6 N/m whose
    forces are right to 1e-3 N).

    Args:
        system: the closed loop being integrated.
        every: steps between energy evaluations.
        rtol: relative tolerance (default 5 %).
        mode: ``"warn"`` or ``"raise"``.
        method: the integrator's name, for the message.
    """

    def __init__(
        self,
        system: System,
        t: float,
        q: np.ndarray,
        v: np.ndarray,
        *,
        every: int,
        rtol: float = ENERGY_RTOL,
        mode: str = "warn",
        method: str = "",
    ):
        self.system, self.every, self.rtol, self.mode, self.method = system, max(1, int(every)), rtol, mode, method
        self.dynamics = system.dynamics
        e = self.dynamics.energy(q, v)
        self.E0 = e.total
        self.peak = self.scale = e.kinetic + e.elastic
        self.work = 0.0
        self.abs_work = 0.0
        self.uncertainty = 0.0  #: accumulated estimate of the quadrature error of ``work`` [J]
        self._pending: tuple[float, float] | None = None  # (h, P at the step start)
        # (h, Δq̇ on the actuated joints, τ at the start, Δq̇ᵀ D̃ Δq̇) of the step whose work the
        # next step's start closes (see the class docstring)
        self._open: tuple[float, np.ndarray, np.ndarray, float] | None = None
        self._act = system.actuated_index
        self._before: tuple[float, float] | None = None  # the interval before that
        self._steps = 0
        self.first_violation: float | None = None
        self.max_excess = 0.0

    def after_step(self, t0: float, q0: np.ndarray, v0: np.ndarray, h: float, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Call right after a step from (t0, q0, v0) of length h [s] to (t, q, v)."""
        p, tau = self.system.power_and_torque_at(t0, q0, v0)
        held = self.system.torque_jump(t0)  # a new control sample at t0: the last hold ends before it
        if held is None:
            self._close_step(tau)
            self._close_interval(p, h)
        else:
            self._close_step(tau - held)
            self._close_interval(p - float(held @ v0[self._act]), h, p, fresh=True)
        damping = self.system.step_damping  # (a linearly implicit step's D̃; None for the other methods)
        if damping is not None:
            dv = v - v0
            self._open = (h, dv[self._act], tau, float(dv @ (damping @ dv)))
        self._steps += 1
        if self._steps % self.every == 0:
            self._check(t0, q0, v0)

    def finish(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Close the work integral at the final state and check once more."""
        self.system.begin_step()
        p, tau = self.system.power_and_torque_at(t, q, v)
        self._close_step(tau)
        self._close_interval(p, None)
        self._check(t, q, v)

    def _close_step(self, tau_end: np.ndarray) -> None:
        """The open step's work taken at its mean velocity and torque: ``h/4 (Δq̇ᵀ D̃ Δq̇ − Δτ·Δq̇)``
        added to the point rule's, its torque ending at ``tau_end`` (the held one, before a new
        sample's jump)."""
        if self._open is not None:
            h, dv, tau, dissipation = self._open
            self.work += 0.25 * h * (dissipation - float((tau_end - tau) @ dv))
            self._open = None

    def _close_interval(self, p_end: float, h_next: float | None, p_next: float | None = None, fresh: bool = False) -> None:
        """Add the work of the pending interval, which ends where the power is ``p_end``; the
        next interval starts at ``p_next`` (default ``p_end``), afresh after a jump of the held
        torques (``fresh``: no three-point rule across it)."""
        if self._pending is not None:
            h, p = self._pending
            if self._before is not None and abs(self._before[0] - h) <= 1e-12 * h:
                dw = h / 12.0 * (5.0 * p_end + 8.0 * p - self._before[1])
                self.uncertainty += h / 12.0 * abs(p_end - 2.0 * p + self._before[1])  # |this − trapezoid|
            else:
                dw = 0.5 * h * (p + p_end)
                self.uncertainty += 0.5 * h * abs(p_end - p)  # |trapezoid − rectangle|
            self.work += dw
            self.abs_work += abs(dw)
            self._before = self._pending
        if fresh:
            self._before = None
        self._pending = None if h_next is None else (h_next, p_end if p_next is None else p_next)

    def _check(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """Compare the energy at (t, q, v) — where the work integral ends — with the work."""
        e = self.dynamics.energy(q, v)
        self.peak = max(self.peak, e.kinetic + e.elastic)
        self.scale = self.peak + self.abs_work
        excess = (e.total - self.E0) - self.work
        tol = self.rtol * self.scale + self.uncertainty + 1e-9 * (abs(self.E0) + 1.0)
        self.max_excess = max(self.max_excess, excess)
        if excess > tol and self.first_violation is None:
            self.first_violation = t
            msg = violation_message(t, e.total - self.E0, self.work, excess, self.rtol, self.scale, self.method)
            if self.mode == "raise":
                raise EnergyBalanceError(msg)
            _progress.warn(msg, EnergyBalanceWarning, stacklevel=None)  # (at the user's call, however deep the loop)


#: what the energy warning suggests instead of a method that is not one of them: stable at any
#: step, and dissipating what they cannot resolve rather than keeping it
DISSIPATIVE = ("implicit_euler", "ros2")


def violation_message(t: float, growth: float, work: float, excess: float, rtol: float, scale: float, method: str = "") -> str:
    """What :class:`EnergyMonitor` says when the balance breaks (the compiled loop says the same);
    ``method``: the integrator's name (a dissipative method is not told to use itself)."""
    if method in DISSIPATIVE:
        fix = "reduce dt, or use an error-controlled method ('dopri5', 'dop853', 'ros2_adaptive')"
    else:
        fix = f"reduce dt, or use {' or '.join(repr(m) for m in DISSIPATIVE)}"
    return (
        f"energy balance broken at t = {t:.6g} s: the energy grew by {growth:.6g} J while the joint "
        f"torques did {work:.6g} J of net work (dissipation included); the excess {excess:.3g} J is more than "
        f"{rtol:.0%} of the energy in play ({scale:.3g} J). The integrator{f' ({method})' if method else ''} is "
        f"probably unstable or too coarse here: {fix} (see coopdyn.advise)"
    )
