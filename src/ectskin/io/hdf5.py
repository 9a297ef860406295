"""HDF5 recordings: one file per experiment holding the layout and every trial.

The schema (``format = "ectskin.recording"``, ``format_version = 1``) is documented in
``docs/recording-format.md``. In short, all frames of all trials are stored back to back in one set
of resizable datasets under ``/frames`` and a trial index under ``/trials`` says where each trial
starts; ``/committed`` records how many frames, trials and events are part of the recording::

    /                attrs format, format_version, complete, frame_rate_hz, created_utc,
                           ectskin_version, writer, meta_json
    /layout          attrs json (SensorLayout.to_json()), name
    /committed       (3,) int64: n_frames, n_trials, n_events
    /frames/capacitance  (n_frames, n_pairs) float64, pF
    /frames/timestamps   (n_frames,) float64, s
    /frames/labels       (n_frames,) int16
    /frames/markers      (n_frames, n_markers, 3) float64, mm   [if any trial has markers]
    /frames/force        (n_frames,) float64, N                 [if any trial has force]
    /trials/{name, start, region, inflation_ml, has_markers, has_force, meta_json}  (n_trials,)
    /events/{t_s, trial, text}                                                     (n_events,)

Why one set of datasets rather than a group per trial: the live :class:`RecordingWriter` uses
HDF5 SWMR (single writer, multiple readers), whose on-disk file stays consistent while it is written,
so a process killed with SIGKILL leaves a readable file. SWMR only supports appending to datasets
that exist when it is switched on; a new group per trial would break that guarantee. One schema
serves both writers, so the reader has a single code path.

Three entry points write or read whole files:

* :func:`write_recording` writes a :class:`~ectskin.io.recording.Recording` atomically (temp file,
  fsync, ``os.replace``);
* :func:`read_recording` checks the schema and returns a ``Recording`` (bit-exact arrays);
* :func:`read_layout` and :func:`list_trials` read metadata only, for big files.

Every problem with a file is reported as one :class:`~ectskin.EctskinError` naming the file and
the field; no h5py or OS traceback escapes for bad input.
"""

from __future__ import annotations

import ctypes
import dataclasses
import functools
import json
import logging
import math
import os
import threading
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Self

import h5py
import numpy as np

from ectskin._check import EctskinError, check_array, check_type
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

FORMAT = "ectskin.recording"
FORMAT_VERSION = 1

#: Key of ``Recording.meta`` that holds the events table (list of ``{"t_s", "trial", "text"}``).
EVENTS_KEY = "events"

_STR = h5py.string_dtype("utf-8")
_VLEN_F8 = h5py.vlen_dtype(np.float64)
_TRIAL_FIELDS = ("name", "start", "region", "inflation_ml", "has_markers", "has_force", "meta_json")
_EVENT_FIELDS = ("t_s", "trial", "text")
_COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
_BATCH_CHUNK_BYTES = 256 * 1024  # target size of one capacitance chunk in write_recording
_TABLE_CHUNK = 64  # rows per chunk of the trial and event tables
_clock = time.monotonic  # the writer's flush clock, s (a module attribute so tests can drive it)


# ---------------------------------------------------------------------------------- helpers
def _utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _version() -> str:
    from ectskin import __version__

    return __version__


def _json_default(value: Any) -> Any:
    # NumPy scalars and arrays are stored as the equivalent JSON numbers and lists.
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _to_json(name: str, value: Any) -> str:
    """JSON text of ``value`` (a dict of JSON-able values) or a clear error naming ``name``."""
    if value is None:
        value = {}
    check_type(name, value, dict)
    try:
        return json.dumps(value, default=_json_default, sort_keys=False)
    except (TypeError, ValueError) as exc:
        raise EctskinError(
            f"{name} must hold JSON-able values (str, numbers, lists, dicts): {exc}"
        ) from None


def _fsync_path(path: Path, directory: bool = False) -> None:
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


def _frames_arg(
    name: str,
    value: Any,
    tail: tuple[int, ...],
    n: int | None,
    src: str,
    *,
    finite: bool = False,
    broadcast: bool = False,
) -> np.ndarray:
    """``value`` as a float64 array (n, *tail); an array of shape ``tail`` is one frame.

    With ``broadcast`` a scalar is repeated for all ``n`` frames.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{src}: {name} must be numeric; {exc}") from None
    if broadcast and arr.ndim == 0 and n is not None:
        arr = np.full(n, arr)
    elif arr.shape == tail:
        arr = arr[None]
    return check_array(name, arr, (n, *tail), finite=finite, source=src)


def _temp_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def _write_root(
    f: h5py.File, layout: SensorLayout, frame_rate_hz: float, meta_json: str, writer: str
) -> None:
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    f.attrs["complete"] = np.bool_(False)
    f.attrs["frame_rate_hz"] = np.float64(frame_rate_hz)
    f.attrs["created_utc"] = _utc_now()
    f.attrs["ectskin_version"] = _version()
    f.attrs["writer"] = writer
    f.attrs["meta_json"] = meta_json
    g = f.create_group("layout")
    g.attrs["json"] = layout.to_json()
    g.attrs["name"] = layout.name
    c = f.create_dataset("committed", data=np.zeros(3, dtype=np.int64))
    c.attrs["fields"] = ["n_frames", "n_trials", "n_events"]


def _create_frames(
    f: h5py.File,
    layout: SensorLayout,
    n_frames: int,
    chunk_frames: int,
    with_markers: bool,
    with_force: bool,
    compress: bool,
) -> dict[str, h5py.Dataset]:
    """Create the resizable ``/frames`` datasets with ``n_frames`` rows (filled by the caller).

    ``compress``: gzip + shuffle. The live writer does not compress: a compressed chunk that is
    flushed half full is rewritten elsewhere when it grows and its old space is not reused, so the
    file would grow with every flush (measured: 32x the data at one flush per frame).
    """
    g = f.create_group("frames")
    rows = max(1, int(chunk_frames))
    spec = {
        "capacitance": ((layout.n_pairs,), np.float64, np.nan, "pF"),
        "timestamps": ((), np.float64, np.nan, "s"),
        "labels": ((), np.int16, -1, "class (0 = no touch, 1..n_regions)"),
    }
    if with_markers:
        spec["markers"] = ((layout.n_markers, 3), np.float64, np.nan, "mm")
    if with_force:
        spec["force"] = ((), np.float64, np.nan, "N")
    out = {}
    for name, (tail, dtype, fill, unit) in spec.items():
        ds = g.create_dataset(
            name,
            shape=(n_frames, *tail),
            maxshape=(None, *tail),
            chunks=(rows, *tail),
            dtype=dtype,
            fillvalue=fill,
            **(_COMPRESSION if compress else {}),
        )
        ds.attrs["unit"] = unit
        out[name] = ds
    out["capacitance"].attrs["pair_names"] = list(layout.pair_names)
    if with_markers:
        out["markers"].attrs["marker_names"] = [m.name for m in layout.markers]
    return out


def _create_tables(f: h5py.File, n_trials: int, n_events: int) -> tuple[dict, dict]:
    trials = f.create_group("trials")
    tspec = {
        "name": _STR,
        "start": np.int64,
        "region": np.int32,
        "inflation_ml": _VLEN_F8,
        "has_markers": np.bool_,
        "has_force": np.bool_,
        "meta_json": _STR,
    }
    tds = {
        k: trials.create_dataset(
            k, shape=(n_trials,), maxshape=(None,), chunks=(_TABLE_CHUNK,), dtype=dt
        )
        for k, dt in tspec.items()
    }
    tds["start"].attrs["unit"] = "frame index into /frames"
    tds["inflation_ml"].attrs["unit"] = "ml"
    events = f.create_group("events")
    espec = {"t_s": np.float64, "trial": np.int32, "text": _STR}
    eds = {
        k: events.create_dataset(
            k, shape=(n_events,), maxshape=(None,), chunks=(_TABLE_CHUNK,), dtype=dt
        )
        for k, dt in espec.items()
    }
    eds["t_s"].attrs["unit"] = "s"
    eds["trial"].attrs["unit"] = "row in /trials, -1 = before the first trial"
    return tds, eds


def _check_events(events: Any, trial_names: list[str]) -> list[tuple[float, int, str]]:
    """Validate ``Recording.meta["events"]`` into (t_s, trial index, text) rows."""
    src = f"recording meta[{EVENTS_KEY!r}]"
    check_type(src, events, list)
    index = {n: k for k, n in enumerate(trial_names)}
    rows = []
    for k, ev in enumerate(events):
        if not isinstance(ev, dict) or set(ev) != set(_EVENT_FIELDS):
            raise EctskinError(
                f"{src}[{k}] must be a dict with keys 't_s', 'trial', 'text', got {ev!r:.80}"
            )
        t = ev["t_s"]
        if isinstance(t, bool) or not isinstance(t, (int, float, np.number)) or not np.isfinite(t):
            raise EctskinError(f"{src}[{k}].t_s must be a finite number of seconds, got {t!r}")
        trial = ev["trial"]
        if trial is not None and trial not in index:
            raise EctskinError(f"{src}[{k}].trial names no trial of the recording: {trial!r}")
        check_type(f"{src}[{k}].text", ev["text"], str)
        rows.append((float(t), -1 if trial is None else index[trial], ev["text"]))
    return rows


def _write_events(eds: dict, rows: list[tuple[float, int, str]], start: int = 0) -> None:
    if not rows:
        return
    end = start + len(rows)
    for k in _EVENT_FIELDS:
        eds[k].resize((end,))
    eds["t_s"][start:end] = np.array([r[0] for r in rows], dtype=np.float64)
    eds["trial"][start:end] = np.array([r[1] for r in rows], dtype=np.int32)
    eds["text"][start:end] = np.array([r[2] for r in rows], dtype=object)


def _write_trial_table(tds: dict, trials: Sequence[Trial], starts: np.ndarray) -> None:
    n = len(trials)
    if n == 0:
        return
    tds["name"][:] = np.array([t.name for t in trials], dtype=object)
    tds["start"][:] = starts
    tds["region"][:] = np.array([t.region for t in trials], dtype=np.int32)
    for k, t in enumerate(trials):  # row by row: h5py would read equal lengths as a 2-D array
        tds["inflation_ml"][k] = np.asarray(t.inflation, dtype=np.float64)
    tds["has_markers"][:] = np.array([t.markers is not None for t in trials])
    tds["has_force"][:] = np.array([t.force is not None for t in trials])
    tds["meta_json"][:] = np.array(
        [_to_json(f"trial {t.name!r}: meta", t.meta) for t in trials], dtype=object
    )


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
        if t.markers is not None:
            fds["markers"][s:e] = t.markers
        if t.force is not None:
            fds["force"][s:e] = t.force


# ------------------------------------------------------------------------------ batch writer
def write_recording(rec: Recording, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``rec`` to the HDF5 file ``path`` atomically and return the path.

    The file is written to ``.<name>.tmp-<pid>`` in the same directory, marked ``complete``,
    flushed to disk (fsync) and renamed onto ``path`` with ``os.replace``: a crash at any moment
    leaves either no file (or the old one) at ``path``, never a partial one, and the temporary file
    is removed on error. An existing ``path`` is refused unless ``overwrite=True``.

    ``rec.meta`` and every ``Trial.meta`` must hold JSON-able values (NumPy scalars and arrays are
    stored as numbers and lists). ``rec.meta["events"]``, if present, is a list of
    ``{"t_s": float, "trial": str | None, "text": str}`` and is stored in the ``/events`` table.
    """
    check_type("rec", rec, Recording)
    path = Path(os.fspath(path))
    if path.is_dir():
        raise EctskinError(f"{path}: is a directory; expected the path of an .h5 file to write")
    if path.exists() and not overwrite:
        raise EctskinError(f"{path}: file exists; pass overwrite=True to replace it")
    if not path.parent.is_dir():
        raise EctskinError(f"{path}: directory {path.parent} does not exist")
    # Re-run the Recording checks (trials may have been edited since it was built).
    rec = Recording(rec.layout, list(rec.trials), rec.frame_rate_hz, rec.meta)
    meta = dict(rec.meta)
    events = (
        _check_events(meta.pop(EVENTS_KEY), [t.name for t in rec.trials])
        if EVENTS_KEY in meta
        else []
    )
    meta_json = _to_json("recording meta", meta)
    for t in rec.trials:  # fail on bad metadata before touching the disk
        _to_json(f"trial {t.name!r}: meta", t.meta)

    tmp = _temp_path(path)
    try:
        _write_file(tmp, rec, meta_json, events)
        _fsync_path(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):  # disk full, permissions, ...
            raise EctskinError(f"{path}: cannot write the recording ({exc})") from None
        raise
    _fsync_path(path.parent, directory=True)
    logger.info("wrote %s: %d trials, %d frames", path, rec.n_trials, rec.n_frames)
    return path


def _write_file(tmp: Path, rec: Recording, meta_json: str, events: list) -> None:
    layout = rec.layout
    counts = np.array([t.n_frames for t in rec.trials], dtype=np.int64)
    starts = (
        np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if len(counts) else counts
    )
    n_frames = int(counts.sum())
    chunk = min(max(1, n_frames), max(1, _BATCH_CHUNK_BYTES // (8 * layout.n_pairs)))
    try:
        f = h5py.File(tmp, "w", libver=("earliest", "v110"))
    except OSError as exc:
        raise EctskinError(f"{tmp.parent}: cannot create a file there ({exc})") from None
    with f:
        _write_root(f, layout, rec.frame_rate_hz, meta_json, "write_recording")
        fds = _create_frames(
            f,
            layout,
            n_frames,
            chunk,
            with_markers=layout.n_markers > 0 and any(t.markers is not None for t in rec.trials),
            with_force=any(t.force is not None for t in rec.trials),
            compress=True,
        )
        tds, eds = _create_tables(f, rec.n_trials, 0)
        _write_trial_table(tds, rec.trials, starts)
        _write_frames(fds, layout, rec.trials, starts)
        _write_events(eds, events)
        f["committed"][:] = [n_frames, rec.n_trials, len(events)]
        f.attrs["complete"] = np.bool_(True)


# ----------------------------------------------------------------------------------- reader
class _FileReader:
    """Reads one open file, turning every problem into an EctskinError naming file and field."""

    def __init__(self, f: h5py.File, path: Path):
        self.f = f
        self.path = path
        self.field = "/"

    def fail(self, msg: str) -> EctskinError:
        return EctskinError(f"{self.path}: {msg}")

    def node(self, name: str, kind: type = h5py.Dataset):
        self.field = name
        obj = self.f.get(name)
        if obj is None:
            what = "dataset" if kind is h5py.Dataset else "group"
            raise self.fail(
                f"missing {what} {name} (required by {FORMAT} version {FORMAT_VERSION})"
            )
        if not isinstance(obj, kind):
            raise self.fail(f"{name} is a {type(obj).__name__}, expected a {kind.__name__}")
        return obj

    def attr(self, obj, key: str, where: str = "/") -> Any:
        self.field = f"{where} attribute {key!r}"
        if key not in obj.attrs:
            raise self.fail(f"missing attribute {key!r} on {where}")
        value = obj.attrs[key]
        if isinstance(value, bytes):
            value = value.decode("utf-8", errors="replace")
        return value

    def str_attr(self, obj, key: str, where: str = "/") -> str:
        v = self.attr(obj, key, where)
        if not isinstance(v, str):
            raise self.fail(f"attribute {key!r} on {where} must be a string, found {v!r:.60}")
        return v

    def json_attr(self, obj, key: str, where: str = "/") -> Any:
        text = self.str_attr(obj, key, where)
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise self.fail(f"attribute {key!r} on {where} is not valid JSON ({exc.msg})") from None

    # ------------------------------------------------------------------ header
    def header(self, allow_partial: bool) -> dict[str, Any]:
        f = self.f
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode("utf-8", errors="replace")
        if fmt != FORMAT:
            raise self.fail(
                f"not an ectskin recording: root attribute 'format' is {fmt!r}, expected {FORMAT!r}"
            )
        version = self.attr(f, "format_version")
        if isinstance(version, (bool, np.bool_)) or not isinstance(version, (int, np.integer)):
            raise self.fail(f"attribute 'format_version' must be an integer, found {version!r}")
        version = int(version)
        if version > FORMAT_VERSION:
            raise self.fail(
                f"format_version {version} is newer than this ectskin reads ({FORMAT_VERSION}); "
                "upgrade ectskin"
            )
        if version < 1:
            raise self.fail(f"format_version {version} is invalid (expected {FORMAT_VERSION})")
        complete = self.attr(f, "complete")
        if not isinstance(complete, (bool, np.bool_, int, np.integer)) or int(complete) not in (
            0,
            1,
        ):
            raise self.fail(f"attribute 'complete' must be a boolean, found {complete!r}")
        complete = bool(complete)
        if not complete and not allow_partial:
            raise self.fail(
                "incomplete recording (complete=False): it was not closed properly (the writer "
                "crashed or is still running); pass allow_partial=True to read what it holds"
            )
        rate = self.attr(f, "frame_rate_hz")
        try:
            rate = float(rate)
        except (TypeError, ValueError):
            rate = math.nan
        if not (math.isfinite(rate) and rate > 0):
            raise self.fail(f"attribute 'frame_rate_hz' must be a number > 0, found {rate!r}")
        meta = self.json_attr(f, "meta_json")
        if not isinstance(meta, dict):
            raise self.fail("attribute 'meta_json' must hold a JSON object")
        return {"version": version, "complete": complete, "frame_rate_hz": rate, "meta": meta}

    def layout(self) -> SensorLayout:
        g = self.node("/layout", h5py.Group)
        text = self.str_attr(g, "json", "/layout")
        self.field = "/layout"
        try:
            layout = SensorLayout.from_json(text, source="/layout")
        except EctskinError as exc:
            raise self.fail(f"invalid layout in attribute 'json': {exc}") from None
        return dataclasses.replace(layout, source=f"{self.path}:/layout")

    # ------------------------------------------------------------------- index
    def index(self, layout: SensorLayout, complete: bool) -> dict[str, Any]:
        """The trial table, frame count and events, with every count checked."""
        c = self.node("/committed")
        if c.shape != (3,) or c.dtype.kind not in "iu":
            raise self.fail(
                f"/committed has shape {c.shape} and dtype {c.dtype}, expected (3,) int64"
            )
        n_frames, n_trials, n_events = (int(v) for v in c[()])
        if min(n_frames, n_trials, n_events) < 0:
            raise self.fail(f"/committed holds negative counts {[n_frames, n_trials, n_events]}")

        tds = {k: self.node(f"/trials/{k}") for k in _TRIAL_FIELDS}
        n_trials = self._check_rows(tds, "trials", n_trials, complete)
        self._check_kind(tds["start"], "iu", "an integer")
        self._check_kind(tds["region"], "iu", "an integer")
        self._check_kind(tds["has_markers"], "biu", "a boolean")
        self._check_kind(tds["has_force"], "biu", "a boolean")
        for k in ("name", "meta_json"):
            if h5py.check_string_dtype(tds[k].dtype) is None:
                raise self.fail(
                    f"/trials/{k} has dtype {tds[k].dtype}, expected variable-length strings"
                )
        if h5py.check_vlen_dtype(tds["inflation_ml"].dtype) is None:
            raise self.fail(
                f"/trials/inflation_ml has dtype {tds['inflation_ml'].dtype}, expected variable-"
                "length float64"
            )

        fds = {}
        for k in ("capacitance", "timestamps", "labels", "markers", "force"):
            if k in ("markers", "force") and f"frames/{k}" not in self.f:
                continue
            fds[k] = self.node(f"/frames/{k}")
        tails = {
            "capacitance": ((layout.n_pairs,), f"(n_frames, {layout.n_pairs})", "f"),
            "timestamps": ((), "(n_frames,)", "f"),
            "labels": ((), "(n_frames,)", "iu"),
            "markers": ((layout.n_markers, 3), f"(n_frames, {layout.n_markers}, 3)", "f"),
            "force": ((), "(n_frames,)", "f"),
        }
        for k, ds in fds.items():
            tail, want, kinds = tails[k]
            if ds.ndim != 1 + len(tail) or tuple(ds.shape[1:]) != tail:
                raise self.fail(
                    f"/frames/{k} has shape {ds.shape}, expected {want} for layout {layout.name!r}"
                )
            self._check_kind(ds, kinds, "a float" if kinds == "f" else "an integer")
        n_frames = self._check_rows(fds, "frames", n_frames, complete)

        self.field = "/trials"
        names = [str(s) for s in tds["name"].asstr()[:n_trials]]
        starts = np.asarray(tds["start"][:n_trials], dtype=np.int64)
        regions = np.asarray(tds["region"][:n_trials], dtype=np.int64)
        infl = [tuple(float(v) for v in row) for row in tds["inflation_ml"][:n_trials]]
        has_m = np.asarray(tds["has_markers"][:n_trials]).astype(bool)
        has_f = np.asarray(tds["has_force"][:n_trials]).astype(bool)
        metas = []
        for k, text in enumerate(tds["meta_json"].asstr()[:n_trials]):
            try:
                m = json.loads(text)
            except json.JSONDecodeError as exc:
                raise self.fail(
                    f"/trials/meta_json[{k}] (trial {names[k]!r}) is not valid JSON ({exc.msg})"
                ) from None
            if not isinstance(m, dict):
                raise self.fail(
                    f"/trials/meta_json[{k}] (trial {names[k]!r}) must hold a JSON object"
                )
            metas.append(m)
        seen = set()
        for k, name in enumerate(names):
            if not name or name in seen:
                raise self.fail(f"/trials/name[{k}]: trial name {name!r} is empty or repeated")
            seen.add(name)
        if n_trials:
            bad = np.flatnonzero(np.diff(starts) < 0)
            if starts[0] != 0:
                raise self.fail(f"/trials/start[0] is {starts[0]}, expected 0 (the first frame)")
            if bad.size:
                k = int(bad[0]) + 1
                raise self.fail(
                    f"/trials/start[{k}] (trial {names[k]!r}) is {starts[k]}, before the start "
                    f"{starts[k - 1]} of the trial before it"
                )
            if starts[-1] > n_frames:
                if complete:
                    k = int(np.argmax(starts > n_frames))
                    raise self.fail(
                        f"/trials/start[{k}] (trial {names[k]!r}) is {starts[k]}, beyond the "
                        f"{n_frames} frames of /frames"
                    )
                starts = np.minimum(starts, n_frames)  # partial: rows never committed
        elif n_frames:
            raise self.fail(f"/frames holds {n_frames} frames but /trials is empty")
        stops = np.append(starts[1:], n_frames).astype(np.int64) if n_trials else starts
        if has_m.any() and "markers" not in fds and layout.n_markers:
            k = int(np.argmax(has_m))
            raise self.fail(
                f"missing dataset /frames/markers: trial {names[k]!r} has has_markers=True"
            )
        if has_f.any() and "force" not in fds:
            k = int(np.argmax(has_f))
            raise self.fail(f"missing dataset /frames/force: trial {names[k]!r} has has_force=True")

        events = self._events(n_events, complete, names)
        trials = [
            {
                "name": names[k],
                "start_frame": int(starts[k]),
                "n_frames": int(stops[k] - starts[k]),
                "region": int(regions[k]),
                "inflation": infl[k],
                "has_markers": bool(has_m[k]),
                "has_force": bool(has_f[k]),
                "meta": metas[k],
            }
            for k in range(n_trials)
        ]
        return {"n_frames": n_frames, "trials": trials, "events": events, "frames": fds}

    def _events(self, n_events: int, complete: bool, names: list[str]) -> list[dict[str, Any]]:
        eds = {k: self.node(f"/events/{k}") for k in _EVENT_FIELDS}
        n_events = self._check_rows(eds, "events", n_events, complete)
        self._check_kind(eds["t_s"], "f", "a float")
        self._check_kind(eds["trial"], "iu", "an integer")
        if h5py.check_string_dtype(eds["text"].dtype) is None:
            raise self.fail(
                f"/events/text has dtype {eds['text'].dtype}, expected variable-length strings"
            )
        self.field = "/events"
        t = eds["t_s"][:n_events]
        tri = eds["trial"][:n_events]
        text = eds["text"].asstr()[:n_events]
        out = []
        for k in range(n_events):
            j = int(tri[k])
            if not -1 <= j < len(names):
                raise self.fail(
                    f"/events/trial[{k}] is {j}, expected -1 or a row of /trials (0..{len(names) - 1})"
                )
            out.append(
                {"t_s": float(t[k]), "trial": None if j < 0 else names[j], "text": str(text[k])}
            )
        return out

    def _check_kind(self, ds: h5py.Dataset, kinds: str, what: str) -> None:
        if ds.dtype.kind not in kinds:
            raise self.fail(f"{ds.name} has dtype {ds.dtype}, expected {what}")

    def _check_rows(self, dsets: dict, group: str, committed: int, complete: bool) -> int:
        """Rows of every dataset of a group vs /committed; returns the usable row count."""
        for k, ds in dsets.items():
            if ds.ndim < 1:
                raise self.fail(f"/{group}/{k} is a scalar, expected one row per {group[:-1]}")
        lengths = {k: ds.shape[0] for k, ds in dsets.items()}
        if complete:
            for k, n in lengths.items():
                if n != committed:
                    raise self.fail(
                        f"/{group}/{k} has {n} rows, but /committed says the recording holds "
                        f"{committed} {group}"
                    )
            return committed
        short = {k: n for k, n in lengths.items() if n < committed}
        if short:
            logger.warning(
                "%s: partial file: /%s datasets shorter than committed (%d): %s",
                self.path,
                group,
                committed,
                short,
            )
            return min(short.values())
        return committed

    # ------------------------------------------------------------------ frames
    def trials(self, layout: SensorLayout, index: dict, select: list[dict]) -> list[Trial]:
        fds = index["frames"]
        out = []
        for row in select:
            s, e = row["start_frame"], row["start_frame"] + row["n_frames"]
            src = f"/frames rows {s}:{e}"
            self.field = src
            cap = self._read(fds["capacitance"], s, e, np.float64)
            ts = self._read(fds["timestamps"], s, e, np.float64)
            lab = self._read(fds["labels"], s, e, np.int16)
            mk = None
            if row["has_markers"]:  # a layout without markers stores none: (n, 0, 3)
                mk = (
                    self._read(fds["markers"], s, e, np.float64)
                    if layout.n_markers
                    else np.zeros((e - s, 0, 3))
                )
            fo = self._read(fds["force"], s, e, np.float64) if row["has_force"] else None
            try:
                out.append(
                    Trial(
                        name=row["name"],
                        capacitance=cap,
                        timestamps=ts,
                        labels=lab,
                        inflation=row["inflation"],
                        region=row["region"],
                        markers=mk,
                        force=fo,
                        meta=row["meta"],
                    )
                )
            except EctskinError as exc:
                raise self.fail(f"{src}: {exc}") from None
        return out

    def _read(self, ds: h5py.Dataset, s: int, e: int, dtype: Any) -> np.ndarray:
        a = ds[s:e]
        if a.dtype != dtype:
            b = a.astype(dtype)
            if not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
                raise self.fail(
                    f"{ds.name}[{s}:{e}] does not fit {np.dtype(dtype).name} losslessly"
                )
            a = b
        return a


#: Metadata read attempts of a SWMR reader (HDF5's default, 100 with doubling sleeps, turns a
#: truncated file into an endless wait); a few suffice for a live writer's torn reads.
_SWMR_READ_ATTEMPTS = 10


@functools.cache
def _set_read_attempts_fn():
    """``H5Pset_metadata_read_attempts`` of the HDF5 library h5py uses (h5py does not wrap it)."""
    try:
        fn = ctypes.CDLL(h5py.h5p.__file__).H5Pset_metadata_read_attempts
    except (OSError, AttributeError):  # e.g. Windows, where dependencies are not searched
        logger.debug("H5Pset_metadata_read_attempts not found; SWMR reads use HDF5's default")
        return None
    fn.argtypes = [ctypes.c_int64, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def _open_swmr(p: Path) -> h5py.File:
    """Open a file that a SWMR writer holds (or held when it was killed) for SWMR reading."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fn = _set_read_attempts_fn()
    if fn is not None:
        fn(fapl.id, _SWMR_READ_ATTEMPTS)
    fid = h5py.h5f.open(os.fsencode(p), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)


def _open(path: str | os.PathLike) -> tuple[h5py.File, Path]:
    """Open ``path`` read-only; a file of a running or killed SWMR writer opens in SWMR mode."""
    p = Path(os.fspath(path))
    if not p.exists():
        raise EctskinError(f"{p}: no such file")
    if p.is_dir():
        raise EctskinError(f"{p}: is a directory, expected an .h5 recording")
    try:
        try:
            return h5py.File(p, "r"), p
        except OSError as exc:
            if "already open" not in str(exc):
                raise
        # HDF5 marks a file open for writing; only a SWMR writer's file may be read meanwhile.
        try:
            return _open_swmr(p), p
        except OSError as exc:
            if "already open" in str(exc):
                raise EctskinError(
                    f"{p}: another program has this file open for writing (or crashed while "
                    f"writing it without SWMR); if none does, clear the flag with `h5clear -s {p}`"
                ) from None
            raise
    except PermissionError:
        raise EctskinError(f"{p}: cannot read (permission denied)") from None
    except OSError as exc:
        msg = str(exc)
        if "truncated" in msg:
            detail = msg[msg.find("truncated") :].rstrip(")")
            raise EctskinError(
                f"{p}: not an HDF5 file (or truncated): the file is shorter than its header says "
                f"({detail}); was it copied completely?"
            ) from None
        if "signature" in msg:
            raise EctskinError(
                f"{p}: not an HDF5 file (or truncated): no HDF5 signature found"
            ) from None
        if "lock" in msg:
            raise EctskinError(
                f"{p}: cannot open, the file is locked by another process ({msg})"
            ) from None
        raise EctskinError(f"{p}: not an HDF5 file (or truncated): {msg}") from None


def _guarded(path: str | os.PathLike, fn):
    """Run ``fn(reader)`` on the open file; damaged-file errors become one EctskinError."""
    f, p = _open(path)
    reader = _FileReader(f, p)
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
    """Read an HDF5 recording written by :func:`write_recording` or :class:`RecordingWriter`.

    The schema is checked first; a file that is not HDF5, truncated, of another format or a
    newer ``format_version``, or whose datasets disagree with its layout, raises one
    :class:`EctskinError` naming the file and the field. A file whose writer did not close it
    (``complete=False``: crashed, killed or still running) is refused unless ``allow_partial``,
    in which case every committed frame is returned (all frames up to the writer's last flush).

    ``trials``: names of the trials to load (in that order); default all, in file order.
    Arrays are returned exactly as written (float64 capacitance in pF, timestamps in s, int16
    labels, markers in mm, force in N). Events, if any, are in ``meta["events"]`` as a list of
    ``{"t_s": float, "trial": str | None, "text": str}``.
    """

    def run(r: _FileReader) -> Recording:
        head = r.header(allow_partial)
        layout = r.layout()
        index = r.index(layout, head["complete"])
        rows = index["trials"]
        if trials is not None:
            by_name = {row["name"]: row for row in rows}
            missing = [n for n in trials if n not in by_name]
            if missing:
                raise r.fail(f"no trial named {missing[0]!r} (the file has {len(rows)} trials)")
            rows = [by_name[n] for n in trials]
        meta = dict(head["meta"])
        if index["events"]:
            meta[EVENTS_KEY] = index["events"]
        loaded = r.trials(layout, index, rows)
        r.field = "/"
        try:
            return Recording(layout, loaded, head["frame_rate_hz"], meta)
        except EctskinError as exc:
            raise r.fail(str(exc)) from None

    rec = _guarded(path, run)
    logger.info("read %s: %d trials, %d frames", path, rec.n_trials, rec.n_frames)
    return rec


def read_layout(path: str | os.PathLike) -> SensorLayout:
    """The :class:`SensorLayout` stored in a recording (complete or not), without its frames."""

    def run(r: _FileReader) -> SensorLayout:
        r.header(allow_partial=True)
        return r.layout()

    return _guarded(path, run)


def list_trials(path: str | os.PathLike, *, allow_partial: bool = False) -> list[dict[str, Any]]:
    """One dict per trial, in file order, without loading any frame.

    Keys: ``name``, ``n_frames``, ``region``, ``inflation`` (tuple, ml), ``start_frame`` (row in
    ``/frames``), ``has_markers``, ``has_force``, ``meta``. Incomplete files as in
    :func:`read_recording`.
    """

    def run(r: _FileReader) -> list[dict[str, Any]]:
        head = r.header(allow_partial)
        layout = r.layout()
        return r.index(layout, head["complete"])["trials"]

    return _guarded(path, run)


# ----------------------------------------------------------------------- append-mode writer
class RecordingWriter:
    """Append frames to an HDF5 recording while they arrive; survives SIGKILL.

    Usage::

        with RecordingWriter("run.h5", layout, 30.0, meta={"source": "sim"}) as w:
            w.start_trial("trial_0000", inflation=(0, 10, 20), region=3)
            w.append(capacitance, timestamps, labels)      # (n, n_pairs) / (n,) or one frame
            w.add_event(12.5, "finger lifted")
        # close() marks the file complete

    How it survives a crash: the file is built (all groups and resizable datasets) in a temporary
    file, moved to ``path`` and reopened in HDF5 SWMR-write mode, in which the library keeps the
    on-disk file consistent at every moment. Appended frames are buffered in memory and written
    by :meth:`flush`: frames, trial rows and events first, then ``/committed`` (the commit record:
    counts of frames, trials, events). :meth:`flush` runs automatically inside :meth:`append`,
    :meth:`start_trial` and :meth:`add_event` once ``flush_interval_s`` has passed since the last
    one, so a killed process loses at most the frames of the last ``flush_interval_s`` (plus one
    append); a caller whose frames may stop arriving should call :meth:`flush` itself. Such a file
    opens with ``read_recording(path, allow_partial=True)`` (also while the writer still runs).

    Within a trial, timestamps (s) must increase; labels default to 0; markers (mm) and force (N)
    are optional, but a trial gives them with every append or never. Thread-safe.
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
    ) -> None:
        check_type("layout", layout, SensorLayout)
        self.path = Path(os.fspath(path))
        try:
            rate = float(frame_rate_hz)
        except (TypeError, ValueError):
            rate = math.nan
        if not (math.isfinite(rate) and rate > 0):
            raise EctskinError(f"frame_rate_hz must be > 0, got {frame_rate_hz!r}")
        try:
            self.flush_interval_s = float(flush_interval_s)
        except (TypeError, ValueError):
            self.flush_interval_s = math.nan
        if not self.flush_interval_s >= 0:
            raise EctskinError(f"flush_interval_s must be >= 0 s, got {flush_interval_s!r}")
        if isinstance(chunk_frames, bool) or not isinstance(chunk_frames, int) or chunk_frames < 1:
            raise EctskinError(f"chunk_frames must be an integer >= 1, got {chunk_frames!r}")
        meta = dict(meta or {})
        if EVENTS_KEY in meta:
            raise EctskinError(
                f"RecordingWriter meta: key {EVENTS_KEY!r} is reserved; use add_event() instead"
            )
        meta_json = _to_json("RecordingWriter meta", meta)
        self.layout = layout
        self.frame_rate_hz = rate
        if self.path.is_dir():
            raise EctskinError(f"{self.path}: is a directory; expected the path of an .h5 file")
        if not self.path.parent.is_dir():
            raise EctskinError(f"{self.path}: directory {self.path.parent} does not exist")
        if self.path.exists() and not overwrite:
            raise EctskinError(f"{self.path}: file exists; pass overwrite=True to replace it")

        self._lock = threading.RLock()
        self._closed = True  # until the file is open
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
        self._create(meta_json, overwrite, chunk_frames)
        self._closed = False
        self._last_flush = _clock()
        logger.info("recording to %s (SWMR, flush every %.3g s)", self.path, self.flush_interval_s)

    # ------------------------------------------------------------------ setup
    def _create(self, meta_json: str, overwrite: bool, chunk_frames: int) -> None:
        tmp = _temp_path(self.path)
        try:
            with h5py.File(tmp, "w", libver=("v110", "v110")) as f:
                _write_root(f, self.layout, self.frame_rate_hz, meta_json, "RecordingWriter")
                _create_frames(
                    f, self.layout, 0, chunk_frames, self._has_markers_ds, True, compress=False
                )
                _create_tables(f, 0, 0)
            _fsync_path(tmp)
            if overwrite:
                os.replace(tmp, self.path)
            else:
                try:  # no-clobber move: link fails if path exists
                    os.link(tmp, self.path)
                except FileExistsError:
                    raise EctskinError(
                        f"{self.path}: file exists; pass overwrite=True to replace it"
                    ) from None
                except OSError:  # file system without hard links
                    if self.path.exists():
                        raise EctskinError(
                            f"{self.path}: file exists; pass overwrite=True to replace it"
                        ) from None
                    os.replace(tmp, self.path)
        except OSError as exc:
            raise EctskinError(f"{self.path}: cannot create the recording ({exc})") from None
        finally:
            try:
                tmp.unlink()
            except FileNotFoundError:
                pass
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
        self._tds = {k: self._f["trials"][k] for k in _TRIAL_FIELDS}
        self._eds = {k: self._f["events"][k] for k in _EVENT_FIELDS}

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
        if _clock() - self._last_flush >= self.flush_interval_s:
            self.flush()

    # ------------------------------------------------------------------ public
    def start_trial(
        self,
        name: str,
        *,
        inflation: Sequence[float] = (),
        region: int = 0,
        meta: dict[str, Any] | None = None,
    ) -> None:
        """Start a new trial; the frames appended from now on belong to it.

        ``inflation``: chamber volumes p in ml; ``region``: touched region (0 = none).
        """
        with self._lock:
            self._check_open()
            check_type("trial name", name, str)
            if not name:
                raise EctskinError(f"{self.path}: trial name must not be empty")
            if name in self._names:
                raise EctskinError(f"{self.path}: trial {name!r} already exists in this recording")
            try:
                infl = np.asarray([float(v) for v in inflation], dtype=np.float64)
            except (TypeError, ValueError):
                raise EctskinError(
                    f"trial {name!r}: inflation must be a sequence of numbers (ml), got {inflation!r}"
                ) from None
            if isinstance(region, bool) or not isinstance(region, (int, np.integer)):
                raise EctskinError(f"trial {name!r}: region must be an integer, got {region!r}")
            if not 0 <= int(region) <= self.layout.n_regions:
                raise EctskinError(
                    f"trial {name!r}: region {region} is not 0..{self.layout.n_regions} of layout "
                    f"{self.layout.name!r}"
                )
            row = {
                "name": name,
                "start": self.n_frames,
                "region": int(region),
                "inflation_ml": infl,
                "has_markers": None,  # decided by the first append
                "has_force": None,
                "meta_json": _to_json(f"trial {name!r}: meta", meta),
            }
            self._names.append(name)
            self._trial_rows.append(row)
            self._cur = row
            self._cur_index = len(self._names) - 1
            self._cur_last_t = -math.inf
            self._maybe_flush()

    def append(
        self,
        capacitance: Any,
        timestamps: Any,
        labels: Any = None,
        markers: Any = None,
        force: Any = None,
    ) -> None:
        """Append frames to the current trial.

        capacitance: (n, n_pairs) or one frame (n_pairs,), pF (NaN = masked channel).
        timestamps: (n,) or a scalar, s, finite and increasing within the trial.
        labels: (n,) or a scalar class 0..n_regions, default 0.
        markers: (n, n_markers, 3) or (n_markers, 3), mm, NaN = occluded.
        force: (n,) or a scalar, N.

        The first append of a trial decides whether the trial carries markers and force; an
        append of 0 frames only declares that (for a trial that may stay empty).
        """
        with self._lock:
            self._check_open()
            if self._cur is None:
                raise EctskinError(f"{self.path}: call start_trial() before append()")
            L = self.layout
            src = f"{self.path}: append to trial {self._cur['name']!r}"
            cap = _frames_arg("capacitance", capacitance, (L.n_pairs,), None, src)
            n = cap.shape[0]
            ts = _frames_arg("timestamps", timestamps, (), n, src, finite=True)
            if labels is None:
                lab = np.zeros(n, dtype=np.int16)
            else:
                lab = _frames_arg("labels", labels, (), n, src, finite=True, broadcast=True)
                bad = (lab != np.round(lab)) | (lab < 0) | (lab > L.n_regions)
                if bad.any():
                    k = int(np.argmax(bad))
                    raise EctskinError(
                        f"{src}: labels[{k}] is {lab[k]}, expected an integer 0..{L.n_regions}"
                    )
                lab = lab.astype(np.int16)
            mk = (
                None
                if markers is None
                else _frames_arg("markers", markers, (L.n_markers, 3), n, src)
            )
            fo = None if force is None else _frames_arg("force", force, (), n, src, broadcast=True)
            prev = np.concatenate([[self._cur_last_t], ts])
            if n and np.any(np.diff(prev) <= 0):
                k = int(np.argmax(np.diff(prev) <= 0))
                raise EctskinError(
                    f"{src}: timestamps must increase within a trial; timestamps[{k}] = {ts[k]} "
                    f"comes after {prev[k]}"
                )
            flags = {"has_markers": mk is not None, "has_force": fo is not None}
            for key, given in flags.items():
                what = key[4:]
                if self._cur[key] is not None and self._cur[key] != given:
                    raise EctskinError(
                        f"{src}: {what} {'given' if given else 'missing'} here, but the trial's "
                        f"earlier frames {'had' if self._cur[key] else 'had no'} {what}; give "
                        "them with every append of a trial or never"
                    )
            if flags["has_markers"] and not self._has_markers_ds:
                raise EctskinError(f"{src}: layout {L.name!r} has no markers")
            if self._cur["has_markers"] is None:  # the trial's first append decides
                self._cur.update(flags)
                if not any(r is self._cur for r in self._trial_rows):
                    self._trial_rows.append(self._cur)  # already written: rewrite its flags
            if n == 0:
                return
            self._cur_last_t = float(ts[-1])
            self._buf.setdefault("capacitance", []).append(cap)
            self._buf.setdefault("timestamps", []).append(ts)
            self._buf.setdefault("labels", []).append(lab)
            if mk is not None:
                self._buf.setdefault("markers", []).append((self._n_buf, mk))
            if fo is not None:
                self._buf.setdefault("force", []).append((self._n_buf, fo))
            self._n_buf += n
            self._maybe_flush()

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
            self._events.append((t, self._cur_index, text))
            self._maybe_flush()

    def flush(self) -> None:
        """Write the buffered trials, events and frames, then the commit record, to disk."""
        with self._lock:
            self._check_open()
            self._flush()

    def _flush(self) -> None:
        # Idempotent: rows are written by index and the counters only move once written, so a
        # failed flush (disk full) can be retried.
        try:
            self._write_buffers()
        except OSError as exc:
            raise EctskinError(f"{self.path}: cannot write the recording ({exc})") from None

    def _write_buffers(self) -> None:
        t0 = time.perf_counter()
        # 1. trial rows (new trials, and flag updates of the current one)
        for row in self._trial_rows:
            k = self._names.index(row["name"])
            if k >= self._n_trials_written:
                for ds in self._tds.values():
                    ds.resize((k + 1,))
                self._n_trials_written = k + 1
            for key in _TRIAL_FIELDS:
                value = row[key]
                if key in ("has_markers", "has_force"):
                    value = bool(value)
                self._tds[key][k] = value
        self._trial_rows = []
        # 2. events
        _write_events(self._eds, self._events, self._n_events_written)
        self._n_events_written += len(self._events)
        self._events = []
        # 3. frames
        if self._n_buf:
            s, e = self._n_frames_written, self._n_frames_written + self._n_buf
            for ds in self._fds.values():
                ds.resize((e, *ds.shape[1:]))
            for key in ("capacitance", "timestamps", "labels"):
                self._fds[key][s:e] = np.concatenate(self._buf[key])
            for key in ("markers", "force"):
                for off, arr in self._buf.get(key, []):
                    self._fds[key][s + off : s + off + arr.shape[0]] = arr
            self._n_frames_written = e
            self._buf = {}
            self._n_buf = 0
        self._f.flush()
        # 4. the commit record, only once everything it counts is on disk
        self._f["committed"][:] = [
            self._n_frames_written,
            self._n_trials_written,
            self._n_events_written,
        ]
        self._f.flush()
        self._last_flush = _clock()
        logger.debug(
            "%s: flushed %d frames in %.1f ms",
            self.path,
            self._n_frames_written,
            1e3 * (time.perf_counter() - t0),
        )

    def close(self, *, complete: bool = True) -> None:
        """Flush, mark the file complete and close it. Idempotent.

        ``complete=False`` closes without marking it (as for an interrupted session): the file
        then reads only with ``allow_partial=True``.
        """
        with self._lock:
            if self._closed:
                return
            try:
                self._flush()
                if complete:
                    self._f.attrs["complete"] = np.bool_(True)
                    self._f.flush()
            finally:
                self._closed = True
                self._f.close()
            _fsync_path(self.path)
            logger.info(
                "closed %s (%s): %d trials, %d frames, %d events",
                self.path,
                "complete" if complete else "left incomplete",
                self._n_trials_written,
                self._n_frames_written,
                self._n_events_written,
            )

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            logger.warning(
                "%s: closed after %s; left incomplete (read it with allow_partial=True)",
                self.path,
                exc_type.__name__,
            )
            self.close(complete=False)
