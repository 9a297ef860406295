"""Dask distributed clients for the project's parallel work (layout sweeps, response fields).

:func:`dask_client` opens a new ``LocalCluster`` of single-threaded worker processes (BLAS
limited to one thread each: the workers are the parallelism), or connects to a running scheduler
(``tcp://HOST:PORT``, a real cluster), and closes what it opened. Deferred imports: the package
starts without Dask.

The workers keep freed heap memory (:mod:`ectskin._malloc`). glibc reads its thresholds when a
process starts, and a Dask nanny applies its ``env`` only inside the worker, after the start, while
its own ``pre-spawn-environ`` (``MALLOC_TRIM_THRESHOLD_=65536``) reaches the start and turns off
glibc's adaptive mmap threshold: every array above 128 KiB was then mapped and zero-filled anew
(a cold build of the reproduction's response fields spent 330 of 808 CPU-s in the kernel,
BENCHMARKS.md). So :data:`~ectskin._malloc.MALLOC_ENV` goes into the local cluster's
pre-spawn environment, and the workers of a given scheduler set the same thresholds at run time
(:func:`~ectskin._malloc.keep_freed_memory`).
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator
from typing import Any

from ectskin._check import EctskinError
from ectskin._malloc import MALLOC_ENV, keep_freed_memory

log = logging.getLogger(__name__)

#: seconds a scheduler (and, where asked, its first worker) has to answer (assumed: long enough
#: for a scheduler on a LAN)
CONNECT_TIMEOUT_S = 10.0


@contextlib.contextmanager
def _restored(saved: dict[str, str | None]) -> Iterator[None]:
    """Put the environment variables ``saved`` (name → value, None: unset) back on exit."""
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@contextlib.contextmanager
def dask_client(
    n_workers: int,
    scheduler: str | None = None,
    *,
    option: str = "--scheduler",
    wait_for_workers: bool = False,
    timeout_s: float | None = None,
    what: str = "Dask",
) -> Iterator[Any]:
    """A ``distributed.Client``: on the scheduler at ``scheduler`` if given, else on a new
    ``LocalCluster`` of ``n_workers`` single-threaded processes. ``option`` names the setting in
    errors; ``wait_for_workers``: a scheduler must have a worker within the timeout;
    ``what`` names the work in the log."""
    import dask
    from distributed import Client, LocalCluster

    timeout = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    logging.getLogger("distributed").setLevel(logging.WARNING)
    if scheduler is not None:
        if not isinstance(scheduler, str) or not scheduler.startswith(("tcp://", "tls://")):
            raise EctskinError(f"{option}: expected an address like tcp://HOST:PORT, got {scheduler!r}")
        try:
            client = Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError) as exc:
            raise EctskinError(
                f"{option} {scheduler}: no Dask scheduler answered within {timeout:g} s "
                f"({type(exc).__name__}: {exc}); start one with `dask scheduler` and workers "
                f"with `dask worker {scheduler}`, or leave {option} out for a local cluster"
            ) from None
        try:
            client.run(keep_freed_memory)  # the workers already there (module docstring)
            if wait_for_workers:
                try:
                    client.wait_for_workers(1, timeout=timeout)
                except TimeoutError:
                    raise EctskinError(
                        f"{option} {scheduler}: no worker joined within {timeout:g} s; start "
                        f"some with `dask worker {scheduler}`"
                    ) from None
            yield client
        finally:
            client.close()
        return
    threads = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    pre_spawn = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **threads, **MALLOC_ENV}
    # the nanny writes its pre-spawn environment into this process's before each start; what
    # this process had is put back after (its later children get their own settings)
    saved = {k: os.environ.get(k) for k in pre_spawn}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": pre_spawn}), _restored(saved):
        cluster = LocalCluster(
            n_workers=n_workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # any free port: never clashes with another cluster
            silence_logs=logging.WARNING,
            env=threads,
        )
    client = Client(cluster)
    log.info("%s: LocalCluster with %d worker(s) at %s", what, n_workers, cluster.scheduler_address)
    try:
        yield client
    finally:
        client.close()
        cluster.close()
