"""``ectskin._malloc``: with glibc's thresholds raised, a large array freed and allocated again
comes from the heap instead of a fresh mmap that the kernel zero-fills page by page. Measured by
the page faults (``ru_minflt``) of 30 allocate-fill-free cycles of a 40 MB array in a fresh
process, with and without :func:`keep_freed_memory`. Catches a wrong ``mallopt`` option number or
a threshold below the array's size (then every cycle faults its pages in again)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from ectskin._malloc import MALLOC_ENV, keep_freed_memory

CYCLES = """
import resource, sys
import numpy as np
from ectskin._malloc import keep_freed_memory
if sys.argv[1] == "keep":
    assert keep_freed_memory()
np.ones(5_000_000).sum()  # the first one faults in either way
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(30):
    a = np.ones(5_000_000)  # 40 MB: above glibc's largest dynamic mmap threshold (32 MiB)
    del a
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str, env: dict[str, str] | None = None) -> int:
    out = subprocess.run([sys.executable, "-c", CYCLES, mode], capture_output=True, text=True,
                         check=True, env=env)
    return int(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_arrays_are_reused_not_faulted_in_again():
    import os

    default = _faults("default")
    kept = _faults("keep")
    # glibc's default maps every cycle's array anew and faults it in (17 040 faults measured:
    # fewer than its 9 766 pages per cycle where the kernel backs it with huge pages)
    assert default > 30 * 100
    assert kept < 100  # reused from the heap: no new page after the first array (0 measured)
    # the environment form (what the Dask workers get) does the same
    assert _faults("default", {**os.environ, **MALLOC_ENV}) < 100
    assert keep_freed_memory() is True
