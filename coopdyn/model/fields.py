"""The keys of a scene description and how values become data: shared by the description
(:mod:`coopdyn.model.description`) and by each object class, which declares its own keys."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .. import _validate


class Field(NamedTuple):
    """One key of a description table."""

    kind: str  #: the kind of value (a key of :data:`coopdyn.model.description.KINDS`)
    doc: str  #: what it means, with its unit
    required: bool = False


def pose_data(pose: Any, name: str = "pose") -> list[float] | dict[str, Any]:
    """A pose as data: its translation alone when it does not rotate, else translation and rotation."""
    M = _validate.se3(pose, name)
    if np.array_equal(M.rotation, np.eye(3)):
        return M.translation.tolist()
    return {"translation": M.translation.tolist(), "rotation": M.rotation.tolist()}


def numbers(value: Any, name: str) -> Any:
    """A finite array as nested lists of floats (``name`` in the message if it is not)."""
    return _validate.finite_array(value, name).tolist()
