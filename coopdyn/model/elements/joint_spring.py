"""Joint-space springs: each elastic joint's transmission between its motor θ and its link q.

The element of an elastic joint (:mod:`coopdyn.model.elastic_joints`) is linear in the
deflection ``δ = θ ⊖ q`` (θ − q; for a continuous joint the angle between the two (cos, sin)
pairs) and its rate ``δ̇ = θ̇ − q̇``: the torque ``τ_s = K δ + D δ̇`` acts on the link (+τ_s)
and on the motor (−τ_s); its energy is ``½ K δ²`` and it dissipates ``D δ̇²``. Its stiffness and
damping in the scene's coordinates are the constant matrices ``K Lᵀ L`` and ``D Lᵀ L`` with
``L = e_θ − e_q``. The compiled kernel's twin is src/native/elements/joint_springs.hpp.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class JointSprings:
    """Every elastic joint of a scene, one entry each (scene indices into q and v)."""

    link_q: np.ndarray  #: the link joint's first q index
    link_v: np.ndarray  #: its v index
    motor_q: np.ndarray  #: the motor's first q index
    motor_v: np.ndarray  #: its v index
    stiffness: np.ndarray  #: K [N·m/rad or N/m]
    damping: np.ndarray  #: D [N·m·s/rad or N·s/m]
    continuous: np.ndarray  #: bool: q is a (cos, sin) pair

    @classmethod
    def none(cls) -> JointSprings:
        """No elastic joint."""
        empty = np.zeros(0, dtype=int)
        return cls(empty, empty, empty, empty, np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool))

    @property
    def size(self) -> int:
        """Number of elastic joints."""
        return int(self.stiffness.size)

    def deflection(self, Q: np.ndarray) -> np.ndarray:
        """δ = θ ⊖ q [rad or m], (m,) for a state q (nq,) or (n, m) along a trajectory (n, nq)."""
        Q = np.asarray(Q)
        delta = Q[..., self.motor_q] - Q[..., self.link_q]
        if np.any(self.continuous):
            c = self.continuous
            cm, sm = Q[..., self.motor_q[c]], Q[..., self.motor_q[c] + 1]
            cl, sl = Q[..., self.link_q[c]], Q[..., self.link_q[c] + 1]
            delta[..., c] = np.arctan2(sm * cl - cm * sl, cm * cl + sm * sl)
        return delta

    def rate(self, V: np.ndarray) -> np.ndarray:
        """δ̇ = θ̇ − q̇ [rad/s or m/s], like :meth:`deflection`."""
        V = np.asarray(V)
        return V[..., self.motor_v] - V[..., self.link_v]

    def torque(self, Q: np.ndarray, V: np.ndarray) -> np.ndarray:
        """τ_s = K δ + D δ̇ [N·m or N], the torque each transmission puts on its link."""
        return self.stiffness * self.deflection(Q) + self.damping * self.rate(V)

    def energy(self, Q: np.ndarray) -> np.ndarray:
        """½ Σ K δ² [J]: a float for a state, (n,) along a trajectory."""
        delta = self.deflection(Q)
        return 0.5 * np.sum(self.stiffness * delta * delta, axis=-1)

    def power(self, V: np.ndarray) -> np.ndarray:
        """Σ D δ̇² [W], the power the transmissions' damping dissipates, like :meth:`energy`."""
        rate = self.rate(V)
        return np.sum(self.damping * rate * rate, axis=-1)

    def add_force(self, Q: np.ndarray, q: np.ndarray, v: np.ndarray) -> float:
        """Add the springs' generalized force to Q (nv,) at (q, v), in place; returns the power
        their damping dissipates [W]."""
        if not self.size:
            return 0.0
        rate = self.rate(v)
        tau = self.stiffness * self.deflection(q) + self.damping * rate
        np.add.at(Q, self.link_v, tau)
        np.add.at(Q, self.motor_v, -tau)
        return float(np.sum(self.damping * rate * rate))

    def add_matrices(self, K: np.ndarray, D: np.ndarray | None = None) -> None:
        """Add ``K Lᵀ L`` to K (nv, nv) and ``D Lᵀ L`` to D, in place: the springs' −∂Q/∂q and −∂Q/∂v."""
        for matrix, value in ((K, self.stiffness), (D, self.damping)):
            if matrix is None:
                continue
            np.add.at(matrix, (self.link_v, self.link_v), value)
            np.add.at(matrix, (self.motor_v, self.motor_v), value)
            np.add.at(matrix, (self.link_v, self.motor_v), -value)
            np.add.at(matrix, (self.motor_v, self.link_v), -value)

    def native_table(self) -> np.ndarray:
        """The springs for the compiled kernel: (7m,), seven values per spring, one spring after
        the other: (link q, link v, motor q, motor v, K, D, continuous)."""
        columns = [self.link_q, self.link_v, self.motor_q, self.motor_v, self.stiffness, self.damping, self.continuous]
        return np.column_stack(columns).astype(float).reshape(self.size * 7)
