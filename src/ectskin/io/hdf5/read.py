"""Read HDF5 recordings: the whole :class:`Recording`, or only its layout or trial list.

A file of a running (or killed) :class:`~ectskin.io.hdf5.append.RecordingWriter` is opened in
SWMR mode (:mod:`ectskin.io.hdf5._swmr`). Every problem with a file is one
:class:`~ectskin.EctskinError` naming the file and the field; no h5py or OS traceback escapes for
bad input.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import h5py

from ectskin._check import EctskinError
from ectskin.io.hdf5._swmr import open_swmr
from ectskin.io.hdf5.reader import FileReader
from ectskin.io.hdf5.schema import EVENTS_KEY
from ectskin.io.recording import Recording
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

T = TypeVar("T")


def _open_error(p: Path, exc: OSError) -> EctskinError:
    """One clear message for an HDF5 file that does not open."""
    msg = str(exc)
    if "truncated" in msg:
        detail = msg[msg.find("truncated") :].rstrip(")")
        return EctskinError(
            f"{p}: not an HDF5 file (or truncated): the file is shorter than its header says "
            f"({detail}); was it copied completely?"
        )
    if "signature" in msg:
        return EctskinError(f"{p}: not an HDF5 file (or truncated): no HDF5 signature found")
    if "lock" in msg:
        return EctskinError(f"{p}: cannot open, the file is locked by another process ({msg})")
    return EctskinError(f"{p}: not an HDF5 file (or truncated): {msg}")


def _open_file(p: Path) -> h5py.File:
    try:
        return h5py.File(p, "r")
    except OSError as exc:
        if "already open" not in str(exc):
            raise
    # HDF5 marks a file open for writing; only a SWMR writer's file may be read meanwhile.
    try:
        return open_swmr(p)
    except OSError as exc:
        if "already open" in str(exc):
            raise EctskinError(
                f"{p}: another program has this file open for writing (or crashed while "
                f"writing it without SWMR); if none does, clear the flag with `h5clear -s {p}`"
            ) from None
        raise


def open_recording(path: str | os.PathLike) -> tuple[h5py.File, Path]:
    """Open ``path`` read-only; a file of a running or killed SWMR writer opens in SWMR mode."""
    p = Path(os.fspath(path))
    if not p.exists():
        raise EctskinError(f"{p}: no such file")
    if p.is_dir():
        raise EctskinError(f"{p}: is a directory, expected an .h5 recording")
    try:
        return _open_file(p), p
    except PermissionError:
        raise EctskinError(f"{p}: cannot read (permission denied)") from None
    except OSError as exc:
        raise _open_error(p, exc) from None


def guarded(path: str | os.PathLike, fn: Callable[[FileReader], T]) -> T:
    """Run ``fn(reader)`` on the open file; damaged-file errors become one EctskinError."""
    f, p = open_recording(path)
    reader = FileReader(f, p)
    try:
        with f:
            return fn(reader)
    except EctskinError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError) as exc:
        raise EctskinError(
            f"{p}: cannot read {reader.field}: the file is damaged or truncated "
            f"({type(exc).__name__}: {exc})"
        ) from None


def read_recording(
    path: str | os.PathLike, *, allow_partial: bool = False, trials: Sequence[str] | None = None
) -> Recording:
    """Read an HDF5 recording written by ``write_recording`` or ``RecordingWriter``.

    The schema is checked first; a file that is not HDF5, truncated, of another format or a
    newer ``format_version``, or whose datasets disagree with its layout, raises one
    :class:`EctskinError` naming the file and the field. A file whose writer did not close it
    (``complete=False``: crashed, killed or still running) is refused unless ``allow_partial``,
    in which case every committed frame is returned (all frames up to the writer's last flush).

    ``trials``: names of the trials to load (in that order); default all, in file order.
    Arrays are returned exactly as written (float64 capacitance in pF, timestamps in s, int16
    labels, markers in mm, and on the fingers axis force in N and the finger ground truth).
    Events, if any, are in ``meta["events"]`` as a list of
    ``{"t_s": float, "trial": str | None, "text": str}``. Files of format version 1 predate the
    finger ground truth: their trials have ``contact``, ``finger_uv_mm`` and ``finger_height_mm``
    None. Files of versions 1 to 3 give one finger per trial, a version-3 trial's second finger
    as finger 1 (``docs/recording-format.md``, "Versioning"). The recording's ``source`` is
    ``path`` and its ``format_version`` the file's.
    """

    def run(r: FileReader) -> Recording:
        head = r.header(allow_partial)
        layout = r.layout()
        index = r.index(layout, head["complete"])
        rows = _select(r, index["trials"], trials)
        meta = dict(head["meta"])
        if index["events"]:
            meta[EVENTS_KEY] = index["events"]
        loaded = r.trials(layout, index, rows)
        r.field = "/"
        try:
            return Recording(
                layout,
                loaded,
                head["frame_rate_hz"],
                meta,
                source=str(r.path),
                format_version=head["version"],
            )
        except EctskinError as exc:
            raise r.fail(str(exc)) from None

    rec = guarded(path, run)
    logger.info("read %s: %d trials, %d frames", path, rec.n_trials, rec.n_frames)
    return rec


def _select(r: FileReader, rows: list[dict], names: Sequence[str] | None) -> list[dict]:
    if names is None:
        return rows
    by_name = {row["name"]: row for row in rows}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise r.fail(f"no trial named {missing[0]!r} (the file has {len(rows)} trials)")
    return [by_name[n] for n in names]


def read_layout(path: str | os.PathLike) -> SensorLayout:
    """The :class:`SensorLayout` stored in a recording (complete or not), without its frames."""

    def run(r: FileReader) -> SensorLayout:
        r.header(allow_partial=True)
        return r.layout()

    return guarded(path, run)


def list_trials(path: str | os.PathLike, *, allow_partial: bool = False) -> list[dict[str, Any]]:
    """One dict per trial, in file order, without loading any frame.

    Keys: ``name``, ``n_frames``, ``region``, ``inflation`` (tuple, ml), ``start_frame`` (row in
    ``/frames``), ``has_markers``, ``has_force``, ``has_contact``, ``has_finger_uv_mm``,
    ``has_finger_height_mm`` (all False in a version-1 file), ``n_fingers``, and per finger (a
    tuple of ``n_fingers``) ``finger_surface`` (str or None), ``finger_radius_mm`` and
    ``finger_modulus_mpa`` (NaN = unknown); ``meta``. Incomplete files as in
    :func:`read_recording`.
    """

    def run(r: FileReader) -> list[dict[str, Any]]:
        head = r.header(allow_partial)
        layout = r.layout()
        rows = r.index(layout, head["complete"])["trials"]
        return [{k: v for k, v in row.items() if not k.startswith("_")} for row in rows]

    return guarded(path, run)
