"""Run jobs in worker processes that die with their driver (the twin's parallel driver).

Workers die with the driver. A worker blocks on the task queue, whose pipe every worker holds
open too, so it never sees the driver go: without the guards below a killed ``simulate`` left its
workers running for good. Linux kills a worker when its parent dies (prctl PR_SET_PDEATHSIG);
elsewhere a watchdog thread exits the worker once it is orphaned (its parent process changes),
and a worker whose driver died before it started exits at once. A driver that stops on an
exception (Ctrl-C) cancels the queued jobs and terminates its workers (:func:`_stop_workers`).

Each worker limits BLAS to one thread: the workers are the parallelism. With one worker the jobs
run in this process, BLAS limited only while they run.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from threadpoolctl import threadpool_limits

from ectskin._malloc import keep_freed_memory

log = logging.getLogger(__name__)

J = TypeVar("J")
R = TypeVar("R")

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_WATCHDOG_PERIOD_S = 0.5
_LIMITS: list[Any] = []  # the worker's BLAS thread limit, kept alive for the worker's life


def _die_with_parent(driver_pid: int) -> None:
    """End this worker process when its parent (the driver, or the driver's fork server) goes."""
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watchdog still works
            log.debug("prctl(PR_SET_PDEATHSIG) unavailable; relying on the watchdog")
    try:
        os.kill(driver_pid, 0)
    except ProcessLookupError:  # the driver died before this worker started
        os._exit(1)
    except OSError:
        pass

    def watch() -> None:
        while os.getppid() == parent:  # an orphan is adopted by another process
            time.sleep(_WATCHDOG_PERIOD_S)
        os._exit(1)

    threading.Thread(target=watch, name="ectskin-worker-watchdog", daemon=True).start()


def _stop_workers(ex: ProcessPoolExecutor) -> None:
    """Cancel the queued jobs and terminate the running workers now (not after their jobs)."""
    # (taken before the shutdown: ProcessPoolExecutor.shutdown sets _processes to None, and the
    # workers would then run their current jobs to the end, minutes for a sliding touch trial)
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=5)


def _start_worker(driver_pid: int, init: Callable[..., None], initargs: tuple) -> None:
    _die_with_parent(driver_pid)
    keep_freed_memory()
    _LIMITS.append(threadpool_limits(1))
    init(*initargs)


def run_in_workers(
    run: Callable[[J], R],
    jobs: Iterable[J],
    *,
    workers: int,
    init: Callable[..., None],
    initargs: tuple = (),
) -> Iterator[R]:
    """Yield ``run(job)`` for each job, in order, from ``workers`` processes.

    ``init(*initargs)`` prepares each worker (module-level state that ``run`` reads); ``run`` and
    ``init`` must be module-level functions (they are pickled by name). With ``workers == 1``
    everything runs in this process.
    """
    if workers == 1:
        init(*initargs)
        with threadpool_limits(1):
            for job in jobs:
                yield run(job)
        return
    ex = ProcessPoolExecutor(workers, initializer=_start_worker, initargs=(os.getpid(), init, initargs))
    try:
        yield from ex.map(run, jobs, chunksize=1)
    except BaseException:
        _stop_workers(ex)
        raise
    ex.shutdown()
