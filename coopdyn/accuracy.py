"""Whether a fixed-step run's forces can be trusted, judged before it starts over its whole
length and by what each mode contributes to the grasp forces (:func:`run_accuracy`).

A stable method that does not resolve an oscillatory mode completes without complaint while it
damps or mis-phases that mode: over N steps its amplitude is multiplied by (R(λh)/e^{λh})^N,
R the method's stability function. One step's loss can be small (|λ|h < 1) and the run's still
total: implicit Euler at |λ|h = 0.5 keeps 89 % per step and nothing after 50 steps. And a mode
that is badly integrated but moves no interconnection (a beam's internal node mode, far above
what the grasps feel) costs no grasp force. So each oscillatory mode λ of the linearised closed
loop (at the initial state; damping ratio below 0.5: a more damped mode has decayed within its
period, and smooth forcing moves it quasi-statically) is judged by

* its **error over the run**: max over 0 ≤ t ≤ T of e^{Re λ t}·|(R(λh)e^{−λh})^{t/h} − 1| — the
  deviation of the method's mode from the exact one, in units of the mode's initial amplitude
  (a damped mode stops counting once it has decayed);
* its **share of the grasp forces**: the interconnection force per unit of modal energy,
  relative to the largest among all the complex modes (equal energy in every mode is the prior).

Their product above :data:`FORCE_ERROR_LIMIT` is a warning that names the mode. Measured against
a grid of methods, steps, stiffnesses and damping (``benchmarks/accuracy_grid.py``): it leaves
few wrong runs silent but also warns on some right ones (docs/benchmarks.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .closed_loop import System
from .integrators import Integrator
from .stability import OSCILLATORY_DAMPING, state_matrix

FORCE_ERROR_LIMIT = 0.1  #: the force-weighted error of a mode above which a run is not trusted
OSCILLATORY = 1e-6  #: |Im λ| / |λ| above which a mode oscillates
TIME_SAMPLES = 256  #: points of [0, T] on which a mode's error is maximised


@dataclass(frozen=True)
class ModeAccuracy:
    """How a method treats one oscillatory mode over a run."""

    frequency: float  #: [Hz]
    rate: float  #: |λ| [1/s]
    damping_ratio: float  #: −Re λ / |λ|
    error: float  #: the mode's largest deviation over the run, in units of its initial amplitude
    force_share: float  #: its grasp force per unit energy, relative to the largest (0–1)
    kept_per_step: float  #: |R(λh) e^{−λh}|: the amplitude it keeps per step, relative to the exact

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
    """The oscillatory modes of a closed loop linearised at a state (:func:`closed_loop_modes`)."""

    eigenvalues: np.ndarray  #: λ (m,), Im λ > 0 [1/s]
    force_share: np.ndarray  #: (m,) each mode's grasp force per unit energy, relative to the largest


def closed_loop_modes(system: System, q: np.ndarray, v: np.ndarray) -> Modes:
    """The oscillatory modes of the closed loop (elements, joint damping, the controller's joint
    gains) linearised at (q, v), with their share of the grasp forces."""
    M, K, D = system.dynamics.stiffness(q, v)
    kp, kd = system.gains
    system.dynamics.add_joint_gains(K, D, kp, kd)
    nv = M.shape[0]
    lam, phi = np.linalg.eig(state_matrix(M, K, D))
    mag = np.abs(lam)
    pairs = (lam.imag > OSCILLATORY * np.maximum(mag, 1e-300)) & np.isfinite(lam)  # one of each complex pair
    lam, phi, mag = lam[pairs], phi[:, pairs], mag[pairs]
    if not len(lam):
        return Modes(lam, np.zeros(0))
    F = grasp_force_map(system, q, v)
    forces = np.abs(F @ phi).reshape(-1, 3, len(lam)).max(axis=(0, 1)) if F.size else np.zeros(len(lam))
    dq, dv = phi[:nv], phi[nv:]
    energy = 0.5 * np.real(np.einsum("ij,ik,kj->j", dv.conj(), M, dv) + np.einsum("ij,ik,kj->j", dq.conj(), K, dq))
    per_energy = forces / np.sqrt(np.maximum(energy, 1e-300))
    top = float(per_energy.max())  # over every complex mode: the share does not depend on which are judged
    share = per_energy / top if top > 0 else np.zeros(len(lam))
    judged = -lam.real < OSCILLATORY_DAMPING * mag
    return Modes(lam[judged], share[judged])


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
        steps = np.linspace(0.0, duration, TIME_SAMPLES) / dt
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
            float(np.exp(log_rel[j].real)) if np.isfinite(log_rel[j].real) else 0.0,
        )
        for j in range(len(lam))
    ]
    return sorted(out, key=lambda m: -m.weighted)


def run_accuracy(
    system: System, q: np.ndarray, v: np.ndarray, method: Integrator, dt: float, duration: float
) -> list[ModeAccuracy]:
    """Every oscillatory mode of the closed loop linearised at (q, v), judged for ``method`` at
    step ``dt`` [s] over ``duration`` [s], worst first."""
    return judge(closed_loop_modes(system, q, v), method, dt, duration)


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


def accuracy_message(system: System, method: Integrator, q: np.ndarray, v: np.ndarray, dt: float, duration: float) -> str | None:
    """The warning for a run whose forces a mode's error spoils (:data:`FORCE_ERROR_LIMIT`), or None."""
    modes = closed_loop_modes(system, q, v)
    worst = judge(modes, method, dt, duration)
    if not worst or worst[0].weighted <= FORCE_ERROR_LIMIT:
        return None
    m = worst[0]
    kept = m.kept_per_step
    effect = (
        f"keeps {kept:.1%} of its amplitude per step (relative to its true decay)"
        if abs(kept - 1.0) > 1e-3
        else "keeps its amplitude but not its phase"
    )
    error = "more than its whole amplitude" if m.error > 1 else f"{m.error:.0%} of its amplitude"
    return (
        f"{method.name} at dt = {dt * 1e3:.4g} ms misrepresents the scene's {m.frequency:.4g} Hz mode over this "
        f"{duration:g} s run (damping ratio {m.damping_ratio:.3g}, |λ|·dt = {m.rate * dt:.3g}): the method {effect}, so "
        f"by the end the mode is off by {error}, and it carries {m.force_share:.0%} of the largest grasp force per unit "
        f"energy among the modes: the interconnection forces can be wrong by a large part of their swing. Use "
        f"dt ≤ {trusted_dt(modes, method, dt, duration) * 1e3:.4g} ms, or dopri5 (error-controlled); "
        "coopdyn.advise(scene, dt=dt) says more"
    )


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
