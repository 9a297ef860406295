"""Write a whole :class:`~ectskin.io.recording.Recording` to an HDF5 file, atomically.

The file is built in memory (HDF5's ``core`` driver without a backing store, :func:`file_image`),
marked ``complete``, and its bytes are written by :func:`ectskin._files.atomic_write`: a hidden
temporary file, fsynced and renamed onto the target. The frames are stored gzip-compressed in
chunks of about 256 KiB of capacitance.

Why in memory: HDF5 does not survive a failed write to disk. After a write that fails (a full
disk), closing the file flushes HDF5's caches onto the failing disk again, and a second failure
inside the library's close leaves its handles half released: releasing them later crashes the
process (a segfault with h5py 3.16 / HDF5 2.0). Built in memory, HDF5 never writes to disk; a full
disk is an ``OSError`` of a plain file write, which :func:`~ectskin._files.atomic_write` turns into
one clear error, removing the temporary file.
"""

from __future__ import annotations

import itertools
import logging
import os
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

import h5py
import numpy as np

from ectskin._check import EctskinError, check_type
from ectskin._files import atomic_write
from ectskin.io.hdf5.schema import (
    EVENTS_KEY,
    FINGER_FRAMES,
    OPTIONAL_FRAMES,
    check_events,
    create_frames,
    create_tables,
    finger_row,
    to_json,
    write_events,
    write_root,
)
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

_BATCH_CHUNK_BYTES = 256 * 1024  # target size of one capacitance chunk
_CORE_INCREMENT = 8 << 20  # the in-memory file grows by this many bytes at a time
_image_names = itertools.count()


def fsync_path(path: Path, directory: bool = False) -> None:
    """fsync a file (or, with ``directory``, a folder: best effort) by path."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # e.g. directories on Windows
        return
    try:
        os.fsync(fd)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(fd)


def file_image(build: Callable[[h5py.File], None], libver: tuple[str, str]) -> bytes:
    """The bytes of an HDF5 file that ``build(f)`` fills, built in memory (never on disk)."""
    name = f"ectskin-image-{os.getpid()}-{threading.get_ident()}-{next(_image_names)}"
    f = h5py.File(
        name, "w", driver="core", backing_store=False, block_size=_CORE_INCREMENT, libver=libver
    )
    with f:
        build(f)
        f.flush()
        return f.id.get_file_image()


def _trial_meta_json(t: Trial) -> str:
    return to_json(f"trial {t.name!r}: meta", t.meta)


def _check_target(path: Path, overwrite: bool) -> None:
    if path.is_dir():
        raise EctskinError(f"{path}: is a directory; expected the path of an .h5 file to write")
    if path.exists() and not overwrite:
        raise EctskinError(
            f"{path}: file exists; use overwrite=True (--overwrite on the command line) to "
            "replace it"
        )
    if not path.parent.is_dir():
        raise EctskinError(f"{path}: directory {path.parent} does not exist")


def write_recording(rec: Recording, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``rec`` to the HDF5 file ``path`` atomically and return the path.

    The file is built in memory, marked ``complete``, written to ``.<name>.tmp-<pid>`` in the
    same directory, flushed to disk (fsync) and renamed onto ``path`` with ``os.replace``: a crash
    or a full disk at any moment leaves either no file (or the old one) at ``path``, never a
    partial one, and the temporary file is removed on error. An existing ``path`` is refused unless
    ``overwrite=True``.

    ``rec.meta`` and every ``Trial.meta`` must hold JSON-able values (NumPy scalars and arrays are
    stored as numbers and lists). ``rec.meta["events"]``, if present, is a list of
    ``{"t_s": float, "trial": str | None, "text": str}`` and is stored in the ``/events`` table.
    """
    check_type("rec", rec, Recording)
    path = Path(os.fspath(path))
    _check_target(path, overwrite)
    # Re-run the Recording checks (trials may have been edited since it was built).
    rec = Recording(rec.layout, list(rec.trials), rec.frame_rate_hz, rec.meta)
    meta = dict(rec.meta)
    events = (
        check_events(meta.pop(EVENTS_KEY), [t.name for t in rec.trials])
        if EVENTS_KEY in meta
        else []
    )
    meta_json = to_json("recording meta", meta)
    for t in rec.trials:  # fail on bad metadata before touching the disk
        _trial_meta_json(t)

    image = file_image(lambda f: _write_file(f, rec, meta_json, events), ("earliest", "v110"))
    atomic_write(path, lambda fh: fh.write(image), what="the recording")
    fsync_path(path.parent, directory=True)
    logger.info("wrote %s: %d trials, %d frames", path, rec.n_trials, rec.n_frames)
    return path


def _write_file(f: h5py.File, rec: Recording, meta_json: str, events: list) -> None:
    layout = rec.layout
    counts = np.array([t.n_frames for t in rec.trials], dtype=np.int64)
    starts = (
        np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if len(counts) else counts
    )
    n_frames = int(counts.sum())
    chunk = min(max(1, n_frames), max(1, _BATCH_CHUNK_BYTES // (8 * layout.n_pairs)))
    write_root(f, layout, rec.frame_rate_hz, meta_json, "write_recording")
    optional = [k for k in OPTIONAL_FRAMES if any(getattr(t, k) is not None for t in rec.trials)]
    if layout.n_markers == 0 and "markers" in optional:  # (n, 0, 3): nothing to store
        optional.remove("markers")
    width = max([1, *(t.n_fingers for t in rec.trials)])  # the fingers axis
    fds = create_frames(f, layout, n_frames, chunk, optional, compress=True, n_fingers=width)
    tds, eds = create_tables(f, rec.n_trials, 0, n_fingers=width)
    _write_trial_table(tds, rec.trials, starts, width)
    _write_frames(fds, layout, rec.trials, starts)
    write_events(eds, events)
    f["committed"][:] = [n_frames, rec.n_trials, len(events)]
    f.attrs["complete"] = np.bool_(True)


def _write_trial_table(
    tds: dict, trials: Sequence[Trial], starts: np.ndarray, width: int
) -> None:
    """The ``/trials`` rows; the per-finger columns padded to the fingers axis (``width``)."""
    if not trials:
        return
    tds["name"][:] = np.array([t.name for t in trials], dtype=object)
    tds["start"][:] = starts
    tds["region"][:] = np.array([t.region for t in trials], dtype=np.int32)
    for k, t in enumerate(trials):  # row by row: h5py would read equal lengths as a 2-D array
        tds["inflation_ml"][k] = np.asarray(t.inflation, dtype=np.float64)
    for k in OPTIONAL_FRAMES:
        tds[f"has_{k}"][:] = np.array([getattr(t, k) is not None for t in trials])
    tds["n_fingers"][:] = np.array([t.n_fingers for t in trials], dtype=np.int32)
    tds["finger_surface"][:] = np.array(
        [finger_row([s or "" for s in t.finger_surface], width, "") for t in trials], dtype=object
    )
    for k in ("finger_radius_mm", "finger_modulus_mpa"):
        tds[k][:] = np.array([finger_row(_values(getattr(t, k)), width, np.nan) for t in trials])
    tds["meta_json"][:] = np.array([_trial_meta_json(t) for t in trials], dtype=object)


def _values(per_finger: np.ndarray | None) -> list[float]:
    """A trial's per-finger numbers (None: unknown for every finger, stored as NaN)."""
    return [] if per_finger is None else [float(v) for v in per_finger]


def _write_frames(
    fds: dict, layout: SensorLayout, trials: Sequence[Trial], starts: np.ndarray
) -> None:
    """Copy every trial's arrays into the ``/frames`` datasets, one trial at a time."""
    for t, s in zip(trials, starts):
        e = s + t.n_frames
        if e == s:
            continue
        fds["capacitance"][s:e] = t.capacitance
        fds["timestamps"][s:e] = t.timestamps
        fds["labels"][s:e] = t.labels
        for k in OPTIONAL_FRAMES:
            value = getattr(t, k)
            if value is None or k not in fds or not value.size:  # (no markers in the layout,
                continue  # or a trial of 0 fingers)
            if k in FINGER_FRAMES:  # the trial's columns of the fingers axis
                fds[k][s:e, : t.n_fingers] = value
            else:
                fds[k][s:e] = value
