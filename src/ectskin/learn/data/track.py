"""Deformation-tracking samples from a recording: :func:`track_dataset` → :class:`TrackData`.

One sample per frame of every tracking trial: the window of the last ``k`` calibrated frames
(oldest first) ending at that frame, the marker coordinates of the trajectory's first frame
(``init``) and of the window's last frame (``y``). With ``prior=True`` (the paper, §4.2) each
trajectory is calibrated against its own first frame; ``prior=False`` is the ablation: absolute
calibration against the touch reference, ``init`` = 0.

Channels a recording does not measure are left out, as for touch (:mod:`ectskin.learn.data.touch`):
``pair_names`` and ``pairs`` list the measured channels only.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ectskin._check import EctskinError
from ectskin.io.calibration import calibrate, is_difference, is_no_contact, touch_reference
from ectskin.io.recording import Recording, Trial
from ectskin.learn.channels import channel_names, check_regions, measured_channels
from ectskin.learn.data.base import NONFINITE_OPTIONS, SampleData, finite_rows, select_trials

log = logging.getLogger(__name__)

__all__ = ["TrackData", "track_dataset", "tracking_trials"]


@dataclass
class TrackData(SampleData):
    """Deformation-tracking samples, one per frame (the window ends at that frame).

    Attributes
    ----------
    x : (n, k, n_pairs) float32
        Calibrated readouts of the window's k frames, oldest first.
    init : (n, n_markers, 3) float32
        Marker coordinates of the trajectory's first frame, mm (zeros when ``prior`` is False).
    y : (n, n_markers, 3) float32
        Marker coordinates at the window's last frame, mm.
    group : (n,) int64
        Index into ``group_names`` of the sample's trial.
    frame : (n,) int64
        Index of the window's last frame inside its trial.
    group_names : list of str
        Trial names.
    electrode_desc : (n_electrodes, d) float32
        ``layout.electrode_descriptors()`` (P / Q embeddings of the C2DT).
    pairs : (n_pairs, 2) int64
        Electrode indices of each channel (measured pairs only).
    prior : bool
        True: per-trajectory reference and init coordinates (paper); False: ablation.
    pair_names : list of str
        Channel names, length n_pairs.
    group_region : (n_groups,) int64
        Each trial's touched region.
    """

    SAMPLE_FIELDS: ClassVar[tuple[str, ...]] = ("x", "init", "y", "group", "frame")
    MATCH_FIELDS: ClassVar[tuple[str, ...]] = ("pair_names", "prior")

    x: np.ndarray
    init: np.ndarray
    y: np.ndarray
    group: np.ndarray
    frame: np.ndarray
    group_names: list[str]
    electrode_desc: np.ndarray
    pairs: np.ndarray
    prior: bool
    pair_names: list[str] = field(default_factory=list)
    group_region: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def window(self) -> int:
        return int(self.x.shape[1])

    @property
    def n_pairs(self) -> int:
        return int(self.x.shape[2])

    @property
    def n_markers(self) -> int:
        return int(self.y.shape[1])


def tracking_trials(rec: Recording, trials: Any = None) -> list[Trial]:
    """The trials usable for deformation tracking (paper §3: touch trials without occlusion).

    Skips, with a logged count per reason: empty trials, trials without markers, no-contact
    trials, and trials whose markers have any NaN (occlusion).
    """
    chosen = select_trials(rec, trials)
    check_regions(rec, chosen)
    out, empty, no_markers, no_contact, occluded = [], [], [], [], []
    for t in chosen:
        if t.n_frames == 0:
            empty.append(t.name)
        elif t.markers is None or t.n_markers == 0:
            no_markers.append(t.name)
        elif is_no_contact(t):
            no_contact.append(t.name)
        elif t.has_occlusion:
            occluded.append(t.name)
        else:
            out.append(t)
    for what, names in (
        ("without frames", empty),
        ("without markers", no_markers),
        ("without contact", no_contact),
        ("with occluded markers (NaN)", occluded),
    ):
        if names:
            log.info("tracking: skipped %d trial(s) %s", len(names), what)
            log.debug("tracking: skipped %s: %s", what, ", ".join(names))
    log.info("tracking: %d of %d trial(s) used", len(out), len(chosen))
    return out


def _windows(c: np.ndarray, k: int, pad: bool) -> tuple[np.ndarray, np.ndarray]:
    """Sliding windows of the last ``k`` frames, oldest first.

    c : (n, P) → windows (m, k, P) (a strided view) and the index of each window's last frame (m,).
    With ``pad`` the first k−1 frames are preceded by copies of frame 0 (m = n); otherwise windows
    start at frame k−1 (m = n − k + 1).
    """
    n = c.shape[0]
    if pad:
        c = np.concatenate([np.repeat(c[:1], k - 1, axis=0), c], axis=0)
        last = np.arange(n, dtype=np.int64)
    else:
        last = np.arange(k - 1, n, dtype=np.int64)
    # sliding_window_view over frames: (m, P, k) → (m, k, P)
    w = sliding_window_view(c, k, axis=0).transpose(0, 2, 1)
    return w, last


def track_dataset(
    rec: Recording,
    *,
    window: int = 10,
    prior: bool = True,
    trials: Sequence[str | int] | None = None,
    reference: str | np.ndarray = "auto",
    pad: bool = True,
    nonfinite: str = "raise",
) -> TrackData:
    """Calibrated windows and marker coordinates of the tracking trials, one sample per frame.

    Parameters
    ----------
    rec : Recording
    window : int
        k, frames per window (paper: 10, against the unknown camera/readout delay).
    prior : bool
        True (paper): each trajectory is calibrated against its own first frame and ``init`` holds
        the first frame's marker coordinates. False (ablation): absolute calibration against the
        touch reference (``reference``) and ``init`` = zeros.
    trials : sequence of names or indices, optional
        Candidate trials (default all); no-contact, marker-less and occluded ones are skipped and
        counted in the log (see :func:`tracking_trials`).
    reference : "auto" | "rest" | "meta" | array
        The touch reference, used only when ``prior`` is False.
    pad : bool
        True (default): the first k−1 frames of a trial get windows padded by repeating the first
        frame, so every frame is a sample (the paper's 900 samples per 30-s trial). False: those
        frames are dropped (n − k + 1 samples per trial).
    nonfinite : "raise" | "drop"
        A non-finite readout is an error naming trial/frame/channel, or every window containing it
        is dropped (with a logged count). The first frame of a trajectory must be finite when
        ``prior`` is True (it is the reference).

    Returns
    -------
    TrackData; ``group`` indexes the used trials in order.
    """
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise EctskinError(f"window must be an integer >= 1 (frames), got {window!r}")
    if nonfinite not in NONFINITE_OPTIONS:
        raise EctskinError(
            f"Invalid value for 'nonfinite': allowed values are 'raise', 'drop'; got {nonfinite!r}"
        )
    k = int(window)
    keep = measured_channels(rec)
    pair_names = channel_names(rec, keep)
    used = tracking_trials(rec, trials)
    if not used:
        raise EctskinError(
            "track_dataset: no usable tracking trial (need touch trials with markers and no "
            "occlusion)"
        )
    if prior and is_difference(rec):
        raise EctskinError(
            "track_dataset: prior knowledge calibrates each trajectory against its first frame "
            "by Eq. 2, a ratio, but the recording's readouts are differences (meta 'readouts': "
            "'difference'); train without it (--no-prior)"
        )
    refs = None if prior else touch_reference(rec, reference=reference, channels=keep)

    # per trial: calibrated frames and which windows are kept; then fill preallocated arrays
    per_trial = []
    dropped = short = 0
    for t in used:
        cap = t.capacitance[:, keep]
        src = f"trial {t.name!r}"
        if prior:
            if not np.all(np.isfinite(cap[0])):
                j = int(np.argmax(~np.isfinite(cap[0])))
                raise EctskinError(
                    f"{src}: frame 0, channel {j} ({pair_names[j]!r}) is {cap[0, j]}; the first "
                    f"frame is the trajectory's reference (prior) and must be finite"
                )
            ref = cap[0]  # prior knowledge: first frame = reference of Eq. 2
        else:
            ref = refs[t.name]
        c = calibrate(
            cap, ref, source=src, pair_names=pair_names, allow_nonfinite=nonfinite == "drop"
        )
        if not pad and c.shape[0] < k:
            short += 1
            continue
        ok = finite_rows(c)
        if ok.all():
            valid = None
        else:
            # a window is valid when all its k frames are finite
            okw, _ = _windows(ok[:, None], k, pad)
            valid = okw[:, :, 0].all(axis=1)
            dropped += int((~valid).sum())
        per_trial.append((t, c, valid))
    if short:
        log.warning("tracking: skipped %d trial(s) shorter than the window (%d frames)", short, k)
    if dropped:
        log.warning("tracking: dropped %d window(s) containing non-finite readouts", dropped)
    if not per_trial:
        raise EctskinError(f"track_dataset: every tracking trial is shorter than window={k}")

    counts = []
    for _, c, valid in per_trial:
        m = c.shape[0] if pad else c.shape[0] - k + 1
        counts.append(m if valid is None else int(valid.sum()))
    n_total = int(sum(counts))
    n_markers = per_trial[0][0].n_markers
    x = np.empty((n_total, k, keep.size), dtype=np.float32)
    init = np.zeros((n_total, n_markers, 3), dtype=np.float32)
    y = np.empty((n_total, n_markers, 3), dtype=np.float32)
    group = np.empty(n_total, dtype=np.int64)
    frame = np.empty(n_total, dtype=np.int64)
    pos = 0
    for g, ((t, c, valid), m) in enumerate(zip(per_trial, counts)):
        w, last = _windows(c, k, pad)
        if valid is not None:
            w, last = w[valid], last[valid]
        sl = slice(pos, pos + m)
        x[sl] = w
        y[sl] = t.markers[last]
        if prior:
            init[sl] = t.markers[0]
        group[sl] = g
        frame[sl] = last
        pos += m
    layout = rec.layout
    return TrackData(
        x=x,
        init=init,
        y=y,
        group=group,
        frame=frame,
        group_names=[t.name for t, _, _ in per_trial],
        electrode_desc=layout.electrode_descriptors().astype(np.float32),
        pairs=layout.pairs[keep].astype(np.int64),
        prior=bool(prior),
        pair_names=pair_names,
        group_region=np.array([t.region for t, _, _ in per_trial], dtype=np.int64),
    )
