"""Read OptiTrack Motive CSV exports: marker trajectories in mm, NaN where a marker was occluded.

A Motive export (format versions 1.2x) looks like this (see ``docs/instrument-import.md``)::

    Format Version,1.23,Take Name,touch_017,...,Export Frame Rate,120.000000,...,Length Units,Meters
    <blank>
    ,Type,Rigid Body,...,Marker,Marker,Marker
    ,Name,Body,...,Skin:M1,Skin:M1,Skin:M1
    ,ID,1,...,2,2,2
    ,,Rotation,...,Position,Position,Position
    Frame,Time (Seconds),X,Y,Z,W,...,X,Y,Z
    0,0.000000,...
    1,0.008333,...

An occluded marker leaves its three cells empty. By default the reader keeps the labelled columns
of Type ``Marker`` (Motive's "Unlabeled …" markers are left out); ``marker_names`` selects markers
by name instead (any Type, e.g. ``Rigid Body Marker``), in the order given. Positions are converted
from the file's ``Length Units`` (Meters, Centimeters, Millimeters) to mm.
"""

from __future__ import annotations

import csv
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.capmeter import read_text

log = logging.getLogger(__name__)

#: Motive's ``Length Units`` → factor to mm.
LENGTH_UNITS: dict[str, float] = {
    "millimeters": 1.0,
    "millimetres": 1.0,
    "mm": 1.0,
    "centimeters": 10.0,
    "centimetres": 10.0,
    "cm": 10.0,
    "meters": 1000.0,
    "metres": 1000.0,
    "m": 1000.0,
}
_N_FIRST_LINES = 5
_AXES = ("X", "Y", "Z")


@dataclass
class MarkerOcclusion:
    """Frames in which one marker was occluded (all cells empty) or partly empty (also NaN)."""

    name: str
    n_occluded: int = 0
    n_partial: int = 0
    first_lines: list[int] = field(default_factory=list)

    def add(self, line: int, partial: bool) -> None:
        self.n_occluded += 1
        self.n_partial += int(partial)
        if len(self.first_lines) < _N_FIRST_LINES:
            self.first_lines.append(line)


@dataclass
class MocapData:
    """Marker trajectories from one Motive take.

    ==================  ============================  ======================================
    field               shape                         meaning
    ==================  ============================  ======================================
    ``timestamps``      (n_frames,) float64           s, the file's ``Time (Seconds)``
    ``positions``       (n_frames, n_markers, 3) f64  mm, NaN where the marker was occluded
    ``frame_numbers``   (n_frames,) int64             Motive frame number
    ``lines``           (n_frames,) int64             line number (1-based) of each frame
    ==================  ============================  ======================================

    ``units`` is the ``Length Units`` of the file (positions are always mm); ``meta`` holds the
    metadata row (take name, frame rates, ...).
    """

    path: str
    timestamps: np.ndarray
    positions: np.ndarray
    marker_names: tuple[str, ...]
    frame_rate_hz: float
    units: str
    frame_numbers: np.ndarray
    lines: np.ndarray
    meta: dict[str, str] = field(default_factory=dict)
    occlusions: dict[str, MarkerOcclusion] = field(default_factory=dict)
    skipped_rows: list[tuple[int, str]] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_markers(self) -> int:
        return self.positions.shape[1]

    def summary(self) -> str:
        """Human-readable occlusion report, one line per occluded marker."""
        out = []
        for name, o in self.occlusions.items():
            if o.n_occluded:
                part = f" ({o.n_partial} partly empty)" if o.n_partial else ""
                lines = ", ".join(str(n) for n in o.first_lines)
                out.append(
                    f"{name}: occluded in {o.n_occluded} of {self.n_frames} frames{part}, first "
                    f"at line(s) {lines}"
                )
        for line, reason in self.skipped_rows:
            out.append(f"line {line} skipped: {reason}")
        return "\n".join(out) if out else "no occlusions, no skipped rows"


def _header_rows(rows: list[tuple[int, list[str]]], src: str):
    """Find the axis row (``Frame,Time (Seconds),X,Y,Z,...``) and the labelled rows above it."""
    axis = next(
        (r for r, (_, c) in enumerate(rows) if c and c[0].strip().lower() == "frame"), -1
    )
    if axis < 0:
        raise EctskinError(
            f"{src}: no column header row starting with 'Frame,Time (Seconds),X,Y,Z' was found "
            f"(was the CSV exported with 'Header information' switched off?)"
        )
    line, cells = rows[axis]
    if len(cells) < 2 or not cells[1].strip().lower().startswith("time"):
        raise EctskinError(
            f"{src}: line {line}: expected the second column to be 'Time (Seconds)', found "
            f"{cells[1] if len(cells) > 1 else ''!r}"
        )
    labelled: dict[str, tuple[int, list[str]]] = {}
    for ln, c in rows[1:axis]:
        if not any(x.strip() for x in c):
            continue
        label = c[1].strip().lower() if len(c) > 1 and not c[0].strip() else c[0].strip().lower()
        if label == "" and any(x.strip().lower() in ("position", "rotation") for x in c):
            label = "component"
        labelled.setdefault(label, (ln, c))
    return axis, labelled


def read_motive_csv(
    path: str | Path,
    marker_names: Sequence[str] | None = None,
    *,
    strict: bool = True,
    length_units: str | None = None,
    include_unlabeled: bool = False,
) -> MocapData:
    """Read marker positions from an OptiTrack Motive CSV export.

    Parameters
    ----------
    path : the ``.csv`` exported by Motive (with header information).
    marker_names : markers to keep, in this order, matched against the ``Name`` row exactly or by
        the part after the asset prefix (``M1`` matches ``Skin:M1``). None: every labelled marker
        of Type ``Marker``, in file order.
    strict : True: a malformed row or cell is an error naming file, line and column. False: the
        row is skipped and listed in ``skipped_rows``.
    length_units : for files whose metadata lacks ``Length Units`` (Meters, Centimeters,
        Millimeters); must agree with the file when both are given.
    include_unlabeled : also keep Motive's ``Unlabeled …`` markers when selecting by Type.

    Returns
    -------
    MocapData with timestamps in s (n_frames,) and positions in mm (n_frames, n_markers, 3).
    """
    src = str(path)
    if isinstance(marker_names, str):
        raise EctskinError(
            f"marker_names must be a list of names, e.g. ['M1', 'M2'], got the string "
            f"{marker_names!r}"
        )
    text = read_text(path, "Motive")
    lines = text.splitlines()
    rows: list[tuple[int, list[str]]] = []
    reader = csv.reader(lines)
    try:
        for cells in reader:
            rows.append((reader.line_num, cells))
    except csv.Error as exc:
        raise EctskinError(f"{src}: line {reader.line_num}: not valid CSV ({exc})") from None
    if not rows or not rows[0][1] or rows[0][1][0].strip() != "Format Version":
        found = ",".join(rows[0][1])[:60] if rows else ""
        raise EctskinError(
            f"{src}: not a Motive CSV export: line 1 should start with 'Format Version', "
            f"found {found!r}"
        )
    first = rows[0][1]
    meta = {
        first[i].strip(): first[i + 1].strip() if i + 1 < len(first) else ""
        for i in range(0, len(first), 2)
        if first[i].strip()
    }

    # --- units and frame rate from the metadata row
    unit = meta.get("Length Units")
    if unit is None and length_units is None:
        raise EctskinError(
            f"{src}: line 1 has no 'Length Units' field; pass length_units='Meters', "
            f"'Centimeters' or 'Millimeters'"
        )
    if unit is not None and length_units is not None and (
        LENGTH_UNITS.get(unit.lower()) != LENGTH_UNITS.get(length_units.lower())
    ):
        raise EctskinError(
            f"{src}: the file states Length Units {unit!r}, but length_units={length_units!r} "
            f"was passed"
        )
    unit = unit or length_units
    if unit.lower() not in LENGTH_UNITS:
        raise EctskinError(
            f"{src}: line 1: Length Units {unit!r} is not supported; expected Meters, "
            f"Centimeters or Millimeters"
        )
    scale = LENGTH_UNITS[unit.lower()]
    stated_rate = None
    for key in ("Export Frame Rate", "Capture Frame Rate"):
        if key in meta:
            try:
                stated_rate = float(meta[key])
            except ValueError:
                raise EctskinError(
                    f"{src}: line 1: {key} must be a number, found {meta[key]!r}"
                ) from None
            if not (np.isfinite(stated_rate) and stated_rate > 0):
                raise EctskinError(f"{src}: line 1: {key} must be > 0, found {meta[key]!r}")
            break

    # --- header rows
    axis, labelled = _header_rows(rows, src)
    axis_line, axis_cells = rows[axis]
    width = len(axis_cells)  # every data row has exactly as many cells
    if "name" not in labelled:
        raise EctskinError(
            f"{src}: no ',Name,...' row above the column header on line {axis_line}; the export "
            f"needs its header information"
        )

    def row_of(label: str) -> list[str]:
        if label not in labelled:
            return [""] * width
        c = labelled[label][1]
        return [c[k].strip() if k < len(c) else "" for k in range(width)]

    types, names, comps = row_of("type"), row_of("name"), row_of("component")
    axes = [c.strip().upper() for c in axis_cells]
    has_component = "component" in labelled

    # columns per name that hold positions
    position: dict[str, dict[str, list[int]]] = {}
    for k in range(2, width):
        if not names[k] or axes[k] not in _AXES:
            continue
        if has_component and comps[k].lower() != "position":
            continue
        position.setdefault(names[k], {}).setdefault(axes[k], []).append(k)

    if marker_names is None:
        if "type" not in labelled:
            raise EctskinError(
                f"{src}: no ',Type,...' row, so markers cannot be told from rigid bodies; "
                f"pass marker_names"
            )
        chosen = []
        for name in position:
            k0 = position[name][next(iter(position[name]))][0]
            if types[k0].lower() != "marker":
                continue
            if name.lower().startswith("unlabeled") and not include_unlabeled:
                continue
            chosen.append(name)
        skipped = [n for n in position if n.lower().startswith("unlabeled")]
        if skipped and not include_unlabeled:
            log.info("%s: left out %d unlabeled marker(s)", src, len(skipped))
        if not chosen:
            raise EctskinError(
                f"{src}: no labelled columns of Type 'Marker' (found types: "
                f"{', '.join(sorted({t for t in types[2:] if t})) or 'none'}); pass marker_names "
                f"to select by name"
            )
    else:
        chosen = []
        for want in marker_names:
            if want in position:
                chosen.append(want)
                continue
            hits = [n for n in position if n.split(":")[-1] == want]
            if len(hits) != 1:
                why = "is ambiguous" if hits else "is not in the file"
                raise EctskinError(
                    f"{src}: marker {want!r} {why}; markers with positions: "
                    f"{', '.join(position) or 'none'}"
                )
            chosen.append(hits[0])
        if len(set(chosen)) != len(chosen):
            raise EctskinError(f"{src}: marker_names select a marker twice: {list(marker_names)}")

    col_idx = np.empty((len(chosen), 3), dtype=np.int64)
    for m, name in enumerate(chosen):
        for a, ax in enumerate(_AXES):
            cols = position[name].get(ax, [])
            if len(cols) != 1:
                found = ", ".join(str(c + 1) for c in cols) or "none"
                raise EctskinError(
                    f"{src}: marker {name!r} needs exactly one {ax} position column on line "
                    f"{axis_line}, found column(s) {found}"
                )
            col_idx[m, a] = cols[0]

    # --- data rows
    n_rows = len(rows) - axis - 1
    t = np.empty(n_rows)
    frames = np.empty(n_rows, dtype=np.int64)
    line_no = np.empty(n_rows, dtype=np.int64)
    pos = np.full((n_rows, len(chosen), 3), np.nan)
    occl = {name: MarkerOcclusion(name) for name in chosen}
    skipped_rows: list[tuple[int, str]] = []
    pending: list[tuple[str, bool]] = []
    last_t = -np.inf
    n = 0

    def bad_row(line: int, reason: str) -> None:
        if strict:
            raise EctskinError(f"{src}: line {line}: {reason}")
        log.warning("%s: line %d skipped: %s", src, line, reason)
        skipped_rows.append((line, reason))

    for line, cells in rows[axis + 1:]:
        if not any(c.strip() for c in cells):
            continue
        if len(cells) != width:
            bad_row(
                line,
                f"expected {width} cells (as in the column header on line {axis_line}), found "
                f"{len(cells)}",
            )
            continue
        try:
            frame = int(cells[0])
        except ValueError:
            bad_row(line, f"column 1 (Frame): expected an integer, found {cells[0]!r}")
            continue
        try:
            tt = float(cells[1])
        except ValueError:
            tt = float("nan")
        if not np.isfinite(tt):
            bad_row(line, f"column 2 (Time (Seconds)): expected a number, found {cells[1]!r}")
            continue
        if tt <= last_t:
            bad_row(
                line,
                f"column 2 (Time (Seconds)): time {tt:.6f} s does not increase (previous frame: "
                f"{last_t:.6f} s)",
            )
            continue
        pending.clear()
        row_bad = None
        for m, name in enumerate(chosen):
            empty = 0
            for a in range(3):
                cell = cells[col_idx[m, a]].strip()
                if not cell:
                    empty += 1
                    continue
                try:
                    v = float(cell)
                except ValueError:
                    v = float("nan")
                if not np.isfinite(v):
                    row_bad = (
                        f"column {col_idx[m, a] + 1} (marker {name!r}, {_AXES[a]}): expected a "
                        f"number or an empty cell (occluded), found {cell!r}"
                    )
                    break
                pos[n, m, a] = v * scale
            if row_bad:
                break
            if empty:
                pos[n, m] = np.nan  # a partly empty marker counts as occluded
                pending.append((name, empty < 3))
        if row_bad:
            pos[n] = np.nan
            bad_row(line, row_bad)
            continue
        for name, partial in pending:
            occl[name].add(line, partial)
        t[n], frames[n], line_no[n] = tt, frame, line
        last_t = tt
        n += 1

    if n == 0:
        raise EctskinError(f"{src}: no data rows after the column header on line {axis_line}")
    t, frames, line_no, pos = t[:n], frames[:n], line_no[:n], pos[:n]

    measured = float(1.0 / np.median(np.diff(t))) if n > 1 else float("nan")
    rate = stated_rate if stated_rate is not None else measured
    if not np.isfinite(rate):
        raise EctskinError(f"{src}: one frame and no frame rate in the metadata")
    if stated_rate is not None and np.isfinite(measured) and abs(measured / stated_rate - 1) > 0.01:
        log.warning(
            "%s: the Time column gives %.3f frames/s, the metadata says %.3f", src, measured,
            stated_rate,
        )
    for name, o in occl.items():
        if o.n_occluded:
            log.info(
                "%s: marker %r occluded in %d of %d frames, first at line %d", src, name,
                o.n_occluded, n, o.first_lines[0],
            )
    return MocapData(
        path=src,
        timestamps=t,
        positions=pos,
        marker_names=tuple(chosen),
        frame_rate_hz=float(rate),
        units=unit,
        frame_numbers=frames,
        lines=line_no,
        meta=meta,
        occlusions=occl,
        skipped_rows=skipped_rows,
    )
