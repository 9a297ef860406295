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
cells or an unparseable cell is an :class:`EctskinError` naming the file, the line and the
column; with ``strict=False`` the row (or cell) is skipped (masked) and reported instead. Time
stamps that repeat or step back are kept in the file's order with re-derived times, sorted, or
refused (``time_order``); the frames can be resampled onto a uniform grid (``resample_hz``).

Modules, in the reader's order: :mod:`ectskin.io.text` (text, delimiter, numbers, bulk reads),
:mod:`~ectskin.io.capmeter.header` (metadata, header, units row, columns),
:mod:`~ectskin.io.capmeter.rows` (data rows, in bulk or one at a time),
:mod:`~ectskin.io.capmeter.timing` (time order, resampling), :mod:`~ectskin.io.capmeter.read`
(cross-check of the relative change, pair order, the result); :mod:`~ectskin.io.capmeter.units`
holds the unit tables and the cell and channel-name parsers, :mod:`~ectskin.io.capmeter.data` the
result types.
"""

from __future__ import annotations

from ectskin.io.capmeter.data import CapmeterData, ChannelMask, MaskReport
from ectskin.io.capmeter.read import read_capmeter_csv
from ectskin.io.capmeter.units import (
    CAPACITANCE_UNITS,
    CLOCK_UNITS,
    MISSING_MARKERS,
    RELATIVE_UNITS,
    TIME_UNITS,
    canonical_pair_order,
    missing_marker,
    parse_clock,
    parse_pair_name,
)

__all__ = [
    "CAPACITANCE_UNITS",
    "CLOCK_UNITS",
    "MISSING_MARKERS",
    "RELATIVE_UNITS",
    "TIME_UNITS",
    "CapmeterData",
    "ChannelMask",
    "MaskReport",
    "canonical_pair_order",
    "missing_marker",
    "parse_clock",
    "parse_pair_name",
    "read_capmeter_csv",
]
