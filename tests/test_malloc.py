"""``ectskin._malloc``: with glibc's thresholds raised, a large array comes from the heap (and is
reused from it when freed) instead of a fresh ``mmap`` that the kernel zero-fills page by page.

Read from glibc's own accounting (``mallinfo2``: ``hblkhd``, the bytes held in mmapped blocks)
while a 40 MB array is alive, in a fresh process, without and with :func:`keep_freed_memory`
(and with :data:`MALLOC_ENV`, the Dask workers' form). 40 MB is above glibc's largest dynamic
mmap threshold (32 MiB), so by default it is always mapped. Catches a wrong ``mallopt`` option
number or a threshold below the array's size. (Page-fault counts were tried first: the kernel's
huge pages made them vary tenfold between runs.)"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from ectskin._malloc import MALLOC_ENV, keep_freed_memory

MAPPED = """
import ctypes, sys
import numpy as np
from ectskin._malloc import keep_freed_memory

class Mallinfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]

mallinfo2 = ctypes.CDLL("libc.so.6").mallinfo2
mallinfo2.restype = Mallinfo2
if sys.argv[1] == "keep":
    assert keep_freed_memory()
a = np.ones(5_000_000)  # 40 MB
print(mallinfo2().hblkhd)
"""


def _mapped_bytes(mode: str, env: dict[str, str] | None = None) -> int:
    if env is None:  # glibc's defaults, whatever this process was started with
        env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run([sys.executable, "-c", MAPPED, mode], capture_output=True, text=True,
                         check=True, env=env)
    return int(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_a_large_array_comes_from_the_heap_not_a_fresh_mmap():
    size = 5_000_000 * 8
    assert _mapped_bytes("default") >= size  # glibc's default: mapped anew
    assert _mapped_bytes("keep") < size  # from the heap, reused when freed
    assert _mapped_bytes("default", {**os.environ, **MALLOC_ENV}) < size
    assert keep_freed_memory() is True


def _worker_mapped_bytes(script: str) -> int:
    """``script`` (:data:`MAPPED`) run in this process (a Dask worker): the bytes it prints."""
    import contextlib
    import io
    import sys

    out, argv = io.StringIO(), sys.argv
    sys.argv = ["", "default"]  # glibc as the worker started
    try:
        with contextlib.redirect_stdout(out):
            exec(script, {"__name__": "mapped"})
    finally:
        sys.argv = argv
    return int(out.getvalue().strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_the_dask_workers_start_with_the_thresholds():
    """A Dask nanny applies its ``env`` inside the worker after the start, too late for glibc, and
    its own pre-spawn ``MALLOC_TRIM_THRESHOLD_`` turns the adaptive threshold off: the worker of
    :func:`ectskin._dask.dask_client` must hold a 40 MB array in the heap, not in a mapping.
    Catches MALLOC_ENV passed as the cluster's ``env`` only (what the code did)."""
    from ectskin._dask import dask_client

    fn = _worker_mapped_bytes
    fn.__module__ = "__main__"  # shipped by value: the worker need not import the tests
    before = {k: v for k, v in os.environ.items() if k.startswith("MALLOC_")}
    with dask_client(1) as client:
        held = client.submit(fn, MAPPED, pure=False).result()
    assert held < 5_000_000 * 8
    # and this process's own environment is left as it was
    assert {k: v for k, v in os.environ.items() if k.startswith("MALLOC_")} == before
