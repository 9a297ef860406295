"""Keep freed heap memory in the process instead of handing every large array back to the kernel.

The method of moments builds and frees dense matrices of tens of MB per solve. glibc's default
serves an allocation that large with a fresh ``mmap`` and returns it with ``munmap`` when freed,
so the kernel zero-fills every page of every matrix again: on this project's solved sliding
trials a third of the CPU time was system time (BENCHMARKS.md). :func:`keep_freed_memory` raises
glibc's mmap and trim thresholds (``mallopt``) so that freed blocks are reused from the heap;
:data:`MALLOC_ENV` does the same for a process started with it in its environment (the Dask
workers). The price: a process keeps up to :data:`LIMIT_BYTES` of freed memory it does not give
back until it exits. Outside Linux/glibc both are no-ops.
"""

from __future__ import annotations

import ctypes
import sys

#: freed memory a process may keep (and the size below which arrays come from the heap)
LIMIT_BYTES = 1 << 30
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
#: the same settings as environment variables, read by glibc when a process starts
MALLOC_ENV = {
    "MALLOC_MMAP_THRESHOLD_": str(LIMIT_BYTES),
    "MALLOC_TRIM_THRESHOLD_": str(LIMIT_BYTES),
    "MALLOC_TOP_PAD_": str(1 << 28),
}


def keep_freed_memory() -> bool:
    """Set this process's glibc thresholds (module docstring); True if glibc took them."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):  # not glibc (e.g. musl)
        return False
    settings = ((_M_MMAP_THRESHOLD, LIMIT_BYTES), (_M_TRIM_THRESHOLD, LIMIT_BYTES),
                (_M_TOP_PAD, 1 << 28))
    return all(mallopt(option, value) == 1 for option, value in settings)
