"""What the generic readers hand to the builder: the parsed fields of one file, format
independent, and the checks both formats share."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ectskin._check import EctskinError
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
)
CSV_COLUMNS = "group, time_s, label, c:<channel>, ref:<channel>, m:<marker>.x|.y|.z"
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
