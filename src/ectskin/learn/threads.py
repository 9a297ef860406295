"""The torch CPU thread policy: one place decides how many threads training and inference use.

``threads`` everywhere (``ectskin train/reproduce/demo/live --threads``, the Python API) means:

* an int ≥ 1: exactly that many torch CPU threads;
* ``"auto"``: 1 on machines with at most :data:`AUTO_ONE_THREAD_CORES` cores, else torch's
  default (one per core). The models are small: on a small shared CPU more threads only add
  OpenMP oversubscription (figures in ``BENCHMARKS.md``);
* ``None``: leave torch's current setting.

:func:`torch_threads` applies a value for the duration of a block and restores the previous
setting afterwards, so a library call never leaves the process changed.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

from ectskin._check import EctskinError

#: ``threads="auto"`` uses one torch thread on machines with at most this many cores.
AUTO_ONE_THREAD_CORES = 4

#: The thread count training uses when none is given: results depend on the thread count (float
#: reduction order), so a fixed default keeps runs reproducible.
TRAIN_DEFAULT_THREADS = 1


def resolve_threads(threads: int | str | None, *, name: str = "threads") -> int | None:
    """The torch thread count for ``threads`` (see the module docstring); None = leave as is."""
    if threads == "auto":
        return 1 if (os.cpu_count() or 1) <= AUTO_ONE_THREAD_CORES else None
    if threads is None:
        return None
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise EctskinError(f"{name} must be an integer >= 1, 'auto' or None, got {threads!r}")
    return threads


@contextmanager
def torch_threads(threads: int | str | None) -> Iterator[int]:
    """Run the block with the torch CPU threads that ``threads`` resolves to; yield the count."""
    n = resolve_threads(threads)
    before = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(n)
    try:
        yield torch.get_num_threads()
    finally:
        torch.set_num_threads(before)
