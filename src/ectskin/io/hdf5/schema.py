"""The recording schema: names, versions, dataset layout and the JSON of the metadata.

Both writers (:mod:`~ectskin.io.hdf5.write` and :mod:`~ectskin.io.hdf5.append`) build a file with
:func:`write_root`, :func:`create_frames` and :func:`create_tables`, so there is one schema and
the reader (:mod:`~ectskin.io.hdf5.reader`) has one code path. The schema itself is documented in
``docs/recording-format.md``.

The fingers: the per-frame finger datasets (:data:`FINGER_FRAMES`) and the per-finger columns of
``/trials`` (:data:`FINGER_COLUMNS`) have a fingers axis after their row axis, as wide as the
trial with the most fingers (at least 1); ``/trials/n_fingers`` says how many of its columns each
trial uses. The axis is resizable, so the live writer widens it when a trial brings more fingers.

JSON policy of the metadata (``meta_json``): unlike the result files of :mod:`ectskin._files`
(strict JSON, non-finite floats written as ``null``), a recording keeps NaN and ±inf in
``Recording.meta`` and ``Trial.meta`` as JSON's ``NaN``/``Infinity`` extension, which Python's
``json`` reads back as the same floats: the format promises that metadata round-trips exactly
(``docs/recording-format.md``, "Metadata as JSON"). NumPy scalars and arrays are stored as
numbers and lists; anything else that is not a JSON value is refused. That is why this module does
not use :func:`ectskin._files.to_jsonable`, which writes NaN as ``null`` and turns dataclasses,
paths and objects with ``to_dict`` into JSON values: here they are refused, naming the key.
"""

from __future__ import annotations

import json
from collections.abc import Collection, Sequence
from datetime import UTC, datetime
from typing import Any

import h5py
import numpy as np

from ectskin import __version__
from ectskin._check import EctskinError, check_type
from ectskin.io.recording import FINGER_FRAME_FIELDS, FINGER_TRIAL_FIELDS, check_name
from ectskin.layout import SensorLayout

FORMAT = "ectskin.recording"
#: The version written. 1: the first; 2: adds the finger ground truth (``/frames/contact``,
#: ``finger_uv_mm``, ``finger_height_mm`` and their ``/trials`` columns); 3: adds a second finger
#: in suffixed datasets (:data:`V3_SECOND_FINGER`); 4: the fingers become an axis of the finger
#: datasets (``force`` included) and of ``/trials/finger_surface``, with ``/trials/n_fingers``
#: and the per-finger ``finger_radius_mm`` and ``finger_modulus_mpa``: an older reader would
#: misread the re-shaped datasets, so it must refuse the file. Versions 1 to 4 read.
FORMAT_VERSION = 4

#: Key of ``Recording.meta`` that holds the events table (list of ``{"t_s", "trial", "text"}``).
EVENTS_KEY = "events"

STR = h5py.string_dtype("utf-8")
VLEN_F8 = h5py.vlen_dtype(np.float64)
#: Optional ``/frames`` datasets (present when some trial has them), each flagged per trial by
#: the ``/trials`` column ``has_<name>``; the finger ground truth exists from version 2 on.
OPTIONAL_FRAMES = ("markers", "force", "contact", "finger_uv_mm", "finger_height_mm")
#: The ``/frames`` datasets on the fingers axis (version 4): (n_frames, n_fingers, ...).
FINGER_FRAMES = tuple(FINGER_FRAME_FIELDS)
#: The ``/trials`` columns on the fingers axis (version 4): (n_trials, n_fingers).
FINGER_COLUMNS = ("finger_surface", *FINGER_TRIAL_FIELDS)
#: Version 3's second finger: ``/frames`` datasets (n_frames,), (n_frames, 2), (n_frames,), each
#: flagged by ``/trials/has_<name>``, and its face in ``/trials/finger2_surface`` (read only).
V3_SECOND_FINGER = ("contact2", "finger2_uv_mm", "force2")
_BASE_COLUMNS = ("name", "start", "region", "inflation_ml", "has_markers", "has_force")
_TRUTH_FLAGS = ("has_contact", "has_finger_uv_mm", "has_finger_height_mm")
#: ``/trials`` columns of each format version.
TRIAL_FIELDS_OF_VERSION = {
    1: (*_BASE_COLUMNS, "meta_json"),
    2: (*_BASE_COLUMNS, *_TRUTH_FLAGS, "finger_surface", "meta_json"),
    3: (
        *_BASE_COLUMNS,
        *_TRUTH_FLAGS,
        "finger_surface",
        *(f"has_{k}" for k in V3_SECOND_FINGER),
        "finger2_surface",
        "meta_json",
    ),
    4: (*_BASE_COLUMNS, *_TRUTH_FLAGS, "n_fingers", *FINGER_COLUMNS, "meta_json"),
}
TRIAL_FIELDS = TRIAL_FIELDS_OF_VERSION[FORMAT_VERSION]
EVENT_FIELDS = ("t_s", "trial", "text")
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
TABLE_CHUNK = 64  # rows per chunk of the trial and event tables


# ------------------------------------------------------------------------------------ JSON
def _json_default(value: Any) -> Any:
    # NumPy scalars and arrays are stored as the equivalent JSON numbers and lists.
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _first_bad_key(value: Any, path: str = "", seen: frozenset[int] = frozenset()) -> str:
    """The key path (``['a'][2]``) of the first value json cannot store, or ``""``."""
    if isinstance(value, dict):
        items = [(f"[{k!r}]", v) for k, v in value.items()]
    elif isinstance(value, list | tuple):
        items = [(f"[{k}]", v) for k, v in enumerate(value)]
    elif isinstance(value, str | int | float | np.generic | np.ndarray | None):
        return ""
    else:
        return path
    if id(value) in seen:  # a circular reference
        return path
    for key, item in items:
        found = _first_bad_key(item, path + key, seen | {id(value)})
        if found:
            return found
    return ""


def to_json(name: str, value: Any) -> str:
    """JSON text of ``value`` (a dict of JSON-able values, None = {}) or a clear error naming
    ``name`` and the key path of the offending value."""
    if value is None:
        value = {}
    check_type(name, value, dict)
    try:
        return json.dumps(value, default=_json_default, sort_keys=False)
    except (TypeError, ValueError) as exc:
        where = _first_bad_key(value)
        at = f" (at {where})" if where else ""
        raise EctskinError(
            f"{name} must hold JSON-able values (str, numbers, lists, dicts){at}: {exc}"
        ) from None


def utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


# ------------------------------------------------------------------------- file structure
def write_root(
    f: h5py.File, layout: SensorLayout, frame_rate_hz: float, meta_json: str, writer: str
) -> None:
    """Root attributes (``complete`` False until the writer's last step), /layout, /committed."""
    check_layout_names(layout)
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    f.attrs["complete"] = np.bool_(False)
    f.attrs["frame_rate_hz"] = np.float64(frame_rate_hz)
    f.attrs["created_utc"] = utc_now()
    f.attrs["ectskin_version"] = __version__
    f.attrs["writer"] = writer
    f.attrs["meta_json"] = meta_json
    g = f.create_group("layout")
    g.attrs["json"] = layout.to_json()
    g.attrs["name"] = layout.name
    c = f.create_dataset("committed", data=np.zeros(3, dtype=np.int64))
    c.attrs["fields"] = ["n_frames", "n_trials", "n_events"]


def check_layout_names(layout: SensorLayout) -> None:
    """The layout's name, pair names and marker names are stored as HDF5 strings: none may hold
    a NUL byte (h5py would fail with a ValueError deep in the write)."""
    where = f"layout {layout.name!r}"
    check_name(f"{where}: name", layout.name)
    for n in layout.pair_names:
        check_name(f"{where}: pair name", n)
    for m in layout.markers:
        check_name(f"{where}: marker name", m.name)


def frame_specs(
    layout: SensorLayout, optional: Collection[str]
) -> dict[str, tuple[tuple[int, ...], Any, Any, str]]:
    """``/frames`` datasets, the required ones and those of ``optional`` (of
    :data:`OPTIONAL_FRAMES`): name → (shape of one frame after the fingers axis for
    :data:`FINGER_FRAMES`, else of one frame; dtype, fill value, unit)."""
    spec = {
        "capacitance": ((layout.n_pairs,), np.float64, np.nan, "pF"),
        "timestamps": ((), np.float64, np.nan, "s"),
        "labels": ((), np.int16, -1, "class (0 = no touch, 1..n_regions)"),
        "markers": ((layout.n_markers, 3), np.float64, np.nan, "mm"),
        "force": ((), np.float64, np.nan, "N (per finger)"),
        "contact": ((), np.bool_, False, "bool (True = the finger is on the skin)"),
        "finger_uv_mm": ((2,), np.float64, np.nan, "mm (surface coordinates u, v)"),
        "finger_height_mm": ((), np.float64, np.nan, "mm (above the skin)"),
    }
    unknown = set(optional) - set(OPTIONAL_FRAMES)
    if unknown:
        raise ValueError(f"not optional /frames datasets: {sorted(unknown)}")
    return {k: v for k, v in spec.items() if k not in OPTIONAL_FRAMES or k in optional}


def create_frames(
    f: h5py.File,
    layout: SensorLayout,
    n_frames: int,
    chunk_frames: int,
    optional: Collection[str],
    compress: bool,
    n_fingers: int = 1,
) -> dict[str, h5py.Dataset]:
    """Create the resizable ``/frames`` datasets with ``n_frames`` rows (filled by the caller):
    the required ones and those named in ``optional`` (of :data:`OPTIONAL_FRAMES`); those of
    :data:`FINGER_FRAMES` ``n_fingers`` wide (at least 1) on a resizable fingers axis.

    ``compress``: gzip + shuffle. The live writer does not compress: a compressed chunk that is
    flushed half full is rewritten elsewhere when it grows and its old space is not reused, so the
    file would grow with every flush.
    """
    g = f.create_group("frames")
    rows = max(1, int(chunk_frames))
    width = max(1, int(n_fingers))
    out = {}
    for name, (tail, dtype, fill, unit) in frame_specs(layout, optional).items():
        axis: tuple[int | None, ...] = ()
        chunk: tuple[int, ...] = ()
        if name in FINGER_FRAMES:
            axis, chunk = (None,), (width,)
        ds = g.create_dataset(
            name,
            shape=(n_frames, *((width,) if axis else ()), *tail),
            maxshape=(None, *axis, *tail),
            chunks=(rows, *chunk, *tail),
            dtype=dtype,
            fillvalue=fill,
            **(COMPRESSION if compress else {}),
        )
        ds.attrs["unit"] = unit
        out[name] = ds
    out["capacitance"].attrs["pair_names"] = list(layout.pair_names)
    if "markers" in out:
        out["markers"].attrs["marker_names"] = [m.name for m in layout.markers]
    return out


def _create_table(
    f: h5py.File, group: str, spec: dict[str, Any], n_rows: int, n_fingers: int = 1
) -> dict:
    """Resizable columns of ``n_rows``; those of :data:`FINGER_COLUMNS` ``n_fingers`` wide."""
    g = f.create_group(group)
    width = max(1, int(n_fingers))
    out = {}
    for k, dt in spec.items():
        axis = k in FINGER_COLUMNS
        out[k] = g.create_dataset(
            k,
            shape=(n_rows, width) if axis else (n_rows,),
            maxshape=(None, None) if axis else (None,),
            chunks=(TABLE_CHUNK, width) if axis else (TABLE_CHUNK,),
            dtype=dt,
            fillvalue=np.nan if dt is np.float64 and axis else None,
        )
    return out


def create_tables(
    f: h5py.File, n_trials: int, n_events: int, n_fingers: int = 1
) -> tuple[dict, dict]:
    """Create the ``/trials`` and ``/events`` tables; returns their datasets by field. The
    per-finger columns (:data:`FINGER_COLUMNS`) are ``n_fingers`` wide (at least 1)."""
    tds = _create_table(
        f,
        "trials",
        {
            "name": STR,
            "start": np.int64,
            "region": np.int32,
            "inflation_ml": VLEN_F8,
            **{f"has_{k}": np.bool_ for k in OPTIONAL_FRAMES},
            "n_fingers": np.int32,
            "finger_surface": STR,
            "finger_radius_mm": np.float64,
            "finger_modulus_mpa": np.float64,
            "meta_json": STR,
        },
        n_trials,
        n_fingers,
    )
    tds["start"].attrs["unit"] = "frame index into /frames"
    tds["n_fingers"].attrs["unit"] = "fingers of the trial: its columns of the fingers axis"
    tds["finger_surface"].attrs["unit"] = "surface name per finger, '' = none"
    tds["finger_radius_mm"].attrs["unit"] = "mm (fingertip radius per finger, NaN = unknown)"
    tds["finger_modulus_mpa"].attrs["unit"] = "MPa (pulp modulus per finger, NaN = unknown)"
    tds["inflation_ml"].attrs["unit"] = "ml"
    eds = _create_table(f, "events", {"t_s": np.float64, "trial": np.int32, "text": STR}, n_events)
    eds["t_s"].attrs["unit"] = "s"
    eds["trial"].attrs["unit"] = "row in /trials, -1 = before the first trial"
    return tds, eds


def finger_row(values: Sequence[Any], width: int, fill: Any) -> list[Any]:
    """One trial's per-finger values padded with ``fill`` to the file's fingers axis."""
    return [*values, *([fill] * (width - len(values)))]


# -------------------------------------------------------------------------------- events
def check_events(events: Any, trial_names: list[str]) -> list[tuple[float, int, str]]:
    """Validate ``Recording.meta["events"]`` into (t_s, trial index, text) rows."""
    src = f"recording meta[{EVENTS_KEY!r}]"
    check_type(src, events, list)
    index = {n: k for k, n in enumerate(trial_names)}
    rows = []
    for k, ev in enumerate(events):
        if not isinstance(ev, dict) or set(ev) != set(EVENT_FIELDS):
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
        if "\x00" in ev["text"]:
            raise EctskinError(f"{src}[{k}].text contains a NUL byte, which HDF5 cannot store")
        rows.append((float(t), -1 if trial is None else index[trial], ev["text"]))
    return rows


def write_events(eds: dict, rows: Sequence[tuple[float, int, str]], start: int = 0) -> None:
    """Write event rows at ``start`` of the ``/events`` table (growing it)."""
    if not rows:
        return
    end = start + len(rows)
    for k in EVENT_FIELDS:
        eds[k].resize((end,))
    eds["t_s"][start:end] = np.array([r[0] for r in rows], dtype=np.float64)
    eds["trial"][start:end] = np.array([r[1] for r in rows], dtype=np.int32)
    eds["text"][start:end] = np.array([r[2] for r in rows], dtype=object)
