"""What the generic readers hand to the builder: the parsed fields of one file, format
independent, and the checks both formats share."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.frame_rate import stated_rate
from ectskin.io.text import MAX_ABS_VALUE

NPZ_FIELDS = (
    "readouts",
    "group",
    "labels",
    "markers",
    "reference",
    "timestamps",
    "frame_rate_hz",
    "channel_names",
    "marker_names",
    "contact",
    "position_mm",
    "force_n",
    "height_mm",
    "surface",
)
CSV_COLUMNS = (
    "group, time_s, label, c:<channel>, ref:<channel>, m:<marker>.x|.y|.z, contact, x_mm, z_mm, "
    "force_n, height_mm, surface (and f<k>:<column> of these for finger k = 1, 2, ...)"
)
#: the faces a ``surface`` may name (those of ectskin.layout.layout.SURFACES)
SURFACE_NAMES = ("front", "back", "right", "left")
#: Largest touch class a file may use (a virtual layout gets one region per class).
MAX_CLASS = 1000


@dataclass
class Fields:
    """Parsed file contents, format independent (n frames, m channels, M markers)."""

    source: str
    readouts: np.ndarray  # (n, m) float64, NaN = masked
    group: np.ndarray  # (n,) int64 or str
    labels: np.ndarray | None  # (n,) int64
    markers: np.ndarray | None  # (n, M, 3) float64 mm, NaN = occluded
    reference: np.ndarray | None  # (m,), (n_groups, m) or (n, m)
    timestamps: np.ndarray | None  # (n,) float64 s
    frame_rate_hz: float | None
    channel_names: list[str]
    marker_names: list[str] | None
    row: Callable[[int], str]  # "line 12" (CSV) / "row 11" (NPZ) of frame i
    notes: list[str] = field(default_factory=list)  # what the reader left out, for the log
    truth: GroundTruth | None = None  # contact labels (see ground_truth), None: not given


@dataclass
class GroundTruth:
    """Per-frame contact labels of a file on the fingers axis, checked (n frames, K fingers);
    each None where not given.

    ``contact`` (n, K) bool; ``position_mm`` (n, K, 2) float64 (u, v) of the point under each
    finger, NaN without the finger; ``height_mm`` (n, K) float64, 0 in contact, NaN without the
    finger; ``force_n`` (n, K) float64 ≥ 0; ``surface`` (n, K) str ("" = not given).
    """

    contact: np.ndarray | None
    position_mm: np.ndarray | None
    height_mm: np.ndarray | None
    force_n: np.ndarray | None
    surface: np.ndarray | None

    @property
    def n_fingers(self) -> int:
        given = (self.contact, self.position_mm, self.height_mm, self.force_n, self.surface)
        return next(a.shape[1] for a in given if a is not None)


def ground_truth(
    src: str,
    n: int,
    row: Callable[[int], str],
    name: Callable[[str, int], str],
    *,
    contact: np.ndarray | None,
    position_mm: np.ndarray | None,
    force_n: np.ndarray | None,
    height_mm: np.ndarray | None,
    surface: np.ndarray | None,
) -> GroundTruth | None:
    """Check the contact labels of a file and complete them (``docs/import-format.md``).

    Inputs are on the fingers axis, all of the same K fingers: float64 arrays (NaN = empty) of
    n rows, (n, K) and ``position_mm`` (n, K, 2), ``surface`` (n, K) text; ``name(key, k)`` is
    how the format calls finger k's field in messages ("field 'contact' (finger 1)", "column
    'f1:contact'"). Rules, per finger: contact is 0 or 1; a position row is two finite numbers
    or empty; a contact frame has a position (when positions are given); without a ``contact``
    field a frame with a position is a contact frame; force finite and ≥ 0, and 0 without
    contact; height ≥ 0, 0 (or empty) in contact, and given exactly where a position is outside
    contact (without a height field the height is 0 in contact, and a position outside contact
    is an error: its height is unknown). Every refusal names the file, the row, the field, what
    was expected and found.
    """
    given = {"contact": contact, "position_mm": position_mm, "force_n": force_n}
    given.update(height_mm=height_mm, surface=surface)
    present = [v for v in given.values() if v is not None]
    if not present:
        return None
    K = present[0].shape[1]
    fingers = [
        _finger_truth(src, n, row, lambda key, k=k: name(key, k), **{
            key: None if v is None else v[:, k] for key, v in given.items()
        })
        for k in range(K)
    ]
    out = {}
    for key in ("contact", "position_mm", "height_mm", "force_n", "surface"):
        cols = [f[key] for f in fingers]
        out[key] = None if cols[0] is None else np.stack(cols, axis=1)
    return GroundTruth(**out)


def _finger_truth(
    src: str,
    n: int,
    row: Callable[[int], str],
    name: Callable[[str], str],
    *,
    contact: np.ndarray | None,
    position_mm: np.ndarray | None,
    force_n: np.ndarray | None,
    height_mm: np.ndarray | None,
    surface: np.ndarray | None,
) -> dict[str, np.ndarray | None]:
    """:func:`ground_truth` of one finger: (n,) arrays, ``position_mm`` (n, 2)."""

    def fail(i: int, key: str, expected: str, found: Any) -> EctskinError:
        return EctskinError(f"{src}: {row(i)}, {name(key)}: expected {expected}, found {found}")

    if position_mm is not None:
        nan = np.isnan(position_mm)
        bad = np.isinf(position_mm).any(axis=1) | (nan[:, 0] != nan[:, 1])
        if bad.any():
            i = int(np.argmax(bad))
            raise fail(i, "position_mm", "two finite numbers (mm) or none", position_mm[i].tolist())
        check_magnitude(
            position_mm, src, "position", lambda k: f"{row(k[0])}, {name('position_mm')}"
        )
        has_pos = ~nan[:, 0]
    if contact is not None:
        bad = ~np.isin(contact, (0.0, 1.0))
        if bad.any():
            i = int(np.argmax(bad))
            raise fail(i, "contact", "0 or 1", contact[i])
        touching = contact == 1.0
        if position_mm is not None and np.any(touching & ~has_pos):
            i = int(np.argmax(touching & ~has_pos))
            raise fail(i, "position_mm", "a position where contact is 1", "none")
    elif position_mm is not None:
        touching = has_pos  # documented: a position without a contact field means contact
    else:
        touching = None
    if force_n is not None:
        bad = ~np.isfinite(force_n) | (force_n < 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise fail(i, "force_n", "a finite force >= 0 N", force_n[i])
        check_magnitude(force_n, src, "force", lambda k: f"{row(k[0])}, {name('force_n')}")
        if touching is not None and np.any(~touching & (force_n != 0)):
            i = int(np.argmax(~touching & (force_n != 0)))
            raise fail(i, "force_n", "0 N in a frame without contact", force_n[i])
    height = None
    if height_mm is not None:
        height = height_mm.copy()
        bad = np.isinf(height) | (height < 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise fail(i, "height_mm", "a height >= 0 mm or none", height[i])
        if touching is not None:
            bad = touching & ~np.isnan(height) & (height != 0)
            if bad.any():
                i = int(np.argmax(bad))
                raise fail(i, "height_mm", "0 (or none) in a contact frame", height[i])
            height[touching] = 0.0
        if position_mm is not None:
            bad = has_pos != ~np.isnan(height)
            if bad.any():
                i = int(np.argmax(bad))
                found = f"position {position_mm[i].tolist()}, height {height[i]}"
                raise fail(
                    i, "height_mm", "a height wherever a position is given, else none", found
                )
    elif touching is not None and position_mm is not None:
        above = has_pos & ~touching
        if above.any():
            i = int(np.argmax(above))
            raise fail(
                i,
                "position_mm",
                "no position outside contact without a height_mm field (the height is unknown)",
                position_mm[i].tolist(),
            )
        height = np.where(touching, 0.0, np.nan)
    if surface is not None:
        bad = ~np.isin(surface, ("", *SURFACE_NAMES))
        if bad.any():
            i = int(np.argmax(bad))
            raise fail(i, "surface", f"one of {', '.join(SURFACE_NAMES)}", repr(str(surface[i])))
    return {
        "contact": None if touching is None else touching.astype(bool),
        "position_mm": position_mm,
        "height_mm": height,
        "force_n": force_n,
        "surface": surface,
    }


def file_rate(value: Any, where: str) -> float | None:
    """The frame rate a file states (an NPZ field, a ``# frame_rate_hz`` line), checked by
    :func:`~ectskin.io.frame_rate.stated_rate`; None where it states none."""
    return None if value is None else stated_rate(value, where)


def check_magnitude(
    values: np.ndarray, src: str, what: str, where: Callable[[tuple[int, ...]], str]
) -> None:
    """Refuse a number beyond :data:`~ectskin.io.text.MAX_ABS_VALUE` (NaN passes), naming it."""
    with np.errstate(invalid="ignore"):
        big = np.abs(values) > MAX_ABS_VALUE
    if big.any():
        k = tuple(int(v) for v in np.argwhere(big)[0])
        raise EctskinError(
            f"{src}: {where(k)}: {what} {float(values[k]):g} is beyond ±{MAX_ABS_VALUE:g}, where the "
            "calibration and training overflow; a placeholder for a missing value? Leave the "
            "cell empty (NaN: masked) instead"
        )


def check_group_text(group: np.ndarray, src: str, row: Callable[[int], str]) -> None:
    """Group ids given as text: none empty (or blank), none with a NUL byte (HDF5 cannot store
    it in a trial name)."""
    if group.dtype.kind != "U" or group.size == 0:
        return
    blank = np.char.str_len(np.char.strip(group)) == 0
    if blank.any():
        i = int(np.argmax(blank))
        raise EctskinError(f"{src}: group id at {row(i)} is empty, expected a group id")
    # (in Python: NumPy's own string functions drop the NUL of a search string)
    nul = next((i for i, g in enumerate(group.tolist()) if "\x00" in g), None)
    if nul is not None:
        i = nul
        raise EctskinError(
            f"{src}: group id at {row(i)} contains a NUL byte ({str(group[i])!r}); group ids "
            "become trial names, which cannot hold one"
        )


def group_ids(
    g: np.ndarray, n: int, src: str, row: Callable[[int], str], *, text_ints: bool = False
) -> np.ndarray:
    """The group id of each of the ``n`` frames, checked: int64, or text (``str``).

    Integers, and floats that hold integers (up to 2**53), become int64; ASCII bytes and text
    stay text, none of them empty or with a NUL byte (:func:`check_group_text`), unless
    ``text_ints`` (CSV, where every cell is text) and every id reads as an integer. Errors name
    the file and the field ``'group'``.
    """
    if g.shape != (n,):
        raise EctskinError(
            f"{src}: field 'group' must have shape ({n},) (one group id per frame), got {g.shape}"
        )
    if g.dtype.kind in "iu":
        if g.dtype.kind == "u" and g.size and g.max() > np.iinfo(np.int64).max:
            i = int(np.argmax(g > np.iinfo(np.int64).max))
            raise EctskinError(f"{src}: field 'group' row {i} is {g[i]}, beyond the int64 ids")
        return g.astype(np.int64)
    if g.dtype.kind == "f":
        # beyond 2**53 a float no longer holds every integer: two ids could become one
        bad = ~np.isfinite(g) | (g != np.round(g)) | (np.abs(g) > 2.0**53)
        if bad.any():
            i = int(np.argmax(bad))
            raise EctskinError(f"{src}: field 'group' row {i} is {g[i]}, expected an integer id")
        return g.astype(np.int64)
    if g.dtype.kind == "S":  # bytes: ASCII text
        try:
            g = np.char.decode(g, "ascii")
        except UnicodeDecodeError:
            raise EctskinError(
                f"{src}: field 'group' holds bytes that are not ASCII text; store the group ids "
                "as integers or as a unicode string array (np.asarray(ids, dtype=str))"
            ) from None
    if g.dtype.kind == "U":
        check_group_text(g, src, row)
        if text_ints:
            try:
                return np.asarray([int(v) for v in g.tolist()], dtype=np.int64)
            except (ValueError, OverflowError):
                pass
        return g.astype(str)
    raise EctskinError(f"{src}: field 'group' must hold integers or strings, found dtype {g.dtype}")


def class_labels(
    lab: np.ndarray, n: int, src: str, name: str, row: Callable[[int], str]
) -> np.ndarray:
    if lab.shape != (n,):
        raise EctskinError(
            f"{src}: field {name!r} must have shape ({n},) (a class per frame) or ({n}, "
            f"n_markers, 3) (coordinates), got {lab.shape}"
        )
    bad = ~np.isfinite(lab) | (lab != np.round(lab)) | (lab < 0) | (lab > MAX_CLASS)
    if bad.any():
        i = int(np.argmax(bad))
        raise EctskinError(
            f"{src}: {name} at {row(i)} is {lab[i]}; expected a class 0..{MAX_CLASS} (0 = no touch)"
        )
    return lab.astype(np.int64)
