"""Import of recordings that did not come from the twin: a documented NPZ or CSV layout.

The format is described in ``docs/import-format.md``. In short, every file holds one row per frame
with its readouts (any number of channels), a group id (the frame's trial: splits are
trial-exclusive), and labels: a touch class per frame and/or marker coordinates per frame
(frames × markers × 3, mm); optionally a reference (per trial or per frame) and timestamps (s).

:func:`load_generic` returns a :class:`~ectskin.io.recording.Recording`. Its layout is either the
one passed in (``layout=``: the channels are then that layout's pairs in the fixed order), or a
*virtual* layout built from the data:

* n virtual electrodes ``V1..Vn`` with n the smallest integer such that n(n−1)/2 ≥ channels,
  parallel wires 10 mm apart on one virtual skin (their descriptors only tell the C2DT which
  channel is which);
* when the channel count is not n(n−1)/2 the last pairs have no data: they hold NaN and are listed
  in ``rec.meta["unmeasured_pairs"]``, which every data set of :mod:`ectskin.learn.datasets` leaves
  out (so 5 channels give a 4-electrode layout with 6 pairs, of which pair 5 is unmeasured);
* one region per touch class (1..max label) and one marker per tracked point.

The file's channel and marker names are kept in ``rec.meta["channel_names"]`` and
``rec.meta["marker_names"]``. Every problem is an :class:`~ectskin.EctskinError` naming the file,
the field or column, the line (CSV) or row (NPZ), what was expected and what was found.
"""

from __future__ import annotations

import csv
import logging
import math
import zipfile
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout, load_layout

log = logging.getLogger(__name__)

NPZ_FIELDS = (
    "readouts",
    "group",
    "labels",
    "markers",
    "reference",
    "timestamps",
    "frame_rate_hz",
    "channel_names",
    "marker_names",
)
CSV_COLUMNS = "group, time_s, label, c:<channel>, ref:<channel>, m:<marker>.x|.y|.z"
#: Largest touch class a file may use (a virtual layout gets one region per class).
MAX_CLASS = 1000

__all__ = ["NPZ_FIELDS", "load_generic", "virtual_layout"]


@dataclass
class _Fields:
    """Parsed file contents, format independent (n frames, m channels, M markers)."""

    source: str
    readouts: np.ndarray  # (n, m) float64, NaN = masked
    group: np.ndarray  # (n,) int64 or str
    labels: np.ndarray | None  # (n,) int64
    markers: np.ndarray | None  # (n, M, 3) float64 mm, NaN = occluded
    reference: np.ndarray | None  # (m,), (n_groups, m) or (n, m)
    timestamps: np.ndarray | None  # (n,) float64 s
    frame_rate_hz: float | None
    channel_names: list[str]
    marker_names: list[str] | None
    row: Callable[[int], str]  # "line 12" (CSV) / "row 11" (NPZ) of frame i


# --------------------------------------------------------------------------- public
def load_generic(
    path: str | Path,
    *,
    frame_rate_hz: float | None = None,
    layout: SensorLayout | str | Path | None = None,
) -> Recording:
    """Read a generic NPZ or CSV recording (see ``docs/import-format.md``).

    Parameters
    ----------
    path : str or Path
        ``*.npz`` or ``*.csv`` (by suffix).
    frame_rate_hz : float, optional
        Overrides the file's frame rate; otherwise the file's ``frame_rate_hz`` field (NPZ) or
        ``# frame_rate_hz: 30`` line (CSV), else the median step of the timestamps.
    layout : SensorLayout or path to a layout JSON, optional
        The skin the channels come from: the file must then hold exactly ``layout.n_pairs``
        channels in the fixed pair order, ``layout.n_markers`` markers and classes up to
        ``layout.n_regions``. Default: a virtual layout built from the data (module docstring).

    Returns
    -------
    Recording with one trial per group (in order of first appearance).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npz", ".csv"):
        raise EctskinError(
            f"{path}: unknown generic recording type {path.suffix!r}; expected .npz or .csv "
            f"(see docs/import-format.md)"
        )
    if not path.is_file():
        raise EctskinError(f"{path}: file not found")
    fields = _read_npz(path) if suffix == ".npz" else _read_csv(path)
    if isinstance(layout, (str, Path)):
        layout = load_layout(layout)
    return _build_recording(fields, layout, frame_rate_hz, fmt=suffix[1:])


def virtual_layout(
    n_channels: int, n_regions: int = 0, n_markers: int = 0, marker_names: list[str] | None = None
) -> SensorLayout:
    """A layout of virtual electrodes whose pairs can carry ``n_channels`` channels.

    n electrodes with n the smallest integer ≥ 2 such that n(n−1)/2 ≥ n_channels: vertical wires
    15 mm long, 1 mm wide, 10 mm apart on one virtual skin (surface "front"), pads 2 × 2 mm below
    them; ``n_regions`` strip regions 1..n_regions; ``n_markers`` markers on the right face.
    """
    if n_channels < 1:
        raise EctskinError(f"virtual layout: need at least one channel, got {n_channels}")
    n = 2
    while n * (n - 1) // 2 < n_channels:
        n += 1
    width_mm = 10.0 * n
    names = marker_names or [f"M{j + 1}" for j in range(n_markers)]
    d = {
        "schema": "ectskin.layout",
        "version": 1,
        "name": f"generic-{n}-virtual-electrodes",
        "skins": [
            {"name": "virtual", "surface": "front", "u_mm": [0.0, width_mm], "v_mm": [0.0, 30.0]}
        ],
        "electrodes": [
            {
                "name": f"V{k + 1}",
                "skin": "virtual",
                "polyline_mm": [[10.0 * k + 5.0, 10.0], [10.0 * k + 5.0, 25.0]],
                "width_mm": 1.0,
                "pad": {"centre_mm": [10.0 * k + 5.0, 5.0], "size_mm": [2.0, 2.0]},
            }
            for k in range(n)
        ],
        "regions": [
            {
                "id": r + 1,
                "surface": "front",
                "u_mm": [0.0, width_mm],
                "v_mm": [30.0 * r / n_regions, 30.0 * (r + 1) / n_regions],
            }
            for r in range(n_regions)
        ],
        "markers": [
            {"name": str(names[j]), "surface": "right", "uv_mm": [0.0, 10.0 * j]}
            for j in range(n_markers)
        ],
    }
    return SensorLayout.from_dict(d, source="virtual layout")


# --------------------------------------------------------------------------- NPZ
def _read_npz(path: Path) -> _Fields:
    src = str(path)
    try:
        npz = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise EctskinError(f"{src}: not a readable .npz archive ({exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise EctskinError(f"{src}: holds a single array, expected an .npz archive of named fields")
    with npz:
        unknown = [k for k in npz.files if k not in NPZ_FIELDS]
        if unknown:
            raise EctskinError(
                f"{src}: unknown field(s) {unknown}; allowed fields are {', '.join(NPZ_FIELDS)}"
            )

        def get(name: str) -> np.ndarray | None:
            if name not in npz.files:
                return None
            try:
                return npz[name]
            except ValueError as exc:  # object arrays need pickle, which we never allow
                raise EctskinError(
                    f"{src}: field {name!r} cannot be read without pickle ({exc}); store strings "
                    f"as a fixed-width array, e.g. np.asarray(names, dtype=str)"
                ) from None
            except (OSError, zipfile.BadZipFile, EOFError) as exc:
                raise EctskinError(f"{src}: field {name!r} is corrupt ({exc})") from None

        raw = {k: get(k) for k in NPZ_FIELDS}

    def row(i: int) -> str:
        return f"row {i}"

    readouts = raw["readouts"]
    if readouts is None:
        raise EctskinError(f"{src}: missing field 'readouts' (frames × channels)")
    readouts = _numeric(readouts, src, "readouts")
    if readouts.ndim != 2 or readouts.shape[0] == 0 or readouts.shape[1] == 0:
        raise EctskinError(
            f"{src}: field 'readouts' must have shape (n_frames, n_channels) with both > 0, "
            f"got {readouts.shape}"
        )
    n, m = readouts.shape
    if np.isinf(readouts).any():
        i, j = (int(v) for v in np.argwhere(np.isinf(readouts))[0])
        raise EctskinError(f"{src}: field 'readouts' row {i}, channel {j} is {readouts[i, j]}")

    group = raw["group"]
    if group is None:
        raise EctskinError(f"{src}: missing field 'group' (a group id per frame: the trials)")
    group = _group_ids(group, n, src)

    labels = raw["labels"]
    markers = raw["markers"]
    if labels is not None and np.ndim(labels) == 3:
        if markers is not None:
            raise EctskinError(
                f"{src}: field 'labels' holds coordinates (3-D) and 'markers' is given too; "
                f"put classes in 'labels' (n_frames,) and coordinates in 'markers'"
            )
        markers, labels = labels, None
        marker_field = "labels"
    else:
        marker_field = "markers"
    if labels is not None:
        labels = _class_labels(_numeric(labels, src, "labels"), n, src, "labels", row)
    if markers is not None:
        markers = _numeric(markers, src, marker_field)
        if markers.ndim != 3 or markers.shape[0] != n or markers.shape[2] != 3:
            raise EctskinError(
                f"{src}: field {marker_field!r} must have shape ({n}, n_markers, 3) (mm), got "
                f"{markers.shape}"
            )
        if np.isinf(markers).any():
            i = int(np.argwhere(np.isinf(markers))[0][0])
            raise EctskinError(f"{src}: field {marker_field!r} row {i} holds inf")

    reference = raw["reference"]
    if reference is not None:
        reference = _numeric(reference, src, "reference")
        if reference.ndim not in (1, 2) or reference.shape[-1] != m:
            raise EctskinError(
                f"{src}: field 'reference' must have shape ({m},), (n_groups, {m}) or ({n}, {m}), "
                f"got {reference.shape}"
            )

    timestamps = raw["timestamps"]
    if timestamps is not None:
        timestamps = _numeric(timestamps, src, "timestamps")
        if timestamps.shape != (n,):
            raise EctskinError(
                f"{src}: field 'timestamps' must have shape ({n},) (one per frame, s), got "
                f"{timestamps.shape}"
            )

    fr = raw["frame_rate_hz"]
    frame_rate = None
    if fr is not None:
        if fr.size != 1:
            raise EctskinError(
                f"{src}: field 'frame_rate_hz' must be one number, got shape {fr.shape}"
            )
        frame_rate = float(_numeric(fr, src, "frame_rate_hz").reshape(()))

    channel_names = _names(raw["channel_names"], m, src, "channel_names") or [
        f"ch{j + 1}" for j in range(m)
    ]
    marker_names = None
    if markers is not None:
        marker_names = _names(raw["marker_names"], markers.shape[1], src, "marker_names")
    elif raw["marker_names"] is not None:
        raise EctskinError(f"{src}: field 'marker_names' is given but there are no markers")
    return _Fields(
        src,
        readouts,
        group,
        labels,
        markers,
        reference,
        timestamps,
        frame_rate,
        channel_names,
        marker_names,
        row,
    )


def _numeric(a: np.ndarray, src: str, name: str) -> np.ndarray:
    if a.dtype.kind not in "biuf":
        raise EctskinError(f"{src}: field {name!r} must be numeric, found dtype {a.dtype}")
    return a.astype(np.float64)


def _names(a: np.ndarray | None, count: int, src: str, name: str) -> list[str] | None:
    if a is None:
        return None
    if a.shape != (count,):
        raise EctskinError(f"{src}: field {name!r} must hold {count} names, got shape {a.shape}")
    names = [str(v) for v in a.tolist()]
    if len(set(names)) != len(names):
        raise EctskinError(f"{src}: field {name!r} has duplicate names")
    return names


def _group_ids(g: np.ndarray, n: int, src: str) -> np.ndarray:
    if g.shape != (n,):
        raise EctskinError(
            f"{src}: field 'group' must have shape ({n},) (one group id per frame), got {g.shape}"
        )
    if g.dtype.kind in "iu":
        return g.astype(np.int64)
    if g.dtype.kind == "f":
        bad = ~np.isfinite(g) | (g != np.round(g))
        if bad.any():
            i = int(np.argmax(bad))
            raise EctskinError(f"{src}: field 'group' row {i} is {g[i]}, expected an integer id")
        return g.astype(np.int64)
    if g.dtype.kind in "US":
        return g.astype(str)
    raise EctskinError(f"{src}: field 'group' must hold integers or strings, found dtype {g.dtype}")


def _class_labels(
    lab: np.ndarray, n: int, src: str, name: str, row: Callable[[int], str]
) -> np.ndarray:
    if lab.shape != (n,):
        raise EctskinError(
            f"{src}: field {name!r} must have shape ({n},) (a class per frame) or ({n}, "
            f"n_markers, 3) (coordinates), got {lab.shape}"
        )
    bad = ~np.isfinite(lab) | (lab != np.round(lab)) | (lab < 0) | (lab > MAX_CLASS)
    if bad.any():
        i = int(np.argmax(bad))
        raise EctskinError(
            f"{src}: {name} at {row(i)} is {lab[i]}; expected a class 0..{MAX_CLASS} (0 = no touch)"
        )
    return lab.astype(np.int64)


# --------------------------------------------------------------------------- CSV
def _read_csv(path: Path) -> _Fields:
    """Stream the CSV once: group ids as text, every other column as float64 (one flat buffer),
    so a 170 000-row file costs ~8 bytes per cell rather than a Python string per cell."""
    src = str(path)
    meta: dict[str, str] = {}
    header: list[str] | None = None
    header_line = 0
    cols: dict[str, Any] = {}
    numeric: list[int] = []  # column indices parsed as numbers (all but 'group')
    flat = array("d")
    groups: list[str] = []
    lines = array("q")

    def slow_row(values: tuple[str, ...], line: int, names: list[str]) -> array:
        """Parse one row cell by cell: NaN for allowed empty cells, else a precise error."""
        out = array("d")
        for j, cell in zip(numeric, values):
            try:
                out.append(float(cell))
                continue
            except ValueError:
                pass
            desc, empty_ok = _csv_kind(names[j])
            if cell.strip():
                raise EctskinError(
                    f"{src}: line {line}, column {names[j]!r}: expected {desc}, found {cell!r}"
                )
            if not empty_ok:
                raise EctskinError(
                    f"{src}: line {line}, column {names[j]!r}: empty cell, expected {desc}"
                )
            out.append(math.nan)
        return out

    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            reader = csv.reader(fh)
            for cells in reader:
                if not cells or all(not c.strip() for c in cells):
                    continue
                if cells[0].lstrip().startswith("#"):
                    if header is None:
                        text = ",".join(cells).lstrip()[1:]
                        for sep in (":", "="):
                            if sep in text:
                                key, value = text.split(sep, 1)
                                meta[key.strip().lower()] = value.strip()
                                break
                    continue
                if header is None:
                    header = [c.strip() for c in cells]
                    header_line = reader.line_num
                    cols = _csv_columns(header, src, header_line)
                    numeric = [j for j in range(len(header)) if j != cols["group"]]
                    continue
                line = reader.line_num
                if len(cells) != len(header):
                    raise EctskinError(
                        f"{src}: line {line} has {len(cells)} cells, the header "
                        f"(line {header_line}) has {len(header)}"
                    )
                g = cells[cols["group"]].strip()
                if not g:
                    raise EctskinError(
                        f"{src}: line {line}, column 'group': empty cell, expected a group id"
                    )
                groups.append(g)
                values = tuple(cells[j] for j in numeric)
                try:
                    flat.extend(array("d", map(float, values)))
                except ValueError:
                    flat.extend(slow_row(values, line, header))
                lines.append(line)
    except UnicodeDecodeError:
        raise EctskinError(f"{src}: not UTF-8 text (is it a CSV file?)") from None
    except csv.Error as exc:
        raise EctskinError(f"{src}: malformed CSV ({exc})") from None
    except OSError as exc:
        raise EctskinError(f"{src}: cannot read ({exc.strerror})") from None
    if header is None:
        raise EctskinError(f"{src}: empty file, expected a header row with columns {CSV_COLUMNS}")
    if not groups:
        raise EctskinError(f"{src}: no data rows after the header (line {header_line})")

    def row(i: int) -> str:
        return f"line {lines[i]}"

    n = len(groups)
    table = np.frombuffer(flat, dtype=np.float64).reshape(n, len(numeric)).copy()
    pos = {j: p for p, j in enumerate(numeric)}

    def column(j: int) -> np.ndarray:
        return table[:, pos[j]]

    readouts = np.stack([column(j) for j in cols["c"]], axis=1)
    if np.isinf(readouts).any():
        i, j = (int(v) for v in np.argwhere(np.isinf(readouts))[0])
        raise EctskinError(f"{src}: {row(i)}, column {header[cols['c'][j]]!r} is {readouts[i, j]}")
    try:
        group = np.asarray([int(v) for v in groups], dtype=np.int64)
    except (ValueError, OverflowError):
        group = np.asarray(groups, dtype=str)
    labels = None
    if "label" in cols:
        labels = _class_labels(column(cols["label"]), n, src, "column 'label'", row)
    markers = None
    marker_names = None
    if cols["m"]:
        marker_names = list(cols["m"])
        markers = np.stack(
            [np.stack([column(j) for j in cols["m"][name]], axis=1) for name in marker_names],
            axis=1,
        )
        if np.isinf(markers).any():
            i = int(np.argwhere(np.isinf(markers))[0][0])
            raise EctskinError(f"{src}: {row(i)}: a marker coordinate is inf")
    reference = None
    if cols["ref"]:
        reference = np.stack([column(j) for j in cols["ref"]], axis=1)
    timestamps = None
    if "time_s" in cols:
        timestamps = column(cols["time_s"])
    frame_rate = None
    if "frame_rate_hz" in meta:
        try:
            frame_rate = float(meta["frame_rate_hz"])
        except ValueError:
            raise EctskinError(
                f"{src}: '# frame_rate_hz' must be a number, got {meta['frame_rate_hz']!r}"
            ) from None
    channel_names = [header[j][2:] for j in cols["c"]]
    return _Fields(
        src,
        readouts,
        group,
        labels,
        markers,
        reference,
        timestamps,
        frame_rate,
        channel_names,
        marker_names,
        row,
    )


def _csv_kind(name: str) -> tuple[str, bool]:
    """What a numeric CSV column holds (for messages) and whether an empty cell means NaN."""
    if name.startswith("c:"):
        return "a number (empty = masked)", True
    if name.startswith("m:"):
        return "a coordinate in mm (empty = occluded)", True
    if name.startswith("ref:"):
        return "a reference readout", False
    if name == "label":
        return "a class number", False
    return "a time in s", False


def _csv_columns(header: list[str], src: str, line: int) -> dict[str, Any]:
    """Column indices by role: group, time_s, label, c (list), ref (list), m (name → [x, y, z])."""
    seen: dict[str, int] = {}
    for j, h in enumerate(header):
        if h in seen:
            raise EctskinError(f"{src}: line {line}: duplicate column {h!r}")
        seen[h] = j
    cols: dict[str, Any] = {"c": [], "ref": [], "m": {}}
    refs: dict[str, int] = {}
    for j, h in enumerate(header):
        if h in ("group", "time_s", "label"):
            cols[h] = j
        elif h.startswith("c:") and len(h) > 2:
            cols["c"].append(j)
        elif h.startswith("ref:") and len(h) > 4:
            refs[h[4:]] = j
        elif h.startswith("m:") and h[-2:] in (".x", ".y", ".z") and len(h) > 4:
            cols["m"].setdefault(h[2:-2], {})[h[-1]] = j
        else:
            raise EctskinError(f"{src}: line {line}: unknown column {h!r}; expected {CSV_COLUMNS}")
    if "group" not in cols:
        raise EctskinError(
            f"{src}: line {line}: missing column 'group' (a group id per frame: the trials)"
        )
    if not cols["c"]:
        raise EctskinError(
            f"{src}: line {line}: no readout columns; name them 'c:<channel>' (e.g. 'c:E1-E2')"
        )
    if refs:
        names = [header[j][2:] for j in cols["c"]]
        missing = [c for c in names if c not in refs]
        extra = [r for r in refs if r not in names]
        if missing or extra:
            raise EctskinError(
                f"{src}: line {line}: reference columns must match the readout columns one to "
                f"one ('ref:<channel>' for every 'c:<channel>'); missing {missing}, unmatched "
                f"{extra}"
            )
        cols["ref"] = [refs[c] for c in names]
    for name, axes in cols["m"].items():
        missing = [a for a in "xyz" if a not in axes]
        if missing:
            raise EctskinError(
                f"{src}: line {line}: marker {name!r} lacks column(s) "
                f"{', '.join(f'm:{name}.{a}' for a in missing)}"
            )
        cols["m"][name] = [axes["x"], axes["y"], axes["z"]]
    return cols


# --------------------------------------------------------------------------- build
def _build_recording(
    f: _Fields, layout: SensorLayout | None, frame_rate_hz: float | None, fmt: str
) -> Recording:
    src = f.source
    n, m = f.readouts.shape
    if f.labels is None and f.markers is None:
        raise EctskinError(
            f"{src}: no labels: give touch classes ('labels' / column 'label') and/or marker "
            f"coordinates ('markers' / columns 'm:<marker>.x|.y|.z')"
        )
    n_markers = 0 if f.markers is None else f.markers.shape[1]
    n_classes_max = 0 if f.labels is None else int(f.labels.max())

    # ---- layout and channel → pair mapping
    if layout is not None:
        if m != layout.n_pairs:
            raise EctskinError(
                f"{src}: {m} readout channels, but layout {layout.name!r} has "
                f"{layout.n_electrodes} electrodes = {layout.n_pairs} pairs"
            )
        if f.markers is not None and n_markers != layout.n_markers:
            raise EctskinError(
                f"{src}: {n_markers} markers, but layout {layout.name!r} has {layout.n_markers}"
            )
        if n_classes_max > layout.n_regions:
            i = int(np.argmax(f.labels > layout.n_regions))
            raise EctskinError(
                f"{src}: label at {f.row(i)} is {f.labels[i]}, layout {layout.name!r} has "
                f"classes 0..{layout.n_regions}"
            )
    else:
        layout = virtual_layout(m, n_classes_max, n_markers, f.marker_names)
        if layout.n_pairs != m:
            log.info(
                "%s: %d channels is not n(n-1)/2: virtual layout of %d electrodes (%d pairs), "
                "pairs %d..%d unmeasured",
                src,
                m,
                layout.n_electrodes,
                layout.n_pairs,
                m,
                layout.n_pairs - 1,
            )
    n_pairs = layout.n_pairs

    # ---- groups in order of first appearance
    keys, first, inverse = np.unique(f.group, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(first, kind="stable")  # key indices by first appearance
    # rows of each key, in file order (one sort instead of a scan per group)
    counts = np.bincount(inverse, minlength=keys.size)
    members = np.split(np.argsort(inverse, kind="stable"), np.cumsum(counts)[:-1])

    # ---- reference: per trial (sorted key order for an (n_groups, m) array) or per frame
    ref = f.reference
    per_frame_ref = None
    ref_by_key: dict[int, np.ndarray] = {}
    if ref is not None:
        if ref.ndim == 1:
            _check_reference(ref[None, :], f, lambda i: "field 'reference'")
            ref_by_key = {k: ref for k in range(keys.size)}
        elif ref.shape[0] == n:
            _check_reference(ref, f, lambda i: f"reference at {f.row(i)}")
            const = np.ones(keys.size, dtype=bool)
            for k in range(keys.size):
                rows = ref[members[k]]
                const[k] = bool(np.all(rows == rows[0]))
            if const.all():
                ref_by_key = {k: ref[int(first[k])] for k in range(keys.size)}
            else:
                per_frame_ref = ref
                log.info(
                    "%s: the reference changes within a trial: readouts are stored as ratios "
                    "c_t / c_0 (reference 1)",
                    src,
                )
        elif ref.shape[0] == keys.size:
            _check_reference(ref, f, lambda i: f"reference of group {keys[i].item()!r}")
            ref_by_key = {k: ref[k] for k in range(keys.size)}
        else:
            raise EctskinError(
                f"{src}: reference has {ref.shape[0]} rows; expected {keys.size} (one per group, "
                f"in sorted group order) or {n} (one per frame)"
            )

    # ---- timestamps: finite and increasing inside every group
    if f.timestamps is not None:
        if not np.all(np.isfinite(f.timestamps)):
            i = int(np.argmax(~np.isfinite(f.timestamps)))
            raise EctskinError(f"{src}: timestamp at {f.row(i)} is {f.timestamps[i]}")
        for k in order:
            idx = members[k]
            t = f.timestamps[idx]
            step = np.diff(t)
            if np.any(step <= 0):
                b = int(np.argmax(step <= 0))
                raise EctskinError(
                    f"{src}: group {keys[k].item()!r}: timestamps must increase within a group; "
                    f"{f.row(int(idx[b + 1]))} has {t[b + 1]} s after {t[b]} s at "
                    f"{f.row(int(idx[b]))}"
                )

    # ---- frame rate
    if frame_rate_hz is None:
        frame_rate_hz = f.frame_rate_hz
    if frame_rate_hz is None:
        if f.timestamps is None:
            raise EctskinError(
                f"{src}: no timestamps and no frame rate: give timestamps ('timestamps' / column "
                f"'time_s'), a frame_rate_hz field, or load_generic(..., frame_rate_hz=...)"
            )
        steps = np.concatenate([np.diff(f.timestamps[idx]) for idx in members])
        steps = steps[np.isfinite(steps) & (steps > 0)]
        if steps.size == 0:
            raise EctskinError(
                f"{src}: cannot infer the frame rate from the timestamps (no group has two "
                f"increasing timestamps); pass frame_rate_hz"
            )
        frame_rate_hz = 1.0 / float(np.median(steps))
        log.info("%s: frame rate %.4g Hz from the median timestamp step", src, frame_rate_hz)
    try:
        rate = float(frame_rate_hz)
    except (TypeError, ValueError):
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0):
        raise EctskinError(f"{src}: frame_rate_hz must be a number > 0, got {frame_rate_hz!r}")
    frame_rate_hz = rate

    # ---- trials
    trials = []
    for k in order:
        idx = members[k]
        key = keys[k].item()
        name = f"group_{key}" if isinstance(key, int) else str(key)
        meta: dict[str, Any] = {"group": key}
        cap = np.full((idx.size, n_pairs), np.nan)
        values = f.readouts[idx]
        if per_frame_ref is not None:
            values = values / per_frame_ref[idx]  # Eq. 2 then reads (c_t/c_0 − 1) / 1
            meta["reference"] = [1.0] * m + [None] * (n_pairs - m)
            meta["reference_kind"] = "per_frame_ratio"
        elif ref_by_key:
            meta["reference"] = [float(v) for v in ref_by_key[int(k)]] + [None] * (n_pairs - m)
            meta["reference_kind"] = "per_trial"
        cap[:, :m] = values
        if f.timestamps is not None:
            t = f.timestamps[idx]
            meta["t0_s"] = float(t[0])
            ts = t - t[0]
        else:
            ts = np.arange(idx.size) / frame_rate_hz
        if f.labels is not None:
            lab = f.labels[idx]
            nz = lab[lab > 0]
            region = int(np.bincount(nz).argmax()) if nz.size else 0
            meta["kind"] = "touch" if nz.size else "no_contact"
        else:
            lab = np.zeros(idx.size, dtype=np.int64)
            region = 0
            meta["kind"] = "tracking"
        markers = None if f.markers is None else f.markers[idx]
        trials.append(
            Trial(
                name=name,
                capacitance=cap,
                timestamps=ts,
                labels=lab,
                region=region,
                markers=markers,
                meta=meta,
            )
        )
    rec_meta: dict[str, Any] = {
        "source": "generic",
        "format": fmt,
        "file": src,
        "channel_names": list(f.channel_names),
    }
    if f.marker_names is not None:
        rec_meta["marker_names"] = list(f.marker_names)
    if n_pairs > m:
        rec_meta["unmeasured_pairs"] = list(range(m, n_pairs))
    if per_frame_ref is not None:
        rec_meta["readout_unit"] = "ratio to the per-frame reference"
    rec = Recording(layout=layout, trials=trials, frame_rate_hz=float(frame_rate_hz), meta=rec_meta)
    log.info(
        "%s: %d frames, %d channels, %d trials, %d markers, classes up to %d",
        src,
        n,
        m,
        rec.n_trials,
        n_markers,
        n_classes_max,
    )
    return rec


#: Same rule as ectskin.io.calibration.REFERENCE_RTOL (io does not import learn).
_REFERENCE_RTOL = 1e-6


def _check_reference(ref: np.ndarray, f: _Fields, where: Callable[[int], str]) -> None:
    """Refuse a reference (rows × m) with a non-finite, zero or tiny value (Eq. 2 divides by it),
    naming the row (``where``) and the channel."""
    scale = np.max(np.abs(np.where(np.isfinite(ref), ref, 0.0)), axis=1)
    bad = ~np.isfinite(ref) | (np.abs(ref) <= _REFERENCE_RTOL * scale[:, None])
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad)[0])
        raise EctskinError(
            f"{f.source}: {where(i)}, channel {f.channel_names[j]!r} is {ref[i, j]}; Eq. 2 "
            f"divides by the reference, expected a finite, non-zero readout"
        )
