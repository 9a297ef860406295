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
"""

from __future__ import annotations

import csv
import logging
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ectskin._check import EctskinError

log = logging.getLogger(__name__)

#: CSV rows as :func:`csv_rows` yields them: (1-based line number, cells).
Rows = list[tuple[int, list[str]]]

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
