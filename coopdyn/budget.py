"""Checks before a run starts: whether it fits a step and memory budget (:func:`coopdyn.simulate`
calls them)."""

from __future__ import annotations

import math
from typing import Any

from . import _validate
from .errors import SimulationError
from .model.scene import Scene

#: the most steps a run takes unless told otherwise (simulate's max_steps, a rollout's or a
#: sensitivity run's limit) and the most bytes its records may take (simulate's max_memory)
MAX_STEPS, MAX_MEMORY = 2 * 10**6, 4e9


def step_count(t_final: float, dt: float) -> int:
    """Steps on the grid k·dt up to ``t_final`` (the last one shortened; one step, of
    ``t_final``, when dt exceeds it)."""
    return max(1 if t_final > 0 else 0, math.ceil(t_final / dt - 1e-9))


#: Memory a saved sample takes at the run's peak: BYTES_PER_VALUE per float it holds (t, q, v, τ)
#: plus BYTES_PER_SAMPLE — the samples, the lists they are collected in and the result's arrays.
#: Measured with tracemalloc (two Pandas: 1 475 / 1 313 B per sample, Python / compiled loop;
#: the book's system: 435 / 561 B); ``tests/test_reliability.py`` checks the bound.
BYTES_PER_VALUE = 24.0
BYTES_PER_SAMPLE = 480.0


def check_budget(scene: Scene, t_final: float, dt: float, save_every: int, max_steps: Any, max_memory: Any) -> int | None:
    """Refuse a run that would not finish in reasonable time or memory, before it starts; returns the
    step budget (``None``: unlimited). An adaptive method's budget counts its attempts."""
    if max_steps is not None and not (type(max_steps) is int and max_steps > 0):  # (an int > 0 is already valid)
        max_steps = _validate.count(max_steps, "max_steps", SimulationError, none="no limit")
    if max_memory is not None and not (type(max_memory) is float and 1.0 <= max_memory < math.inf):
        max_memory = _validate.number(max_memory, "max_memory", "bytes", SimulationError)
        if not max_memory >= 1.0:
            raise SimulationError(f"max_memory must be at least 1 [byte] or None (no limit), got {max_memory:g}")
    ratio = t_final / dt
    if not ratio < 1e15 or (max_steps is not None and ratio > max_steps):
        limit = " (beyond what a run can count)" if max_steps is None else f", more than max_steps = {max_steps:,}"
        raise SimulationError(
            f"t_final / dt = {t_final:g} s / {dt:g} s asks for {ratio:.3g} steps{limit}. At ~10 µs per step (the "
            f"compiled loop on two Pandas; Python controllers cost ~10× more) that is {duration(ratio * 1e-5)} of CPU. "
            "Enlarge dt or shorten t_final, or pass max_steps=None (or a larger number) to run it anyway"
        )
    n_saved = step_count(t_final, dt) // save_every + 2
    values = 1 + scene.nq + scene.nv + scene.n_actuated
    memory = n_saved * (values * BYTES_PER_VALUE + BYTES_PER_SAMPLE)
    if max_memory is not None and memory > max_memory:
        suggest = math.ceil(save_every * memory / max_memory)
        raise SimulationError(
            f"saving {n_saved:,} samples of {values} values (t, q, v, τ) takes about {memory / 1e9:.3g} GB, more than "
            f"max_memory = {max_memory / 1e9:.3g} GB. Save fewer samples (save_every = {suggest} or more), shorten the run, "
            "or pass max_memory=None (or a larger number of bytes) to run it anyway"
        )
    return None if max_steps is None else int(max_steps)


def duration(seconds: float) -> str:
    """A rough duration for messages: ``"3.2 min"``, ``"5.1 h"``, ``"12 days"``."""
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 7200:
        return f"{seconds / 60:.3g} min"
    if seconds < 172800:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 86400:.3g} days"
