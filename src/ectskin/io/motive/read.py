"""``read_motive_csv``: read text → metadata row → header rows and markers → data rows → result."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.motive.data import MarkerOcclusion, MocapData
from ectskin.io.motive.header import (
    AXES,
    Columns,
    choose_markers,
    length_unit,
    metadata,
    parse_columns,
    position_columns,
    stated_rate,
)
from ectskin.io.text import MAX_ABS_VALUE, RowErrors, Rows, csv_rows, parse_float, read_text

log = logging.getLogger(__name__)


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
    rows = list(csv_rows(read_text(path, "Motive").splitlines(), src))
    meta = metadata(rows, src)
    unit, scale = length_unit(meta, length_units, src)
    stated = stated_rate(meta, src)
    cols = parse_columns(rows, src)
    chosen = choose_markers(cols, marker_names, include_unlabeled, src)
    col_idx = position_columns(cols, chosen, src)
    errors = RowErrors(src, strict, log)
    take = _parse_rows(rows[cols.axis + 1 :], cols, chosen, col_idx, scale, errors)
    rate = _frame_rate(take.t, stated, src)
    for name, o in take.occlusions.items():
        if o.n_occluded:
            log.info(
                "%s: marker %r occluded in %d of %d frames, first at line %d",
                src,
                name,
                o.n_occluded,
                len(take.t),
                o.first_lines[0],
            )
    return MocapData(
        path=src,
        timestamps=take.t,
        positions=take.positions,
        marker_names=tuple(chosen),
        frame_rate_hz=rate,
        units=unit,
        frame_numbers=take.frames,
        lines=take.lines,
        meta=meta,
        occlusions=take.occlusions,
        skipped_rows=errors.skipped,
    )


# --------------------------------------------------------------------------- data rows
@dataclass
class _Take:
    t: np.ndarray  # (n,) s
    frames: np.ndarray  # (n,) int64
    lines: np.ndarray  # (n,) int64
    positions: np.ndarray  # (n, n_markers, 3) mm
    occlusions: dict[str, MarkerOcclusion]


def _parse_rows(
    rows: Rows,
    columns: Columns,
    chosen: list[str],
    col_idx: np.ndarray,
    scale: float,
    errors: RowErrors,
) -> _Take:
    """The frames of the data rows; a malformed row goes to ``errors`` (raised or skipped)."""
    n_rows = len(rows)
    t = np.empty(n_rows)
    frames = np.empty(n_rows, dtype=np.int64)
    line_no = np.empty(n_rows, dtype=np.int64)
    pos = np.full((n_rows, len(chosen), 3), np.nan)
    occl = {name: MarkerOcclusion(name) for name in chosen}
    last_t = -np.inf
    n = 0
    for line, cells in rows:
        if not any(c.strip() for c in cells):
            continue
        head = _frame_and_time(cells, columns, last_t)
        if isinstance(head, str):
            errors.bad_row(line, head)
            continue
        occluded, row_bad = _marker_cells(cells, chosen, col_idx, scale, pos[n])
        if row_bad:
            pos[n] = np.nan
            errors.bad_row(line, row_bad)
            continue
        for name, partial in occluded:
            occl[name].add(line, partial)
        frames[n], t[n] = head
        line_no[n] = line
        last_t = t[n]
        n += 1
    if n == 0:
        raise EctskinError(
            f"{errors.src}: no data rows after the column header on line {columns.axis_line}"
        )
    return _Take(t[:n], frames[:n], line_no[:n], pos[:n], occl)


def _frame_and_time(cells: list[str], columns: Columns, last_t: float) -> tuple[int, float] | str:
    """(frame number, time in s) of a data row, or why the row is malformed."""
    if len(cells) != columns.width:
        return (
            f"expected {columns.width} cells (as in the column header on line "
            f"{columns.axis_line}), found {len(cells)}"
        )
    try:
        frame = int(cells[0])
    except ValueError:
        return f"column 1 (Frame): expected an integer, found {cells[0]!r}"
    tt = parse_float(cells[1])
    if tt is None or not np.isfinite(tt):
        return f"column 2 (Time (Seconds)): expected a number, found {cells[1]!r}"
    if abs(tt) > MAX_ABS_VALUE:
        return f"column 2 (Time (Seconds)): {cells[1].strip()!r} is beyond ±{MAX_ABS_VALUE:g} s"
    if tt <= last_t:
        return (
            f"column 2 (Time (Seconds)): time {tt:.6f} s does not increase (previous frame: "
            f"{last_t:.6f} s)"
        )
    return frame, tt


def _marker_cells(
    cells: list[str], chosen: list[str], col_idx: np.ndarray, scale: float, out: np.ndarray
) -> tuple[list[tuple[str, bool]], str | None]:
    """Fill ``out`` (n_markers, 3) with the row's positions in mm (NaN for an occluded marker).

    Returns the occluded markers as (name, partly empty) and why the row is malformed (or None).
    """
    occluded = []
    for m, name in enumerate(chosen):
        empty = 0
        for a in range(3):
            cell = cells[col_idx[m, a]].strip()
            if not cell:
                empty += 1
                continue
            v = parse_float(cell)
            if v is None or not np.isfinite(v):
                return occluded, (
                    f"column {col_idx[m, a] + 1} (marker {name!r}, {AXES[a]}): expected a "
                    f"number or an empty cell (occluded), found {cell!r}"
                )
            if abs(v * scale) > MAX_ABS_VALUE:
                return occluded, (
                    f"column {col_idx[m, a] + 1} (marker {name!r}, {AXES[a]}): {cell!r} is "
                    f"beyond ±{MAX_ABS_VALUE:g} mm (a placeholder? leave the cell empty)"
                )
            out[m, a] = v * scale
        if empty:
            out[m] = np.nan  # a partly empty marker counts as occluded
            occluded.append((name, empty < 3))
    return occluded, None


def _frame_rate(t: np.ndarray, stated: float | None, src: str) -> float:
    """The stated frame rate, else 1 / the median step of the times; a mismatch is logged."""
    measured = float(1.0 / np.median(np.diff(t))) if len(t) > 1 else float("nan")
    rate = stated if stated is not None else measured
    if not np.isfinite(rate):
        raise EctskinError(f"{src}: one frame and no frame rate in the metadata")
    if stated is not None and np.isfinite(measured) and abs(measured / stated - 1) > 0.01:
        log.warning(
            "%s: the Time column gives %.3f frames/s, the metadata says %.3f",
            src,
            measured,
            stated,
        )
    return float(rate)
