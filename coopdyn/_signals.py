"""Signals (internal): Ctrl-C held while something must not be cut in half; SIGTERM and SIGHUP as an interrupt."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


@contextmanager
def interrupts_deferred(reraise: bool = True) -> Iterator[None]:
    """Hold SIGINT (Ctrl-C) for the duration of the block: a partial result being assembled or a
    file being written is finished first. With ``reraise``, a Ctrl-C that arrived meanwhile is
    raised as ``KeyboardInterrupt`` when the block ends; without, it is dropped (the caller is
    already stopping because of one). Only the main thread receives signals; elsewhere this does
    nothing."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        yield  # elsewhere signals do not arrive; an ignored SIGINT stays ignored
        return
    pending: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        pending.append(signum)

    previous = signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)
    if pending and reraise:
        raise KeyboardInterrupt("Ctrl-C arrived while writing; the writing was finished first")


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM (a killed job) and SIGHUP (a closed terminal) raise ``KeyboardInterrupt`` inside
    the block, like Ctrl-C, so that what handles Ctrl-C runs (a partial run or table is saved,
    the viewer stops its server). A signal already ignored stays ignored (``nohup``)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"{signal.Signals(signum).name} received")

    caught = [
        s
        for s in (signal.SIGTERM, getattr(signal, "SIGHUP", None))
        if s is not None and signal.getsignal(s) is not signal.SIG_IGN
    ]
    previous = {s: signal.signal(s, interrupt) for s in caught}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
