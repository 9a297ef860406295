"""Touch-recognition samples from a recording: :func:`touch_dataset` → :class:`TouchData`.

One sample per frame: the frame's calibrated readouts (paper Eq. 2 against the rest state, see
:mod:`ectskin.io.calibration`) and its touch class (0 = no touch, 1..n_regions).

Channels a recording does not measure (``rec.meta["unmeasured_pairs"]``, set by the generic
importer, see ``docs/import-format.md``) are left out: ``pair_names`` lists the measured channels
only (the file's own channel names when the import stored them in ``rec.meta["channel_names"]``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.calibration import calibrate, touch_reference
from ectskin.io.recording import Recording
from ectskin.learn.channels import channel_names, check_regions, measured_channels
from ectskin.learn.data.base import NONFINITE_OPTIONS, SampleData, finite_rows, select_trials

log = logging.getLogger(__name__)

__all__ = ["TouchData", "touch_dataset"]


@dataclass
class TouchData(SampleData):
    """Touch-recognition samples, one per frame.

    Attributes
    ----------
    x : (n, n_pairs) float32
        Calibrated readouts (Eq. 2), dimensionless.
    y : (n,) int64
        Touch class, 0 = no touch, 1..n_regions.
    group : (n,) int64
        Index into ``group_names`` of the sample's trial (for trial-exclusive splits).
    group_names : list of str
        Trial names.
    n_classes : int
        1 + number of regions of the layout.
    pair_names : list of str
        Channel names (measured pairs), length n_pairs.
    group_region : (n_groups,) int64
        Each trial's touched region (0 = none): the ``stratify`` labels of
        :func:`~ectskin.learn.splits.split_groups`.
    """

    SAMPLE_FIELDS: ClassVar[tuple[str, ...]] = ("x", "y", "group")
    MATCH_FIELDS: ClassVar[tuple[str, ...]] = ("pair_names", "n_classes")

    x: np.ndarray
    y: np.ndarray
    group: np.ndarray
    group_names: list[str]
    n_classes: int
    pair_names: list[str]
    group_region: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def n_pairs(self) -> int:
        return int(self.x.shape[1])


def touch_dataset(
    rec: Recording,
    *,
    reference: str | np.ndarray = "auto",
    trials: Sequence[str | int] | None = None,
    nonfinite: str = "raise",
) -> TouchData:
    """Calibrated touch frames of a recording, one sample per frame.

    Parameters
    ----------
    rec : Recording
    reference : "auto" | "rest" | "meta" | (n_pairs,) array
        The reference state c_0 of Eq. 2 (see :func:`ectskin.io.calibration.touch_reference`);
        "auto" = the mean readout of the uninflated, untouched trial (or per-trial references of
        a generic import).
    trials : sequence of names or indices, optional
        Restrict to these trials (default: all, in recording order).
    nonfinite : "raise" | "drop"
        A frame with a non-finite readout (masked channel) is an error naming the trial, frame and
        channel ("raise"), or is left out with a logged count ("drop").

    Returns
    -------
    TouchData with ``group`` indexing the selected trials in order.
    """
    if nonfinite not in NONFINITE_OPTIONS:
        raise EctskinError(
            f"Invalid value for 'nonfinite': allowed values are 'raise', 'drop'; got {nonfinite!r}"
        )
    keep = measured_channels(rec)
    pair_names = channel_names(rec, keep)
    refs = touch_reference(rec, reference=reference, channels=keep)
    chosen = select_trials(rec, trials)
    if not chosen:
        raise EctskinError("touch_dataset: no trials selected")
    check_regions(rec, chosen)
    xs, ys, gs = [], [], []
    dropped = 0
    for g, t in enumerate(chosen):
        c = calibrate(
            t.capacitance[:, keep],
            refs[t.name],
            source=f"trial {t.name!r}",
            pair_names=pair_names,
            allow_nonfinite=nonfinite == "drop",
        )
        ok = finite_rows(c)
        if not ok.all():
            dropped += int((~ok).sum())
            c = c[ok]
        xs.append(c)
        ys.append(t.labels[ok].astype(np.int64))
        gs.append(np.full(c.shape[0], g, dtype=np.int64))
    if dropped:
        log.warning("touch_dataset: dropped %d frames with non-finite readouts", dropped)
    return TouchData(
        x=np.concatenate(xs, axis=0),
        y=np.concatenate(ys),
        group=np.concatenate(gs),
        group_names=[t.name for t in chosen],
        n_classes=rec.layout.n_classes,
        pair_names=pair_names,
        group_region=np.array([t.region for t in chosen], dtype=np.int64),
    )
