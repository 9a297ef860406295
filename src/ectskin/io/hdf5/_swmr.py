"""Opening a file for SWMR reading with a bounded number of metadata read attempts.

HDF5's default for a SWMR reader (100 attempts with doubling sleeps) turns a truncated file into
an endless wait; a few attempts suffice for a live writer's torn reads. h5py does not wrap
``H5Pset_metadata_read_attempts``, so it is called through ``ctypes`` from the HDF5 library that
h5py loaded. Where that symbol cannot be found (e.g. on Windows, where ``ctypes`` does not search
h5py's dependencies) the reader falls back to HDF5's default.
"""

from __future__ import annotations

import ctypes
import functools
import logging
import os
from pathlib import Path

import h5py

logger = logging.getLogger(__name__)

#: Metadata read attempts of a SWMR reader.
SWMR_READ_ATTEMPTS = 10


@functools.cache
def _set_read_attempts_fn():
    """``H5Pset_metadata_read_attempts`` of the HDF5 library h5py uses, or None."""
    try:
        fn = ctypes.CDLL(h5py.h5p.__file__).H5Pset_metadata_read_attempts
    except (OSError, AttributeError):
        logger.debug("H5Pset_metadata_read_attempts not found; SWMR reads use HDF5's default")
        return None
    fn.argtypes = [ctypes.c_int64, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def open_swmr(p: Path) -> h5py.File:
    """Open a file that a SWMR writer holds (or held when it was killed) for SWMR reading."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fn = _set_read_attempts_fn()
    if fn is not None:
        fn(fapl.id, SWMR_READ_ATTEMPTS)
    fid = h5py.h5f.open(os.fsencode(p), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)
