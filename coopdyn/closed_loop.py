"""The closed loop :class:`System`: the scene dynamics, a controller and an external object wrench,
with work counters — what integrators advance (they see it through the protocol
:class:`coopdyn.integrators.base.Problem`)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from . import _validate
from .dynamics import Dynamics
from .errors import ControllerError, CoopdynError

Controller = Callable[[float, np.ndarray, np.ndarray], np.ndarray]
_Record = tuple[np.ndarray, np.ndarray, float, np.ndarray]


class System:
    """The closed loop ``q̈ = a(t, q, v)``: dynamics plus controller, with work counters.

    It is what integrators advance, through the protocol
    :class:`coopdyn.integrators.base.Problem` (integrators never see the scene or the dynamics).

    Args:
        dynamics: the scene dynamics.
        controller: ``controller(t, q, v) -> τ`` (n_actuated,) [N·m or N]; ``None`` means τ = 0.
            A controller with a method ``gains() -> (Kp, Kd)`` (each (n_actuated,) [N·m/rad],
            [N·m·s/rad]) has its joint PD gains included in the implicit methods' Jacobian.
        object_wrench: ``object_wrench(t) -> (6,)`` external wrench on the object [N, N·m],
            world axes, at the object frame origin (a disturbance, a contact, a load).
        control_dt: the controller's sample period [s], or ``None`` (default): called at every
            evaluation, a continuous-time controller. With a period, the controller is called at
            the first step start on or after each instant ``k·control_dt`` (the loops make steps
            land there) and its output is held until the next sample (a zero-order hold, as a
            digital controller runs); the implicit methods then leave its gains out of their
            matrix (the held torque does not depend on the stage's state).

    Attributes:
        n_rhs, n_jac, n_factor: right-hand-side evaluations, Jacobian (stiffness) evaluations
            and matrix factorisations so far.
        nv, n_actuated: sizes of the velocity and of the controller output.
        neutral: the neutral configuration (nq,) (the origin of error scales).
    """

    def __init__(
        self,
        dynamics: Dynamics,
        controller: Controller | None = None,
        object_wrench: Callable[[float], np.ndarray] | None = None,
        control_dt: float | None = None,
    ) -> None:
        if controller is not None and not callable(controller):
            raise ControllerError(
                f"controller must be a callable controller(t, q, v) -> τ (e.g. coopdyn.GravityCompensationPD(scene)) "
                f"or None, got {_validate._short(controller)}"
            )
        if object_wrench is not None and not callable(object_wrench):
            raise ControllerError(
                f"object_wrench must be a callable object_wrench(t) -> (6,) or None, got {_validate._short(object_wrench)}"
            )
        self.dynamics = dynamics
        self._scene = dynamics.scene
        self._model = dynamics.model
        # a built-in controller's scene (its own model of the robot); a user's class may hold any
        own = getattr(controller, "scene", None) if type(controller).__module__.startswith("coopdyn.") else None
        sizes = [(getattr(x, "nq", None), getattr(x, "nv", None), getattr(x, "n_actuated", None)) for x in (own, self._scene)]
        if own is not None and own is not self._scene and None not in sizes[0] and sizes[0] != sizes[1]:
            raise ControllerError(
                f"the controller ({type(controller).__name__}) was built for another scene, of nq = {sizes[0][0]}, "
                f"nv = {sizes[0][1]} and {sizes[0][2]} actuated joints; this one has nq = {sizes[1][0]}, nv = {sizes[1][1]} "
                f"and {sizes[1][2]}: build it for this scene"
            )
        self.controller = controller
        self.object_wrench = object_wrench
        self.nv = self._scene.nv
        self.n_actuated = self._scene.n_actuated
        self.neutral = pin.neutral(self._model)
        self._zero = np.zeros(self.n_actuated)
        #: [rad/s or m/s] a state faster than this is a runaway (simulate sets its max_speed): a
        #: controller's non-finite torques there are the state's doing, not the controller's
        self.max_speed = math.inf
        self.n_rhs = 0
        self.n_jac = 0
        self.n_factor = 0
        self._chart = [slice(j.idx_v, j.idx_v + j.nv) for j in self._model.joints[1:] if j.nv > 1]
        self._act = dynamics.actuated_index
        # (q, v, net power [W], τ) of evaluations: the step's first and last, the previous step's last
        self._first: _Record | None = None
        #: D̃ (nv, nv) of the current step's :meth:`implicit_terms`, None before it or for a step
        #: without them (the energy monitor's allowance for a velocity that alternates)
        self.step_damping: np.ndarray | None = None
        self._last: _Record | None = None
        self._previous_last: _Record | None = None
        self.control_dt = control_dt
        self._held: np.ndarray | None = None  # the torque held since the last sample (control_dt)
        self._next_sample = 0  # the index k of the next sample instant k·control_dt
        self._jump = self._zero  # the last sample's change of the held torque, and its time [s]
        self._sampled_at = math.nan
        #: whether the current step's start took a new sample (a method carrying the last step's
        #: derivative, first-same-as-last, must evaluate afresh)
        self.new_sample = False
        self._own_gains = self._read_gains()

    def _read_gains(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The controller's ``gains()``, checked (None without it)."""
        gains = getattr(self.controller, "gains", None)
        if not callable(gains):
            return None
        try:
            raw = gains()
        except (CoopdynError, KeyboardInterrupt):
            raise
        except Exception as exc:
            raise ControllerError(f"the controller's gains() raised {type(exc).__name__}: {exc}") from exc
        return _checked_gains(raw, self.n_actuated)

    def restart(self) -> None:
        """Forget a run: the work counters, the evaluation records and the held sample, and read
        the controller's gains again (a new run with the same dynamics and controller, as
        :class:`coopdyn.Simulator` makes; the controller may have been retuned between runs)."""
        self._own_gains = self._read_gains()
        self.n_rhs = self.n_jac = self.n_factor = 0
        self._first = self._last = self._previous_last = None
        self._held, self._next_sample, self._jump, self._sampled_at = None, 0, self._zero, math.nan
        self.new_sample = False
        self.dynamics.clear_rotation_alarm()

    @property
    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """The controller's joint (Kp, Kd) (n_actuated,) (zero without ``gains()``): the closed
        loop's linearisation (the accuracy screen, the stability advice) includes them."""
        return self._own_gains if self._own_gains is not None else (self._zero, self._zero)

    @property
    def matrix_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """The gains the implicit methods add to their step matrix: :attr:`gains`, or zero under
        a ``control_dt`` hold (the held torque does not depend on the stage's state)."""
        return (self._zero, self._zero) if self.control_dt is not None else self.gains

    @property
    def has_object_wrench(self) -> bool:
        """Whether an external object wrench is applied."""
        return self.object_wrench is not None

    @property
    def q0(self) -> np.ndarray:
        """The scene's initial configuration (nq,)."""
        return self._scene.q0

    def nonlinearity(self) -> str | None:
        """Why the dynamics are not linear, or ``None`` (see :meth:`coopdyn.Scene.nonlinearity`)."""
        return self._scene.nonlinearity()

    def torque(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The controller output, checked: (n_actuated,) finite floats (under a ``control_dt``
        hold: the output of the last sample)."""
        if self._held is not None:
            return self._held
        return self._controller_output(t, q, v)

    def sample(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """With a ``control_dt``: call the controller at (t, q, v) and hold its output when t is
        on or past the next sample instant (to 1e-9 of the period); else nothing. (A run's last
        saved state keeps the held torque: no sample is taken at its end.)"""
        self.new_sample = False
        period = self.control_dt
        if period is None or t < (self._next_sample - 1e-9) * period:
            return
        before = self._zero if self._held is None else self._held
        self._held = None
        self._held = self._controller_output(t, q, v)
        self._jump = self._held - before
        self._sampled_at = t
        self._next_sample = math.floor(t / period + 1e-9) + 1
        self.new_sample = True

    def next_sample_time(self) -> float:
        """[s] the next sample instant a step must land on (inf without ``control_dt``)."""
        return math.inf if self.control_dt is None else self._next_sample * self.control_dt

    def _controller_output(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The controller's output at (t, q, v), checked."""
        if self.controller is None:
            return self._zero
        q_seen, v_seen = q.view(), v.view()  # read-only: a controller cannot change the state it is shown
        q_seen.setflags(write=False)
        v_seen.setflags(write=False)
        try:
            out = self.controller(t, q_seen, v_seen)
        except BaseException as exc:
            failure = self.controller_failure(t, exc)
            if failure is exc:
                raise
            raise failure from exc
        return self.checked_output(out, t, q, v)

    def controller_failure(self, t: float, exc: BaseException) -> BaseException:
        """What a run raises when the controller raised ``exc`` at t: coopdyn's own errors and what
        is not an ``Exception`` (Ctrl-C) as they are, anything else as a :class:`ControllerError`
        that names it and t (its ``__cause__``: ``exc``)."""
        if isinstance(exc, CoopdynError) or not isinstance(exc, Exception):
            return exc
        hint = " (q and v are read-only: copy them to change them)" if "read-only" in str(exc) else ""
        failure = ControllerError(f"the controller raised {type(exc).__name__} at t = {t:.6g} s: {exc}{hint}")
        failure.__cause__ = exc
        return failure

    def checked_output(self, out: object, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The controller's output ``out`` at (t, q, v) as a new (n_actuated,) float array, or a
        :class:`ControllerError` naming what is wrong with it (non-finite torques pass at a
        runaway state, where they carry the state's overflow)."""
        if type(out) is np.ndarray and out.dtype == np.float64:  # not a subclass (masked arrays)
            tau = out.copy()  # (a controller may return the same buffer every call: the run keeps each output)
        else:  # lists, other dtypes, and what is not a torque vector at all
            try:
                tau = _validate.finite_array(out, "the controller's output", error=ControllerError)
            except ControllerError as exc:
                raise ControllerError(
                    f"{exc} at t = {t:.6g} s; a controller must return one torque/force per arm joint, a real array of "
                    f"shape ({self.n_actuated},), in scene order"
                ) from None
        if tau.shape != (self.n_actuated,):
            raise ControllerError(
                f"the controller returned shape {tau.shape} at t = {t:.6g} s; it must return one torque/force per "
                f"arm joint, shape ({self.n_actuated},), in scene order"
            )
        if not math.isfinite(float(np.dot(tau, tau))):  # one dot product; NaN, ±inf (and overflow) fail it
            bad = np.flatnonzero(~np.isfinite(tau)).tolist()
            if bad and self._sane(q, v):
                raise ControllerError(f"the controller returned non-finite torques at t = {t:.6g} s (entries {bad})")
            # at a runaway state (an adaptive method's trial stage far past its stability limit) the
            # torques carry the state's overflow: the attempt is rejected, or the run reported diverged
        return tau

    def _sane(self, q: np.ndarray, v: np.ndarray) -> bool:
        """Whether (q, v) is finite and no faster than :attr:`max_speed`."""
        return bool(np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and (v.size == 0 or np.max(np.abs(v)) <= self.max_speed))

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """q̈ (nv,) at (t, q, v); counts one right-hand-side evaluation and records the net power
        ``τ·q̇ − dissipation`` [W] of that state (see :meth:`power_and_torque_at`)."""
        self.n_rhs += 1
        tau, w = self._inputs(t, q, v)
        a = self.dynamics.acceleration(q, v, tau, w)
        self._record(q, v, tau, w)
        return a

    def _inputs(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The controller's torques and the external object wrench (or None) at (t, q, v)."""
        return self.torque(t, q, v), None if self.object_wrench is None else self._wrench(t)

    def free_acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """q̈ (nv,) for given torques, without the controller or the object wrench (not counted)."""
        return self.dynamics.acceleration(q, v, tau)

    def _record(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, w: np.ndarray | None) -> None:
        """Keep the torque and the net power of the state just evaluated."""
        record = (q, v, self._net_power(q, v, tau, w), tau)
        if self._first is None:
            self._first = record
        self._last = record

    def _net_power(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, w: np.ndarray | None) -> float:
        """``τ·q̇ + external − dissipation`` [W] at the state (q, v) of the last dynamics evaluation."""
        p_ext = 0.0 if w is None else self._object_power(q, v, w)
        return p_ext + float(tau @ v[self._act]) - self.dynamics.last_dissipation

    def _recorded(self, q: np.ndarray, v: np.ndarray) -> _Record | None:
        """The evaluation at exactly these state arrays (the current step's first, or the previous
        step's last for first-same-as-last methods), if kept."""
        for record in (self._first, self._previous_last):
            if record is not None and record[0] is q and record[1] is v:
                return record
        return None

    def recorded_torque(self, q: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """The controller output an integrator step already computed at (q, v), else ``None``
        (lets the saved trajectory reuse it instead of calling the controller again)."""
        record = self._recorded(q, v)
        return None if record is None else record[3]

    def _wrench(self, t: float) -> np.ndarray:
        assert self.object_wrench is not None
        try:
            out = self.object_wrench(t)
        except (CoopdynError, KeyboardInterrupt):
            raise
        except Exception as exc:
            raise ControllerError(f"object_wrench raised {type(exc).__name__} at t = {t:.6g} s: {exc}") from exc
        if type(out) is np.ndarray and out.dtype == np.float64 and out.shape == (6,) and math.isfinite(out.sum()):
            return out.copy()  # the common case, checked in one pass (copied: a reused buffer is not the run's)
        try:
            return _validate.finite_array(out, "object_wrench(t)", (6,), error=ControllerError)
        except ControllerError as exc:
            raise ControllerError(f"{exc} at t = {t:.6g} s; it must return 6 finite real numbers [N, N·m]") from None

    def begin_step(self, t: float | None = None, q: np.ndarray | None = None, v: np.ndarray | None = None) -> None:
        """Mark the start of a step from (t, q, v) (for :meth:`power_and_torque_at` and
        :meth:`recorded_torque`) and take the controller's sample there when one is due
        (:meth:`sample`); the simulation loops call it before every step or attempt."""
        self._previous_last, self._first = self._last, None
        self.step_damping = None
        if t is not None and q is not None and v is not None:
            self.sample(t, q, v)

    def power_and_torque_at(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[float, np.ndarray]:
        """Net power ``τ·q̇ − dissipation`` [W] into the system at a step's start state (q, v), and
        the torque (n_actuated,) there: reused from the step's own first evaluation there (or the
        previous step's last one, for first-same-as-last methods), computed when no evaluation
        was made at that state."""
        record = self._recorded(q, v)
        if record is not None:
            return record[2], record[3]
        tau, w = self._inputs(t, q, v)
        self.dynamics.acceleration(q, v, tau, w)
        return self._net_power(q, v, tau, w), tau

    def torque_jump(self, t: float) -> np.ndarray | None:
        """The change of the held torques (n_actuated,) a sample taken at t made, None when no
        sample was taken at t: the energy monitor ends the last hold's work on the torque (and
        power) before the jump."""
        return self._jump if t == self._sampled_at else None

    @property
    def actuated_index(self) -> np.ndarray | slice:
        """Where the actuated joints' velocities sit in v (indices, or a slice when contiguous):
        the torques act on ``v[actuated_index]``."""
        return self._act

    def implicit_terms(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(f, M, K̃, D̃)`` at (t, q, v) from one kinematics pass: ``f = M q̈`` (nv,) and the
        interconnections' stiffness and damping (without the controller's gains, which
        :meth:`factor` adds). Counts one RHS and one Jacobian, and records the net power like
        :meth:`acceleration`."""
        self.n_rhs += 1
        self.n_jac += 1
        tau, w = self._inputs(t, q, v)
        terms = self.dynamics.implicit_terms(q, v, tau, w)
        self._record(q, v, tau, w)
        self.step_damping = terms[3]
        return terms

    def factor(self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: float, gh2: float | None = None) -> None:
        """Factorise the step matrix ``M + γh D̃ + (γh)² K̃`` with the controller's PD gains added
        (see :meth:`coopdyn.Dynamics.factor`; ``gh2`` replaces (γh)² when given); counts one
        factorisation.

        Raises:
            StepMatrixError: the matrix is not positive definite.
        """
        self.n_factor += 1
        kp, kd = self.matrix_gains
        self.dynamics.factor(M, K, D, gh, kp, kd, gh2)

    def solve(self, f_q: np.ndarray, Mf_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(k_q, k_v)`` with the last :meth:`factor`, given ``M f_v`` (see :meth:`coopdyn.Dynamics.solve`):
        ``S k_v = M f_v − γh K_g f_q``, ``k_q = f_q + γh k_v``; ``(I − γhJ) k = (f_q, f_v)`` when
        ``gh2 = (γh)²``."""
        return self.dynamics.solve(f_q, Mf_v)

    def implicit_euler_velocity(self, t: float, q: np.ndarray, v: np.ndarray, h: float) -> np.ndarray:
        """v⁺ of one linearly implicit Euler step of ``h`` [s] from (t, q, v) (see
        :meth:`coopdyn.Dynamics.implicit_euler_velocity`), with the controller's PD gains in the
        matrix. Counts one RHS, one Jacobian and one factorisation; records the net power like
        :meth:`acceleration`."""
        self.n_rhs += 1
        self.n_jac += 1
        self.n_factor += 1
        tau, w = self._inputs(t, q, v)
        kp, kd = self.matrix_gains
        v_new = self.dynamics.implicit_euler_velocity(q, v, tau, h, kp, kd, w)
        self._record(q, v, tau, w)
        return v_new

    def stiffness(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M, K̃, D̃) (nv, nv) at (q, v), including the controller's PD gains (the closed loop's
        linearisation, a hold or not); counts one Jacobian."""
        self.n_jac += 1
        M, K, D = self.dynamics.stiffness(q, v)
        if self._own_gains is not None:
            self.dynamics.add_joint_gains(K, D, *self._own_gains)
        return M, K, D

    def _object_power(self, q: np.ndarray, v: np.ndarray, wrench: np.ndarray) -> float:
        """Power [W] of a world-aligned wrench at the object origin at (q, v) (its own kinematics
        pass: the compiled kernel keeps its kinematics in data of its own)."""
        data = self.dynamics.data
        pin.forwardKinematics(self._model, data, q, v)
        V = pin.getFrameVelocity(self._model, data, self._scene.object_frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).vector
        return float(wrench @ V)

    def integrate(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """``q ⊕ dq`` on the configuration Lie group (dq (nv,) a tangent displacement)."""
        return pin.integrate(self._model, q, dq)

    def difference(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """``q1 ⊖ q0`` (nv,): the tangent displacement from q0 to q1."""
        return pin.difference(self._model, q0, q1)

    def chart_velocity(self, q0: np.ndarray, delta: np.ndarray, v: np.ndarray) -> np.ndarray:
        """δ̇ = dIntegrate(q₀, δ)⁻¹ v: the chart-coordinate rate for the velocity v at q₀ ⊕ δ.

        NaN on a block whose chart is singular (a rotation of 2π in one trial stage): the stage
        is then rejected (adaptive) or the run reported non-finite, as in the compiled loop."""
        if not self._chart:
            return v
        J = pin.dIntegrate(self._model, q0, delta, pin.ArgumentPosition.ARG1)
        out = v.copy()
        for s in self._chart:
            try:
                out[s] = np.linalg.solve(J[s, s], v[s])
            except np.linalg.LinAlgError:
                out[s] = np.nan
        return out


def _checked_gains(gains: object, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A controller's ``gains()``: two finite real arrays (Kp, Kd), each a scalar or (n,). A negative
    gain is accepted here; the implicit methods' step matrix then says what it does."""
    if not isinstance(gains, tuple | list | np.ndarray) or len(gains) != 2:
        raise ControllerError(
            f"the controller's gains() must return (Kp, Kd), two arrays of shape ({n},), got {_validate._short(gains)}"
        )
    kp = _validate.gain(gains[0], "the controller's gains() Kp", n, "N·m/rad", ControllerError, signed=True)
    kd = _validate.gain(gains[1], "the controller's gains() Kd", n, "N·m·s/rad", ControllerError, signed=True)
    return kp, kd
