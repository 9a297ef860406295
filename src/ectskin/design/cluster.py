"""Where design sweeps run: Dask distributed (a ``LocalCluster`` by default, or a scheduler).

Scoring a layout is one task (:func:`ectskin.design.score.score_layout`); each worker process
runs one task at a time on one thread (torch and BLAS limited to one thread per task), so
``n_workers`` is the number of layouts scored at once. ``scheduler="tcp://HOST:PORT"`` connects
to a running ``dask scheduler`` (its workers must have ectskin installed); an unreachable
address is one :class:`~ectskin._check.EctskinError` naming it, after ``CONNECT_TIMEOUT_S``.
``n_workers=0`` and no scheduler runs the tasks in this process, one after another (the serial
reference the tests compare the cluster against).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from typing import Any

from ectskin._check import EctskinError
from ectskin._dask import dask_client

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S = 5.0  # (assumed) long enough for a scheduler on a LAN to answer


class SerialRunner:
    """Runs tasks in this process, in order (``n_workers=0``)."""

    n_workers = 1
    address = "serial"

    def stream(self, fn: Callable, next_job: Callable[[], tuple | None]) -> Iterator[tuple]:
        """Yield ``(job, fn(*job))`` for each job ``next_job()`` gives until it gives None."""
        while (job := next_job()) is not None:
            yield job, fn(*job)


class DaskRunner:
    """Runs tasks on a Dask ``Client``; results come back as they finish."""

    def __init__(self, client) -> None:
        self.client = client
        self.address = client.scheduler.address
        self.n_workers = max(1, len(client.scheduler_info(n_workers=-1).get("workers", {})))

    def stream(self, fn: Callable, next_job: Callable[[], tuple | None]) -> Iterator[tuple]:
        """Yield ``(job, fn(*job))`` as tasks finish, keeping ``n_workers`` tasks in flight;
        ``next_job()`` gives the next job (it may depend on the results so far) or None. A
        task's error is raised here, and the tasks still in flight are cancelled."""
        from distributed import as_completed

        pending: dict[str, tuple] = {}
        done = as_completed()

        def fill() -> None:
            while len(pending) < self.n_workers and (job := next_job()) is not None:
                fut = self.client.submit(fn, *job, pure=False)
                pending[fut.key] = (job, fut)
                done.add(fut)

        fill()
        try:
            for fut in done:
                job, _ = pending.pop(fut.key)
                yield job, fut.result()
                fill()
        finally:
            for _, f in pending.values():
                f.cancel()


def iter_jobs(jobs) -> Callable[[], tuple | None]:
    """``next_job`` over a fixed list of jobs."""
    it = iter(jobs)
    return lambda: next(it, None)


@contextlib.contextmanager
def open_runner(n_workers: int = 2, scheduler: str | None = None) -> Iterator[Any]:
    """A :class:`DaskRunner` on a new ``LocalCluster`` of ``n_workers`` single-threaded worker
    processes, or on the scheduler at ``scheduler``; a :class:`SerialRunner` for
    ``n_workers=0`` without a scheduler. Closes what it opened."""
    if scheduler is None and (not isinstance(n_workers, int) or n_workers < 0):
        raise EctskinError(f"--workers must be an integer >= 0, got {n_workers!r}")
    if scheduler is None and n_workers == 0:
        yield SerialRunner()
        return
    with dask_client(
        n_workers, scheduler, timeout_s=CONNECT_TIMEOUT_S, what="design"
    ) as client:
        yield DaskRunner(client)
