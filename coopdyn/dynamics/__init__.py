"""The scene dynamics: scratch space and evaluation (Python reference or the compiled kernel)."""

from . import backend
from . import constrained as constrained  # (registers the Dynamics kind "constrained")
from . import native as native  # (registers the Dynamics kind "native")
from .dynamics import Dynamics, Energy

__all__ = ["Dynamics", "Energy", "backend"]
