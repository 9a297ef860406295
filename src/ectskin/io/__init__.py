"""Recordings: the in-memory data objects and their on-disk formats (HDF5, imports)."""

from ectskin.io.recording import Recording, Trial

__all__ = ["Recording", "Trial"]
