"""Read a generic ``.csv`` recording: one row per frame, columns named by role
(``docs/import-format.md``).

The file is streamed once: group ids are kept as text and every other column goes into one flat
float64 buffer, so a big file costs 8 bytes per numeric cell rather than a Python string per cell.
A last row cut short by an incomplete copy (the file ends without a newline inside it) is left
out with a warning (:func:`ectskin.io.text.cut_last_row`).
"""

from __future__ import annotations

import logging
import math
import re
from array import array
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.generic.fields import (
    CSV_COLUMNS,
    Fields,
    check_magnitude,
    class_labels,
    file_rate,
    ground_truth,
    group_ids,
)
from ectskin.io.text import TAIL_ROWS, csv_rows, cut_last_row, parse_float, truncation_note

log = logging.getLogger(__name__)


@dataclass
class _Scan:
    """The rows of one CSV file as they are read: header, roles, and the flat buffers."""

    src: str
    meta: dict[str, str] = field(default_factory=dict)  # "# key: value" lines above the header
    header: list[str] | None = None
    header_line: int = 0
    cols: dict[str, Any] = field(default_factory=dict)  # see _csv_columns
    numeric: list[int] = field(default_factory=list)  # columns parsed as numbers (all but text)
    flat: array = field(default_factory=lambda: array("d"))
    groups: list[str] = field(default_factory=list)
    surfaces: dict[int, list[str]] = field(default_factory=dict)  # per finger: its 'surface'
    text: tuple[int, ...] = ()  # the text columns: 'group' and the 'surface' columns
    lines: array = field(default_factory=lambda: array("q"))
    # the last data rows read, (line, cells): how the file's last row should look
    tail: deque = field(default_factory=lambda: deque(maxlen=TAIL_ROWS + 1))
    notes: list[str] = field(default_factory=list)

    def add_last(self, line: int, cells: list[str]) -> None:
        """Take the file's last row, which no newline ends: left out (noted) if it looks cut."""
        if self.header is None or not cells or cells[0].lstrip().startswith("#"):
            return self.add(line, cells)
        if all(not c.strip() for c in cells):
            return None
        last_is_text = len(self.header) - 1 in self.text
        rows = [*self.tail, (line, cells)]
        why = cut_last_row(rows, len(self.header), None if last_is_text else _is_number)
        if why is None:
            try:
                return self.add(line, cells)
            except EctskinError as exc:
                why = f"it does not read: {str(exc).removeprefix(self.src + ': ')}"
        note = truncation_note(self.src, line, why, len(self.groups))
        log.warning("%s", note)
        self.notes.append(note)
        return None

    def add(self, line: int, cells: list[str]) -> None:
        """Take one CSV row: a blank or comment line, the header, or a data row."""
        if not cells or all(not c.strip() for c in cells):
            return
        if cells[0].lstrip().startswith("#"):
            if self.header is None:
                self._comment(",".join(cells).lstrip()[1:])
            return
        if self.header is None:
            self.header = [c.strip() for c in cells]
            self.header_line = line
            self.cols = _csv_columns(self.header, self.src, line)
            faces = {k: c["surface"] for k, c in self.cols["fingers"].items() if "surface" in c}
            self.surfaces = {k: [] for k in faces}
            self.text = (self.cols["group"], *faces.values())
            self.numeric = [j for j in range(len(self.header)) if j not in self.text]
            return
        if len(cells) != len(self.header):
            raise EctskinError(
                f"{self.src}: line {line} has {len(cells)} cells, the header "
                f"(line {self.header_line}) has {len(self.header)}"
            )
        g = cells[self.cols["group"]].strip()
        if not g:
            raise EctskinError(
                f"{self.src}: line {line}, column 'group': empty cell, expected a group id"
            )
        if "\x00" in g:
            raise EctskinError(
                f"{self.src}: line {line}, column 'group': the group id {g!r} contains a NUL "
                "byte; group ids become trial names, which cannot hold one"
            )
        values = tuple(cells[j] for j in self.numeric)
        try:
            row = array("d", map(float, values))
        except ValueError:
            row = self._slow_row(values, line)
        self.flat.extend(row)  # only a row that reads whole is taken
        self.groups.append(g)
        for k, faces in self.surfaces.items():
            faces.append(cells[self.cols["fingers"][k]["surface"]].strip())
        self.lines.append(line)
        self.tail.append((line, cells))

    def _comment(self, text: str) -> None:
        """``# frame_rate_hz: 30`` (or ``=``) above the header → meta["frame_rate_hz"]."""
        for sep in (":", "="):
            if sep in text:
                key, value = text.split(sep, 1)
                self.meta[key.strip().lower()] = value.strip()
                break

    def _slow_row(self, values: tuple[str, ...], line: int) -> array:
        """Parse one row cell by cell: NaN for allowed empty cells, else a precise error."""
        out = array("d")
        for j, cell in zip(self.numeric, values):
            number = parse_float(cell)
            if number is not None:
                out.append(number)
                continue
            name = self.header[j]
            desc, empty_ok = _csv_kind(name)
            if cell.strip():
                raise EctskinError(
                    f"{self.src}: line {line}, column {name!r}: expected {desc}, found {cell!r}"
                )
            if not empty_ok:
                raise EctskinError(
                    f"{self.src}: line {line}, column {name!r}: empty cell, expected {desc}"
                )
            out.append(math.nan)
        return out


def read_csv(path: Path) -> Fields:
    """The fields of a generic CSV file (columns in ``CSV_COLUMNS``)."""
    scan = _scan(path)
    header, cols, src = scan.header, scan.cols, scan.src
    lines = scan.lines

    def row(i: int) -> str:
        return f"line {lines[i]}"

    n = len(scan.groups)
    table = np.frombuffer(scan.flat, dtype=np.float64).reshape(n, len(scan.numeric)).copy()
    pos = {j: p for p, j in enumerate(scan.numeric)}

    def column(j: int) -> np.ndarray:
        return table[:, pos[j]]

    readouts = np.stack([column(j) for j in cols["c"]], axis=1)
    if np.isinf(readouts).any():
        i, j = (int(v) for v in np.argwhere(np.isinf(readouts))[0])
        raise EctskinError(f"{src}: {row(i)}, column {header[cols['c'][j]]!r} is {readouts[i, j]}")

    def at(columns: list[int]):
        return lambda k: f"{row(k[0])}, column {header[columns[k[1]]]!r}"

    check_magnitude(readouts, src, "readout", at(cols["c"]))
    labels = None
    if "label" in cols:
        labels = class_labels(column(cols["label"]), n, src, "column 'label'", row)
    markers = None
    marker_names = None
    if cols["m"]:
        marker_names = list(cols["m"])
        markers = np.stack(
            [np.stack([column(j) for j in cols["m"][name]], axis=1) for name in marker_names],
            axis=1,
        )
        if np.isinf(markers).any():
            i = int(np.argwhere(np.isinf(markers))[0][0])
            raise EctskinError(f"{src}: {row(i)}: a marker coordinate is inf")
        check_magnitude(
            markers,
            src,
            "marker coordinate",
            lambda k: f"{row(k[0])}, column 'm:{marker_names[k[1]]}.{'xyz'[k[2]]}'",
        )
    reference = None
    if cols["ref"]:
        reference = np.stack([column(j) for j in cols["ref"]], axis=1)
        check_magnitude(reference, src, "reference", at(cols["ref"]))
    timestamps = column(cols["time_s"]) if "time_s" in cols else None
    if timestamps is not None:
        check_magnitude(timestamps, src, "time", lambda k: f"{row(k[0])}, column 'time_s'")
    truth = _truth(scan, n, row, column)
    return Fields(
        src,
        readouts,
        group_ids(np.asarray(scan.groups, dtype=str), n, src, row, text_ints=True),
        labels,
        markers,
        reference,
        timestamps,
        file_rate(scan.meta.get("frame_rate_hz"), f"{src}: '# frame_rate_hz'"),
        [header[j][2:] for j in cols["c"]],
        marker_names,
        row,
        scan.notes,
        truth,
    )


def _truth(scan: _Scan, n: int, row: Any, column: Any) -> Any:
    """The contact labels on the fingers axis: finger 0's columns unprefixed, finger k's
    ``f<k>:<column>`` (every finger with the same columns, :func:`_csv_columns`)."""
    fingers = scan.cols["fingers"]
    if not fingers:
        return None
    order = sorted(fingers)
    first = fingers[0]

    def axis(key: str) -> np.ndarray | None:
        if key not in first:
            return None
        return np.stack([column(fingers[k][key]) for k in order], axis=1)

    def name(key: str, k: int) -> str:
        pre = f"f{k}:" if k else ""
        if key == "position_mm":
            return f"columns '{pre}x_mm', '{pre}z_mm'"
        return f"column '{pre}{key}'"

    position = None
    if "x_mm" in first:
        position = np.stack(
            [np.stack([column(fingers[k]["x_mm"]), column(fingers[k]["z_mm"])], axis=1)
             for k in order],
            axis=1,
        )
    surface = None
    if "surface" in first:
        surface = np.stack([np.asarray(scan.surfaces[k], dtype=str) for k in order], axis=1)
    return ground_truth(
        scan.src,
        n,
        row,
        name,
        contact=axis("contact"),
        position_mm=position,
        force_n=axis("force_n"),
        height_mm=axis("height_mm"),
        surface=surface,
    )


def _is_number(cell: str) -> bool:
    return parse_float(cell) is not None


def _ends_with_newline(path: Path) -> bool:
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        if fh.tell() == 0:
            return True
        fh.seek(-1, 2)
        return fh.read(1) in (b"\n", b"\r")


def _scan(path: Path) -> _Scan:
    src = str(path)
    scan = _Scan(src)
    try:
        complete = _ends_with_newline(path)
        with open(path, encoding="utf-8-sig", newline="") as fh:
            held = None  # one row behind: the last row is read by add_last
            for row in csv_rows(fh, src):
                if held is not None:
                    scan.add(*held)
                held = row
            if held is not None:
                (scan.add if complete else scan.add_last)(*held)
    except UnicodeDecodeError:
        raise EctskinError(f"{src}: not UTF-8 text (is it a CSV file?)") from None
    except OSError as exc:
        raise EctskinError(f"{src}: cannot read ({exc.strerror})") from None
    if scan.header is None:
        raise EctskinError(f"{src}: empty file, expected a header row with columns {CSV_COLUMNS}")
    if not scan.groups:
        raise EctskinError(f"{src}: no data rows after the header (line {scan.header_line})")
    return scan


def _csv_kind(name: str) -> tuple[str, bool]:
    """What a numeric CSV column holds (for messages) and whether an empty cell means NaN."""
    finger = _FINGER_PREFIX.match(name)
    if finger:
        name = name[finger.end() :]
    if name.startswith("c:"):
        return "a number (empty = masked)", True
    if name.startswith("m:"):
        return "a coordinate in mm (empty = occluded)", True
    if name.startswith("ref:"):
        return "a reference readout", False
    if name == "label":
        return "a class number", False
    if name == "contact":
        return "0 or 1", False
    if name in ("x_mm", "z_mm"):
        return "a position in mm (empty = no finger)", True
    if name == "height_mm":
        return "a height in mm (empty = no finger)", True
    if name == "force_n":
        return "a force in N", False
    return "a time in s", False


#: the optional contact-label columns (docs/import-format.md): finger 0's as named here,
#: finger k's (k = 1, 2, ...) with the prefix ``f<k>:``
TRUTH_COLUMNS = ("contact", "x_mm", "z_mm", "force_n", "height_mm", "surface")
_FINGER_PREFIX = re.compile(r"f([1-9][0-9]*):")


def _csv_columns(header: list[str], src: str, line: int) -> dict[str, Any]:
    """Column indices by role: group, time_s, label, c (list), ref (list), m (name → [x, y, z])."""
    seen: dict[str, int] = {}
    for j, h in enumerate(header):
        if "\x00" in h:
            raise EctskinError(f"{src}: line {line}: column name {h!r} contains a NUL byte")
        if h in seen:
            raise EctskinError(f"{src}: line {line}: duplicate column {h!r}")
        seen[h] = j
    cols: dict[str, Any] = {"c": [], "ref": [], "m": {}, "fingers": {}}
    refs: dict[str, int] = {}
    for j, h in enumerate(header):
        finger = _FINGER_PREFIX.match(h)
        if h in ("group", "time_s", "label"):
            cols[h] = j
        elif h in TRUTH_COLUMNS:
            cols["fingers"].setdefault(0, {})[h] = j
        elif finger and h[finger.end() :] in TRUTH_COLUMNS:
            cols["fingers"].setdefault(int(finger.group(1)), {})[h[finger.end() :]] = j
        elif h.startswith("c:") and len(h) > 2:
            cols["c"].append(j)
        elif h.startswith("ref:") and len(h) > 4:
            refs[h[4:]] = j
        elif h.startswith("m:") and h[-2:] in (".x", ".y", ".z") and len(h) > 4:
            cols["m"].setdefault(h[2:-2], {})[h[-1]] = j
        else:
            raise EctskinError(f"{src}: line {line}: unknown column {h!r}; expected {CSV_COLUMNS}")
    if "group" not in cols:
        raise EctskinError(
            f"{src}: line {line}: missing column 'group' (a group id per frame: the trials)"
        )
    if not cols["c"]:
        raise EctskinError(
            f"{src}: line {line}: no readout columns; name them 'c:<channel>' (e.g. 'c:E1-E2')"
        )
    _finger_columns(cols["fingers"], src, line)
    if refs:
        names = [header[j][2:] for j in cols["c"]]
        missing = [c for c in names if c not in refs]
        extra = [r for r in refs if r not in names]
        if missing or extra:
            raise EctskinError(
                f"{src}: line {line}: reference columns must match the readout columns one to "
                f"one ('ref:<channel>' for every 'c:<channel>'); missing {missing}, unmatched "
                f"{extra}"
            )
        cols["ref"] = [refs[c] for c in names]
    for name, axes in cols["m"].items():
        missing = [a for a in "xyz" if a not in axes]
        if missing:
            raise EctskinError(
                f"{src}: line {line}: marker {name!r} lacks column(s) "
                f"{', '.join(f'm:{name}.{a}' for a in missing)}"
            )
        cols["m"][name] = [axes["x"], axes["y"], axes["z"]]
    return cols


def _finger_columns(fingers: dict[int, dict[str, int]], src: str, line: int) -> None:
    """The contact-label columns of fingers 0, 1, ... (none missing in between), each finger
    with the same columns, x_mm and z_mm together."""
    for k in range(max(fingers, default=-1) + 1):
        if k not in fingers:
            raise EctskinError(
                f"{src}: line {line}: contact-label columns of finger {max(fingers)} but none "
                f"of finger {k}; number the fingers 1, 2, ... after the unprefixed finger 0"
            )
    for k, have in fingers.items():
        pre = f"f{k}:" if k else ""
        if ("x_mm" in have) != ("z_mm" in have):
            found = f"{pre}x_mm" if "x_mm" in have else f"{pre}z_mm"
            raise EctskinError(
                f"{src}: line {line}: the position on the skin needs both columns "
                f"'{pre}x_mm' and '{pre}z_mm', found only {found!r}"
            )
        if set(have) != set(fingers[0]):
            raise EctskinError(
                f"{src}: line {line}: finger {k} has the contact-label columns "
                f"{', '.join(pre + c for c in sorted(have))}, finger 0 "
                f"{', '.join(sorted(fingers[0]))}; every finger gives the same columns"
            )
