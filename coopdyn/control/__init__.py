"""The controllers: callables ``controller(t, q, v) -> τ`` for :func:`coopdyn.simulate`.

* :mod:`.joint` — joint space: :class:`GravityCompensationPD`, :class:`ComputedTorque`, for
  arms with elastic joints :class:`MotorPD`, and open-loop torques :class:`TorqueSequence`;
* :mod:`.cooperative` — on the object: :class:`ObjectImpedance` (impedance, non-squeezing load
  distribution, commanded internal force) and its task :class:`GripLiftOscillate` (also
  ``coopdyn.cooperative``).

A controller whose class defines ``compiled_spec(scene)`` runs in the compiled loop through its
C++ twin in ``src/native/controllers/`` (docs/extending.md).
"""

from .cooperative import GripLiftOscillate, ObjectImpedance, ObjectReference
from .joint import ComputedTorque, GravityCompensationPD, MotorPD, TorqueSequence

__all__ = [
    "ComputedTorque",
    "GravityCompensationPD",
    "GripLiftOscillate",
    "MotorPD",
    "ObjectImpedance",
    "ObjectReference",
    "TorqueSequence",
]
