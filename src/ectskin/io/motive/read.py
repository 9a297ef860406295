"""``read_motive_csv``: read text → metadata row → header rows and markers → data rows (in
bulk; one by one to report a fault) → result.

A last row cut short by an incomplete copy (the file ends without a newline inside it) is left
out and listed among the skipped rows, with a warning (:func:`ectskin.io.text.cut_last_row`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.frame_rate import frame_rate
from ectskin.io.motive.data import N_FIRST_LINES, MarkerOcclusion, MocapData
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
from ectskin.io.text import (
    MAX_ABS_VALUE,
    TAIL_ROWS,
    RowErrors,
    Rows,
    csv_rows,
    cut_last_row,
    data_cells,
    ends_with_newline,
    float_cells,
    parse_float,
    read_text,
    truncation_note,
)

log = logging.getLogger(__name__)

#: Lines at the top of a file in which the header is looked for before the whole file is.
HEAD_LINES = 200
#: Data lines read in bulk at a time (bounds the memory of the cell texts).
CHUNK_LINES = 20_000


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
    head = _head_rows(lines, src)
    rows = head if head is not None else list(csv_rows(lines, src))
    meta = metadata(rows, src)
    unit, scale = length_unit(meta, length_units, src)
    stated = stated_rate(meta, src)
    cols = parse_columns(rows, src)
    chosen = choose_markers(cols, marker_names, include_unlabeled, src)
    col_idx = position_columns(cols, chosen, src)
    errors = RowErrors(src, strict, log)
    bulk = None if head is None else _bulk_read(text, lines, cols, chosen, col_idx, scale, src)
    if bulk is not None:  # one row per line down to the data: read in bulk
        take, cut = bulk
    else:  # one row at a time: the reference, which reports every fault
        if head is not None:
            rows = list(csv_rows(lines, src))
        data = rows[cols.axis + 1 :]
        cut = None if ends_with_newline(text) else _cut_last_row(data, cols)
        if cut is not None:
            data = data[:-1]
        take = _parse_rows(data, cols, chosen, col_idx, scale, errors)
    if cut is not None:
        line, why = cut
        log.warning("%s", truncation_note(src, line, why, len(take.t) + len(errors.skipped)))
        errors.skipped.append(
            (line, f"cut short ({why}); the file ends there without a newline (truncated?)")
        )
    rate = frame_rate(
        stated,
        np.diff(take.t),
        src,
        no_rate="one frame and no frame rate in the metadata",
        what="steps of the Time column",
    )
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


def _head_rows(lines: list[str], src: str) -> Rows | None:
    """The CSV rows of the head of the file when they hold the column header row (``Frame,Time
    (Seconds),...``) and one row per line (no quoted cell over several lines); else None."""
    head = lines[:HEAD_LINES]
    try:
        rows = list(csv_rows(head, src))
    except EctskinError:
        return None
    if len(head) < len(lines):
        rows = rows[:-1]  # the last row of a cut head may be incomplete
    if any(line != k + 1 for k, (line, _) in enumerate(rows)):
        return None
    if not any(c and c[0].strip().lower() == "frame" for _, c in rows):
        return None
    return rows


def _bulk_read(
    text: str,
    lines: list[str],
    cols: Columns,
    chosen: list[str],
    col_idx: np.ndarray,
    scale: float,
    src: str,
) -> tuple[_Take, tuple[int, str] | None] | None:
    """The frames of the data lines read by :func:`_bulk_take` and the cut last line left out
    (or None), or None when the rows must be read one at a time (a fault, or a quote near the
    end)."""
    data_lines = lines[cols.axis_line :]
    cut = None
    if not ends_with_newline(text):
        first = max(cols.axis_line, len(lines) - TAIL_ROWS - 1)
        tail = lines[first:]
        if any('"' in ln for ln in tail):
            return None
        try:
            rows = [(first + line, c) for line, c in csv_rows(tail, src)]
        except EctskinError:  # the whole file's reader names the right line
            return None
        cut = _cut_last_row(rows, cols)
        if cut is not None:
            data_lines = data_lines[:-1]
    take = _bulk_take(data_lines, cols.axis_line + 1, cols, chosen, col_idx, scale)
    return None if take is None else (take, cut)


def _cut_last_row(data: Rows, columns: Columns) -> tuple[int, str] | None:
    """(line, why) when the last data row (the file ends without a newline) looks cut short."""
    why = cut_last_row(data, columns.width, lambda c: parse_float(c) is not None)
    return None if why is None else (data[-1][0], why)


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


# --------------------------------------------------------------------------- bulk read
def _bulk_take(
    lines: list[str],
    first_line: int,
    columns: Columns,
    chosen: list[str],
    col_idx: np.ndarray,
    scale: float,
) -> _Take | None:
    """:func:`_parse_rows` of the data ``lines`` (the first being line ``first_line``), read in
    bulk: the same frames, or None when a row is malformed (then :func:`_parse_rows` reports it)."""
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for start in range(0, len(lines), CHUNK_LINES):
        chunk = lines[start : start + CHUNK_LINES]
        block = data_cells(chunk, first_line + start, ",", columns.width)
        if block is None:
            return None
        cells, line_no = block
        if not len(line_no):
            continue
        try:
            frames = cells[:, 0].astype(np.int64)  # int() of each cell, as _frame_and_time
        except (ValueError, OverflowError):
            return None
        t = float_cells(cells[:, 1], parse_float)
        if not (np.isfinite(t).all() and (np.abs(t) <= MAX_ABS_VALUE).all()):
            return None
        pos = np.empty((len(line_no), len(chosen), 3))
        empty = np.zeros(pos.shape, dtype=bool)
        for m in range(len(chosen)):
            for a in range(3):
                col = cells[:, col_idx[m, a]]
                v = float_cells(col, parse_float)
                nan = np.isnan(v)
                if nan.any():
                    if any(c.strip() for c in col[nan].tolist()):
                        return None  # "nan" or no number: not an empty (occluded) cell
                    empty[nan, m, a] = True
                v = v * scale
                if not (np.abs(v[~nan]) <= MAX_ABS_VALUE).all():
                    return None
                pos[:, m, a] = v
        parts.append((t, frames, line_no, pos, empty))
    if not parts:
        return None  # _parse_rows reports that there are no data rows
    t = np.concatenate([p[0] for p in parts])
    if np.any(np.diff(t) <= 0):
        return None  # _parse_rows names the row whose time does not increase
    line_no = np.concatenate([p[2] for p in parts])
    pos = np.concatenate([p[3] for p in parts])
    n_empty = np.concatenate([p[4] for p in parts]).sum(axis=2)  # (n, n_markers)
    occl = {name: MarkerOcclusion(name) for name in chosen}
    for m, name in enumerate(chosen):
        hit = n_empty[:, m] > 0
        pos[hit, m] = np.nan  # a partly empty marker counts as occluded
        o = occl[name]
        o.n_occluded = int(hit.sum())
        o.n_partial = int((hit & (n_empty[:, m] < 3)).sum())
        o.first_lines = [int(v) for v in line_no[hit][:N_FIRST_LINES]]
    return _Take(t, np.concatenate([p[1] for p in parts]), line_no, pos, occl)
