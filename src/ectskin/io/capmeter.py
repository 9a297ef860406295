"""Read capacitance-meter CSV exports (one readout per row, one column per electrode pair).

Readout electronics and bench meters export tables that differ in small, annoying ways. This
reader accepts the layout described in ``docs/instrument-import.md``:

* optional metadata rows (instrument, date, ...) before the header;
* a header row that names a time column (``Time [s]``, ``Time (ms)``, ``t/s``, ``Timestamp``...)
  and one column per channel, optionally followed by a row of units (``s``, ``pF``, ``fF``, ``%``);
  units may instead sit in the names, ``C12 [pF]``;
* per-channel column pairs: the value (``C12 [pF]``) and its relative change (``C12 dC/C [%]``).
  The value is kept; the relative change is only cross-checked against it;
* a UTF-8 byte-order mark (or UTF-16 with BOM, or Windows-1252 text), comma, semicolon or tab
  delimiters (with a decimal comma allowed when the delimiter is not a comma), cells padded with
  spaces, thousands grouped with spaces;
* missing-value markers ``OL`` (overload), ``NaN``, ``-``, ``N/A`` and empty cells: masked as NaN
  and reported per channel (counts per marker and the first line numbers), never turned into 0;
* time in s, ms, or clock time ``hh:mm:ss.fff`` (optionally after a date).

Values are converted to pF (``aF``, ``fF``, ``pF``, ``nF`` accepted). A row with the wrong number of
cells, an unparseable cell or a time that does not increase is an :class:`EctskinError` naming the
file, the line and the column; with ``strict=False`` the row (or cell) is skipped (masked) and
reported instead.
"""

from __future__ import annotations

import csv
import logging
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError, check_option

log = logging.getLogger(__name__)

#: Cell texts read as "no value" (compared upper-case, after stripping), with the report key.
MISSING_MARKERS: dict[str, str] = {
    "": "empty",
    "OL": "OL",
    "+OL": "OL",
    "-OL": "OL",
    "OVL": "OL",
    "OVER": "OL",
    "OVERLOAD": "OL",
    "NAN": "NaN",
    "-NAN": "NaN",
    "-": "-",
    "--": "-",
    "---": "-",
    "N/A": "N/A",
    "NA": "N/A",
    "INF": "inf",
    "+INF": "inf",
    "-INF": "inf",
}

#: Capacitance units → factor to pF.
CAPACITANCE_UNITS: dict[str, float] = {
    "af": 1e-6,
    "ff": 1e-3,
    "pf": 1.0,
    "nf": 1e3,
    "uf": 1e6,
    "µf": 1e6,
    "μf": 1e6,
    "f": 1e12,
}
#: Time units → factor to s.
TIME_UNITS: dict[str, float] = {
    "s": 1.0,
    "sec": 1.0,
    "secs": 1.0,
    "second": 1.0,
    "seconds": 1.0,
    "ms": 1e-3,
    "msec": 1e-3,
    "millisecond": 1e-3,
    "milliseconds": 1e-3,
    "us": 1e-6,
    "µs": 1e-6,
    "μs": 1e-6,
}
#: Unit texts that announce a clock time such as 14:03:22.100.
CLOCK_UNITS = frozenset(
    {"hh:mm:ss", "hh:mm:ss.f", "hh:mm:ss.ff", "hh:mm:ss.fff", "hh:mm:ss.s", "hh:mm:ss.ss",
     "hh:mm:ss.sss", "clock", "time of day", "timeofday"}
)
#: Relative-change units → factor to a plain fraction.
RELATIVE_UNITS: dict[str, float] = {"%": 1e-2, "ppm": 1e-6, "1": 1.0, "fraction": 1.0}

_TIME_NAME = re.compile(
    r"^(?:time|timestamp|time\s*stamp|t|zeit|elapsed(?:\s*time)?|relative\s*time)"
    r"(?:$|[\s\[\(/_,:])",
    re.IGNORECASE,
)
_UNIT_IN_NAME = re.compile(r"^(?P<base>.*?)\s*[\[\(](?P<unit>[^\]\)]*)[\]\)]\s*$")
_TIME_SLASH_UNIT = re.compile(r"^(?P<base>time|t)\s*/\s*(?P<unit>\w+)$", re.IGNORECASE)
_RELATIVE_TOKEN = re.compile(
    r"(?<![a-z])(?:(?:d|δ|Δ|delta)\s*c\s*/\s*c0?|rel(?:ative)?\.?(?:\s*change)?|change)"
    r"(?![a-z])",
    re.IGNORECASE,
)
_PAIR_SEPARATED = re.compile(r"^[A-Za-z]*\s*(\d+)\s*(?:[-_/:&x]|\s)\s*[A-Za-z]*\s*(\d+)$")
_PAIR_TWO_DIGITS = re.compile(r"^[A-Za-z]+\s*(\d)(\d)$")
_CLOCK = re.compile(
    r"^(?:(?P<date>\d{4}[-/]\d{1,2}[-/]\d{1,2}|\d{1,2}\.\d{1,2}\.\d{4})[ T])?"
    r"(?P<h>\d{1,2}):(?P<m>\d{2}):(?P<s>\d{2}(?:[.,]\d+)?)$"
)
_THOUSANDS_SPACES = re.compile(r"^[+-]?\d{1,3}(?: \d{3})+(?:[.,]\d*)?(?:[eE][+-]?\d+)?$")
_N_FIRST_LINES = 5


@dataclass
class ChannelMask:
    """Masked cells of one channel: how many, which markers, and the first line numbers (1-based).

    ``relative_mismatch`` counts rows whose relative-change column disagrees with the value column
    (see :func:`read_capmeter_csv`); ``relative_checked`` is False when there was nothing to check.
    """

    channel: str
    column: int
    n_masked: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    first_lines: list[int] = field(default_factory=list)
    relative_checked: bool = False
    relative_mismatch: int = 0
    relative_first_lines: list[int] = field(default_factory=list)

    def add(self, marker: str, line: int) -> None:
        self.n_masked += 1
        self.counts[marker] = self.counts.get(marker, 0) + 1
        if len(self.first_lines) < _N_FIRST_LINES:
            self.first_lines.append(line)


@dataclass
class MaskReport:
    """What the reader masked or skipped: per-channel masks and skipped rows (line, reason)."""

    path: str
    channels: dict[str, ChannelMask]
    skipped_rows: list[tuple[int, str]] = field(default_factory=list)

    @property
    def n_masked(self) -> int:
        return sum(c.n_masked for c in self.channels.values())

    @property
    def masked_channels(self) -> list[str]:
        return [name for name, c in self.channels.items() if c.n_masked]

    def summary(self) -> str:
        """Human-readable lines, e.g. ``C13: 3 masked (OL: 2, empty: 1), first at lines 9, 14``."""
        out = []
        for name, c in self.channels.items():
            if c.n_masked:
                kinds = ", ".join(f"{k}: {v}" for k, v in c.counts.items())
                lines = ", ".join(str(n) for n in c.first_lines)
                out.append(f"{name}: {c.n_masked} masked ({kinds}), first at line(s) {lines}")
            if c.relative_mismatch:
                lines = ", ".join(str(n) for n in c.relative_first_lines)
                out.append(
                    f"{name}: relative-change column disagrees with the value on "
                    f"{c.relative_mismatch} row(s), first at line(s) {lines}"
                )
        for line, reason in self.skipped_rows:
            out.append(f"line {line} skipped: {reason}")
        return "\n".join(out) if out else "no masked cells, no skipped rows"

    def to_dict(self) -> dict:
        """Plain JSON-able summary (for ``Trial.meta``)."""
        return {
            "masked": {
                name: {
                    "n": c.n_masked, "counts": dict(c.counts), "first_lines": list(c.first_lines)
                }
                for name, c in self.channels.items()
                if c.n_masked
            },
            "relative_mismatch": {
                name: c.relative_mismatch
                for name, c in self.channels.items()
                if c.relative_mismatch
            },
            "skipped_rows": [[line, reason] for line, reason in self.skipped_rows],
        }


@dataclass
class CapmeterData:
    """One capacitance-meter export, converted to the units ectskin uses.

    ================  =============================  ==========================================
    field             shape                          meaning
    ================  =============================  ==========================================
    ``timestamps``    (n_frames,) float64            s, strictly increasing; clock times are
                                                     counted from the first row
    ``values``        (n_frames, n_channels) f64     capacitance, pF, NaN where masked
    ``channels``      n_channels names               channel names without unit (``C12``)
    ``units``         n_channels strings             the unit each channel had in the file
    ``lines``         (n_frames,) int64              line number (1-based) of each frame
    ``pairs``         (n_channels, 2) int or None    electrode numbers (1-based) when every
                                                     channel name reads as a pair, e.g. ``C12``
    ================  =============================  ==========================================
    """

    path: str
    timestamps: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...]
    lines: np.ndarray
    mask_report: MaskReport
    time_unit: str
    pairs: np.ndarray | None = None
    meta: dict[str, str] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return self.values.shape[0]

    @property
    def n_channels(self) -> int:
        return self.values.shape[1]

    @property
    def frame_rate_hz(self) -> float:
        """1 / median frame interval (NaN with fewer than 2 frames)."""
        if self.n_frames < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.timestamps)))


# --------------------------------------------------------------------------- text and cells
def read_text(path: str | Path, what: str) -> str:
    """Read a text export: UTF-8 (with or without BOM), UTF-16 with BOM, or Windows-1252."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise EctskinError(f"cannot read {what} {path}: {exc.strerror}") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            raise EctskinError(
                f"{path}: starts with a UTF-16 byte-order mark but is not UTF-16"
            ) from None
    if b"\x00" in raw[:4096]:
        raise EctskinError(f"{path}: binary data (NUL bytes), not a {what} CSV export")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        try:
            text = raw.decode("cp1252")
        except UnicodeDecodeError:
            raise EctskinError(
                f"{path}: not UTF-8 text (byte {exc.start}) and not Windows-1252 either"
            ) from None
        log.info("%s: not UTF-8; read as Windows-1252", path)
        return text


def detect_delimiter(lines: Sequence[str]) -> str:
    """Tab, semicolon or comma: the first found equally often (≥ 1) in the last data lines."""
    filled = [ln for ln in lines if ln.strip()]
    tail = filled[-min(20, max(2, len(filled) // 2)):]
    for d in ("\t", ";", ","):
        counts = {ln.count(d) for ln in tail}
        if len(counts) == 1 and counts.pop() > 0:
            return d
    return ","


def parse_number(text: str, decimal_comma: bool) -> float | None:
    """Parse a numeric cell (spaces, a decimal comma if allowed); None if it is not a number."""
    s = text.strip().replace("\u00a0", " ").replace("\u202f", " ").replace("\u2009", " ")
    if " " in s:
        if not _THOUSANDS_SPACES.match(s):
            return None
        s = s.replace(" ", "")
    if decimal_comma and "," in s:
        if "." in s or s.count(",") > 1:
            return None
        s = s.replace(",", ".")
    try:
        return float(s)
    except ValueError:
        return None


def missing_marker(text: str) -> str | None:
    """The report key of a missing-value marker (``OL``, ``NaN``, ``-``, ``empty``...) or None."""
    return MISSING_MARKERS.get(text.strip().upper())


def parse_clock(text: str) -> tuple[float, datetime | None] | None:
    """``[date ]hh:mm:ss[.fff]`` → (seconds since midnight, date or None); None if no match."""
    m = _CLOCK.match(text.strip())
    if not m:
        return None
    h, mi, s = int(m["h"]), int(m["m"]), float(m["s"].replace(",", "."))
    if h > 23 or mi > 59 or s >= 61:
        return None
    day = None
    if m["date"]:
        for fmt in ("%Y-%m-%d", "%Y/%m/%d", "%d.%m.%Y"):
            try:
                day = datetime.strptime(m["date"], fmt)
                break
            except ValueError:
                continue
        else:
            return None
    return h * 3600.0 + mi * 60.0 + s, day


def _split_unit(name: str) -> tuple[str, str | None]:
    """``"C12 [pF]"`` → ``("C12", "pF")``; ``"t/ms"`` → ``("t", "ms")``; no unit → None."""
    m = _UNIT_IN_NAME.match(name)
    if m:
        return m["base"].strip(), m["unit"].strip()
    m = _TIME_SLASH_UNIT.match(name.strip())
    if m:
        return m["base"], m["unit"]
    return name.strip(), None


def _is_unit_token(text: str) -> bool:
    t = text.strip().lower()
    return (
        t in CAPACITANCE_UNITS or t in TIME_UNITS or t in CLOCK_UNITS or t in RELATIVE_UNITS
        or t in {"°c", "v", "mv", "hz", "khz", "pf/pf"}
    )


def parse_pair_name(name: str) -> tuple[int, int] | None:
    """``C12``, ``C1-2``, ``E1-E2``, ``1_2`` → (1, 2) (1-based electrodes); else None."""
    m = _PAIR_SEPARATED.match(name.strip()) or _PAIR_TWO_DIGITS.match(name.strip())
    if not m:
        return None
    i, j = int(m[1]), int(m[2])
    if i < 1 or j < 1 or i == j:
        return None
    return (i, j) if i < j else (j, i)


def canonical_pair_order(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """If ``names`` are exactly the pairs of n electrodes: (pairs in ECT order, column order).

    The ECT order is (1,2),(1,3)…(1,n),(2,3)…(n-1,n). Returns None when any name is not a pair,
    a pair repeats, or the set is not complete.
    """
    parsed = [parse_pair_name(n) for n in names]
    if not parsed or any(p is None for p in parsed) or len(set(parsed)) != len(parsed):
        return None
    n = max(j for _, j in parsed)
    if len(parsed) != n * (n - 1) // 2:
        return None
    i, j = np.triu_indices(n, k=1)
    want = [(a + 1, b + 1) for a, b in zip(i, j)]
    index = {p: k for k, p in enumerate(parsed)}
    order = np.array([index[p] for p in want], dtype=np.int64)
    return np.asarray(want, dtype=np.int64), order


# --------------------------------------------------------------------------- columns
@dataclass
class _Column:
    index: int  # 0-based column
    header: str  # header text as in the file
    base: str  # name without unit / relative token
    unit: str | None
    kind: str  # "time", "value", "relative", "ignore"
    factor: float = 1.0  # to pF (value) or to a fraction (relative)


def _classify(
    header: list[str], units: list[str] | None, time_col: int, value_unit: str | None, src: str,
    header_line: int,
) -> list[_Column]:
    cols = []
    for k, text in enumerate(header):
        base, unit = _split_unit(text)
        if units is not None and k < len(units) and units[k].strip():
            row_unit = units[k].strip()
            if unit is not None and unit.lower() != row_unit.lower():
                raise EctskinError(
                    f"{src}: column {k + 1} {text!r}: the name gives unit {unit!r} but the units "
                    f"row (line {header_line + 1}) gives {row_unit!r}"
                )
            unit = row_unit
        if k == time_col:
            cols.append(_Column(k, text, base, unit, "time"))
            continue
        if not text.strip():
            cols.append(_Column(k, text, "", unit, "ignore"))
            continue
        if _TIME_NAME.match(text.strip()):
            cols.append(_Column(k, text, base, unit, "ignore"))
            continue
        ulow = unit.lower() if unit is not None else None
        rel_token = _RELATIVE_TOKEN.search(base)
        if rel_token or ulow in RELATIVE_UNITS:
            chan = _RELATIVE_TOKEN.sub(" ", base).strip(" _-:") if rel_token else base
            factor = RELATIVE_UNITS.get(ulow or "", float("nan"))
            cols.append(_Column(k, text, chan, unit, "relative", factor))
            continue
        if ulow is None:
            if value_unit is None:
                raise EctskinError(
                    f"{src}: column {k + 1} {text!r} (header line {header_line}) has no unit, so "
                    f"it is unclear whether it holds capacitance; give the unit in the file "
                    f"('{text} [pF]' or a units row) or pass value_unit='pF' (or 'fF')"
                )
            ulow = value_unit.lower()
            unit = value_unit
        if ulow in CAPACITANCE_UNITS:
            cols.append(_Column(k, text, base, unit, "value", CAPACITANCE_UNITS[ulow]))
        else:
            log.info(
                "%s: ignoring column %d %r (unit %r is not a capacitance)", src, k + 1, text, unit
            )
            cols.append(_Column(k, text, base, unit, "ignore"))
    return cols


def _is_units_row(cells: list[str], decimal_comma: bool) -> bool:
    """A row of units (``s, pF, %``): no numbers or clock times, at least one unit token."""
    cand = [c for c in cells if c.strip()]
    return (
        bool(cand)
        and all(parse_number(c, decimal_comma) is None and not parse_clock(c) for c in cand)
        and any(_is_unit_token(c) for c in cand)
    )


def _find_header(rows: list[tuple[int, list[str]]], decimal_comma: bool) -> int:
    """Index in ``rows`` of the header row, or -1.

    The header names a time column (``Time [s]``...) and at least one other column, holds no
    numbers, and is followed (after an optional units row) by a row with a number or clock time.
    A metadata row such as ``Time zone,UTC+1`` fails the last test. Without any data row the first
    candidate is returned (the caller then reports the missing data).
    """
    first = -1
    for r, (_, cells) in enumerate(rows):
        named = [c.strip() for c in cells if c.strip()]
        if len(named) < 2 or not any(_TIME_NAME.match(c) for c in named):
            continue
        if any(parse_number(c, decimal_comma) is not None or parse_clock(c) for c in named):
            continue
        first = r if first < 0 else first
        nxt = r + 1
        if nxt < len(rows) and _is_units_row(rows[nxt][1], decimal_comma):
            nxt += 1
        while nxt < len(rows) and not any(c.strip() for c in rows[nxt][1]):
            nxt += 1
        if nxt < len(rows) and any(
            parse_number(c, decimal_comma) is not None or parse_clock(c) for c in rows[nxt][1]
        ):
            return r
    return first


# --------------------------------------------------------------------------- reader
def read_capmeter_csv(
    path: str | Path,
    *,
    n_pairs: int | None = None,
    strict: bool = True,
    time_unit: str | None = None,
    value_unit: str | None = None,
    delimiter: str | None = None,
    pair_order: str = "auto",
    relative_tolerance: float = 2e-3,
) -> CapmeterData:
    """Read a capacitance-meter CSV export (layout in ``docs/instrument-import.md``).

    Parameters
    ----------
    path : the CSV file.
    n_pairs : if given, the number of channels the file must hold (e.g. ``layout.n_pairs``).
    strict : True: a malformed row or unparseable cell is an error. False: the row is skipped /
        the cell masked, and both are listed in ``mask_report``.
    time_unit : ``"s"``, ``"ms"`` or ``"hh:mm:ss"``, for files whose time column states no unit.
    value_unit : capacitance unit (``"pF"``, ``"fF"``) of channel columns that state none.
    delimiter : ``","``, ``";"`` or ``"\\t"``; None detects it from the data lines.
    pair_order : ``"auto"``: if every channel name reads as an electrode pair (``C12``, ``E1-E2``)
        and together they are all pairs of n electrodes, columns are put in the ECT order
        (1,2),(1,3)…(n-1,n); ``"file"``: keep the file's column order.
    relative_tolerance : largest relative disagreement between the reference implied by the
        relative-change column, ``C / (1 + dC/C)``, and its median before a row counts as a
        mismatch (reported, not an error).

    Returns
    -------
    CapmeterData with timestamps in s (shape (n_frames,)), values in pF (n_frames, n_channels),
    NaN where a cell was masked.
    """
    check_option("pair_order", pair_order, ("auto", "file"))
    if delimiter is not None:
        check_option("delimiter", delimiter, (",", ";", "\t"))
    if time_unit is not None and time_unit.lower() not in TIME_UNITS and (
        time_unit.lower() not in CLOCK_UNITS
    ):
        raise EctskinError(
            f"Invalid value for 'time_unit': allowed values are 's', 'ms', 'hh:mm:ss'; "
            f"got {time_unit!r}"
        )
    if value_unit is not None and value_unit.lower() not in CAPACITANCE_UNITS:
        raise EctskinError(
            f"Invalid value for 'value_unit': allowed values are 'aF', 'fF', 'pF', 'nF'; "
            f"got {value_unit!r}"
        )
    src = str(path)
    text = read_text(path, "capacitance-meter")
    lines = text.splitlines()
    if not any(ln.strip() for ln in lines):
        raise EctskinError(f"{src}: the file is empty")
    delim = delimiter or detect_delimiter(lines)
    decimal_comma = delim != ","

    rows: list[tuple[int, list[str]]] = []
    reader = csv.reader(lines, delimiter=delim)
    try:
        for cells in reader:
            rows.append((reader.line_num, cells))
    except csv.Error as exc:
        raise EctskinError(f"{src}: line {reader.line_num}: not valid CSV ({exc})") from None

    h = _find_header(rows, decimal_comma)
    if h < 0:
        first = "; ".join(repr(delim.join(c))[:60] for _, c in rows[:4])
        raise EctskinError(
            f"{src}: no header row found: expected a row naming a time column (e.g. 'Time [s]') "
            f"and the channel columns (e.g. 'C12 [pF]'); the file starts with {first}"
        )
    header_line, header = rows[h]
    width = len(header)  # every data row has exactly as many cells (trailing delimiters included)
    meta = {}
    for _, cells in rows[:h]:
        named = [c.strip() for c in cells if c.strip()]
        if named:
            meta[named[0].rstrip(":")] = ", ".join(named[1:])

    units = None
    data_start = h + 1
    if data_start < len(rows) and _is_units_row(rows[data_start][1], decimal_comma):
        units = rows[data_start][1]
        data_start += 1

    time_col = next(k for k, c in enumerate(header) if _TIME_NAME.match(c.strip()))
    cols = _classify(header, units, time_col, value_unit, src, header_line)

    # time unit: file (name or units row) and the time_unit argument must agree
    t_unit = cols[time_col].unit
    if t_unit is not None and t_unit.strip().lower() in ("", "-"):
        t_unit = None
    if t_unit is not None and _time_kind(t_unit) not in ("s", "ms", "us", "clock"):
        raise EctskinError(
            f"{src}: time column {header[time_col]!r} has unit {t_unit!r}; expected s, ms or "
            f"hh:mm:ss.fff"
        )
    if time_unit is not None:
        if t_unit is not None and _time_kind(t_unit) != _time_kind(time_unit):
            raise EctskinError(
                f"{src}: time column {header[time_col]!r} states unit {t_unit!r}, but "
                f"time_unit={time_unit!r} was passed"
            )
        t_unit = t_unit or time_unit

    values_cols = [c for c in cols if c.kind == "value"]
    if not values_cols:
        raise EctskinError(
            f"{src}: header line {header_line} names no capacitance column (a column with a "
            f"capacitance unit such as 'C12 [pF]'); found {header}"
        )
    by_name: dict[str, _Column] = {}
    for c in values_cols:
        if c.base in by_name:
            raise EctskinError(
                f"{src}: header line {header_line}: channel {c.base!r} appears twice (columns "
                f"{by_name[c.base].index + 1} and {c.index + 1})"
            )
        by_name[c.base] = c
    rel_of: dict[str, _Column] = {}
    for c in cols:
        if c.kind != "relative":
            continue
        if c.base not in by_name:
            raise EctskinError(
                f"{src}: column {c.index + 1} {c.header!r} is a relative change of channel "
                f"{c.base!r}, but no capacitance column for {c.base!r} exists (channels: "
                f"{', '.join(by_name)})"
            )
        rel_of[c.base] = c

    names = [c.base for c in values_cols]
    report = MaskReport(src, {c.base: ChannelMask(c.base, c.index + 1) for c in values_cols})
    n_rows = len(rows) - data_start
    t_raw = np.empty(n_rows)
    vals = np.full((n_rows, len(values_cols)), np.nan)
    rels = np.full((n_rows, len(rel_of)), np.nan)
    rel_cols = [rel_of.get(n) for n in names]
    rel_index = {n: k for k, n in enumerate(rel_of)}
    line_no = np.empty(n_rows, dtype=np.int64)
    kind = _time_kind(t_unit) if t_unit else None
    pending: list[tuple[int, str]] = []  # masks of the current row, committed if the row is kept
    last_t, last_text = -np.inf, ""  # time of the last kept frame, s, and its cell
    first_day: datetime | None = None
    wraps = 0  # midnight roll-overs of a clock time without a date
    n = 0

    def bad_row(line: int, reason: str) -> None:
        if strict:
            raise EctskinError(f"{src}: line {line}: {reason}")
        log.warning("%s: line %d skipped: %s", src, line, reason)
        report.skipped_rows.append((line, reason))

    for line, cells in rows[data_start:]:
        if not any(c.strip() for c in cells):
            continue
        if len(cells) != width:
            bad_row(
                line,
                f"expected {width} cells (as in the header on line {header_line}), found "
                f"{len(cells)}",
            )
            continue
        # --- time, s
        tcell = cells[time_col]
        if kind is None:
            if ":" not in tcell:
                raise EctskinError(
                    f"{src}: time column {header[time_col]!r} states no unit and holds numbers "
                    f"(line {line}: {tcell.strip()!r}); name it 'Time [s]' / 'Time [ms]' or pass "
                    f"time_unit='s' or 'ms'"
                )
            kind = "clock"
        t_val = None
        if kind == "clock":
            parsed = parse_clock(tcell)
            if parsed is not None:
                t_val, day = parsed
                if day is not None:
                    first_day = first_day or day
                    t_val += (day - first_day).days * 86400.0
                elif t_val + 86400.0 * wraps < last_t - 43200.0:
                    wraps += 1  # past midnight
                t_val += 86400.0 * wraps
        else:
            num = parse_number(tcell, decimal_comma)
            if num is not None and np.isfinite(num):
                t_val = num * TIME_UNITS[t_unit.lower()]
        if t_val is None:
            want = "a clock time hh:mm:ss.fff" if kind == "clock" else "a number"
            bad_row(line, f"time column {header[time_col]!r}: expected {want}, found {tcell!r}")
            continue
        if t_val <= last_t:
            bad_row(
                line,
                f"time column {header[time_col]!r}: time {tcell.strip()!r} does not increase "
                f"(previous frame, line {line_no[n - 1]}: {last_text!r})",
            )
            continue
        # --- values, pF
        pending.clear()
        for k, c in enumerate(values_cols):
            cell = cells[c.index]
            num = parse_number(cell, decimal_comma)
            if num is not None and np.isfinite(num):
                vals[n, k] = num * c.factor
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
                if strict:
                    raise EctskinError(f"{src}: line {line}: {msg}")
                log.warning("%s: line %d: %s; masked", src, line, msg)
                marker = "invalid"
            vals[n, k] = np.nan
            pending.append((k, marker))
        for name, c in rel_of.items():
            num = parse_number(cells[c.index], decimal_comma)
            if num is not None:
                rels[n, rel_index[name]] = num * c.factor
        for k, marker in pending:
            report.channels[names[k]].add(marker, line)
        if n == 0 and kind == "clock":
            meta["clock_start"] = tcell.strip()
        t_raw[n] = t_val
        line_no[n] = line
        last_t, last_text = t_val, tcell.strip()
        n += 1

    t_raw, vals, rels, line_no = t_raw[:n], vals[:n], rels[:n], line_no[:n]
    if n == 0:
        raise EctskinError(f"{src}: no data rows after the header on line {header_line}")
    if kind == "clock":
        t_raw = t_raw - t_raw[0]  # clock times count from the first frame

    # cross-check the relative change: C / (1 + r) must be one constant reference per channel
    for k, name in enumerate(names):
        rc = rel_cols[k]
        if rc is None:
            continue
        ch = report.channels[name]
        r = rels[:, rel_index[name]]
        if not np.isfinite(rc.factor):
            log.info("%s: %r has no known unit; relative change not cross-checked", src, rc.header)
            continue
        ok = np.isfinite(r) & np.isfinite(vals[:, k]) & (np.abs(1 + r) > 1e-9)
        if not ok.any():
            continue
        implied = vals[ok, k] / (1 + r[ok])
        ref = np.median(implied)
        bad = np.abs(implied - ref) > relative_tolerance * abs(ref)
        ch.relative_checked = True
        ch.relative_mismatch = int(bad.sum())
        ch.relative_first_lines = [int(x) for x in line_no[ok][bad][:_N_FIRST_LINES]]
        if bad.any():
            log.warning(
                "%s: channel %r: relative-change column %r disagrees with the value on %d row(s), "
                "first at line %d", src, name, rc.header, int(bad.sum()), ch.relative_first_lines[0]
            )

    units_out = tuple(c.unit or "" for c in values_cols)
    pairs = None
    if pair_order == "auto":
        canon = canonical_pair_order(names)
        if canon is not None:
            pairs, order = canon
            if np.any(order != np.arange(len(order))):
                log.info("%s: channels reordered into the ECT pair order (1,2),(1,3)...", src)
            vals = vals[:, order]
            names = [names[k] for k in order]
            units_out = tuple(units_out[k] for k in order)
            report.channels = {nm: report.channels[nm] for nm in names}
        else:
            log.debug("%s: channel names are not all pairs of n electrodes; file order", src)
    if n_pairs is not None and len(names) != n_pairs:
        raise EctskinError(
            f"{src}: expected {n_pairs} capacitance channels (one per electrode pair), found "
            f"{len(names)}: {', '.join(names)}"
        )
    for name in report.masked_channels:
        c = report.channels[name]
        log.warning(
            "%s: channel %r: %d cell(s) masked (%s), first at line %d",
            src, name, c.n_masked, ", ".join(f"{k} {v}" for k, v in c.counts.items()),
            c.first_lines[0],
        )
    return CapmeterData(
        path=src,
        timestamps=t_raw,
        values=vals,
        channels=tuple(names),
        units=units_out,
        lines=line_no,
        mask_report=report,
        time_unit=t_unit or "hh:mm:ss",
        pairs=pairs,
        meta=meta,
    )


def _time_kind(unit: str) -> str:
    """``"clock"``, ``"s"``, ``"ms"``, ``"us"``, or the unit itself when it is not a time unit."""
    u = unit.strip().lower()
    if u in CLOCK_UNITS:
        return "clock"
    return {1.0: "s", 1e-3: "ms", 1e-6: "us"}.get(TIME_UNITS.get(u, -1.0), u)

