"""Recordings: the in-memory data objects and their on-disk formats (HDF5, imports)."""

from ectskin.io.hdf5 import (
    RecordingWriter,
    list_trials,
    read_layout,
    read_recording,
    write_recording,
)
from ectskin.io.recording import Recording, Trial

__all__ = [
    "Recording",
    "RecordingWriter",
    "Trial",
    "list_trials",
    "read_layout",
    "read_recording",
    "write_recording",
]
