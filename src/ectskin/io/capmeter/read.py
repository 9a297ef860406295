"""``read_capmeter_csv``: read text → parse the header → read the rows (in bulk; one by one to
report a fault) → time order → cross-check → (resample) → result.

A last row cut short by an incomplete copy (the file ends without a newline inside it) is left
out and listed among the skipped rows, with a warning (:func:`ectskin.io.text.cut_last_row`); a
value beyond :data:`~ectskin.io.text.MAX_ABS_VALUE` pF is refused. Time stamps that repeat or
step back are handled by the ``time_order`` policy (:mod:`~ectskin.io.capmeter.timing`).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.io.capmeter.data import N_FIRST_LINES, CapmeterData, MaskReport
from ectskin.io.capmeter.header import Header, locate_header, parse_header
from ectskin.io.capmeter.rows import Table, bulk_rows, parse_rows
from ectskin.io.capmeter.timing import TIME_ORDERS, order_frames, resample
from ectskin.io.capmeter.units import (
    CAPACITANCE_UNITS,
    CLOCK_UNITS,
    TIME_UNITS,
    canonical_pair_order,
    missing_marker,
    parse_clock,
)
from ectskin.io.frame_rate import stated_rate
from ectskin.io.text import (
    MAX_ABS_VALUE,
    TAIL_ROWS,
    RowErrors,
    Rows,
    csv_rows,
    cut_last_row,
    detect_delimiter,
    ends_with_newline,
    parse_number,
    read_text,
    truncation_note,
)

log = logging.getLogger(__name__)

#: Lines at the top of a file in which the header is looked for before the whole file is.
HEAD_LINES = 200


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
    time_order: str = "file",
    resample_hz: float | None = None,
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
    time_order : time stamps that repeat or step back: ``"file"`` keeps the rows in the file's
        order and re-derives their times, ``"sort"`` sorts the rows by time stamp, ``"strict"``
        makes such a row malformed (see :mod:`~ectskin.io.capmeter.timing`). A repair is logged,
        noted in ``mask_report.notes`` and recorded in ``timing``.
    resample_hz : if given, the frames are resampled onto a uniform grid at this rate (each
        channel linearly interpolated; :func:`~ectskin.io.capmeter.timing.resample`).

    Returns
    -------
    CapmeterData with timestamps in s (shape (n_frames,)), values in pF (n_frames, n_channels),
    NaN where a cell was masked.
    """
    _check_arguments(time_unit, value_unit, delimiter, pair_order, time_order)
    src = str(path)
    if resample_hz is not None:
        resample_hz = stated_rate(resample_hz, "resample_hz")
    text = read_text(path, "capacitance-meter")
    lines = text.splitlines()
    if not any(ln.strip() for ln in lines):
        raise EctskinError(f"{src}: the file is empty")
    delim = delimiter or detect_delimiter(lines)
    decimal_comma = delim != ","
    head = _head_rows(lines, src, delim, decimal_comma)
    rows = head if head is not None else list(csv_rows(lines, src, delimiter=delim))
    header = parse_header(
        rows,
        src,
        delimiter=delim,
        decimal_comma=decimal_comma,
        time_unit=time_unit,
        value_unit=value_unit,
    )
    check_order = time_order == "strict"
    table = None
    if head is not None:  # one row per line down to the data: read the data lines in bulk
        table = _bulk_table(text, lines, header, src, delim, decimal_comma, check_order)
    if table is None:  # one row at a time: the reference, which reports every fault
        if head is not None:
            rows = list(csv_rows(lines, src, delimiter=delim))
        errors = RowErrors(src, strict, log)
        data = rows[header.data_start :]
        cut = None if ends_with_newline(text) else _cut_last_row(data, header, decimal_comma)
        if cut is not None:
            data = data[:-1]
        table = parse_rows(data, header, errors, decimal_comma, check_order)
        if cut is not None:
            _leave_out(table, cut, sum(1 for _, c in data if any(x.strip() for x in c)), src)
    _check_magnitudes(table, header, src)
    timing = _time_order(table, header, time_order, src)
    _check_relative(table, header, relative_tolerance, src)
    if resample_hz is not None:
        _resample(table, resample_hz, src)
        timing["resampled_hz"] = resample_hz
    return _result(table, header, src, pair_order, n_pairs, timing, resample_hz)


def _bulk_table(
    text: str,
    lines: list[str],
    header: Header,
    src: str,
    delim: str,
    decimal_comma: bool,
    check_order: bool,
) -> Table | None:
    """The data lines read by :func:`bulk_rows` (a cut last line left out), or None when the
    rows must be read one at a time (a fault, or a quote near the end)."""
    data_lines = lines[header.data_start :]
    cut = None
    if not ends_with_newline(text):
        first = max(header.data_start, len(lines) - TAIL_ROWS - 1)
        tail = lines[first:]
        if any('"' in ln for ln in tail):
            return None
        try:
            rows = [(first + line, c) for line, c in csv_rows(tail, src, delimiter=delim)]
        except EctskinError:  # the whole file's reader names the right line
            return None
        cut = _cut_last_row(rows, header, decimal_comma)
        if cut is not None:
            data_lines = data_lines[:-1]
    table = bulk_rows(
        data_lines, header.data_start + 1, header, src, delim, decimal_comma, check_order
    )
    if table is not None and cut is not None:
        _leave_out(table, cut, len(table.times), src)
    return table


def _leave_out(table: Table, cut: tuple[int, str], kept: int, src: str) -> None:
    """Log the cut last row and list it among the skipped rows."""
    line, why = cut
    log.warning("%s", truncation_note(src, line, why, kept))
    table.report.skipped_rows.append(
        (line, f"cut short ({why}); the file ends there without a newline (truncated?)")
    )


def _head_rows(lines: list[str], src: str, delim: str, decimal_comma: bool) -> Rows | None:
    """The CSV rows of the head of the file when they settle the header (a data row below it)
    and hold one row per line (no quoted cell over several lines); else None."""
    head = lines[:HEAD_LINES]
    try:
        rows = list(csv_rows(head, src, delimiter=delim))
    except EctskinError:
        return None
    if len(head) < len(lines):
        rows = rows[:-1]  # the last row of a cut head may be incomplete
    if any(line != k + 1 for k, (line, _) in enumerate(rows)):
        return None
    return rows if locate_header(rows, decimal_comma)[1] else None


def _time_order(table: Table, header: Header, time_order: str, src: str) -> dict:
    """Apply the ``time_order`` policy to the table; clock times then count from the first
    frame. Returns the record of a repair (empty when every stamp increased)."""
    order, times, repair = order_frames(
        table.times, table.lines, time_order, src, header.time_name
    )
    if order is not None:
        table.take(order)
    table.times = times
    if table.kind == "clock":
        header.meta["clock_start"] = table.time_cells[0].strip()
        table.times = table.times - table.times[0]  # clock times count from the first frame
    if repair is None:
        return {}
    table.report.notes.append(repair.note(src).removeprefix(f"{src}: "))
    return repair.to_dict()


def _resample(table: Table, hz: float, src: str) -> None:
    """Put the table's frames onto the uniform grid of ``hz`` (:func:`resample`), noted."""
    times, values, lines_at = resample(table.times, table.values, table.lines, hz)
    note = (
        f"{len(table.times)} frames resampled to {len(times)} at {hz:g} frames/s (linear "
        "interpolation of each channel)"
    )
    log.info("%s: %s", src, note)
    table.report.notes.append(note)
    table.times, table.values, table.lines = times, values, lines_at


def _cut_last_row(data: Rows, header: Header, decimal_comma: bool) -> tuple[int, str] | None:
    """(line, why) when the last data row (the file ends without a newline) looks cut short."""
    if header.width - 1 == header.time_col:

        def is_value(c: str) -> bool:
            return parse_number(c, decimal_comma) is not None or parse_clock(c) is not None
    else:

        def is_value(c: str) -> bool:
            return parse_number(c, decimal_comma) is not None or missing_marker(c) is not None

    why = cut_last_row(data, header.width, is_value, decimal_comma)
    return None if why is None else (data[-1][0], why)


def _check_magnitudes(table: Table, header: Header, src: str) -> None:
    """Refuse a value (pF) or time (s) beyond MAX_ABS_VALUE: the calibration would overflow."""
    with np.errstate(invalid="ignore"):
        big = np.abs(table.values) > MAX_ABS_VALUE
    if big.any():
        i, k = (int(v) for v in np.argwhere(big)[0])
        c = header.values[k]
        raise EctskinError(
            f"{src}: line {table.lines[i]}, column {c.index + 1} (channel {c.base!r}): "
            f"{table.values[i, k]:g} pF is beyond ±{MAX_ABS_VALUE:g} pF, where the calibration "
            "and training overflow; a placeholder for a missing value? Write OL, NaN or leave "
            "the cell empty (masked) instead"
        )
    big = np.abs(table.times) > MAX_ABS_VALUE
    if big.any():
        i = int(np.argmax(big))
        raise EctskinError(
            f"{src}: line {table.lines[i]}: time {table.times[i]:g} s is beyond "
            f"±{MAX_ABS_VALUE:g} s"
        )


def _check_arguments(
    time_unit: str | None,
    value_unit: str | None,
    delimiter: str | None,
    pair_order: str,
    time_order: str,
) -> None:
    check_option("pair_order", pair_order, ("auto", "file"))
    check_option("time_order", time_order, TIME_ORDERS)
    if delimiter is not None:
        check_option("delimiter", delimiter, (",", ";", "\t"))
    if (
        time_unit is not None
        and time_unit.lower() not in TIME_UNITS
        and time_unit.lower() not in CLOCK_UNITS
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


def _check_relative(table: Table, header: Header, tolerance: float, src: str) -> None:
    """Cross-check each relative-change column: C / (1 + r) must be one constant reference.

    Rows that disagree with the median reference by more than ``tolerance`` are counted in the
    channel's mask report (and logged), never an error.
    """
    rel_index = {name: k for k, name in enumerate(header.relative)}
    for k, c in enumerate(header.values):
        rc = header.relative.get(c.base)
        if rc is None:
            continue
        ch = table.report.channels[c.base]
        r = table.relative[:, rel_index[c.base]]
        if not np.isfinite(rc.factor):
            log.info("%s: %r has no known unit; relative change not cross-checked", src, rc.header)
            continue
        v = table.values[:, k]
        ok = np.isfinite(r) & np.isfinite(v) & (np.abs(1 + r) > 1e-9)
        if not ok.any():
            continue
        implied = v[ok] / (1 + r[ok])
        ref = np.median(implied)
        bad = np.abs(implied - ref) > tolerance * abs(ref)
        ch.relative_checked = True
        ch.relative_mismatch = int(bad.sum())
        ch.relative_first_lines = [int(x) for x in table.lines[ok][bad][:N_FIRST_LINES]]
        if bad.any():
            log.warning(
                "%s: channel %r: relative-change column %r disagrees with the value on %d row(s), "
                "first at line %d",
                src,
                c.base,
                rc.header,
                int(bad.sum()),
                ch.relative_first_lines[0],
            )


def _result(
    table: Table,
    header: Header,
    src: str,
    pair_order: str,
    n_pairs: int | None,
    timing: dict,
    resampled_hz: float | None,
) -> CapmeterData:
    """The :class:`CapmeterData`, channels in the ECT pair order when ``pair_order="auto"``."""
    names = [c.base for c in header.values]
    units = tuple(c.unit or "" for c in header.values)
    values, report, pairs = table.values, table.report, None
    if pair_order == "auto":
        canon = canonical_pair_order(names)
        if canon is not None:
            pairs, order = canon
            if np.any(order != np.arange(len(order))):
                log.info("%s: channels reordered into the ECT pair order (1,2),(1,3)...", src)
            values = values[:, order]
            names = [names[k] for k in order]
            units = tuple(units[k] for k in order)
            report.channels = {nm: report.channels[nm] for nm in names}
        else:
            log.debug("%s: channel names are not all pairs of n electrodes; file order", src)
    if n_pairs is not None and len(names) != n_pairs:
        raise EctskinError(
            f"{src}: expected {n_pairs} capacitance channels (one per electrode pair), found "
            f"{len(names)}: {', '.join(names)}"
        )
    report.notes = (
        list(header.notes) + report.notes + _dead_channel_notes(report, table.values.shape[0], src)
    )
    _log_masks(report, src)
    return CapmeterData(
        path=src,
        timestamps=table.times,
        values=values,
        channels=tuple(names),
        units=units,
        lines=table.lines,
        mask_report=report,
        time_unit=header.time_unit or "hh:mm:ss",
        pairs=pairs,
        meta=header.meta,
        timing=timing,
        resampled_hz=resampled_hz,
    )


def _dead_channel_notes(report: MaskReport, n_frames: int, src: str) -> list[str]:
    """A note for each channel with no readout in any frame (``OL`` in every row, say): it is
    kept here, as NaN, and left out when a recording is built (``unmeasured_pairs``)."""
    notes = []
    for name, c in report.channels.items():
        if c.n_masked == n_frames:
            kinds = ", ".join(c.counts)
            notes.append(
                f"channel {name!r} has no readout in any frame ({kinds} in every row): left out "
                "when a recording is built (listed in unmeasured_pairs)"
            )
            log.warning("%s: %s", src, notes[-1])
    return notes


def _log_masks(report: MaskReport, src: str) -> None:
    for name in report.masked_channels:
        c = report.channels[name]
        log.warning(
            "%s: channel %r: %d cell(s) masked (%s), first at line %d",
            src,
            name,
            c.n_masked,
            ", ".join(f"{k} {v}" for k, v in c.counts.items()),
            c.first_lines[0],
        )
