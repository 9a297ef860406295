"""The serial/TCP line protocol (``docs/serial-protocol.md``): one text line → one frame's content.

:func:`parse_line` is pure: it parses one decoded line and raises :class:`LineError` (with the
counter it belongs to) for anything it cannot use. Splitting a byte stream into lines, numbering
them and turning them into frames is :class:`~ectskin.live.sources.lines.LineSource`'s job.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError

#: The longest line the protocol allows, in bytes (a longer one is discarded as malformed).
MAX_LINE_BYTES = 65536
#: The largest ``seq`` the protocol allows: 2**53 - 1, the largest integer every JSON reader (the
#: dashboard's JavaScript included) keeps exact. A larger one is a malformed line, so one garbled
#: counter cannot add 1e23 frames to ``seq_gaps``.
MAX_SEQ = 2**53 - 1

_KEYS = ("t", "seq", "label", "markers")


class LineError(EctskinError):
    """One line of the line protocol could not be used; ``kind`` is the counter it belongs to."""

    def __init__(self, message: str, kind: str = "malformed"):
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class ParsedLine:
    """The content of one data line (see :func:`parse_line`)."""

    capacitance: np.ndarray  # (n_pairs,) float64 pF, NaN = masked
    t: float | None = None
    seq: int | None = None
    label: int | None = None
    markers: np.ndarray | None = None  # (n_markers, 3) mm


def parse_line(
    text: str, n_pairs: int, n_markers: int = 0, where: str = "line"
) -> ParsedLine | None:
    """Parse one line of the serial/TCP line protocol (``docs/serial-protocol.md``).

    ``[key=value;]* v1,v2,...,vN [# comment]`` with keys ``t`` (s), ``seq`` (int), ``label`` (int)
    and ``markers`` (3 × n_markers comma-separated mm). Returns None for a blank or comment-only
    line. Raises :class:`LineError` naming ``where`` (e.g. ``"tcp:host:5000 line 17"``) and the
    offending channel; its ``kind`` is ``"wrong_channels"`` for a count mismatch, else
    ``"malformed"``.
    """
    body = text.split("#", 1)[0].strip()
    if not body:
        return None
    parts = [p.strip() for p in body.split(";")]
    if parts and parts[-1] == "" and len(parts) > 1:  # a trailing ';' after the values
        parts = parts[:-1]
    values_text: str | None = None
    info: dict[str, Any] = {}
    for part in parts:
        key, eq, value = part.partition("=")
        key = key.strip()
        if not eq:
            if values_text is not None:
                raise LineError(f"{where}: two value lists ({values_text[:20]!r}…, {part[:20]!r}…)")
            values_text = part
            continue
        if key not in _KEYS:
            raise LineError(
                f"{where}: unknown field {key!r}; allowed fields are {', '.join(_KEYS)}"
            )
        if key in info:
            raise LineError(f"{where}: field {key!r} given twice")
        info[key] = _parse_field(key, value.strip(), n_markers, where)
    if values_text is None:
        raise LineError(f"{where}: no channel values (expected {n_pairs} comma-separated numbers)")
    cap = _parse_values(values_text, n_pairs, where, "channel", allow_nan=True)
    return ParsedLine(capacitance=cap, **info)


def _parse_field(key: str, value: str, n_markers: int, where: str) -> Any:
    """The value of one ``key=value`` field (``key`` is one of ``_KEYS``)."""
    if key == "t":
        try:
            t = float(value)
        except ValueError:
            raise LineError(
                f"{where}: field 't' must be a number of seconds, got {_quote(value)}"
            ) from None
        if not math.isfinite(t):
            raise LineError(f"{where}: field 't' must be finite, got {_quote(value)}")
        return t
    if key in ("seq", "label"):
        try:
            n = int(value)
        except ValueError:
            raise LineError(
                f"{where}: field {key!r} must be an integer, got {_quote(value)}"
            ) from None
        if n < 0:
            raise LineError(f"{where}: field {key!r} must be >= 0, got {_quote(value)}")
        if key == "seq" and n > MAX_SEQ:
            raise LineError(
                f"{where}: field 'seq' must be at most {MAX_SEQ} (2**53 - 1), got {_quote(value)}"
            )
        return n
    # markers
    m = _parse_values(
        value, 3 * n_markers, f"{where}: field 'markers'", "coordinate", allow_nan=True
    )
    return m.reshape(n_markers, 3)


def _quote(text: str, limit: int = 40) -> str:
    """``repr`` of a field value for a message, cut to ``limit`` characters (a line may hold 64 kB)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"… ({len(text)} characters)"


def _parse_values(text: str, n: int, where: str, what: str, *, allow_nan: bool) -> np.ndarray:
    """Comma-separated floats, exactly ``n`` of them (one trailing comma tolerated)."""
    tokens = text.split(",")
    if len(tokens) > 1 and tokens[-1].strip() == "":
        tokens = tokens[:-1]
    if len(tokens) != n:
        raise LineError(f"{where}: expected {n} {what} values, got {len(tokens)}", "wrong_channels")
    try:
        arr = np.array([float(tok) for tok in tokens], dtype=np.float64)
    except ValueError:
        for k, tok in enumerate(tokens):
            try:
                float(tok)
            except ValueError:
                raise LineError(
                    f"{where}: {what} {k + 1} of {n}: {tok.strip()!r} is not a number"
                ) from None
        raise  # pragma: no cover - float() failed on the whole list but on no token
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if bad.any():
        k = int(np.argmax(bad))
        raise LineError(
            f"{where}: {what} {k + 1} of {n}: {tokens[k].strip()!r} is not finite "
            f"(write 'nan' for a masked {what})"
        )
    return arr
