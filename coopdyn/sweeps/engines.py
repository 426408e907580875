"""Where a sweep's runs execute: in this process, in local worker processes, or on any
``concurrent.futures.Executor`` — a Dask ``Client`` among them. coopdyn schedules nothing
itself: it submits chunks of runs and collects their rows as they finish.

Each engine's :meth:`run` yields the rows of each chunk as it finishes, and turns a dying worker
into rows with status ``"crashed"`` instead of an exception:

* :class:`LocalProcesses` (the default) knows which run each worker process is running (a marker
  file per process): when a process dies, the pool is restarted, the runs that were in progress
  are run again one at a time in a pool of their own — the one that kills its process again is
  ``"crashed"``, with its exit code or signal — and every other run goes on as before.
* :class:`Executor` (any other executor) resubmits the runs of a chunk whose task failed one by
  one; a run whose own task fails is ``"crashed"`` with the executor's error (for Dask: the
  ``KilledWorker`` after the scheduler's retries).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import ctypes
import multiprocessing
import os
import shutil
import signal
import sys
import tempfile
import warnings
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from .. import _validate
from ..errors import SweepError
from .cases import Item, placeholder, run_chunk

Rows = list[dict[str, Any]]


def cpu_count() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def chunks(items: Sequence[Item], size: int) -> list[list[Item]]:
    return [list(items[i : i + size]) for i in range(0, len(items), size)]


def _describe_failure(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{type(exc).__name__}{': ' + text if text else ''}"


class Serial:
    """Every run in this process, one after the other (no pickling: any ``make_case`` works)."""

    workers = 1
    name = "this process (serial)"
    pickles = False

    def run(self, payload: Any, work: Sequence[list[Item]], trajectories: str | None) -> Iterator[Rows]:
        for chunk in work:
            yield run_chunk(payload, chunk, trajectories)

    def abort(self) -> None:
        pass

    def close(self) -> None:
        pass


_PAYLOAD: Any = None  #: a local worker's job, handed over once when its process starts


def _die_with_parent(parent: int) -> None:
    """On Linux, this process is killed when the sweep's process dies, however it dies (kill -9
    included): no worker runs on for nobody."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # pragma: no cover - a libc without prctl
        return
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)


PR_SET_PDEATHSIG = 1  #: prctl(2): the signal this process gets when its parent dies


def _worker_init(markers: str, payload: Any = None, parent: int | None = None) -> None:
    """A local worker: it dies with the sweep's process; Ctrl-C, SIGTERM and SIGHUP are the
    parent's to handle (it stops the pool); a fatal signal writes the Python stack to
    ``markers/<pid>.fault`` for the crashed row's message; ``payload`` is the job every chunk of
    this process runs (inherited under fork, pickled once under spawn)."""
    global _PAYLOAD
    _PAYLOAD = payload
    if parent is not None:
        _die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("SIGTERM", "SIGHUP"):  # under fork the parent's handlers were inherited: back to the defaults
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    import faulthandler

    faulthandler.enable(file=open(Path(markers) / f"{os.getpid()}.fault", "w"))


def _local_chunk(items: list[Item], trajectories: str | None, markers: str) -> Rows:
    """A local worker's task: ``items`` of the job it was started with."""
    return run_chunk(_PAYLOAD, items, trajectories, markers)


def _alone(payload: Any, item: Item, trajectories: str | None, markers: str, conn: Any, parent: int) -> None:
    """A process of its own for one run (a suspect of a crash): its rows back through ``conn``."""
    _worker_init(markers, parent=parent)
    try:
        conn.send(run_chunk(payload, [item], trajectories, markers))
    finally:
        conn.close()


class LocalProcesses:
    """Runs in ``workers`` processes on this machine (``fork`` where the platform has it safely,
    i.e. Linux: no re-import of the calling script; ``spawn`` elsewhere, where the script needs an
    ``if __name__ == "__main__":`` guard)."""

    pickles = True

    def __init__(self, workers: int | None = None) -> None:
        self.workers = cpu_count() if workers is None else _validate.count(workers, "workers", SweepError, none="every core")
        self.name = f"{self.workers} local process{'es' if self.workers > 1 else ''}"
        method = "fork" if sys.platform.startswith("linux") else "spawn"
        self._context: Any = multiprocessing.get_context(method)
        self._markers = tempfile.mkdtemp(prefix="coopdyn-sweep-")
        self._pool: cf.ProcessPoolExecutor | None = None
        self._solo: Any = None  #: the process running a suspect alone

    def _new_pool(self, payload: Any) -> cf.ProcessPoolExecutor:
        self._pool = cf.ProcessPoolExecutor(
            self.workers, mp_context=self._context, initializer=_worker_init, initargs=(self._markers, payload, os.getpid())
        )
        return self._pool

    def run(self, payload: Any, work: Sequence[list[Item]], trajectories: str | None) -> Iterator[Rows]:
        todo: deque[list[Item]] = deque(work)
        size = max(len(c) for c in work) if work else 1
        while todo:
            pool = self._new_pool(payload)  # the job once per process, not once per chunk
            futures = {pool.submit(_local_chunk, c, trajectories, self._markers): c for c in todo}
            todo.clear()
            lost: list[Item] = []
            for future in cf.as_completed(futures):
                try:
                    yield future.result()
                except BrokenProcessPool:
                    lost += futures[future]
                except Exception as exc:  # the chunk could not be sent or its rows not returned
                    yield [
                        placeholder(i, "crashed", f"the worker could not run it: {_describe_failure(exc)}")
                        for i in futures[future]
                    ]
            self._shutdown()
            if lost:
                running = self._running()
                suspects = [i for i in lost if i.run in running] or lost
                for item in suspects:
                    yield self._alone(payload, item, trajectories)
                rest = [i for i in lost if i not in suspects]
                todo.extend(chunks(rest, size))

    def _running(self) -> set[int]:
        """The runs the pool's processes were running when it broke (and clear the markers)."""
        running = set()
        for mark in Path(self._markers).iterdir():
            if mark.suffix != ".fault":
                with contextlib.suppress(OSError, ValueError):
                    text = mark.read_text().strip()
                    if text:
                        running.add(int(text))
            with contextlib.suppress(OSError):
                mark.unlink()
        return running

    def _alone(self, payload: Any, item: Item, trajectories: str | None) -> Rows:
        """Run one suspect in a process of its own: its rows, or a "crashed" row with the exit
        code or signal if it kills that process too."""
        receiver, sender = self._context.Pipe(duplex=False)
        process = self._context.Process(
            target=_alone, args=(payload, item, trajectories, self._markers, sender, os.getpid()), daemon=True
        )
        process.start()
        sender.close()
        self._solo = process
        try:
            rows = receiver.recv()
        except EOFError:  # it died before sending its row
            rows = None
        finally:
            receiver.close()
            process.join()
            self._solo = None
        if rows is None:
            code = process.exitcode or 0
            message = "the worker process running it died" + (f" ({_signal_name(-code)})" if code < 0 else f" (exit code {code})")
            rows = [placeholder(item, "crashed", message + self._fault_trace(process.pid))]
        self._running()  # (clears the markers)
        return rows

    def _fault_trace(self, pid: int | None) -> str:
        """The innermost frames faulthandler wrote for a process killed by a fatal signal."""
        try:
            content = (Path(self._markers) / f"{pid}.fault").read_text().strip()
        except OSError:
            return ""
        frames = [ln.strip() for ln in content.splitlines() if ln.strip().startswith("File ")]
        return f"; faulthandler: {' < '.join(frames[:3])}" if frames else ""

    def _shutdown(self) -> None:
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def abort(self) -> None:
        """Stop now (Ctrl-C): drop the queued runs and end the worker processes."""
        if self._solo is not None:
            self._solo.terminate()
        pool, self._pool = self._pool, None
        if pool is None:
            return
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            with contextlib.suppress(Exception):
                p.terminate()
        for p in processes:
            with contextlib.suppress(Exception):
                p.join(5)

    def close(self) -> None:
        self._shutdown()
        shutil.rmtree(self._markers, ignore_errors=True)


def _signal_name(number: int) -> str:
    try:
        return f"signal {number}, {signal.Signals(number).name}"
    except ValueError:
        return f"signal {number}"


class Executor:
    """Runs on any ``concurrent.futures.Executor`` (a thread pool, MPI, Dask's
    ``Client.get_executor()``); a Dask ``Client`` is taken as its executor."""

    pickles = True

    def __init__(self, executor: Any) -> None:
        self.client = None
        if hasattr(executor, "get_executor") and hasattr(executor, "scheduler_info"):  # a dask.distributed.Client
            self.client = executor
            executor = executor.get_executor(pure=False)  # a run submitted again runs again (no cached result)
        if not isinstance(executor, cf.Executor):
            raise SweepError(
                "executor must be None (local processes), 'serial', 'processes', a concurrent.futures.Executor or a "
                f"dask.distributed.Client; got {type(executor).__name__}"
            )
        self.executor = executor
        if self.client is not None:
            self.workers = max(1, sum(self.client.nthreads().values()))
            address = getattr(self.client.scheduler, "address", "?")
            self.name = f"Dask at {address} ({self.workers} worker thread{'s' if self.workers > 1 else ''})"
        else:
            self.workers = int(getattr(executor, "_max_workers", None) or cpu_count())
            self.name = f"{type(executor).__name__} ({self.workers} workers)"
        self._futures: dict[cf.Future[Rows], list[Item]] = {}  #: submitted, not yet collected

    def run(self, payload: Any, work: Sequence[list[Item]], trajectories: str | None) -> Iterator[Rows]:
        if self.client is not None:  # on Dask: the job to every worker once, each chunk refers to it
            payload = self.client.scatter(payload, broadcast=True)
        try:
            futures = self._futures = {self.executor.submit(run_chunk, payload, c, trajectories): c for c in work}
        except (AssertionError, RuntimeError) as exc:  # e.g. a process pool inside a daemonic process
            raise SweepError(
                f"the executor cannot take the sweep's runs here ({_describe_failure(exc)}); in a daemonic process (a "
                "pool's worker) use executor='serial' or executor=None"
            ) from exc
        while futures:
            done, _ = cf.wait(futures, return_when=cf.FIRST_COMPLETED)
            for future in done:
                chunk = futures.pop(future)
                try:
                    yield future.result()
                except cf.CancelledError:
                    continue
                except cf.BrokenExecutor as exc:  # this executor takes no more work: the rest cannot run
                    rest = [i for c in (chunk, *futures.values()) for i in c]
                    futures.clear()
                    why = (
                        f"the executor broke ({_describe_failure(exc)}); with executor=None coopdyn's own process pool "
                        "runs the others on"
                    )
                    yield [placeholder(i, "crashed", why) for i in rest]
                except Exception as exc:
                    if len(chunk) > 1:  # find the run that fails: each on its own
                        for item in chunk:
                            f = self.executor.submit(run_chunk, payload, [item], trajectories)
                            futures[f] = [item]
                    else:
                        yield [placeholder(chunk[0], "crashed", f"its task failed: {_describe_failure(exc)}")]

    def abort(self) -> None:
        for future in self._futures:
            future.cancel()
        if self.client is not None:  # its futures are Dask's: cancel them on the cluster
            with contextlib.suppress(Exception):
                self.executor.shutdown(wait=False)

    def close(self) -> None:
        pass


def engine(executor: Any, workers: int | None) -> Serial | LocalProcesses | Executor:
    """The engine for ``sweep(executor=…)``."""
    name = executor if isinstance(executor, str) else None  # `==` on an array or a Series is not a bool
    if executor is None or name == "processes":
        if multiprocessing.current_process().daemon:  # e.g. inside another pool's worker: it may not start processes
            warnings.warn(
                "this sweep runs inside a daemonic process (a worker of a multiprocessing pool?), which may not start "
                "processes of its own: its runs go one after the other in this process (executor='serial')",
                RuntimeWarning,
                stacklevel=4,
            )
            return Serial()
        return LocalProcesses(workers)
    if workers is not None:  # it would size nothing: the executor has its own workers
        raise SweepError(f"workers sizes the local processes (executor='processes'); executor={executor!r} has its own")
    if name == "serial":
        return Serial()
    if name is not None:
        raise SweepError(f"unknown executor {executor!r}: give 'processes' (default), 'serial', an Executor or a Dask Client")
    return Executor(executor)
