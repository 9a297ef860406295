"""Checked reading of one open recording file: every problem is an error naming file and field.

:class:`FileReader` walks a file in the order of the schema (``docs/recording-format.md``):
root attributes (:meth:`~FileReader.header`), ``/layout``, the commit record and the trial and
event tables (:meth:`~FileReader.index`), then the frames of the selected trials
(:meth:`~FileReader.trials`). ``field`` names the part being read, so an unexpected h5py error
can still be reported against it (:func:`ectskin.io.hdf5.read.guarded`).

Files of every version up to :data:`~ectskin.io.hdf5.schema.FORMAT_VERSION` are read: a version-1
file has no finger ground truth, so its trials come back with ``contact``, ``finger_uv_mm``,
``finger_height_mm`` and ``finger_surface`` None; version 1 and 2 files have no second finger
(``contact2``, ``finger2_uv_mm``, ``force2`` and ``finger2_surface`` None).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from ectskin._check import EctskinError
from ectskin.io.hdf5.schema import (
    EVENT_FIELDS,
    FORMAT,
    FORMAT_VERSION,
    OPTIONAL_FRAMES,
    TRIAL_FIELDS_OF_VERSION,
)
from ectskin.io.recording import Trial
from ectskin.layout import SensorLayout
from ectskin.layout.layout import SURFACES

logger = logging.getLogger(__name__)


class FileReader:
    """Reads one open file, turning every problem into an EctskinError naming file and field."""

    def __init__(self, f: h5py.File, path: Path):
        self.f = f
        self.path = path
        self.field = "/"
        self.version = FORMAT_VERSION  # the file's, once the header is read

    def fail(self, msg: str) -> EctskinError:
        return EctskinError(f"{self.path}: {msg}")

    # ------------------------------------------------------------------ nodes and attributes
    def node(self, name: str, kind: type = h5py.Dataset):
        self.field = name
        obj = self.f.get(name)
        if obj is None:
            what = "dataset" if kind is h5py.Dataset else "group"
            raise self.fail(f"missing {what} {name} (required by {FORMAT} version {self.version})")
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

    def _check_kind(self, ds: h5py.Dataset, kinds: str, what: str) -> None:
        if ds.dtype.kind not in kinds:
            raise self.fail(f"{ds.name} has dtype {ds.dtype}, expected {what}")

    def _check_strings(self, ds: h5py.Dataset) -> None:
        if h5py.check_string_dtype(ds.dtype) is None:
            raise self.fail(f"{ds.name} has dtype {ds.dtype}, expected variable-length strings")

    # ------------------------------------------------------------------ header
    def header(self, allow_partial: bool) -> dict[str, Any]:
        """Root attributes: format, version, completeness, frame rate and ``Recording.meta``."""
        self._check_format()
        version = self.version = self._format_version()
        complete = self.attr(self.f, "complete")
        if not isinstance(complete, (bool, np.bool_, int, np.integer)) or int(complete) not in (
            0,
            1,
        ):
            raise self.fail(f"attribute 'complete' must be a boolean, found {complete!r}")
        complete = bool(complete)
        if not complete and not allow_partial:
            raise self.fail(
                "incomplete recording (complete=False): it was not closed properly (the writer "
                "crashed or is still running); read what it holds with allow_partial=True "
                "(--allow-partial on the command line of live)"
            )
        rate = self.attr(self.f, "frame_rate_hz")
        try:
            rate = float(rate)
        except (TypeError, ValueError):
            rate = math.nan
        if not (math.isfinite(rate) and rate > 0):
            raise self.fail(f"attribute 'frame_rate_hz' must be a number > 0, found {rate!r}")
        meta = self.json_attr(self.f, "meta_json")
        if not isinstance(meta, dict):
            raise self.fail("attribute 'meta_json' must hold a JSON object")
        return {"version": version, "complete": complete, "frame_rate_hz": rate, "meta": meta}

    def _check_format(self) -> None:
        fmt = self.f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode("utf-8", errors="replace")
        if fmt != FORMAT:
            raise self.fail(
                f"not an ectskin recording: root attribute 'format' is {fmt!r}, expected {FORMAT!r}"
            )

    def _format_version(self) -> int:
        version = self.attr(self.f, "format_version")
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
        return version

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
        n_frames, n_trials, n_events = self._committed()
        tds, n_trials = self._trial_table(n_trials, complete)
        fds, n_frames = self._frame_datasets(layout, n_frames, complete)
        self.field = "/trials"
        cols = self._trial_columns(tds, n_trials)
        names = cols["name"]
        starts = self._check_starts(names, cols["start"], n_frames, complete)
        stops = np.append(starts[1:], n_frames).astype(np.int64) if n_trials else starts
        self._check_optional_frames(layout, fds, names, cols)
        events = self._events(n_events, complete, names)
        trials = [
            {
                "name": names[k],
                "start_frame": int(starts[k]),
                "n_frames": int(stops[k] - starts[k]),
                "region": int(cols["region"][k]),
                "inflation": cols["inflation"][k],
                **{f"has_{d}": bool(cols[f"has_{d}"][k]) for d in OPTIONAL_FRAMES},
                "finger_surface": cols["finger_surface"][k],
                "finger2_surface": cols["finger2_surface"][k],
                "meta": cols["meta"][k],
            }
            for k in range(n_trials)
        ]
        return {"n_frames": n_frames, "trials": trials, "events": events, "frames": fds}

    def _committed(self) -> tuple[int, int, int]:
        c = self.node("/committed")
        if c.shape != (3,) or c.dtype.kind not in "iu":
            raise self.fail(
                f"/committed has shape {c.shape} and dtype {c.dtype}, expected (3,) int64"
            )
        n_frames, n_trials, n_events = (int(v) for v in c[()])
        if min(n_frames, n_trials, n_events) < 0:
            raise self.fail(f"/committed holds negative counts {[n_frames, n_trials, n_events]}")
        return n_frames, n_trials, n_events

    def _trial_table(self, n_trials: int, complete: bool) -> tuple[dict, int]:
        """The ``/trials`` columns of the file's version (a version-1 file has fewer)."""
        tds = {k: self.node(f"/trials/{k}") for k in TRIAL_FIELDS_OF_VERSION[self.version]}
        n_trials = self._check_rows(tds, "trials", n_trials, complete)
        self._check_kind(tds["start"], "iu", "an integer")
        self._check_kind(tds["region"], "iu", "an integer")
        for k in tds:
            if k.startswith("has_"):
                self._check_kind(tds[k], "biu", "a boolean")
        self._check_strings(tds["name"])
        self._check_strings(tds["meta_json"])
        for k in ("finger_surface", "finger2_surface"):
            if k in tds:
                self._check_strings(tds[k])
        if h5py.check_vlen_dtype(tds["inflation_ml"].dtype) is None:
            raise self.fail(
                f"/trials/inflation_ml has dtype {tds['inflation_ml'].dtype}, expected variable-"
                "length float64"
            )
        return tds, n_trials

    def _frame_datasets(
        self, layout: SensorLayout, n_frames: int, complete: bool
    ) -> tuple[dict, int]:
        fds = {}
        for k in ("capacitance", "timestamps", "labels", *OPTIONAL_FRAMES):
            if k in OPTIONAL_FRAMES and f"frames/{k}" not in self.f:
                continue
            fds[k] = self.node(f"/frames/{k}")
        tails = {
            "capacitance": ((layout.n_pairs,), f"(n_frames, {layout.n_pairs})", "f"),
            "timestamps": ((), "(n_frames,)", "f"),
            "labels": ((), "(n_frames,)", "iu"),
            "markers": ((layout.n_markers, 3), f"(n_frames, {layout.n_markers}, 3)", "f"),
            "force": ((), "(n_frames,)", "f"),
            "contact": ((), "(n_frames,)", "biu"),
            "finger_uv_mm": ((2,), "(n_frames, 2)", "f"),
            "finger_height_mm": ((), "(n_frames,)", "f"),
            "contact2": ((), "(n_frames,)", "biu"),
            "finger2_uv_mm": ((2,), "(n_frames, 2)", "f"),
            "force2": ((), "(n_frames,)", "f"),
        }
        kind_names = {"f": "a float", "iu": "an integer", "biu": "a boolean"}
        for k, ds in fds.items():
            tail, want, kinds = tails[k]
            if ds.ndim != 1 + len(tail) or tuple(ds.shape[1:]) != tail:
                raise self.fail(
                    f"/frames/{k} has shape {ds.shape}, expected {want} for layout {layout.name!r}"
                )
            self._check_kind(ds, kinds, kind_names[kinds])
        return fds, self._check_rows(fds, "frames", n_frames, complete)

    def _trial_columns(self, tds: dict, n_trials: int) -> dict[str, Any]:
        """The first ``n_trials`` rows of the trial table as Python values, names checked."""
        names = [str(s) for s in tds["name"].asstr()[:n_trials]]
        cols = {
            "name": names,
            "start": np.asarray(tds["start"][:n_trials], dtype=np.int64),
            "region": np.asarray(tds["region"][:n_trials], dtype=np.int64),
            "inflation": [tuple(float(v) for v in row) for row in tds["inflation_ml"][:n_trials]],
            **{  # a version-1 (2) file has no (second finger's) ground-truth columns: all False
                f"has_{k}": (
                    np.asarray(tds[f"has_{k}"][:n_trials]).astype(bool)
                    if f"has_{k}" in tds
                    else np.zeros(len(names), dtype=bool)
                )
                for k in OPTIONAL_FRAMES
            },
            "finger_surface": self._finger_surfaces(tds, names),
            "finger2_surface": self._finger_surfaces(tds, names, "finger2_surface"),
            "meta": [],
        }
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
            cols["meta"].append(m)
        seen = set()
        for k, name in enumerate(names):
            if not name or name in seen:
                raise self.fail(f"/trials/name[{k}]: trial name {name!r} is empty or repeated")
            seen.add(name)
        return cols

    def _finger_surfaces(
        self, tds: dict, names: list[str], column: str = "finger_surface"
    ) -> list[str | None]:
        """``/trials/<column>`` as surface names ('' → None); None for a file without it."""
        if column not in tds:
            return [None] * len(names)
        out = []
        for k, s in enumerate(tds[column].asstr()[: len(names)]):
            s = str(s)
            if s and s not in SURFACES:
                raise self.fail(
                    f"/trials/{column}[{k}] (trial {names[k]!r}) is {s!r}, expected '' "
                    f"(none) or one of {', '.join(SURFACES)}"
                )
            out.append(s or None)
        return out

    def _check_starts(
        self, names: list[str], starts: np.ndarray, n_frames: int, complete: bool
    ) -> np.ndarray:
        """Trial starts: 0 first, never decreasing, within /frames (clipped when partial)."""
        if not names:
            if n_frames:
                raise self.fail(f"/frames holds {n_frames} frames but /trials is empty")
            return starts
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
        return starts

    def _check_optional_frames(
        self, layout: SensorLayout, fds: dict, names: list[str], cols: dict
    ) -> None:
        for d in OPTIONAL_FRAMES:
            has = cols[f"has_{d}"]
            if d == "markers" and not layout.n_markers:  # markers (n, 0, 3) are not stored
                continue
            if has.any() and d not in fds:
                k = int(np.argmax(has))
                raise self.fail(f"missing dataset /frames/{d}: trial {names[k]!r} has has_{d}=True")

    def _events(self, n_events: int, complete: bool, names: list[str]) -> list[dict[str, Any]]:
        eds = {k: self.node(f"/events/{k}") for k in EVENT_FIELDS}
        n_events = self._check_rows(eds, "events", n_events, complete)
        self._check_kind(eds["t_s"], "f", "a float")
        self._check_kind(eds["trial"], "iu", "an integer")
        self._check_strings(eds["text"])
        self.field = "/events"
        t = eds["t_s"][:n_events]
        tri = eds["trial"][:n_events]
        text = eds["text"].asstr()[:n_events]
        out = []
        for k in range(n_events):
            if not np.isfinite(t[k]):  # as the writers require (schema.check_events)
                raise self.fail(f"/events/t_s[{k}] is {t[k]}, expected a finite time in s")
            j = int(tri[k])
            if not -1 <= j < len(names):
                raise self.fail(
                    f"/events/trial[{k}] is {j}, expected -1 or a row of /trials (0..{len(names) - 1})"
                )
            out.append(
                {"t_s": float(t[k]), "trial": None if j < 0 else names[j], "text": str(text[k])}
            )
        return out

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
        """The :class:`Trial` of every row of ``select`` (rows of ``index["trials"]``)."""
        return [self._trial(layout, index["frames"], row) for row in select]

    def _trial(self, layout: SensorLayout, fds: dict, row: dict) -> Trial:
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
        optional = {  # force and the finger ground truth
            k: self._read(fds[k], s, e, np.bool_ if k in ("contact", "contact2") else np.float64)
            if row[f"has_{k}"]
            else None
            for k in OPTIONAL_FRAMES
            if k != "markers"
        }
        try:
            return Trial(
                name=row["name"],
                capacitance=cap,
                timestamps=ts,
                labels=lab,
                inflation=row["inflation"],
                region=row["region"],
                markers=mk,
                **optional,
                finger_surface=row["finger_surface"],
                finger2_surface=row["finger2_surface"],
                meta=row["meta"],
            )
        except EctskinError as exc:
            raise self.fail(f"{src}: {exc}") from None

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
