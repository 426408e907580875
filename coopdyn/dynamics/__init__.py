"""The scene dynamics: scratch space and evaluation (Python reference or the compiled kernel)."""

from . import backend
from .dynamics import Dynamics, Energy

__all__ = ["Dynamics", "Energy", "backend"]
