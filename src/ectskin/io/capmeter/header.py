"""The header of a capacitance-meter export: metadata rows, the column header, the units row,
and what every column holds (time, a channel's value, its relative change, or nothing used)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from ectskin._check import EctskinError
from ectskin.io.capmeter.units import (
    CAPACITANCE_UNITS,
    RELATIVE_TOKEN,
    RELATIVE_UNITS,
    TIME_NAME,
    is_unit_token,
    parse_clock,
    split_unit,
    time_kind,
)
from ectskin.io.text import Rows, parse_number

log = logging.getLogger(__name__)


@dataclass
class Column:
    index: int  # 0-based column
    header: str  # header text as in the file
    base: str  # name without unit / relative token
    unit: str | None
    kind: str  # "time", "value", "relative", "ignore"
    factor: float = 1.0  # to pF (value) or to a fraction (relative)


@dataclass
class Header:
    """The parsed header: where the data starts and what each column holds."""

    line: int  # line number of the column header
    cells: list[str]  # the column header's cells (every data row has as many)
    data_start: int  # index (into the rows) of the first row after the header and units row
    time_col: int
    time_unit: str | None  # as stated by the file or the caller; None: not stated
    values: list[Column]  # capacitance columns, in file order
    relative: dict[str, Column]  # relative-change column by channel name
    meta: dict[str, str]  # the metadata rows above the header
    notes: list[str] = field(default_factory=list)  # what the import did that a user should know

    @property
    def width(self) -> int:
        return len(self.cells)

    @property
    def time_name(self) -> str:
        return self.cells[self.time_col]


def parse_header(
    rows: Rows,
    src: str,
    *,
    delimiter: str,
    decimal_comma: bool,
    time_unit: str | None,
    value_unit: str | None,
) -> Header:
    """Find and check the header of ``rows`` (``(line, cells)`` of the whole file)."""
    h = find_header(rows, decimal_comma)
    if h < 0:
        first = "; ".join(repr(delimiter.join(c))[:60] for _, c in rows[:4])
        raise EctskinError(
            f"{src}: no header row found: expected a row naming a time column (e.g. 'Time [s]') "
            f"and the channel columns (e.g. 'C12 [pF]'); the file starts with {first}"
        )
    header_line, header = rows[h]
    units = None
    data_start = h + 1
    if data_start < len(rows) and is_units_row(rows[data_start][1], decimal_comma):
        units = rows[data_start][1]
        data_start += 1
    time_col = next(k for k, c in enumerate(header) if TIME_NAME.match(c.strip()))
    cols = classify(header, units, time_col, value_unit, src, header_line)
    t_unit = _time_unit(cols[time_col].unit, header[time_col], time_unit, src)
    notes: list[str] = []
    meta_end = h
    if h > 0 and (groups := channel_group_row(rows[h - 1][1], cols, time_col)) is not None:
        meta_end = h - 1
        notes = _apply_groups(cols, groups, rows[h - 1][0], src)
    values, relative = _channel_columns(cols, header, header_line, src)
    return Header(
        line=header_line,
        cells=header,
        data_start=data_start,
        time_col=time_col,
        time_unit=t_unit,
        values=values,
        relative=relative,
        meta=_metadata(rows[:meta_end]),
        notes=notes,
    )


def channel_group_row(cells: list[str], cols: list[Column], time_col: int) -> list[str] | None:
    """The channel of each column when ``cells`` (the row above the column header) names each
    channel once over its columns (``,Ch1,,Ch2,`` above ``Time (s),C (pF),ΔC/C0 (%),...``), else
    None.

    Such a row names a channel above a capacitance column, leaves the cells to its right empty up
    to the next channel, names nothing above or left of the time column, and names a channel
    above every capacitance column: every value column then gets the channel it stands under.
    """
    named = [k for k, c in enumerate(cells) if c.strip()]
    value_cols = [c.index for c in cols if c.kind == "value"]
    if not named or not value_cols or len(named) != len(value_cols):
        return None
    if named[0] <= time_col or any(cols[k].kind != "value" for k in named if k < len(cols)):
        return None
    if any(k >= len(cols) for k in named):
        return None
    groups = [""] * len(cols)
    for k in range(len(cols)):
        if k < len(cells) and cells[k].strip():
            groups[k] = cells[k].strip()
        elif k > named[0]:
            groups[k] = groups[k - 1]
    # one capacitance column per channel: the named ones are exactly the value columns
    return groups if named == value_cols else None


def _apply_groups(cols: list[Column], groups: list[str], line: int, src: str) -> list[str]:
    """Name the columns after the channel row's cells; relative changes are ignored."""
    ignored = []
    for c in cols:
        if c.kind == "value":
            c.base = groups[c.index]
        elif c.kind == "relative" and groups[c.index]:
            c.base = groups[c.index]
            c.kind = "ignore"
            ignored.append(f"{c.index + 1} ({c.base} {c.header.strip()})")
    notes = [f"two-row header: channel names from line {line}, units from line {line + 1}"]
    if ignored:
        notes.append(
            f"relative-change column(s) {', '.join(ignored)} ignored: each channel's capacitance "
            "column is used"
        )
    for n in notes:
        log.info("%s: %s", src, n)
    return notes


def _metadata(rows: Rows) -> dict[str, str]:
    """``Instrument: ECT-Eval`` rows above the header: first cell → the other cells."""
    meta = {}
    for _, cells in rows:
        named = [c.strip() for c in cells if c.strip()]
        if named:
            meta[named[0].rstrip(":")] = ", ".join(named[1:])
    return meta


def _time_unit(stated: str | None, name: str, time_unit: str | None, src: str) -> str | None:
    """The time unit: the file's (name or units row) and the ``time_unit`` argument must agree."""
    t_unit = stated
    if t_unit is not None and t_unit.strip().lower() in ("", "-"):
        t_unit = None
    if t_unit is not None and time_kind(t_unit) not in ("s", "ms", "us", "clock"):
        raise EctskinError(
            f"{src}: time column {name!r} has unit {t_unit!r}; expected s, ms or hh:mm:ss.fff"
        )
    if time_unit is not None:
        if t_unit is not None and time_kind(t_unit) != time_kind(time_unit):
            raise EctskinError(
                f"{src}: time column {name!r} states unit {t_unit!r}, but "
                f"time_unit={time_unit!r} was passed"
            )
        t_unit = t_unit or time_unit
    return t_unit


def _channel_columns(
    cols: list[Column], header: list[str], header_line: int, src: str
) -> tuple[list[Column], dict[str, Column]]:
    """The value columns (one per channel) and the relative-change column of each channel."""
    values = [c for c in cols if c.kind == "value"]
    if not values:
        raise EctskinError(
            f"{src}: header line {header_line} names no capacitance column (a column with a "
            f"capacitance unit such as 'C12 [pF]'); found {header}"
        )
    by_name: dict[str, Column] = {}
    for c in values:
        if c.base in by_name:
            raise EctskinError(
                f"{src}: header line {header_line}: channel {c.base!r} appears twice (columns "
                f"{by_name[c.base].index + 1} and {c.index + 1})"
            )
        by_name[c.base] = c
    relative: dict[str, Column] = {}
    for c in cols:
        if c.kind != "relative":
            continue
        if c.base not in by_name:
            raise EctskinError(
                f"{src}: column {c.index + 1} {c.header!r} is a relative change of channel "
                f"{c.base!r}, but no capacitance column for {c.base!r} exists (channels: "
                f"{', '.join(by_name)})"
            )
        relative[c.base] = c
    return values, relative


def classify(
    header: list[str],
    units: list[str] | None,
    time_col: int,
    value_unit: str | None,
    src: str,
    header_line: int,
) -> list[Column]:
    """What every header column holds, with its unit from the name or the units row."""
    cols = []
    for k, text in enumerate(header):
        base, unit = split_unit(text)
        if units is not None and k < len(units) and units[k].strip():
            row_unit = units[k].strip()
            if unit is not None and unit.lower() != row_unit.lower():
                raise EctskinError(
                    f"{src}: column {k + 1} {text!r}: the name gives unit {unit!r} but the units "
                    f"row (line {header_line + 1}) gives {row_unit!r}"
                )
            unit = row_unit
        if k == time_col:
            cols.append(Column(k, text, base, unit, "time"))
        elif not text.strip():
            cols.append(Column(k, text, "", unit, "ignore"))
        elif TIME_NAME.match(text.strip()):
            cols.append(Column(k, text, base, unit, "ignore"))
        else:
            cols.append(_channel_column(k, text, base, unit, value_unit, src, header_line))
    return cols


def _channel_column(
    k: int,
    text: str,
    base: str,
    unit: str | None,
    value_unit: str | None,
    src: str,
    header_line: int,
) -> Column:
    """A column that is not the time: a relative change, a capacitance, or ignored."""
    ulow = unit.lower() if unit is not None else None
    rel_token = RELATIVE_TOKEN.search(base)
    if rel_token or ulow in RELATIVE_UNITS:
        chan = RELATIVE_TOKEN.sub(" ", base).strip(" _-:") if rel_token else base
        factor = RELATIVE_UNITS.get(ulow or "", float("nan"))
        return Column(k, text, chan, unit, "relative", factor)
    if ulow is None:
        if value_unit is None:
            raise EctskinError(
                f"{src}: column {k + 1} {text!r} (header line {header_line}) has no unit, so "
                f"it is unclear whether it holds capacitance; give the unit in the file "
                f"('{text} [pF]' or a units row) or give it (value_unit='pF' or 'fF'; "
                "--value-unit on the command line)"
            )
        ulow = value_unit.lower()
        unit = value_unit
    if ulow in CAPACITANCE_UNITS:
        return Column(k, text, base, unit, "value", CAPACITANCE_UNITS[ulow])
    log.info("%s: ignoring column %d %r (unit %r is not a capacitance)", src, k + 1, text, unit)
    return Column(k, text, base, unit, "ignore")


def _is_number_or_clock(cell: str, decimal_comma: bool) -> bool:
    return parse_number(cell, decimal_comma) is not None or bool(parse_clock(cell))


def is_units_row(cells: list[str], decimal_comma: bool) -> bool:
    """A row of units (``s, pF, %``): no numbers or clock times, at least one unit token."""
    cand = [c for c in cells if c.strip()]
    return (
        bool(cand)
        and not any(_is_number_or_clock(c, decimal_comma) for c in cand)
        and any(is_unit_token(c) for c in cand)
    )


def find_header(rows: Rows, decimal_comma: bool) -> int:
    """Index in ``rows`` of the header row, or -1.

    The header names a time column (``Time [s]``...) and at least one other column, holds no
    numbers, and is followed (after an optional units row) by a row with a number or clock time.
    A metadata row such as ``Time zone,UTC+1`` fails the last test. Without any data row the first
    candidate is returned (the caller then reports the missing data).
    """
    return locate_header(rows, decimal_comma)[0]


def locate_header(rows: Rows, decimal_comma: bool) -> tuple[int, bool]:
    """:func:`find_header`, and whether a data row after the header confirmed it: then the
    answer is the same for any rows that begin with ``rows`` (the head of a file is enough)."""
    first = -1
    for r, (_, cells) in enumerate(rows):
        named = [c.strip() for c in cells if c.strip()]
        if len(named) < 2 or not any(TIME_NAME.match(c) for c in named):
            continue
        if any(_is_number_or_clock(c, decimal_comma) for c in named):
            continue
        first = r if first < 0 else first
        nxt = r + 1
        if nxt < len(rows) and is_units_row(rows[nxt][1], decimal_comma):
            nxt += 1
        while nxt < len(rows) and not any(c.strip() for c in rows[nxt][1]):
            nxt += 1
        if nxt < len(rows) and any(_is_number_or_clock(c, decimal_comma) for c in rows[nxt][1]):
            return r, True
    return first, False
