"""Which channels and regions of a recording the learning tasks can use.

* :func:`measured_channels` / :func:`channel_names`: the channels that hold data (a generic import
  may leave pairs unmeasured, ``rec.meta["unmeasured_pairs"]``) and their names;
* :func:`check_regions`: every trial's region is one of the layout's (or 0, no touch).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial


def measured_channels(rec: Recording) -> np.ndarray:
    """(n_measured,) int64 indices of the channels that hold data (all but
    ``rec.meta["unmeasured_pairs"]``)."""
    unmeasured = rec.meta.get("unmeasured_pairs", [])
    try:
        drop = np.asarray(list(unmeasured), dtype=np.int64)
    except (TypeError, ValueError):
        raise EctskinError(
            f"recording meta 'unmeasured_pairs' must be a list of pair indices, got {unmeasured!r}"
        ) from None
    if drop.size and (drop.min() < 0 or drop.max() >= rec.n_pairs):
        raise EctskinError(
            f"recording meta 'unmeasured_pairs' must hold indices in 0..{rec.n_pairs - 1}, "
            f"got {drop.tolist()}"
        )
    keep = np.setdiff1d(np.arange(rec.n_pairs, dtype=np.int64), drop)
    if keep.size == 0:
        raise EctskinError("recording meta 'unmeasured_pairs' leaves no channel to learn from")
    return keep


def channel_names(rec: Recording, keep: np.ndarray | None = None) -> list[str]:
    """Names of the measured channels: ``rec.meta["channel_names"]`` when a generic import stored
    the file's own names (one per measured channel), else the layout's pair names."""
    keep = measured_channels(rec) if keep is None else keep
    names = rec.meta.get("channel_names")
    if isinstance(names, (list, tuple)) and len(names) == keep.size:
        return [str(v) for v in names]
    return [rec.layout.pair_names[j] for j in keep]


def check_regions(rec: Recording, trials: Sequence[Trial]) -> None:
    """Refuse a trial whose ``region`` is not a region of the recording's layout (0 = no touch,
    1..n_regions): it would stratify the split and label the data with a class the model does
    not have. The error names the trial."""
    n = rec.layout.n_regions
    for t in trials:
        if not 0 <= t.region <= n:
            raise EctskinError(
                f"trial {t.name!r}: region {t.region} is not a region of layout "
                f"{rec.layout.name!r} (1..{n}, or 0 for no touch)"
            )
