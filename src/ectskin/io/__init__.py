"""Recordings: the in-memory data objects and their on-disk formats (HDF5, imports).

:func:`read_recording` is the one entry point for a recording file of any supported type: it
dispatches on the file's suffix (HDF5 ``.h5``/``.hdf5`` → :mod:`ectskin.io.hdf5`; generic
``.npz``/``.csv`` → :mod:`ectskin.io.generic`).

Modules, by job:

* :mod:`~ectskin.io.recording`: :class:`Recording` and :class:`Trial` (its fingers on an axis,
  :meth:`Trial.finger` gives one as a :class:`FingerTruth`), checked at construction, and
  :func:`require_ground_truth` for code that needs the fingers' per-frame ground truth;
* :mod:`~ectskin.io.hdf5`: the recording file format (schema, reader, batch and append writers);
* :mod:`~ectskin.io.generic`: recordings from other sources in a documented NPZ/CSV layout;
* :mod:`~ectskin.io.capmeter`, :mod:`~ectskin.io.motive`: instrument exports (capacitance meter,
  OptiTrack Motive), one package per vendor format, on the shared text helpers of
  :mod:`~ectskin.io.text` and the frame-rate checks of :mod:`~ectskin.io.frame_rate` (which the
  generic readers share);
* :mod:`~ectskin.io.align`: the delay between the two instruments, and a recording built from them;
* :mod:`~ectskin.io.calibration`: paper Eq. 2 and the choice of the reference state.
"""

from __future__ import annotations

import os
from pathlib import Path

from ectskin._check import EctskinError
from ectskin.io import hdf5
from ectskin.io.generic import load_generic
from ectskin.io.hdf5 import RecordingWriter, list_trials, read_layout, write_recording
from ectskin.io.recording import (
    GROUND_TRUTH_FIELDS,
    FingerTruth,
    Recording,
    Trial,
    require_ground_truth,
)

#: Suffixes :func:`read_recording` takes, by reader.
GENERIC_SUFFIXES = (".npz", ".csv")


def read_recording(path: str | os.PathLike, **kwargs) -> Recording:
    """The :class:`Recording` in ``path``: HDF5 (any other suffix) or a generic ``.npz``/``.csv``.

    Keyword arguments go to the reader (e.g. ``allow_partial`` for HDF5).
    """
    path = Path(os.fspath(path))
    if not path.exists():
        raise EctskinError(f"{path}: no such data file")
    if path.suffix.lower() in GENERIC_SUFFIXES:
        return load_generic(path, **kwargs)
    return hdf5.read_recording(path, **kwargs)


__all__ = [
    "GROUND_TRUTH_FIELDS",
    "FingerTruth",
    "Recording",
    "RecordingWriter",
    "Trial",
    "list_trials",
    "read_layout",
    "read_recording",
    "require_ground_truth",
    "write_recording",
]
