"""The data rows of a capacitance-meter export: times in s, values in pF, masked cells reported.

:func:`bulk_rows` reads a well-formed block of rows in bulk (column by column); :func:`parse_rows`
reads the rows one at a time and is the reference: it runs when the bulk read finds a fault, so
that the fault is reported with its line and column (or the row skipped, with ``strict=False``).
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass
from datetime import datetime
from functools import partial

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.capmeter.data import N_FIRST_LINES, ChannelMask, MaskReport
from ectskin.io.capmeter.header import Header
from ectskin.io.capmeter.units import (
    MISSING_MARKERS,
    TIME_UNITS,
    missing_marker,
    parse_clock,
    time_kind,
)
from ectskin.io.text import (
    RowErrors,
    Rows,
    data_cells,
    float_cells,
    parse_float,
    parse_number,
)

log = logging.getLogger(__name__)


@dataclass
class Table:
    """The kept data rows: times (s; clock times still since midnight), values (pF), relative
    changes (fractions, one column per channel with a relative-change column), line numbers, and
    the text of each row's time cell."""

    times: np.ndarray  # (n,)
    values: np.ndarray  # (n, n_channels), NaN where masked
    relative: np.ndarray  # (n, n_relative)
    lines: np.ndarray  # (n,) int64
    kind: str  # "s", "ms", "us" or "clock"
    report: MaskReport
    time_cells: list[str]  # (n,) the time column's cells

    def take(self, order: np.ndarray) -> None:
        """Put the rows in ``order`` (indices into the rows)."""
        self.times, self.values = self.times[order], self.values[order]
        self.relative, self.lines = self.relative[order], self.lines[order]
        self.time_cells = [self.time_cells[i] for i in order]


class _Clock:
    """Clock times ``[date ]hh:mm:ss.fff`` → s since midnight of the first date; a time more than
    12 h before the previous frame's (without a date) is a midnight roll-over."""

    def __init__(self) -> None:
        self.first_day: datetime | None = None
        self.wraps = 0  # midnight roll-overs of a clock time without a date

    def seconds(self, tcell: str, last_t: float) -> float | None:
        parsed = parse_clock(tcell)
        if parsed is None:
            return None
        t_val, day = parsed
        if day is not None:
            self.first_day = self.first_day or day
            t_val += (day - self.first_day).days * 86400.0
        elif t_val + 86400.0 * self.wraps < last_t - 43200.0:
            self.wraps += 1  # past midnight
        return t_val + 86400.0 * self.wraps


class _RowParser:
    """Parses the data rows one at a time, keeping the state that spans rows (time unit kind,
    last kept time, date and midnight roll-overs of a clock)."""

    def __init__(
        self,
        header: Header,
        n_rows: int,
        errors: RowErrors,
        decimal_comma: bool,
        check_order: bool,
    ):
        self.h = header
        self.errors = errors
        self.src = errors.src
        self.decimal_comma = decimal_comma
        self.check_order = check_order
        self.rel_index = {name: k for k, name in enumerate(header.relative)}
        self.report = MaskReport(
            self.src, {c.base: ChannelMask(c.base, c.index + 1) for c in header.values}
        )
        self.t = np.empty(n_rows)
        self.vals = np.full((n_rows, len(header.values)), np.nan)
        self.rels = np.full((n_rows, len(header.relative)), np.nan)
        self.lines = np.empty(n_rows, dtype=np.int64)
        self.time_cells: list[str] = []
        self.kind = time_kind(header.time_unit) if header.time_unit else None
        self.last_t, self.last_text = -np.inf, ""  # the last kept frame's time, s, and its cell
        self.clock = _Clock()
        self.n = 0

    def row(self, line: int, cells: list[str]) -> None:
        """Parse one row into frame ``n`` (kept), or report it as bad (skipped or an error)."""
        if not any(c.strip() for c in cells):
            return
        h = self.h
        if len(cells) != h.width:
            self.errors.bad_row(
                line,
                f"expected {h.width} cells (as in the header on line {h.line}), found {len(cells)}",
            )
            return
        tcell = cells[h.time_col]
        t_val = self._time(line, tcell)
        if t_val is None:
            want = "a clock time hh:mm:ss.fff" if self.kind == "clock" else "a number"
            self.errors.bad_row(
                line, f"time column {h.time_name!r}: expected {want}, found {tcell!r}"
            )
            return
        if self.check_order and t_val <= self.last_t:
            self.errors.bad_row(
                line,
                f"time column {h.time_name!r}: time {tcell.strip()!r} does not increase "
                f"(previous frame, line {self.lines[self.n - 1]}: {self.last_text!r})",
            )
            return
        masked = self._values(line, cells)
        for k, marker in masked:
            self.report.channels[h.values[k].base].add(marker, line)
        self.t[self.n] = t_val
        self.lines[self.n] = line
        self.time_cells.append(tcell)
        self.last_t, self.last_text = t_val, tcell.strip()
        self.n += 1

    def _time(self, line: int, tcell: str) -> float | None:
        """The time of a row in s (a clock time as s since midnight of the first date)."""
        if self.kind is None:  # the first data row decides: a clock time or an error
            if ":" not in tcell:
                raise _no_time_unit(self.src, self.h, line, tcell)
            self.kind = "clock"
        if self.kind != "clock":
            num = parse_number(tcell, self.decimal_comma)
            if num is not None and np.isfinite(num):
                return num * TIME_UNITS[self.h.time_unit.lower()]
            return None
        return self.clock.seconds(tcell, self.last_t)

    def _values(self, line: int, cells: list[str]) -> list[tuple[int, str]]:
        """Fill frame ``n``'s values (pF) and relative changes; the (channel, marker) masked."""
        n, masked = self.n, []
        for k, c in enumerate(self.h.values):
            cell = cells[c.index]
            num = parse_number(cell, self.decimal_comma)
            if num is not None and np.isfinite(num):
                self.vals[n, k] = num * c.factor
                continue
            marker = _marker(cell, num)
            if marker is None:
                msg = (
                    f"column {c.index + 1} (channel {c.base!r}, {c.header!r}): expected a number "
                    f"or a missing-value marker (OL, NaN, -, empty), found {cell.strip()!r}"
                )
                if self.errors.strict:
                    raise self.errors.error(line, msg)
                log.warning("%s: line %d: %s; masked", self.src, line, msg)
                marker = "invalid"
            self.vals[n, k] = np.nan
            masked.append((k, marker))
        for name, c in self.h.relative.items():
            num = parse_number(cells[c.index], self.decimal_comma)
            if num is not None:
                self.rels[n, self.rel_index[name]] = num * c.factor
        return masked


def _no_time_unit(src: str, h: Header, line: int, tcell: str) -> EctskinError:
    return EctskinError(
        f"{src}: time column {h.time_name!r} states no unit and holds numbers (line {line}: "
        f"{tcell.strip()!r}); name it 'Time [s]' / 'Time [ms]' or give the unit (time_unit='s' "
        f"or 'ms'; --time-unit on the command line)"
    )


def _marker(cell: str, num: float | None) -> str | None:
    """The report key of a value cell that is not a finite number (None: not a marker either)."""
    if num is not None:
        return "NaN" if np.isnan(num) else "inf"
    return missing_marker(cell)


def parse_rows(
    rows: Rows, header: Header, errors: RowErrors, decimal_comma: bool, check_order: bool = True
) -> Table:
    """The frames of the data rows (``rows`` after the header), read one row at a time.

    A malformed row goes to ``errors`` (an error when strict, else skipped and reported); an
    unparseable value cell is an error when strict, else masked as ``"invalid"``. With
    ``check_order`` a time that does not increase makes the row malformed. Clock times are s
    since midnight of the first date (the caller counts them from its first frame).
    """
    parser = _RowParser(header, len(rows), errors, decimal_comma, check_order)
    for line, cells in rows:
        parser.row(line, cells)
    n = parser.n
    if n == 0:
        raise EctskinError(f"{errors.src}: no data rows after the header on line {header.line}")
    parser.report.skipped_rows = errors.skipped
    return Table(
        parser.t[:n],
        parser.vals[:n],
        parser.rels[:n],
        parser.lines[:n],
        parser.kind,
        parser.report,
        parser.time_cells,
    )


# --------------------------------------------------------------------------- bulk read
#: Lines read in bulk at a time (bounds the memory of the cell texts).
CHUNK_LINES = 20_000


def bulk_rows(
    lines: list[str],
    first_line: int,
    header: Header,
    src: str,
    delimiter: str,
    decimal_comma: bool,
    check_order: bool = True,
) -> Table | None:
    """:func:`parse_rows` of the data ``lines`` (the first being line ``first_line``), read in
    bulk: the same table, or None when a row is malformed, a cell is neither a number nor a
    missing-value marker, or a time does not increase (with ``check_order``). The caller then
    reads the rows with :func:`parse_rows`, which reports the row (error or skipped).
    """
    h = header
    kind = time_kind(h.time_unit) if h.time_unit else None
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]] = []
    masked: list[list[tuple[np.ndarray, list[str]]]] = [[] for _ in h.values]
    clock = _Clock()
    last_t = -np.inf
    for start in range(0, len(lines), CHUNK_LINES):
        block = data_cells(
            lines[start : start + CHUNK_LINES], first_line + start, delimiter, h.width
        )
        if block is None:
            return None
        cells, line_no = block
        if not len(line_no):
            continue
        tcells = cells[:, h.time_col]
        if kind is None:
            if ":" not in tcells[0]:
                return None  # parse_rows raises the error naming the line
            kind = "clock"
        if kind == "clock":
            t = np.empty(len(tcells))
            for i, tcell in enumerate(tcells.tolist()):
                v = clock.seconds(tcell, last_t)
                if v is None:
                    return None
                t[i] = last_t = v
        else:
            t = float_cells(tcells, partial(parse_number, decimal_comma=decimal_comma),
                            (), decimal_comma)
            if not np.isfinite(t).all():
                return None
            t = t * TIME_UNITS[h.time_unit.lower()]
        vals = np.empty((len(line_no), len(h.values)))
        for k, c in enumerate(h.values):
            col = _value_column(cells[:, c.index], c.factor, decimal_comma)
            if col is None:
                return None
            vals[:, k], bad, kinds = col
            if kinds:
                masked[k].append((line_no[bad], kinds))
        rels = np.full((len(line_no), len(h.relative)), np.nan)
        for r, c in enumerate(h.relative.values()):
            rels[:, r] = _numbers(cells[:, c.index], decimal_comma) * c.factor
        parts.append((t, vals, rels, line_no, tcells.tolist()))
    if not parts:
        return None  # parse_rows reports that there are no data rows
    t = np.concatenate([p[0] for p in parts])
    if check_order and np.any(np.diff(t) <= 0):
        return None  # parse_rows names the row whose time does not increase
    report = MaskReport(src, {c.base: ChannelMask(c.base, c.index + 1) for c in h.values})
    for k, c in enumerate(h.values):
        _fill_mask(report.channels[c.base], masked[k])
    return Table(
        t,
        np.concatenate([p[1] for p in parts]),
        np.concatenate([p[2] for p in parts]),
        np.concatenate([p[3] for p in parts]),
        kind,
        report,
        [cell for p in parts for cell in p[4]],
    )


#: Missing-value texts as written (upper, lower and title case) that ``float`` refuses.
_NO_VALUE = frozenset(
    v
    for key in MISSING_MARKERS
    if parse_float(key) is None
    for v in (key, key.lower(), key.title())
)


def _numbers(cells: np.ndarray, decimal_comma: bool) -> np.ndarray:
    """Each cell as :func:`parse_number` reads it, NaN where it reads no number."""
    return float_cells(
        cells, partial(parse_number, decimal_comma=decimal_comma), _NO_VALUE, decimal_comma
    )


def _value_column(
    cells: np.ndarray, factor: float, decimal_comma: bool
) -> tuple[np.ndarray, np.ndarray, list[str]] | None:
    """(values in pF with NaN where masked, the masked rows, their markers), or None when a cell
    is neither a number nor a missing-value marker."""
    raw = _numbers(cells, decimal_comma)
    bad = ~np.isfinite(raw)
    if not bad.any():
        return raw * factor, bad, []
    texts = cells[bad].tolist()
    kinds = {text: _marker(text, parse_number(text, decimal_comma)) for text in set(texts)}
    if None in kinds.values():
        return None
    return np.where(bad, np.nan, raw * factor), bad, [kinds[text] for text in texts]


def _fill_mask(mask: ChannelMask, parts: list[tuple[np.ndarray, list[str]]]) -> None:
    """The mask report of one channel from its masked rows, as ChannelMask.add row by row."""
    lines = [int(v) for p in parts for v in p[0][:N_FIRST_LINES]][:N_FIRST_LINES]
    kinds = [kind for p in parts for kind in p[1]]
    mask.n_masked = len(kinds)
    mask.counts = dict(Counter(kinds))
    mask.first_lines = lines
