"""The progress bar on screen, and warnings that print around it instead of through it (internal).

A warning printed while a tqdm bar is drawn lands on the bar's line; :func:`warn` clears the bar,
warns (the text on lines of its own, pointing at the caller's line) and redraws the bar below —
what ``tqdm.write`` does for ``print``.
"""

from __future__ import annotations

import contextlib
import sys
import warnings
from collections.abc import Iterator
from typing import Any

_shown: list[Any] = []  #: the bars on screen, innermost last


@contextlib.contextmanager
def showing(bar: Any) -> Iterator[None]:
    """While in the block, warnings from :func:`warn` print around ``bar`` (None: no bar)."""
    if bar is None:
        yield
        return
    _shown.append(bar)
    try:
        yield
    finally:
        _shown.remove(bar)


def warn(message: str, category: type[Warning], stacklevel: int | None = 1) -> None:
    """``warnings.warn(message, category, stacklevel)`` (the level counted from the caller of
    this function; ``None``: the first frame outside coopdyn, the user's call however deep in
    coopdyn the warning arose), clearing the bar on screen first and redrawing it after."""
    if stacklevel is None:
        stacklevel, frame = 1, sys._getframe(1)
        while frame.f_back is not None and frame.f_globals.get("__name__", "").partition(".")[0] == "coopdyn":
            stacklevel, frame = stacklevel + 1, frame.f_back
    bar = _shown[-1] if _shown else None
    if bar is not None:
        bar.clear()
    try:
        warnings.warn(message, category, stacklevel=stacklevel + 1)
    finally:
        if bar is not None:
            bar.refresh()
