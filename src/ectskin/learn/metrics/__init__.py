"""Test-set metrics, pure functions on plain arrays, one module per task.

==================  ========================================================================
``metrics.touch``   accuracy, the paper's "34 of 28 800" count, confusion map (Fig. 7) and the
                    adjacency of the confusions
``metrics.track``   the average distance AD of Eq. 3, per marker and per trajectory
``metrics.contact`` localisation over the body's faces, force, hover against height, finger
                    count and per-finger error after Hungarian matching
==================  ========================================================================
"""

from __future__ import annotations

from ectskin.learn.metrics.contact import (
    error_map,
    force_metrics,
    hover_metrics,
    localisation_metrics,
    match_fingers,
    multi_metrics,
    point_distance,
    rest_points,
)
from ectskin.learn.metrics.touch import (
    confusion_matrix,
    format_count,
    region_adjacency,
    touch_metrics,
)
from ectskin.learn.metrics.track import average_distance, marker_distances, track_metrics

__all__ = [
    "average_distance",
    "confusion_matrix",
    "error_map",
    "force_metrics",
    "format_count",
    "hover_metrics",
    "localisation_metrics",
    "marker_distances",
    "match_fingers",
    "multi_metrics",
    "point_distance",
    "region_adjacency",
    "rest_points",
    "touch_metrics",
    "track_metrics",
]
