"""The data rows of a capacitance-meter export: times in s, values in pF, masked cells reported."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.capmeter.data import ChannelMask, MaskReport
from ectskin.io.capmeter.header import Header
from ectskin.io.capmeter.units import TIME_UNITS, missing_marker, parse_clock, time_kind
from ectskin.io.text import RowErrors, Rows, parse_number

log = logging.getLogger(__name__)


@dataclass
class Table:
    """The kept data rows: times (s; clock times still since midnight), values (pF), relative
    changes (fractions, one column per channel with a relative-change column), line numbers."""

    times: np.ndarray  # (n,)
    values: np.ndarray  # (n, n_channels), NaN where masked
    relative: np.ndarray  # (n, n_relative)
    lines: np.ndarray  # (n,) int64
    kind: str  # "s", "ms", "us" or "clock"
    report: MaskReport


class _RowParser:
    """Parses the data rows one at a time, keeping the state that spans rows (time unit kind,
    last kept time, date and midnight roll-overs of a clock)."""

    def __init__(self, header: Header, n_rows: int, errors: RowErrors, decimal_comma: bool):
        self.h = header
        self.errors = errors
        self.src = errors.src
        self.decimal_comma = decimal_comma
        self.rel_index = {name: k for k, name in enumerate(header.relative)}
        self.report = MaskReport(
            self.src, {c.base: ChannelMask(c.base, c.index + 1) for c in header.values}
        )
        self.t = np.empty(n_rows)
        self.vals = np.full((n_rows, len(header.values)), np.nan)
        self.rels = np.full((n_rows, len(header.relative)), np.nan)
        self.lines = np.empty(n_rows, dtype=np.int64)
        self.kind = time_kind(header.time_unit) if header.time_unit else None
        self.last_t, self.last_text = -np.inf, ""  # the last kept frame's time, s, and its cell
        self.first_day: datetime | None = None
        self.wraps = 0  # midnight roll-overs of a clock time without a date
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
        if t_val <= self.last_t:
            self.errors.bad_row(
                line,
                f"time column {h.time_name!r}: time {tcell.strip()!r} does not increase "
                f"(previous frame, line {self.lines[self.n - 1]}: {self.last_text!r})",
            )
            return
        masked = self._values(line, cells)
        for k, marker in masked:
            self.report.channels[h.values[k].base].add(marker, line)
        if self.n == 0 and self.kind == "clock":
            h.meta["clock_start"] = tcell.strip()
        self.t[self.n] = t_val
        self.lines[self.n] = line
        self.last_t, self.last_text = t_val, tcell.strip()
        self.n += 1

    def _time(self, line: int, tcell: str) -> float | None:
        """The time of a row in s (a clock time as s since midnight of the first date)."""
        if self.kind is None:  # the first data row decides: a clock time or an error
            if ":" not in tcell:
                raise EctskinError(
                    f"{self.src}: time column {self.h.time_name!r} states no unit and holds "
                    f"numbers (line {line}: {tcell.strip()!r}); name it 'Time [s]' / 'Time [ms]' "
                    f"or give the unit (time_unit='s' or 'ms'; --time-unit on the command line)"
                )
            self.kind = "clock"
        if self.kind != "clock":
            num = parse_number(tcell, self.decimal_comma)
            if num is not None and np.isfinite(num):
                return num * TIME_UNITS[self.h.time_unit.lower()]
            return None
        parsed = parse_clock(tcell)
        if parsed is None:
            return None
        t_val, day = parsed
        if day is not None:
            self.first_day = self.first_day or day
            t_val += (day - self.first_day).days * 86400.0
        elif t_val + 86400.0 * self.wraps < self.last_t - 43200.0:
            self.wraps += 1  # past midnight
        return t_val + 86400.0 * self.wraps

    def _values(self, line: int, cells: list[str]) -> list[tuple[int, str]]:
        """Fill frame ``n``'s values (pF) and relative changes; the (channel, marker) masked."""
        n, masked = self.n, []
        for k, c in enumerate(self.h.values):
            cell = cells[c.index]
            num = parse_number(cell, self.decimal_comma)
            if num is not None and np.isfinite(num):
                self.vals[n, k] = num * c.factor
                continue
            if num is not None:
                marker = "NaN" if np.isnan(num) else "inf"
            else:
                marker = missing_marker(cell)
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


def parse_rows(rows: Rows, header: Header, errors: RowErrors, decimal_comma: bool) -> Table:
    """The frames of the data rows (``rows`` after the header); clock times count from the first.

    A malformed row goes to ``errors`` (an error when strict, else skipped and reported); an
    unparseable value cell is an error when strict, else masked as ``"invalid"``.
    """
    parser = _RowParser(header, len(rows), errors, decimal_comma)
    for line, cells in rows:
        parser.row(line, cells)
    n = parser.n
    if n == 0:
        raise EctskinError(f"{errors.src}: no data rows after the header on line {header.line}")
    t = parser.t[:n]
    if parser.kind == "clock":
        t = t - t[0]  # clock times count from the first frame
    parser.report.skipped_rows = errors.skipped
    return Table(t, parser.vals[:n], parser.rels[:n], parser.lines[:n], parser.kind, parser.report)
