"""Text and CSV helpers shared by the importers (instrument exports, generic CSV).

* :func:`read_text`: a whole text export, UTF-8 (with or without BOM), UTF-16 with BOM, or
  Windows-1252; binary data is refused.
* :func:`csv_rows`: CSV rows with their 1-based line numbers; malformed CSV is an error naming the
  line.
* :func:`detect_delimiter`: tab, semicolon or comma, from the data lines.
* :func:`parse_number` (instrument cells: spaces, thousands groups, a decimal comma) and
  :func:`parse_float` (Python's ``float``): a number, or None when the cell is not one, so the
  caller can name the column and what it expected.
* :class:`RowErrors`: the ``strict`` policy for a malformed data row: raise an error naming file
  and line, or skip the row, log it and remember it for the report.
* :func:`data_cells` and :func:`float_cells`: a block of machine-written data lines read in bulk
  (cells as an array, numbers column by column); the importers read the block line by line only
  when the bulk read finds something to explain (a bad row, a quote), so that every message still
  names the line and the column.
* :func:`cut_last_row` and :func:`truncation_note`: the one rule for the last row of a file that
  ends without a newline: it may have been cut in the middle (a copy that stopped: ``1.00239``
  read as ``1.0``); every importer leaves such a row out and says so, keeping the rows before it.
* :data:`MAX_ABS_VALUE`: the largest magnitude a number of an imported file may have.
"""

from __future__ import annotations

import csv
import logging
import re
from collections.abc import Callable, Collection, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError

log = logging.getLogger(__name__)

#: CSV rows as :func:`csv_rows` yields them: (1-based line number, cells).
Rows = list[tuple[int, list[str]]]

#: Largest magnitude of an imported number (readouts in any unit, mm, s). Beyond it the
#: calibration (Eq. 2 stored as float32) and the statistics of training (sums and squares)
#: overflow to inf; such values are placeholders for "no value" (1.7e308), not measurements.
MAX_ABS_VALUE = 1e30

_THOUSANDS_SPACES = re.compile(r"^[+-]?\d{1,3}(?: \d{3})+(?:[.,]\d*)?(?:[eE][+-]?\d+)?$")


def read_text(path: str | Path, what: str) -> str:
    """Read a text export: UTF-8 (with or without BOM), UTF-16 with BOM, or Windows-1252.

    ``what`` names the kind of file in messages (``"Motive"``: "not a Motive CSV export").
    """
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


def csv_rows(
    lines: Iterable[str], src: str, *, delimiter: str = ","
) -> Iterator[tuple[int, list[str]]]:
    """``(line number, cells)`` of every CSV row of ``lines`` (a list of lines or an open file).

    The line number is 1-based and counts physical lines (a quoted cell may span several); a
    malformed row is an :class:`EctskinError` naming ``src`` and the line.
    """
    reader = csv.reader(lines, delimiter=delimiter)
    try:
        for cells in reader:
            yield reader.line_num, cells
    except csv.Error as exc:
        raise EctskinError(f"{src}: line {reader.line_num}: not valid CSV ({exc})") from None


def detect_delimiter(lines: Sequence[str]) -> str:
    """Tab, semicolon or comma: the first found equally often (≥ 1) in the last data lines."""
    filled = [ln for ln in lines if ln.strip()]
    tail = filled[-min(20, max(2, len(filled) // 2)) :]
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
    return parse_float(s)


def parse_float(text: str) -> float | None:
    """``float(text)`` (surrounding spaces, ``nan``, ``inf`` allowed), or None if not a number."""
    try:
        return float(text)
    except ValueError:
        return None


@dataclass
class RowErrors:
    """Malformed data rows of one file: an error when ``strict``, else skipped and remembered.

    ``skipped`` lists ``(line, reason)`` of every skipped row; ``logger`` is the importer's.
    """

    src: str
    strict: bool
    logger: logging.Logger = log
    skipped: list[tuple[int, str]] = field(default_factory=list)

    def error(self, line: int, reason: str) -> EctskinError:
        """The error for ``reason`` on ``line`` (e.g. a bad cell that cannot be skipped)."""
        return EctskinError(f"{self.src}: line {line}: {reason}")

    def bad_row(self, line: int, reason: str) -> None:
        """Raise :meth:`error` when strict; else log the row as skipped and remember it."""
        if self.strict:
            raise self.error(line, reason)
        self.logger.warning("%s: line %d skipped: %s", self.src, line, reason)
        self.skipped.append((line, reason))


# --------------------------------------------------------------------------- bulk reads
def data_cells(
    lines: Sequence[str], first_line: int, delimiter: str, width: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """The cells of machine-written data lines, read in bulk.

    ``lines`` are consecutive lines of the file, the first being line ``first_line`` (1-based).
    Returns ``(cells, line_numbers)``: an object array (n, ``width``) of the cell texts, exactly as
    :func:`csv_rows` would give them, and the line number of each row (int64); blank lines (no
    cell with more than white space) are left out. None when a line needs the CSV reader or has a
    fault: a quote or NUL character, a line longer than the CSV reader's field limit, or a
    non-blank line without ``width`` cells. The caller then reads the lines one by one, so that the fault is
    reported with its line.
    """
    if not lines:
        return np.empty((0, width), dtype=object), np.empty(0, dtype=np.int64)
    if max(map(len, lines)) > csv.field_size_limit():
        return None
    # a line of other (Unicode) white space is kept here: its cells then send the block to the
    # line reader, which leaves it out
    blank = " \t" + delimiter
    keep = [k for k, ln in enumerate(lines) if ln.strip(blank)]
    kept = lines if len(keep) == len(lines) else [lines[k] for k in keep]
    n_delims = width - 1
    if any(ln.count(delimiter) != n_delims for ln in kept):
        return None
    block = delimiter.join(kept)
    if '"' in block or "\x00" in block:
        return None
    cells = np.array(block.split(delimiter), dtype=object).reshape(len(kept), width)
    return cells, np.asarray(keep, dtype=np.int64) + first_line


def float_cells(
    cells: np.ndarray,
    parse: Callable[[str], float | None],
    no_value: Collection[str] = ("",),
    decimal_comma: bool = False,
) -> np.ndarray:
    """float64 of every cell of ``cells`` (a 1-D object array of texts), as ``parse`` reads it
    (:func:`parse_float` or :func:`parse_number`); NaN where a cell is no number.

    Column by column in C wherever Python's ``float`` takes every cell, which gives the same
    numbers as ``parse`` (both end in ``float``; ``parse_number`` only adds spaces in thousands
    and, with ``decimal_comma``, the one comma of a cell, which ``float`` refuses). Texts in
    ``no_value`` (``""``, ``"OL"``...) are taken as NaN first; a column with any other text that
    ``float`` refuses is parsed cell by cell. A NaN is either a cell ``nan`` or no number: the
    caller tells them apart by the texts of its (few) NaN cells.
    """
    try:
        return cells.astype(np.float64)
    except ValueError:
        pass
    if "" in no_value:  # empty cells, the commonest: compared in C, without hashing every cell
        try:
            return np.where(cells == "", "nan", cells).astype(np.float64)
        except ValueError:
            pass
    texts = cells.tolist()
    if decimal_comma:  # "1,5" → "1.5"; a cell with a dot and a comma, or two commas, is refused
        texts = [c.replace(",", ".") for c in texts]
    nan_for = {t: "nan" for t in no_value}
    texts = list(map(nan_for.get, texts, texts))
    try:
        return np.array(texts, dtype=object).astype(np.float64)
    except ValueError:
        pass
    values = map(parse, cells.tolist())
    return np.fromiter((np.nan if v is None else v for v in values), np.float64, len(cells))


# --------------------------------------------------------------------------- truncated files
def decimals(cell: str, decimal_comma: bool = False) -> int:
    """Digits after the decimal separator of a number cell: ``"1.00239"`` → 5, ``"2"`` → 0,
    ``"1.5e-3"`` → 1 (the exponent does not count)."""
    s = cell.strip()
    for e in "eE":
        s = s.split(e, 1)[0]
    for sep in ".," if decimal_comma else ".":
        if sep in s:
            return sum(ch.isdigit() for ch in s.rsplit(sep, 1)[1])
    return 0


@dataclass
class TailDecimals:
    """The last cell of every row so far: how many were empty, and the decimals of the others
    (one count for all: a fixed-format export; or mixed)."""

    value: int | None = None
    mixed: bool = False
    n: int = 0  # rows
    n_numbers: int = 0  # rows whose last cell is not empty
    n_empty: int = 0

    def add(self, cell: str, decimal_comma: bool = False) -> None:
        self.n += 1
        if not cell.strip():
            self.n_empty += 1
            return
        d = decimals(cell, decimal_comma)
        if self.n_numbers and d != self.value:
            self.mixed = True
        self.value = d
        self.n_numbers += 1

    @property
    def fixed(self) -> int | None:
        """The decimals every non-empty last cell had (at least two of them), else None."""
        return self.value if self.n_numbers >= 2 and not self.mixed else None


def cut_short(
    cells: Sequence[str],
    width: int,
    tail: TailDecimals,
    is_value: Callable[[str], bool] | None,
    decimal_comma: bool = False,
) -> str | None:
    """Why the final row of a file without a newline at its end looks cut short, or None.

    A copy that stops in the middle of the last row leaves fewer cells than the header's
    ``width``, an empty last cell (where every row before it ends with a value), a last cell that
    is no value (``is_value``, None for a text column) or a last number with fewer decimals than
    the same column has in every row before it (``tail``: fixed-format exports). A last row that
    ends like the rows before it is taken as complete.
    """
    if len(cells) < width:
        return f"it has {len(cells)} of the header's {width} cells"
    last = cells[-1]
    if not last.strip():
        if tail.n and not tail.n_empty:  # every row before it ends with a value
            return "it ends with an empty cell"
        return None
    if is_value is None:
        return None
    if not is_value(last):
        return f"its last cell {last.strip()!r} is not a number"
    fixed = tail.fixed
    d = decimals(last, decimal_comma)
    if fixed is not None and d < fixed:
        return (
            f"its last number {last.strip()!r} has {d} decimal{'' if d == 1 else 's'}, the "
            f"{tail.n} rows before it have {fixed}"
        )
    return None


#: How many rows before a file's last row :func:`cut_last_row` compares it with.
TAIL_ROWS = 50


def ends_with_newline(text: str) -> bool:
    """Whether ``text`` (a whole file) ends with a line break (an empty text counts as one)."""
    return not text or text.endswith(("\n", "\r"))


def cut_last_row(
    rows: Sequence[tuple[int, Sequence[str]]],
    width: int,
    is_value: Callable[[str], bool] | None,
    decimal_comma: bool = False,
) -> str | None:
    """Why the last of ``rows`` looks cut short, or None: the one rule of every importer for the
    last data row of a file that ends without a newline.

    ``rows`` are data rows ``(line, cells)`` ending with the file's last one; the last
    :data:`TAIL_ROWS` rows before it that have ``width`` cells tell how its last cell should look
    (:func:`cut_short`: the cell count, an empty last cell, ``is_value``, the decimals). A blank
    last row is no cut. The caller leaves a cut row out, logs :func:`truncation_note` as a warning
    and lists the row among those it skipped.
    """
    if not rows or not any(c.strip() for c in rows[-1][1]):
        return None
    tail = TailDecimals()
    for _, before in rows[-TAIL_ROWS - 1 : -1]:
        if len(before) == width:
            tail.add(before[-1], decimal_comma)
    return cut_short(rows[-1][1], width, tail, is_value, decimal_comma)


def truncation_note(src: str, line: int, reason: str, kept: int) -> str:
    """The message for a last row left out by :func:`cut_short`."""
    return (
        f"{src}: line {line} is cut short ({reason}) and the file ends there without a "
        f"newline: the file looks truncated (copied incompletely?); line {line} is left out, "
        f"the {kept} data rows before it are kept"
    )
