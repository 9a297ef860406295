"""The header of a Motive export: the metadata row (units, frame rate) and the labelled rows
above the column header (Type, Name, ID, component), from which the marker columns are chosen."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError
from ectskin.io import frame_rate
from ectskin.io.text import Rows

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
AXES = ("X", "Y", "Z")


# --------------------------------------------------------------------------- metadata row
def metadata(rows: Rows, src: str) -> dict[str, str]:
    """Line 1, ``Format Version,1.23,Take Name,touch_017,...``, as key → value."""
    if not rows or not rows[0][1] or rows[0][1][0].strip() != "Format Version":
        found = ",".join(rows[0][1])[:60] if rows else ""
        raise EctskinError(
            f"{src}: not a Motive CSV export: line 1 should start with 'Format Version', "
            f"found {found!r}"
        )
    first = rows[0][1]
    return {
        first[i].strip(): first[i + 1].strip() if i + 1 < len(first) else ""
        for i in range(0, len(first), 2)
        if first[i].strip()
    }


def length_unit(meta: dict[str, str], length_units: str | None, src: str) -> tuple[str, float]:
    """The file's ``Length Units`` (or ``length_units``; both must agree) and its factor to mm."""
    unit = meta.get("Length Units") or None  # an empty value states nothing
    if unit is None and length_units is None:
        raise EctskinError(
            f"{src}: line 1 has no 'Length Units' field; give the unit (length_units='Meters', "
            f"'Centimeters' or 'Millimeters'; --length-units on the command line)"
        )
    if (
        unit is not None
        and length_units is not None
        and (LENGTH_UNITS.get(unit.lower()) != LENGTH_UNITS.get(length_units.lower()))
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
    return unit, LENGTH_UNITS[unit.lower()]


def stated_rate(meta: dict[str, str], src: str) -> float | None:
    """``Export Frame Rate`` (else ``Capture Frame Rate``) of the metadata, frames/s, or None."""
    for key in ("Export Frame Rate", "Capture Frame Rate"):
        if key in meta:
            return frame_rate.stated_rate(meta[key], f"{src}: line 1: {key}")
    return None


# --------------------------------------------------------------------------- header rows
@dataclass
class Columns:
    """The header rows: the axis row (``Frame,Time (Seconds),X,Y,Z,...``) and the labelled rows
    above it (``type``, ``name``, ``id``, ``component``: (line, cells))."""

    axis: int  # index of the axis row in the rows
    axis_line: int
    width: int  # cells of the axis row; every data row has as many
    labelled: dict[str, tuple[int, list[str]]]
    types: list[str]  # the Type row, one cell per column ("" without a Type row)
    position: dict[str, dict[str, list[int]]]  # asset name → axis "X"/"Y"/"Z" → columns


def _header_rows(rows: Rows, src: str):
    """Find the axis row (``Frame,Time (Seconds),X,Y,Z,...``) and the labelled rows above it."""
    axis = next((r for r, (_, c) in enumerate(rows) if c and c[0].strip().lower() == "frame"), -1)
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


def parse_columns(rows: Rows, src: str) -> Columns:
    """The header rows, and the position columns (0-based) of every named asset."""
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

    names, comps = row_of("name"), row_of("component")
    axes = [c.strip().upper() for c in axis_cells]
    position: dict[str, dict[str, list[int]]] = {}
    for k in range(2, width):
        if not names[k] or axes[k] not in AXES:
            continue
        if "component" in labelled and comps[k].lower() != "position":
            continue
        position.setdefault(names[k], {}).setdefault(axes[k], []).append(k)
    return Columns(axis, axis_line, width, labelled, row_of("type"), position)


def choose_markers(
    columns: Columns, marker_names: Sequence[str] | None, include_unlabeled: bool, src: str
) -> list[str]:
    """The markers to keep: ``marker_names`` (matched by name), else those of Type ``Marker``."""
    position = columns.position
    if marker_names is not None:
        return _markers_by_name(position, marker_names, src)
    if "type" not in columns.labelled:
        raise EctskinError(
            f"{src}: no ',Type,...' row, so markers cannot be told from rigid bodies; "
            f"select them by name (marker_names=...; --markers on the command line)"
        )
    types = columns.types
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
            f"{', '.join(sorted({t for t in types[2:] if t})) or 'none'}); select markers "
            f"by name (marker_names=...; --markers on the command line)"
        )
    return chosen


def _markers_by_name(
    position: dict[str, dict[str, list[int]]], marker_names: Sequence[str], src: str
) -> list[str]:
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
    return chosen


def position_columns(columns: Columns, chosen: list[str], src: str) -> np.ndarray:
    """(n_markers, 3) column index of every chosen marker's X, Y, Z position."""
    col_idx = np.empty((len(chosen), 3), dtype=np.int64)
    for m, name in enumerate(chosen):
        for a, ax in enumerate(AXES):
            cols = columns.position[name].get(ax, [])
            if len(cols) != 1:
                found = ", ".join(str(c + 1) for c in cols) or "none"
                raise EctskinError(
                    f"{src}: marker {name!r} needs exactly one {ax} position column on line "
                    f"{columns.axis_line}, found column(s) {found}"
                )
            col_idx[m, a] = cols[0]
    return col_idx
