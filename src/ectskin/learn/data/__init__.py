"""Learning data from recordings, one module per task on one base class.

==================  ========================================================================
``data.base``       :class:`SampleData`: per-sample / per-group fields declared by each class,
                    ``n_samples``, ``n_groups``, ``select``, ``take``, ``concat``
``data.touch``      :func:`touch_dataset` → :class:`TouchData` (one calibrated frame per sample)
``data.track``      :func:`track_dataset` → :class:`TrackData` (a window and marker coordinates)
``data.contact``    :func:`contact_dataset` → :class:`ContactData` (a window and the fingers)
==================  ========================================================================

Trial splits: :mod:`ectskin.learn.splits`; normalisation: :mod:`ectskin.learn.normalizer`.
"""

from __future__ import annotations

from ectskin.learn.data.base import NONFINITE_OPTIONS, SampleData
from ectskin.learn.data.contact import (
    CONTACT_SPLIT,
    HOVER_MAX_MM,
    MAX_FINGERS,
    ContactData,
    contact_dataset,
)
from ectskin.learn.data.touch import TouchData, touch_dataset
from ectskin.learn.data.track import TrackData, track_dataset, tracking_trials

__all__ = [
    "CONTACT_SPLIT",
    "HOVER_MAX_MM",
    "MAX_FINGERS",
    "NONFINITE_OPTIONS",
    "ContactData",
    "SampleData",
    "TouchData",
    "TrackData",
    "contact_dataset",
    "touch_dataset",
    "track_dataset",
    "tracking_trials",
]
