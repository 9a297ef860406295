"""Cells and names of a capacitance-meter export: units, missing-value markers, clock times and
electrode-pair channel names."""

from __future__ import annotations

import re
from collections.abc import Sequence
from datetime import datetime

import numpy as np

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
    {
        "hh:mm:ss",
        "hh:mm:ss.f",
        "hh:mm:ss.ff",
        "hh:mm:ss.fff",
        "hh:mm:ss.s",
        "hh:mm:ss.ss",
        "hh:mm:ss.sss",
        "clock",
        "time of day",
        "timeofday",
    }
)
#: Relative-change units → factor to a plain fraction.
RELATIVE_UNITS: dict[str, float] = {"%": 1e-2, "ppm": 1e-6, "1": 1.0, "fraction": 1.0}
#: Other unit texts a units row may hold.
_OTHER_UNITS = frozenset({"°c", "v", "mv", "hz", "khz", "pf/pf"})

TIME_NAME = re.compile(
    r"^(?:time|timestamp|time\s*stamp|t|zeit|elapsed(?:\s*time)?|relative\s*time)"
    r"(?:$|[\s\[\(/_,:])",
    re.IGNORECASE,
)
RELATIVE_TOKEN = re.compile(
    r"(?<![a-z])(?:(?:d|δ|Δ|delta)\s*c\s*/\s*c0?|rel(?:ative)?\.?(?:\s*change)?|change)"
    r"(?![a-z])",
    re.IGNORECASE,
)
_UNIT_IN_NAME = re.compile(r"^(?P<base>.*?)\s*[\[\(](?P<unit>[^\]\)]*)[\]\)]\s*$")
_TIME_SLASH_UNIT = re.compile(r"^(?P<base>time|t)\s*/\s*(?P<unit>\w+)$", re.IGNORECASE)
_PAIR_SEPARATED = re.compile(r"^[A-Za-z]*\s*(\d+)\s*(?:[-_/:&x]|\s)\s*[A-Za-z]*\s*(\d+)$")
_PAIR_TWO_DIGITS = re.compile(r"^[A-Za-z]+\s*(\d)(\d)$")
_CLOCK = re.compile(
    r"^(?:(?P<date>\d{4}[-/]\d{1,2}[-/]\d{1,2}|\d{1,2}\.\d{1,2}\.\d{4})[ T])?"
    r"(?P<h>\d{1,2}):(?P<m>\d{2}):(?P<s>\d{2}(?:[.,]\d+)?)$"
)


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


def time_kind(unit: str) -> str:
    """``"clock"``, ``"s"``, ``"ms"``, ``"us"``, or the unit itself when it is not a time unit."""
    u = unit.strip().lower()
    if u in CLOCK_UNITS:
        return "clock"
    return {1.0: "s", 1e-3: "ms", 1e-6: "us"}.get(TIME_UNITS.get(u, -1.0), u)


def split_unit(name: str) -> tuple[str, str | None]:
    """``"C12 [pF]"`` → ``("C12", "pF")``; ``"t/ms"`` → ``("t", "ms")``; no unit → None."""
    m = _UNIT_IN_NAME.match(name)
    if m:
        return m["base"].strip(), m["unit"].strip()
    m = _TIME_SLASH_UNIT.match(name.strip())
    if m:
        return m["base"], m["unit"]
    return name.strip(), None


def is_unit_token(text: str) -> bool:
    """Whether a cell reads as a unit (``s``, ``pF``, ``%``, ``hh:mm:ss``, ``°C``...)."""
    t = text.strip().lower()
    return (
        t in CAPACITANCE_UNITS
        or t in TIME_UNITS
        or t in CLOCK_UNITS
        or t in RELATIVE_UNITS
        or t in _OTHER_UNITS
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
