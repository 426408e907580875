"""Whether a run's interconnection forces can be trusted: a screen of the linearised closed
loop's modes, judged over the run's whole length and by what each mode contributes to the grasp
forces (:func:`screen`), and — for a run the screen cannot clear — a check of the forces
themselves against a reference run (:func:`reference_for`, :func:`checked_message`; ``simulate``
runs it).

A stable method that does not resolve a mode completes without complaint while it damps,
mis-phases or (the trapezoid on a stiff overdamped mode) rings that mode: over N steps its
amplitude is multiplied by (R(λh)/e^{λh})^N, R the method's stability function. One step's loss
can be small (|λ|h < 1) and the run's still total: implicit Euler at |λ|h = 0.5 keeps 89 % per
step and nothing after 50 steps. And a mode that is badly integrated but moves no
interconnection (a beam's internal node mode, far above what the grasps feel) costs no grasp
force. So each mode λ of the linearised closed loop (at the initial state) is judged by

* its **error over the run**: max over whole steps n ≤ T/h of |R(λh)ⁿ − e^{nλh}| — the deviation of
  the method's mode from the exact one, in units of the mode's initial amplitude (a damped mode
  stops counting once both have decayed);
* its **share of the grasp forces**: the interconnection force per unit of modal energy,
  relative to the largest among the oscillating modes, at most 1 (equal energy in every mode is
  the prior).

What the screen cannot say is how much each mode is excited (by the start, by the task): a
run whose worst product exceeds :data:`SCREEN_LIMIT` has its forces compared with a reference
run of the same scene, controller and start (:func:`reference_for`: dopri5, or ros2_adaptive
at a tight tolerance on stiff scenes), and the warning comes when they differ by more than
:data:`FORCE_ERROR_LIMIT` of their peak, with the figure (``Result.force_error_estimate``).
Where that reference runs past its step budget (:data:`CHECK_COST`, :data:`CHECK_FLOOR`) or
cannot run, the screen's own judgement above :data:`FORCE_ERROR_LIMIT` is the warning. Measured
against a grid of methods, steps, stiffnesses and damping: ``benchmarks/accuracy_grid.py``
(docs/benchmarks.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg

from .closed_loop import System
from .integrators import AdaptiveIntegrator, AdaptiveROS2, DormandPrince, Integrator, Trapezoid
from .linearize import controller_gain, open_loop
from .stability import state_matrix

FORCE_ERROR_LIMIT = 0.1  #: a force error, relative to the peak force, above which a run is not trusted
FORCE_FLOOR = 1e-9  #: [N] forces below this are round-off: a reference without force is not divided by
#: a reference whose forces grow (last third of the compared span over its first, ×) to this many
#: times the run's peak: the run's calm is its integrator's (an unstable closed loop, damped)
UNSTABLE_RATIO, UNSTABLE_GROWTH = 5.0, 2.0
SCREEN_LIMIT = 0.005  #: a mode's force-weighted error above which the forces are checked against a reference run
CHECK_COST = 30  #: the check may take this many times the run's steps (or CHECK_FLOOR), else the screen decides
CHECK_FLOOR = 20_000  #: steps the check may always take
DOPRI5_REACH = 3.3  #: |λ|·h at dopri5's stability limit, for the estimate of its steps
STIFF_REFERENCE = (1e-4, 1e-7)  #: (rtol, atol) of ros2_adaptive as the reference where dopri5 would be stability-bound
OSCILLATORY = 1e-6  #: |Im λ| / |λ| above which a mode oscillates
TIME_SAMPLES = 256  #: points of [0, T] on which a mode's error is maximised


@dataclass(frozen=True)
class ModeAccuracy:
    """How a method treats one mode over a run."""

    frequency: float  #: [Hz] (0: a mode that decays without oscillating)
    rate: float  #: |λ| [1/s]
    damping_ratio: float  #: −Re λ / |λ|
    error: float  #: the mode's largest deviation over the run, in units of its initial amplitude
    force_share: float  #: its grasp force per unit energy, relative to the largest (0–1)
    kept_per_step: float  #: |R(λh) e^{−λh}|: the amplitude it keeps per step, relative to the exact
    amplification: float = 1.0  #: |R(λh)|: the amplitude it keeps per step

    @property
    def weighted(self) -> float:
        """What the mode's error does to the grasp forces (:data:`FORCE_ERROR_LIMIT`); a mode that
        moves no grasp costs none, however wrong."""
        return self.error * self.force_share if self.force_share > 0 else 0.0


def grasp_force_map(system: System, q: np.ndarray, v: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """∂f/∂(δq, δv) (3L, 2nv): how the interconnection forces on the object (world axes [N])
    change with the state, by central differences in the tangent space."""
    dynamics, model = system.dynamics, system.dynamics.scene.model
    nv = model.nv
    Q, V = [], []
    for j in range(2 * nv):
        for sign in (1.0, -1.0):
            dq, dv = np.zeros(nv), np.zeros(nv)
            (dq if j < nv else dv)[j % nv] = sign * eps
            Q.append(pin.integrate(model, q, dq))
            V.append(v + dv)
    wrench = dynamics.readouts(np.array(Q), np.array(V)).object_wrench[:, :, :3]
    n_links = wrench.shape[1]
    diff = (wrench[0::2] - wrench[1::2]).reshape(2 * nv, 3 * n_links) / (2 * eps)
    return np.asarray(diff.T)


@dataclass(frozen=True)
class Modes:
    """The modes of a closed loop linearised at a state (:func:`closed_loop_modes`)."""

    eigenvalues: np.ndarray  #: λ (m,): one of each complex pair (Im λ > 0) and the real ones [1/s]
    force_share: np.ndarray  #: (m,) each mode's grasp force per unit energy, relative to the oscillating modes' largest (≤ 1)
    fastest: float = 0.0  #: the largest |λ| [1/s] (what limits an explicit method's step)


def closed_loop_modes(system: System, q: np.ndarray, v: np.ndarray) -> Modes:
    """The modes of the closed loop (elements, joint damping, the controller's joint gains)
    linearised at (q, v), with their share of the grasp forces; modes at rest (λ = 0: a free
    drift) are left out."""
    M, K, D = system.dynamics.stiffness(q, v)
    kp, kd = system.gains
    system.dynamics.add_joint_gains(K, D, kp, kd)
    nv = M.shape[0]
    lam, phi = np.linalg.eig(state_matrix(M, K, D))
    mag = np.abs(lam)
    fastest = float(np.max(mag, initial=0.0, where=np.isfinite(mag)))
    real = np.abs(lam.imag) <= OSCILLATORY * mag
    kept = (lam.imag > OSCILLATORY * mag) | (real & (mag > 1e-9 * max(fastest, 1e-300)))  # one of each complex pair
    kept &= np.isfinite(lam)
    lam, phi, mag = lam[kept], phi[:, kept], mag[kept]
    lam = np.where(np.abs(lam.imag) <= OSCILLATORY * mag, lam.real + 0j, lam)
    if not len(lam):
        return Modes(lam, np.zeros(0), fastest)
    F = grasp_force_map(system, q, v)
    forces = np.abs(F @ phi).reshape(-1, 3, len(lam)).max(axis=(0, 1)) if F.size else np.zeros(len(lam))
    dq, dv = phi[:nv], phi[nv:]
    energy = 0.5 * np.real(np.einsum("ij,ik,kj->j", dv.conj(), M, dv) + np.einsum("ij,ik,kj->j", dq.conj(), K, dq))
    per_energy = forces / np.sqrt(np.maximum(energy, 1e-300))
    # relative to the oscillatory modes' largest (a stiff non-oscillating mode — a damped node of a
    # beam — can carry far more force per unit energy, and would make every grasp mode look idle)
    oscillating = np.abs(lam.imag) > 0
    top = float(per_energy[oscillating].max() if oscillating.any() else per_energy.max())
    share = np.minimum(per_energy / top, 1.0) if top > 0 else np.zeros(len(lam))
    return Modes(lam, share, fastest)


def judge(modes: Modes, method: Integrator, dt: float, duration: float) -> list[ModeAccuracy]:
    """Each mode of ``modes`` as ``method`` treats it at step ``dt`` [s] over ``duration`` [s]
    (see the module's text), worst first."""
    lam = modes.eigenvalues
    if not len(lam):
        return []
    mag = np.abs(lam)
    z = lam * dt
    with np.errstate(all="ignore"):
        log_r = np.log(_amplification(method, z))
        log_rel = log_r - z  # per step, relative to the exact solution
        steps = np.unique(np.ceil(np.linspace(0.0, duration / dt, TIME_SAMPLES) - 1e-9))  # whole steps: R^n exists there
        # |R^n − e^{nz}|: both factors decay for a stable method (no 0·∞ for a heavily damped mode)
        deviation = np.abs(np.exp(np.outer(steps, log_r)) - np.exp(np.outer(steps, z)))
    error = np.where(np.all(np.isfinite(deviation), axis=0), np.max(deviation, axis=0), np.inf)
    out = [
        ModeAccuracy(
            float(mag[j] * math.sqrt(max(1 - (lam[j].real / mag[j]) ** 2, 0.0)) / (2 * math.pi)),
            float(mag[j]),
            0.0 - float(lam[j].real / mag[j]),
            float(error[j]),
            float(modes.force_share[j]),
            _exp(log_rel[j].real),
            _exp(log_r[j].real),
        )
        for j in range(len(lam))
    ]
    return sorted(out, key=lambda m: -m.weighted)


@dataclass(frozen=True)
class Screen:
    """The screen of a run before (fixed step) or after it (adaptive: at its mean step)."""

    modes: Modes
    worst: list[ModeAccuracy]  #: every mode, worst first (:func:`judge`)
    method: Integrator
    dt: float  #: [s] the step judged
    duration: float  #: [s]

    @property
    def weighted(self) -> float:
        """The worst mode's force-weighted error (0 without modes)."""
        return self.worst[0].weighted if self.worst else 0.0

    @property
    def suspect(self) -> bool:
        """Whether the forces must be checked (:data:`SCREEN_LIMIT`)."""
        return self.weighted > SCREEN_LIMIT

    def reference_steps(self) -> float:
        """About how many steps dopri5 takes over the run: its stability limit on the fastest mode."""
        return self.duration * self.modes.fastest / DOPRI5_REACH


def reference_for(s: Screen, n_steps: int) -> tuple[AdaptiveIntegrator, int]:
    """The method the forces of a run of ``n_steps`` steps are checked against, and the most
    steps it may take (max(CHECK_COST × n_steps, CHECK_FLOOR)): dopri5 (rtol 1e-6) where its
    stability limit on the fastest mode fits that budget; else — a stiff scene, e.g. a beam's
    kHz node modes — ros2_adaptive at :data:`STIFF_REFERENCE` (L-stable: a stiff mode decays as
    it should; within 0.13 % of dopri5 at rtol 1e-8 on the held strip, k = 1e3–1e6)."""
    budget = max(CHECK_COST * max(n_steps, 1), CHECK_FLOOR)
    if s.reference_steps() <= budget:
        return DormandPrince(), 2 * budget  # (its rejected steps count)
    rtol, atol = STIFF_REFERENCE
    return AdaptiveROS2(rtol=rtol, atol=atol), budget


def screen(system: System, q: np.ndarray, v: np.ndarray, method: Integrator, dt: float, duration: float) -> Screen:
    """Every mode of the closed loop linearised at (q, v), judged for ``method`` at step ``dt``
    [s] over ``duration`` [s]."""
    modes = closed_loop_modes(system, q, v)
    return Screen(modes, judge(modes, method, dt, duration), method, dt, duration)


def trusted_dt(modes: Modes, method: Integrator, dt: float, duration: float) -> float:
    """The largest of dt/2, dt/4, … (to dt/2¹⁶) at which no mode's force-weighted error exceeds
    :data:`FORCE_ERROR_LIMIT` over ``duration`` [s] (the smallest tried if none)."""
    h = dt
    for _ in range(16):
        h /= 2
        worst = judge(modes, method, h, duration)
        if not worst or worst[0].weighted <= FORCE_ERROR_LIMIT:
            break
    return h


def _mode_text(s: Screen) -> str:
    m = s.worst[0]
    kept = m.kept_per_step
    if m.frequency == 0.0:
        effect = f"keeps {m.amplification:.3g} of it per step where it decays to {math.exp(-m.rate * s.dt):.3g}"
    elif abs(kept - 1.0) > 1e-3:
        effect = f"keeps {kept:.1%} of its amplitude per step (relative to its true decay)"
    else:
        effect = "keeps its amplitude but not its phase"
    name = (
        f"{m.frequency:.4g} Hz mode (damping ratio {m.damping_ratio:.3g}"
        if m.frequency > 0
        else f"non-oscillating mode (time constant {1e3 / m.rate:.3g} ms"
    )
    return (
        f"its {name}, |λ|·dt = {m.rate * s.dt:.3g}, {m.force_share:.0%} of the largest grasp force per unit energy among the "
        f"modes): the method {effect}"
    )


def _advice(s: Screen) -> str:
    instead = ""
    if s.method.order < 2:  # a first-order method needs far smaller steps than a second-order one
        instead = f", the trapezoid at dt ≤ {trusted_dt(s.modes, Trapezoid(), s.dt, s.duration) * 1e3:.4g} ms"
    return (
        f"Use dt ≤ {trusted_dt(s.modes, s.method, s.dt, s.duration) * 1e3:.4g} ms{instead}, or dopri5 (error-controlled); "
        "coopdyn.advise(scene, dt=dt) says more"
    )


def described(reference: AdaptiveIntegrator) -> str:
    """A reference method as a warning names it, e.g. ``dopri5 at rtol 1e-06``."""
    return f"{reference.name} at rtol {reference.rtol:g}"


def checked_message(
    s: Screen,
    error: float,
    peak: float,
    reference: AdaptiveIntegrator,
    *,
    stopped: tuple[str, float, bool] | None = None,
    own_peak: float | None = None,
    growth: float = 1.0,
) -> str | None:
    """The warning for a run whose forces differ from the ``reference`` run's by more than
    :data:`FORCE_ERROR_LIMIT` of their ``peak`` [N] (``error`` [N]), or None. ``stopped``: the
    reference stopped early — (why, at t [s], whether it diverged) — and was compared up to there;
    ``own_peak``: the run's own force peak over that span [N]; ``growth``: the reference's force
    peak over the last third of that span over its first third. A reference that diverged, or
    whose forces grow (:data:`UNSTABLE_GROWTH`) to dwarf the run's (:data:`UNSTABLE_RATIO`), is
    said plainly: the closed loop is unstable when its modes are resolved, and the run's calm
    forces are its integrator's."""
    if not error > FORCE_ERROR_LIMIT * max(peak, FORCE_FLOOR):
        return None
    share = f"{error / peak:.0%} of their {peak:.4g} N peak" if peak > 0 else "where the reference's are zero"
    span = f"this {s.duration:g} s run"
    if stopped is not None:
        span = f"the first {stopped[1]:.4g} s of this {s.duration:g} s run (where the reference stopped: {stopped[0]})"
    unstable = ""
    diverged = stopped is not None and stopped[2]
    dwarfed = own_peak is not None and peak > UNSTABLE_RATIO * max(own_peak, FORCE_FLOOR) and growth > UNSTABLE_GROWTH
    if diverged or dwarfed:
        grew = "diverged" if diverged else f"has forces growing to {peak:.4g} N where this run's stay below {own_peak:.4g} N"
        unstable = (
            f" The reference, which resolves the modes, {grew}: this closed loop is most likely unstable once its fast "
            "modes are resolved, and this run's calm forces are its integrator's damping, not the physics. Check the "
            "controller (its gains on a flexible or stiff object) before trusting any step."
        )
    return (
        f"{s.method.name} at dt = {s.dt * 1e3:.4g} ms gets the interconnection forces of {span} wrong by up "
        f"to {error:.4g} N, {share} (checked against {described(reference)} from the same start, "
        f"Result.force_error_estimate).{unstable} The likely cause is {_mode_text(s)}. {_advice(s)}"
    )


@dataclass(frozen=True)
class StartLoop:
    """A closed loop linearised exactly (:func:`start_loop`): ``ẋ = A x + B τ`` with the open
    loop's A, B at the controller's torque, and the controller's gain ``τ = G x``."""

    A: np.ndarray  #: (2nv, 2nv)
    B: np.ndarray  #: (2nv, n_actuated)
    G: np.ndarray  #: (n_actuated, 2nv)


def start_loop(system: System, q: np.ndarray, v: np.ndarray, t: float = 0.0, gain: np.ndarray | None = None) -> StartLoop | None:
    """The system's loop linearised exactly at (t, q, v) (:func:`coopdyn.linearize`, on the
    system's own dynamics; the
    controller's gain by central differences, calling it 4·nv more times, without the hold of a
    ``control_dt`` — or ``gain`` when given, e.g. its compiled twin's), or None: no controller,
    or a loop that cannot be linearised (rigid grasps, a joint without tangent coordinates, a
    controller that fails when probed — a diagnosis never turns a run into an error)."""
    if system.controller is None:
        return None
    try:
        wrench = None if system.object_wrench is None else system.object_wrench(t)
        continuous = System(system.dynamics, system.controller, system.object_wrench)  # (no hold: its gain)
        tau = continuous.torque(t, q, v)
        lin = open_loop(system.dynamics, q, v, tau, wrench, t)
        return StartLoop(lin.A, lin.B, controller_gain(continuous, t, q, v) if gain is None else gain)
    except Exception:  # (whatever the controller raises when probed, the run stands)
        return None


def unstable_mode(system: System, q: np.ndarray, v: np.ndarray, duration: float, loop: StartLoop | None = None) -> str:
    """ "a 342.3 Hz mode growing at 63.5 /s (×e every 15.7 ms)" when the closed loop under the
    system's controller, linearised exactly at (q, v) (:func:`start_loop`, or ``loop`` when given),
    has an oscillating mode that grows by more than e over ``duration`` [s] — an unstable vibration
    a damping integrator can hide. "" otherwise: no controller, a growing mode that does not
    oscillate (arms falling, a drift), or a loop that cannot be linearised."""
    loop = start_loop(system, q, v) if loop is None else loop
    if loop is None:
        return ""
    lam = np.linalg.eigvals(loop.A + loop.B @ loop.G)
    oscillating = lam[np.abs(lam.imag) > OSCILLATORY * np.abs(lam)]
    if not oscillating.size:
        return ""
    top = oscillating[np.argmax(oscillating.real)]
    if not top.real * duration > 1.0:
        return ""
    return f"a {abs(top.imag) / (2 * math.pi):.4g} Hz mode growing at {top.real:.3g} /s (×e every {1e3 / top.real:.3g} ms)"


#: how a divergence's message says its loop was unstable from the start (a sweep's heat map reads it)
UNSTABLE_AT_START = "From the start the closed loop is unstable"

#: a sampled loop that grows by this much over a run's time explains its divergence by itself
HOLD_EXPLAINS = 1e3


@dataclass(frozen=True)
class HoldInstability:
    """A sampled controller too slow for its gains (:func:`sampled_instability`)."""

    sentence: str  #: what it is and what to do, lower case, no full stop
    growth: float  #: the sampled loop's growth per period (> 1)
    period: float  #: [s]
    continuous: float = 0.0  #: the continuous loop's growth over a period, as a logarithm (≤ 0: it does not grow)

    def explains(self, duration: float) -> bool:
        """Whether its growth over ``duration`` [s] explains a divergence by itself."""
        return math.log(self.growth) * duration / self.period >= math.log(HOLD_EXPLAINS)

    def seconds(self) -> float:
        """[s] the time its growth alone takes to reach ×:data:`HOLD_EXPLAINS`."""
        return self.period * math.log(HOLD_EXPLAINS) / math.log(self.growth)


def sampled_instability(loop: StartLoop, period: float, knob: str = "control_dt") -> HoldInstability | None:
    """A controller sampled every ``period`` [s] and held whose loop, discretised exactly over the
    period (``[Φ Γ] = expm([[AT, BT], [0, 0]])``), ``Φ + Γ G``, has a spectral radius above 1 where
    the same gains applied continuously (``A + B G``) keep it smaller — a digital controller too
    slow for its gains —, with its growth per period and the longest stable period; None when the
    sampled loop is stable, or no stable period is found. ``knob``: what the sentence calls the
    period (``control_dt``, a sensitivity's ``period``). Compared in logarithms: a loop that grows
    past the floats' range over a period (a wrong sign in a gain) is still told."""
    A, B, G = loop.A, loop.B, loop.G
    n, m = B.shape
    sigma = float(np.max(np.linalg.eigvals(A + B @ G).real))  # the continuous loop's growth rate [1/s]

    def log_radius(T: float) -> float:
        with np.errstate(all="ignore"):  # (an exponential past the floats: inf, and said so below)
            E = scipy.linalg.expm(np.block([[A * T, B * T], [np.zeros((m, n + m))]]))
        if not np.all(np.isfinite(E)):
            return math.inf
        radius = float(np.max(np.abs(np.linalg.eigvals(E[:n, :n] + E[:n, n:] @ G))))
        return math.log(radius) if radius > 0 else -math.inf

    def stable(T: float) -> bool:  # (a neutral mode, a free spin say, grows as the continuous one)
        return log_radius(T) <= max(0.0, sigma * T) + math.log1p(1e-6)

    sampled = log_radius(period)
    if not math.isfinite(sampled):  # (past the floats over one period: nothing to tell the hold's part by)
        return None
    if not (sampled > math.log1p(1e-3) and sampled > sigma * period + math.log1p(1e-3)):
        return None
    lo = period / 2.0
    while not stable(lo):
        lo /= 2.0
        if lo < 1e-9 * period:
            return None
    hi = 2.0 * lo  # (unstable: the halving found lo the first stable one below it)
    for _ in range(14):  # log-scale bisection: 0.2 % in the period
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    drift = sigma * period
    applied = "decays" if drift < -1e-9 else "holds it" if drift <= 1e-6 else f"grows {growth_factor(drift)} a period"
    sentence = (
        f"the controller, sampled every {knob} = {period * 1e3:.4g} ms and held, makes the loop unstable: linearised "
        f"exactly at the start and discretised exactly over a period it grows {growth_factor(sampled)} a period (applied "
        f"continuously it {applied}). No integrator makes that stable: sample every {lo * 1e3:.3g} ms or faster, or "
        "lower the gains"
    )
    return HoldInstability(sentence, math.exp(sampled) if sampled < 709.0 else math.inf, period, sigma * period)


def growth_factor(log_growth: float) -> str:
    """A growth factor given by its natural logarithm: "×1.036", "×1.65e+09", "×1e+400" past floats."""
    if log_growth == math.inf:
        return "×inf"
    decades = log_growth / math.log(10.0)
    return f"×{math.exp(log_growth):.4g}" if decades < 300 else f"×1e+{decades:.0f}"


def growth_text(system: System, q: np.ndarray, v: np.ndarray, duration: float) -> str:
    """The sentence a warned run's message ends with (after the advice, which has no full stop)
    when its closed loop is unstable at its start (:func:`unstable_mode`), else ""."""
    mode = unstable_mode(system, q, v, duration)
    if not mode:
        return ""
    return (
        f". Linearised exactly at the start (coopdyn.linearize with the controller), the closed loop has {mode}: it is "
        "unstable, and a calm run is its integrator's damping"
    )


def screen_message(s: Screen, unchecked: str) -> str | None:
    """The warning from the screen alone (the forces could not be checked: ``unchecked`` says
    why), when the worst mode's force-weighted error exceeds :data:`FORCE_ERROR_LIMIT`; or None."""
    if not s.weighted > FORCE_ERROR_LIMIT:
        return None
    m = s.worst[0]
    error = "more than its whole amplitude" if m.error > 1 else f"{m.error:.0%} of its amplitude"
    return (
        f"{s.method.name} at dt = {s.dt * 1e3:.4g} ms misrepresents a mode of the scene over this {s.duration:g} s run, "
        f"{_mode_text(s)}, so by the end the mode is off by {error}: the interconnection forces can be wrong by a large "
        f"part of their swing (not checked against a reference run: {unchecked}). {_advice(s)}"
    )


def _exp(x: float) -> float:
    """e^x for a finite x below the overflow, else 0 (−inf, nan) or inf."""
    return math.exp(min(x, 700.0)) if np.isfinite(x) else (math.inf if x > 0 else 0.0)


def _amplification(method: Integrator, z: np.ndarray) -> np.ndarray:
    """The factor a step of ``method`` multiplies a mode e^{λt} by, at z = λh. A method without a
    scalar stability function (symplectic Euler updates v, then q with the new v) is taken on the
    mechanical oscillator q̈ + 2ζω q̇ + ω² q = 0 the mode belongs to: the eigenvalue of its
    step matrix on (q, h q̇) that continues e^{z}."""
    try:
        return np.asarray(method.stability_function(z), dtype=complex)
    except NotImplementedError:
        pass
    out = np.empty(len(z), dtype=complex)
    for j, zj in enumerate(z):
        w, zeta = abs(zj), -zj.real / abs(zj)
        c = 1.0 - 2.0 * zeta * w
        mu = np.linalg.eigvals(np.array([[1.0 - w * w, c], [-w * w, c]]))
        out[j] = mu[np.argmin(np.abs(mu - np.exp(zj)))]
    return out
