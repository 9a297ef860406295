"""Checked reading of one open recording file: every problem is an error naming file and field.

:class:`FileReader` walks a file in the order of the schema (``docs/recording-format.md``):
root attributes (:meth:`~FileReader.header`), ``/layout``, the commit record and the trial and
event tables (:meth:`~FileReader.index`), then the frames of the selected trials
(:meth:`~FileReader.trials`). ``field`` names the part being read, so an unexpected h5py error
can still be reported against it (:func:`ectskin.io.hdf5.read.guarded`).

Files of every version up to :data:`~ectskin.io.hdf5.schema.FORMAT_VERSION` are read onto the
fingers axis of :class:`~ectskin.io.recording.Trial`: a version-1 file has no finger ground
truth, so its trials come back without ``contact``, ``finger_uv_mm`` and ``finger_height_mm``;
in files of versions 1 to 3 the finger datasets hold one finger (finger 0), and a version-3
trial's second finger (``contact2``, ``finger2_uv_mm``, ``force2``, ``finger2_surface``) becomes
finger 1 (:func:`v3_second_finger`).
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
    FINGER_COLUMNS,
    FINGER_FRAMES,
    FORMAT,
    FORMAT_VERSION,
    OPTIONAL_FRAMES,
    TRIAL_FIELDS_OF_VERSION,
    V3_SECOND_FINGER,
)
from ectskin.io.recording import FINGER_FRAME_FIELDS, FINGER_TRIAL_FIELDS, Trial
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
                **{c: cols[c][k] for c in ("n_fingers", *FINGER_COLUMNS)},
                "meta": cols["meta"][k],
                "_v3_second": bool(cols["_v3_second"][k]),  # (read by _trial, not listed)
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
        if self.version >= 4:
            self._check_kind(tds["n_fingers"], "iu", "an integer")
            for k in FINGER_TRIAL_FIELDS:
                self._check_kind(tds[k], "f", "a float")
            for k in FINGER_COLUMNS:
                if tds[k].ndim != 2:
                    raise self.fail(
                        f"/trials/{k} has shape {tds[k].shape}, expected (n_trials, n_fingers)"
                    )
        if h5py.check_vlen_dtype(tds["inflation_ml"].dtype) is None:
            raise self.fail(
                f"/trials/inflation_ml has dtype {tds['inflation_ml'].dtype}, expected variable-"
                "length float64"
            )
        return tds, n_trials

    def _frame_datasets(
        self, layout: SensorLayout, n_frames: int, complete: bool
    ) -> tuple[dict, int]:
        second = V3_SECOND_FINGER if self.version == 3 else ()
        fds = {}
        for k in ("capacitance", "timestamps", "labels", *OPTIONAL_FRAMES, *second):
            if (k in OPTIONAL_FRAMES or k in second) and f"frames/{k}" not in self.f:
                continue
            fds[k] = self.node(f"/frames/{k}")
        tails: dict[str, tuple[tuple[int | None, ...], str]] = {
            "capacitance": ((layout.n_pairs,), "f"),
            "timestamps": ((), "f"),
            "labels": ((), "iu"),
            "markers": ((layout.n_markers, 3), "f"),
            "contact2": ((), "biu"),  # version 3
            "finger2_uv_mm": ((2,), "f"),
            "force2": ((), "f"),
        }
        axis = (None,) if self.version >= 4 else ()  # the fingers axis (version 4)
        for k, tail in FINGER_FRAME_FIELDS.items():
            tails[k] = ((*axis, *tail), "biu" if k == "contact" else "f")
        kind_names = {"f": "a float", "iu": "an integer", "biu": "a boolean"}
        for k, ds in fds.items():
            tail, kinds = tails[k]
            if ds.ndim != 1 + len(tail) or any(
                t is not None and t != d for t, d in zip(tail, ds.shape[1:])
            ):
                dims = ("n_fingers" if t is None else str(t) for t in tail)
                want = ", ".join(("n_frames", *dims)) + "," * (not tail)
                raise self.fail(
                    f"/frames/{k} has shape {ds.shape}, expected ({want}) for layout "
                    f"{layout.name!r}"
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
            **{  # a version-1 file has no ground-truth columns, version 3 its second finger's
                f"has_{k}": (
                    np.asarray(tds[f"has_{k}"][:n_trials]).astype(bool)
                    if f"has_{k}" in tds
                    else np.zeros(len(names), dtype=bool)
                )
                for k in (*OPTIONAL_FRAMES, *V3_SECOND_FINGER)
            },
            "meta": [],
        }
        for k, values in enumerate(cols["inflation"]):
            bad = [v for v in values if not (math.isfinite(v) and v >= 0)]
            if bad:
                raise self.fail(
                    f"/trials/inflation_ml[{k}] (trial {names[k]!r}) holds {bad[0]} in "
                    f"{list(values)}, expected finite chamber volumes >= 0 ml"
                )
        self._finger_columns(tds, names, cols)
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

    def _finger_columns(self, tds: dict, names: list[str], cols: dict[str, Any]) -> None:
        """``n_fingers`` and the per-finger columns of each trial, as tuples of its fingers.

        Version 4 stores them on the fingers axis. Before, a trial has one finger where it gives
        any finger dataset or a ``finger_surface``, and in version 3 a second one where it gives
        ``contact2`` (``_v3_second``)."""
        n = len(names)
        if self.version >= 4:
            count = np.asarray(tds["n_fingers"][:n], dtype=np.int64)
            width = min(tds[c].shape[1] for c in FINGER_COLUMNS)
            bad = (count < 0) | (count > width)
            if bad.any():
                k = int(np.argmax(bad))
                raise self.fail(
                    f"/trials/n_fingers[{k}] (trial {names[k]!r}) is {count[k]}, expected "
                    f"0..{width} (the fingers axis of /trials/{', '.join(FINGER_COLUMNS)})"
                )
            faces = tds["finger_surface"].asstr()[:n] if width else [()] * n
            cols["n_fingers"] = [int(c) for c in count]
            cols["finger_surface"] = [
                self._faces("finger_surface", k, names[k], faces[k][: count[k]]) for k in range(n)
            ]
            for c in FINGER_TRIAL_FIELDS:
                values = np.asarray(tds[c][:n], dtype=np.float64) if width else np.zeros((n, 0))
                cols[c] = [tuple(float(v) for v in values[k, : count[k]]) for k in range(n)]
            cols["_v3_second"] = np.zeros(n, dtype=bool)
            return
        first = self._old_faces(tds, names, "finger_surface")
        gives = np.zeros(n, dtype=bool)
        for d in FINGER_FRAMES:
            gives |= cols[f"has_{d}"]
        second = np.zeros(n, dtype=bool)
        faces = [() if f is None and not g else (f,) for f, g in zip(first, gives)]
        if self.version == 3:
            second = v3_second_finger_flags(self, names, cols)
            faces2 = self._old_faces(tds, names, "finger2_surface")
            faces = [(*f, faces2[k]) if second[k] else f for k, f in enumerate(faces)]
        cols["n_fingers"] = [len(f) for f in faces]
        cols["finger_surface"] = faces
        for c in FINGER_TRIAL_FIELDS:
            cols[c] = [(math.nan,) * len(f) for f in faces]
        cols["_v3_second"] = second

    def _faces(self, column: str, k: int, name: str, row: Any) -> tuple[str | None, ...]:
        """Surface names of one trial ('' → None), each '' or one of SURFACES."""
        out = []
        for s in row:
            s = str(s)
            if s and s not in SURFACES:
                raise self.fail(
                    f"/trials/{column}[{k}] (trial {name!r}) is {s!r}, expected '' "
                    f"(none) or one of {', '.join(SURFACES)}"
                )
            out.append(s or None)
        return tuple(out)

    def _old_faces(self, tds: dict, names: list[str], column: str) -> list[str | None]:
        """``/trials/<column>`` of a file before version 4 (one face per trial; '' → None);
        None for a file without it."""
        if column not in tds:
            return [None] * len(names)
        return [
            self._faces(column, k, names[k], (s,))[0]
            for k, s in enumerate(tds[column].asstr()[: len(names)])
        ]

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
        second = V3_SECOND_FINGER if self.version == 3 else ()
        for d in (*OPTIONAL_FRAMES, *second):
            has = cols[f"has_{d}"]
            if d == "markers" and not layout.n_markers:  # markers (n, 0, 3) are not stored
                continue
            if has.any() and d not in fds:
                k = int(np.argmax(has))
                raise self.fail(f"missing dataset /frames/{d}: trial {names[k]!r} has has_{d}=True")
            if self.version >= 4 and d in FINGER_FRAMES and has.any():
                count = np.where(has, cols["n_fingers"], 0)
                if count.max() > fds[d].shape[1]:
                    k = int(np.argmax(count > fds[d].shape[1]))
                    raise self.fail(
                        f"/frames/{d} holds {fds[d].shape[1]} finger(s), but trial {names[k]!r} "
                        f"has n_fingers={count[k]}"
                    )

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
        rows = slice(s, e)
        cap = self._read(fds["capacitance"], rows, np.float64)
        ts = self._read(fds["timestamps"], rows, np.float64)
        lab = self._read(fds["labels"], rows, np.int16)
        mk = None
        if row["has_markers"]:  # a layout without markers stores none: (n, 0, 3)
            mk = (
                self._read(fds["markers"], rows, np.float64)
                if layout.n_markers
                else np.zeros((e - s, 0, 3))
            )
        # the fingers: version 4 on the axis (the trial's columns of it), before one finger
        cut = (rows, slice(0, row["n_fingers"])) if self.version >= 4 else rows
        fingers = {
            k: self._read(fds[k], cut, np.bool_ if k == "contact" else np.float64)
            if row[f"has_{k}"]
            else None
            for k in FINGER_FRAMES
        }
        if row["_v3_second"]:
            second = {
                k: self._read(fds[k], rows, np.bool_ if k == "contact2" else np.float64)
                for k in V3_SECOND_FINGER
            }
            fingers = v3_second_finger(fingers, second)
        try:
            return Trial(
                name=row["name"],
                capacitance=cap,
                timestamps=ts,
                labels=lab,
                inflation=row["inflation"],
                region=row["region"],
                markers=mk,
                **fingers,
                finger_surface=row["finger_surface"],
                **{  # all NaN (unknown): not given
                    k: None if all(math.isnan(v) for v in row[k]) else row[k]
                    for k in FINGER_TRIAL_FIELDS
                },
                meta=row["meta"],
            )
        except EctskinError as exc:
            raise self.fail(f"{src}: {exc}") from None

    def _read(self, ds: h5py.Dataset, sel: slice | tuple[slice, ...], dtype: Any) -> np.ndarray:
        a = ds[sel]
        if a.dtype != dtype:
            b = a.astype(dtype)
            if not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
                rows = sel[0] if isinstance(sel, tuple) else sel
                raise self.fail(
                    f"{ds.name}[{rows.start}:{rows.stop}] does not fit {np.dtype(dtype).name} "
                    "losslessly"
                )
            a = b
        return a


# ------------------------------------------------------------------ version 3's second finger
def v3_second_finger_flags(r: FileReader, names: list[str], cols: dict) -> np.ndarray:
    """Which trials of a version-3 file have a second finger: all of ``has_contact2``,
    ``has_finger2_uv_mm``, ``has_force2`` (they must agree), with the first finger's ``contact``,
    ``finger_uv_mm`` and ``finger_height_mm`` (finger 0 of the fingers axis)."""
    flags = np.stack([cols[f"has_{k}"] for k in V3_SECOND_FINGER], axis=1)
    mixed = flags.any(axis=1) & ~flags.all(axis=1)
    if mixed.any():
        k = int(np.argmax(mixed))
        found = ", ".join(f"has_{d}={bool(v)}" for d, v in zip(V3_SECOND_FINGER, flags[k]))
        raise r.fail(
            f"/trials: trial {names[k]!r} has {found}; a second finger (version 3) gives all "
            "three or none"
        )
    second = flags.all(axis=1)
    first = np.ones_like(second)
    for d in ("contact", "finger_uv_mm", "finger_height_mm"):
        first &= cols[f"has_{d}"]
    orphan = second & ~first
    if orphan.any():
        k = int(np.argmax(orphan))
        raise r.fail(
            f"/trials: trial {names[k]!r} has a second finger but not the first finger's "
            "contact, finger_uv_mm and finger_height_mm, which its place on the fingers axis "
            "(finger 1 beside finger 0) needs"
        )
    return second


def v3_second_finger(
    first: dict[str, np.ndarray | None], second: dict[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """The fingers axis of a version-3 trial with a second finger: the first finger's arrays
    (F,) as finger 0, ``contact2``, ``finger2_uv_mm``, ``force2`` as finger 1. Version 3 stores
    no height for the second finger, which existed only on the skin: 0 in contact, NaN (away)
    elsewhere. A first finger without ``force`` has an unknown force (NaN)."""
    n = second["contact2"].shape[0]
    on2 = second["contact2"]
    force0 = first["force"] if first["force"] is not None else np.full(n, np.nan)
    return {
        "contact": np.stack([first["contact"], on2], axis=1),
        "finger_uv_mm": np.stack([first["finger_uv_mm"], second["finger2_uv_mm"]], axis=1),
        "finger_height_mm": np.stack(
            [first["finger_height_mm"], np.where(on2, 0.0, np.nan)], axis=1
        ),
        "force": np.stack([force0, second["force2"]], axis=1),
    }
