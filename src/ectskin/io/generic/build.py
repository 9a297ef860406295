"""Build the :class:`Recording` of a generic file from its parsed fields: the layout (given or
virtual), one trial per group, references, timestamps and the frame rate.

A channel without a usable readout (0 in every frame: not connected; or empty in every frame) is
left out: its readouts are stored as NaN and its pair is listed in ``rec.meta["unmeasured_pairs"]``
(which every data set leaves out), with a warning and a note in ``rec.meta["import_notes"]``.
Kept, it would pass the import and fail training (Eq. 2 divides by a reference of 0)."""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.calibration import DIFFERENCE, REFERENCE_RTOL
from ectskin.io.frame_rate import frame_rate, stated_rate
from ectskin.io.generic.fields import Fields
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout

log = logging.getLogger(__name__)

#: the ``readouts`` option of the import: absolute readouts (Eq. 2 divides by a reference) or
#: differences (difference imaging; Eq. 2 is then the identity)
READOUTS = ("absolute", DIFFERENCE)


def virtual_layout(
    n_channels: int, n_regions: int = 0, n_markers: int = 0, marker_names: list[str] | None = None
) -> SensorLayout:
    """A layout of virtual electrodes whose pairs can carry ``n_channels`` channels.

    n electrodes with n the smallest integer ≥ 2 such that n(n−1)/2 ≥ n_channels: vertical wires
    15 mm long, 1 mm wide, 10 mm apart on one virtual skin (surface "front"), pads 2 × 2 mm below
    them; ``n_regions`` strip regions 1..n_regions; ``n_markers`` markers on the right face.
    """
    if n_channels < 1:
        raise EctskinError(f"virtual layout: need at least one channel, got {n_channels}")
    n = 2
    while n * (n - 1) // 2 < n_channels:
        n += 1
    width_mm = 10.0 * n
    names = marker_names or [f"M{j + 1}" for j in range(n_markers)]
    d = {
        "schema": "ectskin.layout",
        "version": 1,
        "name": f"generic-{n}-virtual-electrodes",
        "skins": [
            {"name": "virtual", "surface": "front", "u_mm": [0.0, width_mm], "v_mm": [0.0, 30.0]}
        ],
        "electrodes": [
            {
                "name": f"V{k + 1}",
                "skin": "virtual",
                "polyline_mm": [[10.0 * k + 5.0, 10.0], [10.0 * k + 5.0, 25.0]],
                "width_mm": 1.0,
                "pad": {"centre_mm": [10.0 * k + 5.0, 5.0], "size_mm": [2.0, 2.0]},
            }
            for k in range(n)
        ],
        "regions": [
            {
                "id": r + 1,
                "surface": "front",
                "u_mm": [0.0, width_mm],
                "v_mm": [30.0 * r / n_regions, 30.0 * (r + 1) / n_regions],
            }
            for r in range(n_regions)
        ],
        "markers": [
            {"name": str(names[j]), "surface": "right", "uv_mm": [0.0, 10.0 * j]}
            for j in range(n_markers)
        ],
    }
    return SensorLayout.from_dict(d, source="virtual layout")


def _labels_from_contact(truth: Any, n: int) -> np.ndarray:
    """Touch classes of a file with contact labels alone: 1 where a finger is on the skin."""
    if truth.contact is not None:
        on = truth.contact.any(axis=1)
    elif truth.position_mm is not None:
        on = np.isfinite(truth.position_mm).all(axis=2).any(axis=1)
    else:
        on = np.zeros(n, dtype=bool)
    return on.astype(np.int64)


def is_virtual_layout(rec: Recording) -> bool:
    """Whether ``rec`` lies on a virtual layout of the generic import (:func:`virtual_layout`):
    its ``meta["virtual_layout"]`` (set by the import), or, for files imported before that was
    stored, the virtual layout's name (``generic-<n>-virtual-electrodes``). Its regions are then
    strips over the whole face, one per touch class, not touch regions of a skin."""
    if "virtual_layout" in rec.meta:
        return bool(rec.meta["virtual_layout"])
    return re.fullmatch(r"generic-\d+-virtual-electrodes", rec.layout.name) is not None


def build_recording(
    f: Fields,
    layout: SensorLayout | None,
    frame_rate_hz: float | None,
    fmt: str,
    readouts: str = "absolute",
) -> Recording:
    """One trial per group (in order of first appearance) on ``layout`` (None: virtual);
    ``readouts`` "difference": the readouts are differences (see ``load_generic``)."""
    n, m = f.readouts.shape
    if f.labels is None and f.markers is None and f.truth is not None:
        f.labels = _labels_from_contact(f.truth, n)
    if f.labels is None and f.markers is None:
        raise EctskinError(
            f"{f.source}: no labels: give touch classes ('labels' / column 'label'), marker "
            f"coordinates ('markers' / columns 'm:<marker>.x|.y|.z') and/or contact labels"
        )
    if readouts == "difference" and f.reference is not None:
        raise EctskinError(
            f"{f.source}: field 'reference' with readouts='difference': the readouts are "
            "already differences, Eq. 2 has no reference to divide by; expected no reference"
        )
    virtual = layout is None
    layout = _layout(f, layout)
    dead = _dead_channels(f)
    groups = _Groups(f.group)
    ref_by_key, per_frame_ref = _references(f, groups)
    _check_timestamps(f, groups)
    rate = _frame_rate(f, frame_rate_hz, groups)
    trials = [
        _trial(f, groups, k, layout.n_pairs, rate, ref_by_key, per_frame_ref, dead)
        for k in groups.order
    ]
    rec_meta: dict[str, Any] = {
        "source": "generic",
        "format": fmt,
        "file": f.source,
        # the names of the measured channels (datasets.channel_names: one per measured channel)
        "channel_names": [c for j, c in enumerate(f.channel_names) if j not in dead],
        "virtual_layout": virtual,
    }
    if f.marker_names is not None:
        rec_meta["marker_names"] = list(f.marker_names)
    unmeasured = sorted(set(dead) | set(range(m, layout.n_pairs)))
    if unmeasured:
        rec_meta["unmeasured_pairs"] = unmeasured
    notes = list(f.notes)
    for j, why in dead.items():
        note = (
            f"{f.source}: channel {f.channel_names[j]!r} {why}: left out (stored as NaN, pair "
            f"{j} listed in unmeasured_pairs)"
        )
        log.warning("%s", note)
        notes.append(note)
    if dead:
        rec_meta["dropped_channels"] = [f.channel_names[j] for j in dead]
    if notes:
        rec_meta["import_notes"] = notes
    if per_frame_ref is not None:
        rec_meta["readout_unit"] = "ratio to the per-frame reference"
    if readouts == "difference":
        rec_meta["readouts"] = DIFFERENCE
    rec = Recording(layout=layout, trials=trials, frame_rate_hz=rate, meta=rec_meta)
    log.info(
        "%s: %d frames, %d channels, %d trials, %d markers, classes up to %d",
        f.source,
        n,
        m,
        rec.n_trials,
        0 if f.markers is None else f.markers.shape[1],
        0 if f.labels is None else int(f.labels.max()),
    )
    return rec


def _dead_channels(f: Fields) -> dict[int, str]:
    """Channels without a usable readout, by index: why (0 in every frame, or none at all)."""
    finite = np.isfinite(f.readouts)
    none = ~finite.any(axis=0)
    zero = ~none & np.all(~finite | (f.readouts == 0), axis=0)
    dead = {
        int(j): "has no readout in any frame (every cell empty or NaN)"
        for j in np.flatnonzero(none)
    }
    dead.update({int(j): "reads 0 in every frame (not connected?)" for j in np.flatnonzero(zero)})
    dead = dict(sorted(dead.items()))
    if len(dead) == f.readouts.shape[1]:
        raise EctskinError(
            f"{f.source}: no channel has a usable readout (each reads 0 or nothing in every frame)"
        )
    return dead


def _layout(f: Fields, layout: SensorLayout | None) -> SensorLayout:
    """``layout`` checked against the file, or a virtual layout built from it."""
    src, m = f.source, f.readouts.shape[1]
    n_markers = 0 if f.markers is None else f.markers.shape[1]
    n_classes_max = 0 if f.labels is None else int(f.labels.max())
    if layout is None:
        layout = virtual_layout(m, n_classes_max, n_markers, f.marker_names)
        if layout.n_pairs != m:
            log.info(
                "%s: %d channels is not n(n-1)/2: virtual layout of %d electrodes (%d pairs), "
                "pairs %d..%d unmeasured",
                src,
                m,
                layout.n_electrodes,
                layout.n_pairs,
                m,
                layout.n_pairs - 1,
            )
        return layout
    if m != layout.n_pairs:
        raise EctskinError(
            f"{src}: {m} readout channels, but layout {layout.name!r} has "
            f"{layout.n_electrodes} electrodes = {layout.n_pairs} pairs"
        )
    if f.markers is not None and n_markers != layout.n_markers:
        raise EctskinError(
            f"{src}: {n_markers} markers, but layout {layout.name!r} has {layout.n_markers}"
        )
    if n_classes_max > layout.n_regions:
        i = int(np.argmax(f.labels > layout.n_regions))
        raise EctskinError(
            f"{src}: label at {f.row(i)} is {f.labels[i]}, layout {layout.name!r} has "
            f"classes 0..{layout.n_regions}"
        )
    return layout


class _Groups:
    """The frames' groups: sorted keys, and per key its first row and its rows in file order."""

    def __init__(self, group: np.ndarray):
        keys, first, inverse = np.unique(group, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        self.keys = keys
        self.first = first
        self.order = np.argsort(first, kind="stable")  # key indices by first appearance
        # rows of each key, in file order (one sort instead of a scan per group)
        counts = np.bincount(inverse, minlength=keys.size)
        self.members = np.split(np.argsort(inverse, kind="stable"), np.cumsum(counts)[:-1])

    @property
    def size(self) -> int:
        return self.keys.size


def _references(f: Fields, groups: _Groups) -> tuple[dict[int, np.ndarray], np.ndarray | None]:
    """Per-trial references by key index, or the per-frame reference when one changes within a
    trial (the readouts are then stored as ratios to it)."""
    ref, n = f.reference, f.readouts.shape[0]
    if ref is None:
        return {}, None
    keys, first, members = groups.keys, groups.first, groups.members
    if ref.ndim == 1:
        _check_reference(ref[None, :], f, lambda i: "field 'reference'")
        return {k: ref for k in range(keys.size)}, None
    if ref.shape[0] == n:
        _check_reference(ref, f, lambda i: f"reference at {f.row(i)}")
        const = np.ones(keys.size, dtype=bool)
        for k in range(keys.size):
            rows = ref[members[k]]
            const[k] = bool(np.all(rows == rows[0]))
        if const.all():
            return {k: ref[int(first[k])] for k in range(keys.size)}, None
        log.info(
            "%s: the reference changes within a trial: readouts are stored as ratios "
            "c_t / c_0 (reference 1)",
            f.source,
        )
        return {}, ref
    if ref.shape[0] == keys.size:
        _check_reference(ref, f, lambda i: f"reference of group {keys[i].item()!r}")
        return {k: ref[k] for k in range(keys.size)}, None
    raise EctskinError(
        f"{f.source}: reference has {ref.shape[0]} rows; expected {keys.size} (one per group, "
        f"in sorted group order) or {n} (one per frame)"
    )


def _check_reference(ref: np.ndarray, f: Fields, where: Callable[[int], str]) -> None:
    """Refuse a reference (rows × m) with a non-finite, zero or tiny value (Eq. 2 divides by it),
    naming the row (``where``) and the channel; "tiny" as in
    :data:`ectskin.io.calibration.REFERENCE_RTOL`."""
    scale = np.max(np.abs(np.where(np.isfinite(ref), ref, 0.0)), axis=1)
    bad = ~np.isfinite(ref) | (np.abs(ref) <= REFERENCE_RTOL * scale[:, None])
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad)[0])
        raise EctskinError(
            f"{f.source}: {where(i)}, channel {f.channel_names[j]!r} is {ref[i, j]}; Eq. 2 "
            f"divides by the reference, expected a finite, non-zero readout"
        )


def _check_timestamps(f: Fields, groups: _Groups) -> None:
    """Timestamps finite and increasing inside every group."""
    if f.timestamps is None:
        return
    src = f.source
    if not np.all(np.isfinite(f.timestamps)):
        i = int(np.argmax(~np.isfinite(f.timestamps)))
        raise EctskinError(f"{src}: timestamp at {f.row(i)} is {f.timestamps[i]}")
    for k in groups.order:
        idx = groups.members[k]
        t = f.timestamps[idx]
        step = np.diff(t)
        if np.any(step <= 0):
            b = int(np.argmax(step <= 0))
            raise EctskinError(
                f"{src}: group {groups.keys[k].item()!r}: timestamps must increase within a "
                f"group; {f.row(int(idx[b + 1]))} has {t[b + 1]} s after {t[b]} s at "
                f"{f.row(int(idx[b]))}"
            )


def _frame_rate(f: Fields, frame_rate_hz: float | None, groups: _Groups) -> float:
    """The caller's rate, else the file's, else 1 / the median timestamp step within groups
    (:func:`~ectskin.io.frame_rate.frame_rate`)."""
    src = f.source
    stated = frame_rate_hz if frame_rate_hz is not None else f.frame_rate_hz
    if stated is not None:
        stated = stated_rate(stated, f"{src}: frame_rate_hz")
    elif f.timestamps is None:
        raise EctskinError(
            f"{src}: no timestamps and no frame rate: give timestamps ('timestamps' / column "
            f"'time_s'), a frame_rate_hz field, or the rate (frame_rate_hz=...; --frame-rate on "
            f"the command line)"
        )
    steps = (
        np.concatenate([np.diff(f.timestamps[idx]) for idx in groups.members])
        if f.timestamps is not None
        else np.empty(0)
    )
    return frame_rate(
        stated,
        steps,
        src,
        no_rate=(
            "cannot infer the frame rate from the timestamps (no group has two increasing "
            "timestamps); give the rate (frame_rate_hz=...; --frame-rate on the command line)"
        ),
        what="timestamp steps within groups",
    )


def _trial(
    f: Fields,
    groups: _Groups,
    k: int,
    n_pairs: int,
    frame_rate_hz: float,
    ref_by_key: dict[int, np.ndarray],
    per_frame_ref: np.ndarray | None,
    dead: dict[int, str],
) -> Trial:
    """The trial of group ``k`` (key index): readouts padded to ``n_pairs`` with NaN."""
    m = f.readouts.shape[1]
    idx = groups.members[k]
    key = groups.keys[k].item()
    name = f"group_{key}" if isinstance(key, int) else str(key)
    meta: dict[str, Any] = {"group": key}
    cap = np.full((idx.size, n_pairs), np.nan)
    values = f.readouts[idx]
    if per_frame_ref is not None:
        values = values / per_frame_ref[idx]  # Eq. 2 then reads (c_t/c_0 − 1) / 1
        meta["reference"] = [1.0] * m + [None] * (n_pairs - m)
        meta["reference_kind"] = "per_frame_ratio"
    elif ref_by_key:
        meta["reference"] = [float(v) for v in ref_by_key[int(k)]] + [None] * (n_pairs - m)
        meta["reference_kind"] = "per_trial"
    cap[:, :m] = values
    cap[:, list(dead)] = np.nan  # left out: see _dead_channels
    if f.timestamps is not None:
        t = f.timestamps[idx]
        meta["t0_s"] = float(t[0])
        ts = t - t[0]
    else:
        ts = np.arange(idx.size) / frame_rate_hz
    if f.labels is not None:
        lab = f.labels[idx]
        nz = lab[lab > 0]
        region = int(np.bincount(nz).argmax()) if nz.size else 0
        meta["kind"] = "touch" if nz.size else "no_contact"
    else:
        lab = np.zeros(idx.size, dtype=np.int64)
        region = 0
        meta["kind"] = "tracking"
    return Trial(
        name=name,
        capacitance=cap,
        timestamps=ts,
        labels=lab,
        region=region,
        markers=None if f.markers is None else f.markers[idx],
        meta=meta,
        **_truth(f, groups, k, idx),
    )


def _truth(f: Fields, groups: _Groups, k: int, idx: np.ndarray) -> dict[str, Any]:
    """The Trial's finger fields of group ``k`` (rows ``idx``) from the file's contact labels,
    on the fingers axis: contact, finger_uv_mm, finger_height_mm, force, and finger_surface (per
    finger the one face of the group; a group naming two faces for a finger is an error naming
    the group and the row)."""
    gt = f.truth
    if gt is None:
        return {}
    out: dict[str, Any] = {
        "contact": None if gt.contact is None else gt.contact[idx],
        "finger_uv_mm": None if gt.position_mm is None else gt.position_mm[idx],
        "finger_height_mm": None if gt.height_mm is None else gt.height_mm[idx],
        "force": None if gt.force_n is None else gt.force_n[idx],
        "finger_surface": (None,) * gt.n_fingers,
    }
    if gt.surface is not None:
        out["finger_surface"] = tuple(
            _one_face(f, groups, k, idx, gt.surface[:, j], gt.n_fingers > 1 and j)
            for j in range(gt.n_fingers)
        )
    return out


def _one_face(
    f: Fields, groups: _Groups, k: int, idx: np.ndarray, surface: np.ndarray, finger: Any
) -> str | None:
    """The one face a group names for a finger (``finger``: its index in messages, or False
    for a file of one finger), None where it names none."""
    faces = surface[idx]
    named = faces[faces != ""]
    if named.size and np.any(named != named[0]):
        j = int(idx[np.argmax((faces != "") & (faces != named[0]))])
        which = "" if finger is False else f" of finger {finger}"
        raise EctskinError(
            f"{f.source}: group {groups.keys[k].item()!r}: surface{which} must be one face per "
            f"group, expected {str(named[0])!r} (as in its first rows), found "
            f"{str(surface[j])!r} at {f.row(j)}"
        )
    return str(named[0]) if named.size else None
