"""The controllers: callables ``controller(t, q, v) -> τ`` for :func:`coopdyn.simulate`.

* :mod:`.joint` — joint space: :class:`GravityCompensationPD`, :class:`ComputedTorque`, and for
  arms with elastic joints :class:`MotorPD`;
* :mod:`.cooperative` — on the object: :class:`ObjectImpedance` (impedance, non-squeezing load
  distribution, commanded internal force) and its task :class:`GripLiftOscillate` (also
  ``coopdyn.cooperative``).

A controller whose class defines ``compiled_spec(scene)`` runs in the compiled loop through its
C++ twin in ``src/native/controllers/`` (docs/extending.md).
"""

from .cooperative import GripLiftOscillate, ObjectImpedance, ObjectReference
from .joint import ComputedTorque, GravityCompensationPD, MotorPD

__all__ = ["ComputedTorque", "GravityCompensationPD", "GripLiftOscillate", "MotorPD", "ObjectImpedance", "ObjectReference"]
