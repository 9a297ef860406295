"""The append-mode writer: frames go to disk while they arrive, and a killed process leaves a
readable file.

The file is built (all groups and resizable datasets) under a temporary name, moved to its path
without clobbering an existing file and reopened in HDF5 SWMR-write mode, in which the library
keeps the on-disk file consistent at every moment. SWMR only supports appending to datasets that
exist when it is switched on, which is why the schema keeps all trials in one set of datasets.

A full disk: before each flush the writer checks that the folder has room for the flush (its
frames, one chunk per dataset, and :data:`SPACE_MARGIN_BYTES` for HDF5's metadata and the close).
Where there is none, or a write fails all the same (another program filled the disk meanwhile, a
file-size limit), the recording stops (:meth:`RecordingWriter._abort`): the file is closed without
writing to the disk again and removed, and one :class:`~ectskin.EctskinError` says so. HDF5 cannot
carry on with a file whose write failed: closing it normally writes its caches again, and a
second failure inside the library's close leaves its handles half released, which crashes the
process when they are released later (a segfault with h5py 3.16 / HDF5 2.0).
"""

from __future__ import annotations

import errno
import logging
import math
import os
import re
import shutil
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Self

import h5py
import numpy as np

from ectskin._check import EctskinError, check_type
from ectskin._files import os_error_text, remove_stale_temps, temp_path
from ectskin.io.hdf5.frame_args import check_frames
from ectskin.io.hdf5.schema import (
    EVENT_FIELDS,
    EVENTS_KEY,
    FINGER_COLUMNS,
    FINGER_FRAMES,
    OPTIONAL_FRAMES,
    TRIAL_FIELDS,
    create_frames,
    create_tables,
    finger_row,
    to_json,
    write_events,
    write_root,
)
from ectskin.io.hdf5.write import file_image, fsync_path
from ectskin.io.recording import FINGER_TRIAL_FIELDS, check_fingers, check_inflation, check_name
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

#: Free space a flush leaves on the disk besides its own bytes: HDF5's metadata and the close.
SPACE_MARGIN_BYTES = 1 << 20


class _NoSpace(OSError):
    """The folder has no room for the next flush (found before HDF5 writes anything)."""


def _free_bytes(folder: Path) -> int | None:
    """Bytes an unprivileged process may still write in ``folder``, or None if unknown (some
    network and FUSE file systems report a size of 0: no check there)."""
    try:
        usage = shutil.disk_usage(folder)
    except OSError:
        return None
    return usage.free if usage.total > 0 else None


def _failure_text(exc: BaseException) -> str:
    """The short reason of a failed h5py write ("No space left on device")."""
    if isinstance(exc, _NoSpace):
        return exc.strerror
    if isinstance(exc, OSError) and exc.errno:
        return os_error_text(exc)
    found = re.search(r"error message = '([^']*)'", str(exc))
    if found:
        return found.group(1)
    return str(exc).split("(")[0].strip() or type(exc).__name__


def _exists_message(path: Path) -> str:
    return (
        f"{path}: file exists; use overwrite=True (--overwrite on the command line) to replace it"
    )


def _positive_rate(frame_rate_hz: Any) -> float:
    try:
        rate = float(frame_rate_hz)
    except (TypeError, ValueError):
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0):
        raise EctskinError(f"frame_rate_hz must be > 0, got {frame_rate_hz!r}")
    return rate


def _flush_interval(flush_interval_s: Any) -> float:
    try:
        value = float(flush_interval_s)
    except (TypeError, ValueError):
        value = math.nan
    if not value >= 0:
        raise EctskinError(f"flush_interval_s must be >= 0 s, got {flush_interval_s!r}")
    return value


class RecordingWriter:
    """Append frames to an HDF5 recording while they arrive; survives SIGKILL.

    Usage::

        with RecordingWriter("run.h5", layout, 30.0, meta={"source": "sim"}) as w:
            w.start_trial("trial_0000", inflation=(0, 10, 20), region=3)
            w.append(capacitance, timestamps, labels)      # (n, n_pairs) / (n,) or one frame
            w.add_event(12.5, "finger lifted")
        # close() marks the file complete

    Appended frames are buffered in memory and written by :meth:`flush`: frames, trial rows and
    events first, then ``/committed`` (the commit record: counts of frames, trials, events).
    :meth:`flush` runs automatically inside :meth:`append`, :meth:`start_trial` and
    :meth:`add_event` once ``flush_interval_s`` has passed on ``clock`` since the last one, so a
    killed process loses at most the frames of the last ``flush_interval_s`` (plus one append); a
    caller whose frames may stop arriving should call :meth:`flush` itself. Such a file opens with
    ``read_recording(path, allow_partial=True)`` (also while the writer still runs).

    Within a trial, timestamps (s) must increase; labels default to 0; markers (mm) and the
    fingers (force in N, contact, finger_uv_mm, finger_height_mm on the fingers axis; see
    :class:`~ectskin.io.recording.Trial`) are optional, but a trial gives each of them with every
    append or never, for the same fingers. The fingers axis of the file widens when a trial
    brings more fingers than the trials before it. Thread-safe.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        layout: SensorLayout,
        frame_rate_hz: float,
        *,
        meta: dict[str, Any] | None = None,
        overwrite: bool = False,
        flush_interval_s: float = 1.0,
        chunk_frames: int = 64,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        check_type("layout", layout, SensorLayout)
        self.path = Path(os.fspath(path))
        rate = _positive_rate(frame_rate_hz)
        self.flush_interval_s = _flush_interval(flush_interval_s)
        if isinstance(chunk_frames, bool) or not isinstance(chunk_frames, int) or chunk_frames < 1:
            raise EctskinError(f"chunk_frames must be an integer >= 1, got {chunk_frames!r}")
        meta = dict(meta or {})
        if EVENTS_KEY in meta:
            raise EctskinError(
                f"RecordingWriter meta: key {EVENTS_KEY!r} is reserved; use add_event() instead"
            )
        meta_json = to_json("RecordingWriter meta", meta)
        self.layout = layout
        self.frame_rate_hz = rate
        if self.path.is_dir():
            raise EctskinError(f"{self.path}: is a directory; expected the path of an .h5 file")
        if not self.path.parent.is_dir():
            raise EctskinError(f"{self.path}: directory {self.path.parent} does not exist")
        if self.path.exists() and not overwrite:
            raise EctskinError(_exists_message(self.path))

        self._clock = clock
        self._lock = threading.RLock()
        self._closed = True  # until the file is open
        self._aborted = False  # a write failed: the file was closed and removed
        self._names: list[str] = []  # every trial started (written or buffered)
        self._trial_rows: list[dict[str, Any]] = []  # trials not yet written
        self._n_trials_written = 0
        self._cur: dict[str, Any] | None = None  # the current trial's row (written or not)
        self._cur_index = -1
        self._cur_last_t = -math.inf
        self._buf: dict[str, list[Any]] = {}  # per dataset: arrays, or (offset, array)
        self._n_buf = 0
        self._n_frames_written = 0
        self._events: list[tuple[float, int, str]] = []
        self._n_events_written = 0
        self._has_markers_ds = layout.n_markers > 0
        self._width = 1  # the file's fingers axis (widened by a trial with more fingers)
        self._create(meta_json, overwrite, chunk_frames)
        self._closed = False
        self._last_flush = self._clock()
        logger.info("recording to %s (SWMR, flush every %.3g s)", self.path, self.flush_interval_s)

    # ------------------------------------------------------------------ setup
    def _create(self, meta_json: str, overwrite: bool, chunk_frames: int) -> None:
        def build(f: h5py.File) -> None:
            write_root(f, self.layout, self.frame_rate_hz, meta_json, "RecordingWriter")
            # SWMR cannot add datasets later: create every optional one now
            optional = [k for k in OPTIONAL_FRAMES if k != "markers" or self._has_markers_ds]
            create_frames(f, self.layout, 0, chunk_frames, optional, compress=False)
            create_tables(f, 0, 0)

        # Built in memory and written as plain bytes: HDF5 never meets a full disk here.
        image = file_image(build, ("v110", "v110"))
        remove_stale_temps(self.path)
        tmp = temp_path(self.path)
        try:
            with open(tmp, "wb") as fh:
                fh.write(image)
                fh.flush()
                os.fsync(fh.fileno())
            self._publish(tmp, overwrite)
        except OSError as exc:
            raise EctskinError(
                f"{self.path}: cannot create the recording ({os_error_text(exc)}); nothing was "
                "written there"
            ) from None
        finally:
            tmp.unlink(missing_ok=True)
        # Reopen directly in SWMR-write mode: the file is never open for non-SWMR writing at path.
        fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
        fapl.set_libver_bounds(h5py.h5f.LIBVER_V110, h5py.h5f.LIBVER_V110)
        try:
            fid = h5py.h5f.open(
                os.fsencode(self.path), h5py.h5f.ACC_RDWR | h5py.h5f.ACC_SWMR_WRITE, fapl=fapl
            )
        except OSError as exc:
            raise EctskinError(f"{self.path}: cannot open for SWMR writing ({exc})") from None
        self._f = h5py.File(fid)
        self._fds = {k: self._f["frames"][k] for k in self._f["frames"]}
        self._tds = {k: self._f["trials"][k] for k in TRIAL_FIELDS}
        self._eds = {k: self._f["events"][k] for k in EVENT_FIELDS}

    def _publish(self, tmp: Path, overwrite: bool) -> None:
        """Move the built file to ``path``; without ``overwrite`` never clobber one that exists."""
        exists = EctskinError(_exists_message(self.path))
        if overwrite:
            os.replace(tmp, self.path)
            return
        try:  # no-clobber move: link fails if path exists
            os.link(tmp, self.path)
        except FileExistsError:
            raise exists from None
        except OSError:  # file system without hard links
            if self.path.exists():
                raise exists from None
            os.replace(tmp, self.path)

    # ------------------------------------------------------------------ state
    @property
    def n_frames(self) -> int:
        """Frames appended so far (written or buffered)."""
        return self._n_frames_written + self._n_buf

    @property
    def n_trials(self) -> int:
        return len(self._names)

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise EctskinError(f"{self.path}: the RecordingWriter is closed")

    def _maybe_flush(self) -> None:
        if self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()

    # ------------------------------------------------------------------ trials
    def start_trial(
        self,
        name: str,
        *,
        inflation: Sequence[float] = (),
        region: int = 0,
        finger_surface: str | Sequence[str | None] | None = None,
        finger_radius_mm: Any = None,
        finger_modulus_mpa: Any = None,
        meta: dict[str, Any] | None = None,
    ) -> None:
        """Start a new trial; the frames appended from now on belong to it.

        ``inflation``: chamber volumes p in ml; ``region``: touched region (0 = none). Per
        finger of the trial (each optional; given, they fix its number of fingers, which
        the appends must then give): ``finger_surface`` the face each finger is on or over
        ("front", "back", ...; None = not given; one name for one finger), the surface of its
        ``finger_uv_mm``; ``finger_radius_mm`` and ``finger_modulus_mpa`` (NaN = unknown).
        Without them the trial's first append decides its number of fingers.
        """
        with self._lock:
            self._check_open()
            infl = self._check_trial(name, inflation, region)
            given = {
                "finger_surface": finger_surface,
                "finger_radius_mm": finger_radius_mm,
                "finger_modulus_mpa": finger_modulus_mpa,
            }
            given = {k: v for k, v in given.items() if v is not None}
            fingers = check_fingers(f"{self.path}: trial {name!r}", 0, **given)
            row = {
                "name": name,
                "start": self.n_frames,
                "region": int(region),
                "inflation_ml": infl,
                **{f"has_{k}": None for k in OPTIONAL_FRAMES},  # decided by the first append
                **{k: fingers[k] for k in ("n_fingers", *FINGER_COLUMNS)},
                "meta_json": to_json(f"trial {name!r}: meta", meta),
                "_given": given,  # what the appends must agree with
            }
            self._names.append(name)
            self._trial_rows.append(row)
            self._cur = row
            self._cur_index = len(self._names) - 1
            self._cur_last_t = -math.inf
            self._maybe_flush()

    def _check_trial(self, name: Any, inflation: Any, region: Any) -> np.ndarray:
        """Check a new trial's name, inflation (returned as float64) and region."""
        check_type("trial name", name, str)
        if not name:
            raise EctskinError(f"{self.path}: trial name must not be empty")
        check_name(f"{self.path}: trial name", name)
        if name in self._names:
            raise EctskinError(f"{self.path}: trial {name!r} already exists in this recording")
        infl = np.asarray(check_inflation(f"trial {name!r}", inflation), dtype=np.float64)
        if isinstance(region, bool) or not isinstance(region, (int, np.integer)):
            raise EctskinError(f"trial {name!r}: region must be an integer, got {region!r}")
        if not 0 <= int(region) <= self.layout.n_regions:
            raise EctskinError(
                f"trial {name!r}: region {region} is not 0..{self.layout.n_regions} of layout "
                f"{self.layout.name!r}"
            )
        return infl

    # ------------------------------------------------------------------ frames
    def append(
        self,
        capacitance: Any,
        timestamps: Any,
        labels: Any = None,
        markers: Any = None,
        force: Any = None,
        *,
        contact: Any = None,
        finger_uv_mm: Any = None,
        finger_height_mm: Any = None,
    ) -> None:
        """Append frames to the current trial.

        capacitance: (n, n_pairs) or one frame (n_pairs,), pF (NaN = masked channel).
        timestamps: (n,) or a scalar, s, finite and increasing within the trial.
        labels: (n,) or a scalar class 0..n_regions, default 0.
        markers: (n, n_markers, 3) or (n_markers, 3), mm, NaN = occluded.
        The fingers, on the fingers axis (n, n_fingers, ...), or one finger without it:
        force: (n, K), (n,) or a scalar, N.
        contact: (n, K), (n,) or a scalar bool, the finger is on the skin.
        finger_uv_mm: (n, K, 2), (n, 2) or (2,) (one frame), mm, the skin point under the
        fingertip; NaN = the finger away.
        finger_height_mm: (n, K), (n,) or a scalar, mm above the skin (0 in contact); NaN = the
        finger away.

        The first append of a trial decides which of markers, force, contact, finger_uv_mm and
        finger_height_mm the trial carries, and for how many fingers (unless ``start_trial`` was
        given them); an append of 0 frames only declares that (for a trial that may stay empty).
        """
        with self._lock:
            self._check_open()
            if self._cur is None:
                raise EctskinError(f"{self.path}: call start_trial() before append()")
            src = f"{self.path}: append to trial {self._cur['name']!r}"
            given = {
                "markers": markers,
                "force": force,
                "contact": contact,
                "finger_uv_mm": finger_uv_mm,
                "finger_height_mm": finger_height_mm,
            }
            frames = check_frames(
                self.layout,
                src,
                self._cur_last_t,
                capacitance,
                timestamps,
                labels,
                given,
                self._cur["_given"],
            )
            self._check_flags(src, {k: frames[k] is not None for k in OPTIONAL_FRAMES}, frames)
            n = frames["capacitance"].shape[0]
            if n == 0:
                return
            self._cur_last_t = float(frames["timestamps"][-1])
            for key in ("capacitance", "timestamps", "labels"):
                self._buf.setdefault(key, []).append(frames[key])
            for key in OPTIONAL_FRAMES:
                if frames[key] is not None:
                    self._buf.setdefault(key, []).append((self._n_buf, frames[key]))
            self._n_buf += n
            self._maybe_flush()

    def _check_flags(self, src: str, has: dict[str, bool], frames: dict[str, Any]) -> None:
        """Each optional dataset given with every append of a trial or never, for the same
        fingers; the first append decides (and the trial's fingers, unless start_trial did)."""
        flags = {f"has_{k}": v for k, v in has.items()}
        for key, given in flags.items():
            what = key[4:]
            if self._cur[key] is not None and self._cur[key] != given:
                raise EctskinError(
                    f"{src}: {what} {'given' if given else 'missing'} here, but the trial's "
                    f"earlier frames {'had' if self._cur[key] else 'had no'} {what}; give "
                    "them with every append of a trial or never"
                )
        if flags["has_markers"] and not self._has_markers_ds:
            raise EctskinError(f"{src}: layout {self.layout.name!r} has no markers")
        first = self._cur["has_markers"] is None
        if not first and frames["n_fingers"] != self._cur["n_fingers"]:
            raise EctskinError(
                f"{src}: {frames['n_fingers']} finger(s) here, but the trial's earlier frames "
                f"had {self._cur['n_fingers']}; a trial keeps its fingers"
            )
        if first:  # the trial's first append decides
            self._cur.update(flags)
            self._cur.update({k: frames[k] for k in ("n_fingers", *FINGER_COLUMNS)})
            if not any(r is self._cur for r in self._trial_rows):
                self._trial_rows.append(self._cur)  # already written: rewrite its flags

    def add_event(self, t_s: float, text: str) -> None:
        """Log an event (e.g. "inflation set to (0, 10, 20)") at time ``t_s`` (s) in the current trial."""
        with self._lock:
            self._check_open()
            try:
                t = float(t_s)
            except (TypeError, ValueError):
                t = math.nan
            if not math.isfinite(t):
                raise EctskinError(
                    f"{self.path}: event time must be a finite number of seconds, got {t_s!r}"
                )
            check_type("event text", text, str)
            if "\x00" in text:
                raise EctskinError(f"{self.path}: event text {text!r} contains a NUL byte")
            self._events.append((t, self._cur_index, text))
            self._maybe_flush()

    # ------------------------------------------------------------------ flushing
    def flush(self) -> None:
        """Write the buffered trials, events and frames, then the commit record, to disk."""
        with self._lock:
            self._check_open()
            self._flush()

    def _flush(self) -> None:
        # Idempotent: rows are written by index and the counters only move once written.
        self._guarded(self._write_buffers)

    def _guarded(self, write: Callable[[], None]) -> None:
        """Run ``write`` (h5py writes) after checking the free space; a failure aborts."""
        try:
            self._check_space()
            write()
            return
        except (OSError, RuntimeError) as exc:  # h5py reports a failed write as either
            reason = _failure_text(exc)
            self._detach_disk()
            # The traceback's frames hold h5py objects of the file: release them now, while the
            # file writes nowhere, not later at some garbage collection.
            traceback.clear_frames(exc.__traceback__)
        raise self._abort(reason)

    def _flush_bytes(self) -> int:
        """Bytes the next flush may add: its frames plus one new chunk per frame dataset."""
        data = sum(
            a.nbytes if isinstance(a, np.ndarray) else a[1].nbytes
            for arrays in self._buf.values()
            for a in arrays
        )
        chunks = sum(
            int(np.prod(ds.chunks)) * ds.dtype.itemsize for ds in self._fds.values() if ds.chunks
        )
        return data + chunks

    def _check_space(self) -> None:
        need = self._flush_bytes() + SPACE_MARGIN_BYTES
        free = _free_bytes(self.path.parent)
        if free is not None and free < need:
            raise _NoSpace(
                errno.ENOSPC,
                f"the disk is full: {free / 1e6:.2f} MB free, the next write needs "
                f"{need / 1e6:.2f} MB",
            )

    def _detach_disk(self) -> None:
        """Point the file's descriptor at /dev/null: from now on HDF5 writes nowhere."""
        try:
            fd = self._f.id.get_vfd_handle()
            null = os.open(os.devnull, os.O_RDWR)
        except (OSError, RuntimeError, ValueError, TypeError) as exc:
            logger.debug("%s: cannot detach the file from the disk: %s", self.path, exc)
            return
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)

    def _abort(self, reason: str) -> EctskinError:
        """Stop after a failed write: close the (detached) file, remove it, return the error.

        What the file holds after a failed write is unknown, so it is not kept: a recording the
        disk could not hold is gone rather than left half written.
        """
        frames = self._n_frames_written + self._n_buf
        f, self._f = self._f, None
        self._fds, self._tds, self._eds, self._buf = {}, {}, {}, {}
        self._closed = True
        self._aborted = True
        try:
            f.close()
        except (OSError, RuntimeError, ValueError) as exc:
            logger.debug("%s: closing after the failed write: %s", self.path, exc)
        del f
        try:
            self.path.unlink(missing_ok=True)
        except OSError as exc:
            logger.warning("%s: cannot remove the unfinished file: %s", self.path, exc)
        return EctskinError(
            f"{self.path}: cannot write the recording ({reason}); the recording stopped after "
            f"{frames} frames and the unfinished file was removed. Free some space and record "
            "again"
        )

    def _write_buffers(self) -> None:
        t0 = time.perf_counter()
        self._widen([row["n_fingers"] for row in self._trial_rows])
        self._write_trial_rows()  # new trials, and flag updates of the current one
        write_events(self._eds, self._events, self._n_events_written)
        self._n_events_written += len(self._events)
        self._events = []
        self._write_frames()
        self._f.flush()
        # the commit record, only once everything it counts is on disk
        self._f["committed"][:] = [
            self._n_frames_written,
            self._n_trials_written,
            self._n_events_written,
        ]
        self._f.flush()
        self._last_flush = self._clock()
        logger.debug(
            "%s: flushed %d frames in %.1f ms",
            self.path,
            self._n_frames_written,
            1e3 * (time.perf_counter() - t0),
        )

    def _widen(self, n_fingers: list[int]) -> None:
        """Widen the fingers axis of the file (frames and trial columns) to ``max(n_fingers)``."""
        need = max(n_fingers, default=0)
        if need <= self._width:
            return
        for key in FINGER_FRAMES:
            if key in self._fds:
                ds = self._fds[key]
                ds.resize((ds.shape[0], need, *ds.shape[2:]))
        for key in FINGER_COLUMNS:
            self._tds[key].resize((self._tds[key].shape[0], need))
        self._width = need

    def _write_trial_rows(self) -> None:
        for row in self._trial_rows:
            k = self._names.index(row["name"])
            if k >= self._n_trials_written:
                for ds in self._tds.values():
                    ds.resize((k + 1, *ds.shape[1:]))
                self._n_trials_written = k + 1
            for key in TRIAL_FIELDS:
                value = row[key]
                if key.startswith("has_"):
                    value = bool(value)
                elif key == "finger_surface":
                    value = finger_row([s or "" for s in value], self._width, "")
                elif key in FINGER_TRIAL_FIELDS:  # (None: unknown for every finger)
                    value = finger_row([] if value is None else list(value), self._width, np.nan)
                self._tds[key][k] = value
        self._trial_rows = []

    def _write_frames(self) -> None:
        if not self._n_buf:
            return
        s, e = self._n_frames_written, self._n_frames_written + self._n_buf
        for ds in self._fds.values():
            ds.resize((e, *ds.shape[1:]))
        for key in ("capacitance", "timestamps", "labels"):
            self._fds[key][s:e] = np.concatenate(self._buf[key])
        for key in OPTIONAL_FRAMES:
            for off, arr in self._buf.get(key, []):
                rows = slice(s + off, s + off + arr.shape[0])
                if key not in FINGER_FRAMES:
                    self._fds[key][rows] = arr
                elif arr.shape[1]:  # the trial's columns of the fingers axis
                    self._fds[key][rows, : arr.shape[1]] = arr
        self._n_frames_written = e
        self._buf = {}
        self._n_buf = 0

    def close(self, *, complete: bool = True) -> None:
        """Flush, mark the file complete and close it. Idempotent.

        ``complete=False`` closes without marking it (as for an interrupted session): the file
        then reads only with ``allow_partial=True``.
        """
        with self._lock:
            if self._closed:
                return
            self._flush()  # a failed write aborts (closed, removed) and raises
            self._guarded(lambda: self._finish(complete))
            fsync_path(self.path)
            logger.info(
                "closed %s (%s): %d trials, %d frames, %d events",
                self.path,
                "complete" if complete else "left incomplete",
                self._n_trials_written,
                self._n_frames_written,
                self._n_events_written,
            )

    def _finish(self, complete: bool) -> None:
        if complete:
            self._f.attrs["complete"] = np.bool_(True)
        self._f.flush()
        self._closed = True
        self._f.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        elif self._aborted:  # the failed write already closed and removed the file
            return
        else:
            logger.warning(
                "%s: closed after %s; left incomplete (read it with allow_partial=True)",
                self.path,
                exc_type.__name__,
            )
            self.close(complete=False)
