"""Read a generic ``.npz`` recording: named arrays, one row per frame (``docs/import-format.md``)."""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.generic.fields import (
    NPZ_FIELDS,
    Fields,
    GroundTruth,
    check_magnitude,
    class_labels,
    file_rate,
    ground_truth,
    group_ids,
)


def _row(i: int) -> str:
    return f"row {i}"


def read_npz(path: Path) -> Fields:
    """The fields of an ``.npz`` archive, each checked against the readouts' shape."""
    src = str(path)
    raw = _load(path, src)
    readouts = _readouts(raw["readouts"], src)
    n, m = readouts.shape
    group = raw["group"]
    if group is None:
        raise EctskinError(f"{src}: missing field 'group' (a group id per frame: the trials)")
    group = group_ids(group, n, src, _row)
    labels, markers = _labels_and_markers(raw["labels"], raw["markers"], n, src)
    reference = raw["reference"]
    if reference is not None:
        reference = _numeric(reference, src, "reference")
        if reference.ndim not in (1, 2) or reference.shape[-1] != m:
            raise EctskinError(
                f"{src}: field 'reference' must have shape ({m},), (n_groups, {m}) or ({n}, {m}), "
                f"got {reference.shape}"
            )
        check_magnitude(reference, src, "reference", lambda k: f"field 'reference' at {k}")
    timestamps = raw["timestamps"]
    if timestamps is not None:
        timestamps = _numeric(timestamps, src, "timestamps")
        if timestamps.shape != (n,):
            raise EctskinError(
                f"{src}: field 'timestamps' must have shape ({n},) (one per frame, s), got "
                f"{timestamps.shape}"
            )
        check_magnitude(timestamps, src, "time", lambda k: f"field 'timestamps' row {k[0]}")
    frame_rate = file_rate(raw["frame_rate_hz"], f"{src}: frame_rate_hz")
    channel_names = _names(raw["channel_names"], m, src, "channel_names") or [
        f"ch{j + 1}" for j in range(m)
    ]
    marker_names = None
    if markers is not None:
        marker_names = _names(raw["marker_names"], markers.shape[1], src, "marker_names")
    elif raw["marker_names"] is not None:
        raise EctskinError(f"{src}: field 'marker_names' is given but there are no markers")
    return Fields(
        src,
        readouts,
        group,
        labels,
        markers,
        reference,
        timestamps,
        frame_rate,
        channel_names,
        marker_names,
        _row,
        truth=_truth(raw, n, src),
    )


def _truth(raw: dict[str, np.ndarray | None], n: int, src: str) -> GroundTruth | None:
    """The contact labels (contact, position_mm, force_n, height_mm, surface), checked: each
    on the fingers axis (n, K[, 2]) or, one finger, without it (n[, 2]); all of the same K."""
    arrays: dict[str, np.ndarray | None] = {}
    fingers: dict[str, int] = {}
    for key, tail in (
        ("contact", ()),
        ("position_mm", (2,)),
        ("force_n", ()),
        ("height_mm", ()),
        ("surface", ()),
    ):
        a = raw[key]
        if a is None:
            arrays[key] = None
            continue
        if key == "surface":
            if a.dtype.kind == "S":
                a = np.char.decode(a, "ascii", errors="replace")
            if a.dtype.kind != "U":
                raise EctskinError(
                    f"{src}: field 'surface' must hold a face name per frame (text), got dtype "
                    f"{a.dtype}"
                )
            a = np.char.strip(a).astype(str)
        else:
            a = _numeric(a, src, key)
        if a.ndim == 1 + len(tail):
            a = a[:, None]  # one finger
        if a.ndim != 2 + len(tail) or a.shape[0] != n or a.shape[2:] != tail:
            one = ", ".join(map(str, (n, *tail))) + ("," if not tail else "")
            axis = ", ".join(map(str, (n, "n_fingers", *tail)))
            raise EctskinError(
                f"{src}: field {key!r} must have shape ({one}) (one per frame) or ({axis}) "
                f"(one per frame and finger), got {raw[key].shape}"
            )
        arrays[key] = a
        fingers[key] = a.shape[1]
    if len(set(fingers.values())) > 1:
        found = ", ".join(f"{k!r} {v}" for k, v in fingers.items())
        raise EctskinError(
            f"{src}: the contact fields disagree on the number of fingers ({found}); give every "
            "one for the same fingers"
        )
    several = max(fingers.values(), default=1) > 1

    def name(key: str, k: int) -> str:
        return f"field {key!r} (finger {k})" if several else f"field {key!r}"

    return ground_truth(src, n, _row, name, **arrays)


def _load(path: Path, src: str) -> dict[str, np.ndarray | None]:
    """Every field of :data:`NPZ_FIELDS` (None where absent); unknown fields are refused."""
    try:
        npz = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise EctskinError(f"{src}: not a readable .npz archive ({exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise EctskinError(f"{src}: holds a single array, expected an .npz archive of named fields")
    with npz:
        unknown = [k for k in npz.files if k not in NPZ_FIELDS]
        if unknown:
            raise EctskinError(
                f"{src}: unknown field(s) {unknown}; allowed fields are {', '.join(NPZ_FIELDS)}"
            )
        return {k: _field(npz, k, src) for k in NPZ_FIELDS}


def _field(npz: Any, name: str, src: str) -> np.ndarray | None:
    if name not in npz.files:
        return None
    try:
        return npz[name]
    except ValueError as exc:  # object arrays need pickle, which we never allow
        raise EctskinError(
            f"{src}: field {name!r} cannot be read without pickle ({exc}); store strings "
            f"as a fixed-width array, e.g. np.asarray(names, dtype=str)"
        ) from None
    except (OSError, zipfile.BadZipFile, EOFError) as exc:
        raise EctskinError(f"{src}: field {name!r} is corrupt ({exc})") from None


def _readouts(readouts: np.ndarray | None, src: str) -> np.ndarray:
    if readouts is None:
        raise EctskinError(f"{src}: missing field 'readouts' (frames × channels)")
    readouts = _numeric(readouts, src, "readouts")
    if readouts.ndim != 2 or readouts.shape[0] == 0 or readouts.shape[1] == 0:
        raise EctskinError(
            f"{src}: field 'readouts' must have shape (n_frames, n_channels) with both > 0, "
            f"got {readouts.shape}"
        )
    if np.isinf(readouts).any():
        i, j = (int(v) for v in np.argwhere(np.isinf(readouts))[0])
        raise EctskinError(f"{src}: field 'readouts' row {i}, channel {j} is {readouts[i, j]}")
    check_magnitude(
        readouts, src, "readout", lambda k: f"field 'readouts' row {k[0]}, channel {k[1]}"
    )
    return readouts


def _labels_and_markers(
    labels: np.ndarray | None, markers: np.ndarray | None, n: int, src: str
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Classes (n,) and marker coordinates (n, M, 3); 3-D ``labels`` are taken as markers."""
    if labels is not None and np.ndim(labels) == 3:
        if markers is not None:
            raise EctskinError(
                f"{src}: field 'labels' holds coordinates (3-D) and 'markers' is given too; "
                f"put classes in 'labels' (n_frames,) and coordinates in 'markers'"
            )
        markers, labels = labels, None
        marker_field = "labels"
    else:
        marker_field = "markers"
    if labels is not None:
        labels = class_labels(_numeric(labels, src, "labels"), n, src, "labels", _row)
    if markers is not None:
        markers = _numeric(markers, src, marker_field)
        if markers.ndim != 3 or markers.shape[0] != n or markers.shape[2] != 3:
            raise EctskinError(
                f"{src}: field {marker_field!r} must have shape ({n}, n_markers, 3) (mm), got "
                f"{markers.shape}"
            )
        if np.isinf(markers).any():
            i = int(np.argwhere(np.isinf(markers))[0][0])
            raise EctskinError(f"{src}: field {marker_field!r} row {i} holds inf")
        check_magnitude(
            markers, src, "marker coordinate", lambda k: f"field {marker_field!r} row {k[0]}"
        )
    return labels, markers


def _numeric(a: np.ndarray, src: str, name: str) -> np.ndarray:
    if a.dtype.kind not in "biuf":
        raise EctskinError(f"{src}: field {name!r} must be numeric, found dtype {a.dtype}")
    return a.astype(np.float64)


def _names(a: np.ndarray | None, count: int, src: str, name: str) -> list[str] | None:
    if a is None:
        return None
    if a.shape != (count,):
        raise EctskinError(f"{src}: field {name!r} must hold {count} names, got shape {a.shape}")
    names = [str(v) for v in a.tolist()]
    for k, v in enumerate(names):
        if not v.strip() or "\x00" in v:
            raise EctskinError(
                f"{src}: field {name!r} entry {k} is {v!r}; a name must be non-empty text "
                "without NUL bytes"
            )
    if len(set(names)) != len(names):
        raise EctskinError(f"{src}: field {name!r} has duplicate names")
    return names
