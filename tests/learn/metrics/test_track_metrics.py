"""Tracking test-set metrics on hand-computed cases (ectskin.learn.metrics.track)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.learn.metrics.track import average_distance, marker_distances, track_metrics


def test_average_distance_two_samples_by_hand():
    true = np.zeros((2, 2, 3))
    pred = np.zeros((2, 2, 3))
    pred[0, 0] = [3, 4, 0]  # distance 5
    pred[0, 1] = [0, 0, 0]  # 0
    pred[1, 0] = [0, 0, 1]  # 1
    pred[1, 1] = [0, 2, 0]  # 2
    true[1] += 10.0  # a shift common to both: distances unchanged
    pred[1] += 10.0
    assert marker_distances(pred, true).tolist() == [[5.0, 0.0], [1.0, 2.0]]
    mean, std = average_distance(pred, true)
    assert mean == pytest.approx(2.0)  # (5 + 0 + 1 + 2) / (N M = 4), Eq. 3
    assert std == pytest.approx(math.sqrt((9 + 4 + 1 + 0) / 4))


def test_average_distance_refuses_bad_input():
    with pytest.raises(EctskinError, match="shape"):
        average_distance(np.zeros((2, 5, 3)), np.zeros((2, 4, 3)))
    true = np.zeros((2, 1, 3))
    true[1, 0, 2] = np.nan
    with pytest.raises(EctskinError, match="sample 1, marker 0"):
        average_distance(np.zeros((2, 1, 3)), true)
    with pytest.raises(EctskinError, match="no samples"):
        average_distance(np.zeros((0, 5, 3)), np.zeros((0, 5, 3)))


def test_track_metrics_per_marker_and_trajectory():
    rng = np.random.default_rng(0)
    true = rng.normal(size=(6, 2, 3)) * 50
    err = np.zeros((6, 2, 3))
    err[:, 0, 0] = 1.0  # marker 1 always 1 mm off
    err[:, 1, 1] = [2, 2, 2, 4, 4, 4]  # marker 2: 2 mm in trajectory 0, 4 mm in trajectory 1
    group = np.array([0, 0, 0, 1, 1, 1])
    m = track_metrics(
        true + err, true, group=group, group_names=["t0", "t1"], marker_names=["A", "B"]
    )
    assert m["ad_mm_mean"] == pytest.approx((6 * 1 + 3 * 2 + 3 * 4) / 12)
    assert m["per_marker"]["A"] == {
        "ad_mm_mean": pytest.approx(1.0),
        "ad_mm_std": pytest.approx(0.0),
    }
    assert m["per_marker"]["B"]["ad_mm_mean"] == pytest.approx(3.0)
    assert m["per_marker"]["B"]["ad_mm_std"] == pytest.approx(1.0)
    assert m["n_test_trajectories"] == 2
    assert m["per_trajectory"][0]["ad_mm_mean"] == pytest.approx(1.5)
    assert m["worst_trajectory"]["name"] == "t1"
    assert m["worst_trajectory"]["ad_mm_mean"] == pytest.approx(2.5)
    assert m["ad_mm_max"] == pytest.approx(4.0)
