"""Peer simulators on coopdyn's benchmark scenes, run the way a careful user would
(docs/benchmarks.md, "Peers").

Only MuJoCo, and only the book's linear case, for now: the faithful MuJoCo model of it is exact
(three slide joints in one nested chain, the interconnections as joint springs), so its error
is the integrator's alone. The Panda scene needs its URDF geometry rewritten and the SE(3)
spring written as a passive-force callback before MuJoCo can run it faithfully; that is not
done here. ``pip install mujoco`` (or the ``peers`` extra) makes ``coopdyn bench`` include it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._optional import require
from ..problems.linear_book import BookParameters, Drive

#: MuJoCo integrators swept by the benchmark (mjtIntegrator names)
MUJOCO_INTEGRATORS = ("Euler", "implicitfast", "RK4")


def mujoco_available() -> bool:
    """True when ``import mujoco`` works."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def mujoco_book_xml(p: BookParameters, integrator: str, dt: float) -> str:
    """MJCF of the book's system: tip 1 (slide q1 = Y1) carries the object (slide q2 = Y2 − Y1,
    spring c_p with rest length s1, damper d_p), which carries tip 2 (slide q3 = Y3 − Y2, spring
    c_k, rest length s3, damper d_k); the drives are force actuators at sites on the tips along
    world z, so τ2 reaches all three joints through the site Jacobian."""
    slide = '<joint name="{n}" type="slide" axis="0 0 1" stiffness="{k}" springref="{r}" damping="{d}"/>'
    return f"""
<mujoco model="linear_book">
  <option timestep="{dt!r}" integrator="{integrator}" gravity="0 0 {-p.g!r}">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <body name="tip1">
      {slide.format(n="q1", k=0, r=0, d=0)}
      <inertial pos="0 0 0" mass="{p.m1!r}" diaginertia="1 1 1"/>
      <site name="s1"/>
      <body name="object">
        {slide.format(n="q2", k=repr(p.c_p), r=repr(p.s1), d=repr(p.d_p))}
        <inertial pos="0 0 0" mass="{p.m!r}" diaginertia="1 1 1"/>
        <body name="tip2">
          {slide.format(n="q3", k=repr(p.c_k), r=repr(p.s3), d=repr(p.d_k))}
          <inertial pos="0 0 0" mass="{p.m2!r}" diaginertia="1 1 1"/>
          <site name="s2"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <general site="s1" gear="0 0 1 0 0 0"/>
    <general site="s2" gear="0 0 1 0 0 0"/>
  </actuator>
</mujoco>"""


@dataclass(frozen=True)
class PeerRun:
    """A peer's trajectory on the output grid."""

    t: np.ndarray  #: (n,) [s]
    Y: np.ndarray  #: (n, 3) positions Y1, Y2, Y3 [m]
    V: np.ndarray  #: (n, 3) velocities [m/s]
    cpu_time: float  #: CPU seconds of the stepping loop
    n_steps: int

    def contact_forces(self, p: BookParameters) -> tuple[np.ndarray, np.ndarray]:
        """(Fc1, Fc2) [N] along the run (the springs' forces on the object)."""
        return p.contact_forces(np.hstack([self.Y, self.V]))


def mujoco_linear_book(
    p: BookParameters, drives: tuple[Drive, Drive], t_final: float, dt: float, integrator: str, save_every: int
) -> PeerRun:
    """Run MuJoCo on the book's system with the drives evaluated in ``mjcb_control`` (at every
    stage of RK4, at the step's start for Euler / implicitfast: the best each offers).

    Raises:
        coopdyn._optional.MissingDependencyError: when MuJoCo is not installed.
    """
    mujoco: Any = require("mujoco", "the MuJoCo peer", "mujoco")
    model = mujoco.MjModel.from_xml_string(mujoco_book_xml(p, integrator, dt))
    data = mujoco.MjData(model)
    data.qpos[:] = [p.Y10, p.Y20 - p.Y10, p.Y30 - p.Y20]
    d1, d2 = drives

    def control(m: Any, d: Any) -> None:
        d.ctrl[0] = d1(d.time)
        d.ctrl[1] = d2(d.time)

    n_steps = round(t_final / dt)
    n_out = n_steps // save_every + 1
    qpos, qvel = np.empty((n_out, 3)), np.empty((n_out, 3))
    t = np.empty(n_out)
    qpos[0], qvel[0], t[0] = data.qpos, data.qvel, 0.0
    mujoco.set_mjcb_control(control)
    try:
        cpu0 = time.process_time()
        for k in range(1, n_steps + 1):
            mujoco.mj_step(model, data)
            if k % save_every == 0:
                i = k // save_every
                qpos[i], qvel[i], t[i] = data.qpos, data.qvel, data.time
        cpu = time.process_time() - cpu0
    finally:
        mujoco.set_mjcb_control(None)
    # absolute positions from the nested chain's relative coordinates
    Y, V = np.cumsum(qpos, axis=1), np.cumsum(qvel, axis=1)
    return PeerRun(t, Y, V, cpu, n_steps)
