"""Trivial and classical baselines beside the models, one module per task ("a model is only as
good as its margin"); each is fit on the training split and scored on the test split.

====================  ======================================================================
``baselines.base``    :func:`subsample` of the training samples (every task's)
``baselines.touch``   majority, logistic regression, random forest, k-NN
``baselines.track``   no motion, mean pose, grouped-CV ridge regression
``baselines.contact`` region centre, k-NN, ridge (the contact model's columns)
====================  ======================================================================
"""

from __future__ import annotations

from ectskin.learn.baselines.base import subsample
from ectskin.learn.baselines.contact import (
    CONTACT_BASELINES,
    contact_baselines,
    contact_knn_baseline,
    contact_ridge_baseline,
    region_centre_baseline,
)
from ectskin.learn.baselines.touch import (
    TOUCH_BASELINES,
    TouchBaselineResult,
    majority_baseline,
    sklearn_touch_baseline,
    touch_baselines,
)
from ectskin.learn.baselines.track import (
    RIDGE_ALPHAS,
    TRACK_BASELINES,
    TrackBaselineResult,
    mean_pose_baseline,
    no_motion_baseline,
    track_baselines,
    track_ridge_baseline,
)

__all__ = [
    "CONTACT_BASELINES",
    "RIDGE_ALPHAS",
    "TOUCH_BASELINES",
    "TRACK_BASELINES",
    "TouchBaselineResult",
    "TrackBaselineResult",
    "contact_baselines",
    "contact_knn_baseline",
    "contact_ridge_baseline",
    "majority_baseline",
    "mean_pose_baseline",
    "no_motion_baseline",
    "region_centre_baseline",
    "sklearn_touch_baseline",
    "subsample",
    "touch_baselines",
    "track_baselines",
    "track_ridge_baseline",
]
