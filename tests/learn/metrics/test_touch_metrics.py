"""Touch test-set metrics on hand-computed cases (ectskin.learn.metrics.touch)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.layout import default_layout
from ectskin.learn.metrics.touch import (
    confusion_matrix,
    format_count,
    region_adjacency,
    touch_metrics,
)


def test_confusion_three_classes_by_hand():
    y_true = [0, 0, 1, 1, 1, 2, 2]
    y_pred = [0, 1, 1, 1, 2, 2, 0]
    conf = confusion_matrix(y_true, y_pred, 3)
    # rows = true class, columns = predicted class, counted by hand
    assert conf.tolist() == [[1, 1, 0], [0, 2, 1], [1, 0, 1]]
    m = touch_metrics(y_true, y_pred, 3)
    assert m["accuracy"] == pytest.approx(4 / 7)
    assert m["n_test_frames"] == 7
    assert m["n_misclassified"] == 3
    assert m["misclassified"] == "3 of 7"
    assert m["per_class_accuracy"] == pytest.approx([0.5, 2 / 3, 0.5])
    assert sorted((c["true"], c["pred"], c["count"]) for c in m["confusions"]) == [
        (0, 1, 1),
        (1, 2, 1),
        (2, 0, 1),
    ]


def test_confusion_refuses_out_of_range_class():
    with pytest.raises(EctskinError, match=r"y_pred\[1\] = 3"):
        confusion_matrix([0, 1], [0, 3], 3)
    with pytest.raises(EctskinError, match="shape"):
        confusion_matrix([0, 1], [0], 3)


def test_format_count_matches_paper_wording():
    assert format_count(34, 28800) == "34 of 28 800"
    assert format_count(0, 112500) == "0 of 112 500"
    assert format_count(5, 999) == "5 of 999"


def test_region_adjacency_of_the_paper_grid():
    lay = default_layout()
    adj = region_adjacency(lay)
    assert adj.shape == (19, 19)
    assert (adj == adj.T).all() and not adj.diagonal().any()
    assert not adj[0].any() and not adj[:, 0].any()  # "no touch" is adjacent to nothing
    # front grid numbered row-major from the base: 1 2 3 / 4 5 6 / 7 8 9
    assert adj[1, 2] and adj[2, 3] and adj[1, 4] and adj[5, 8] and adj[17, 18]
    assert not adj[1, 3]  # same row, not touching
    assert not adj[1, 5]  # diagonal: corner only
    assert not adj[1, 10] and not adj[9, 18]  # other face
    # a 3 x 3 grid has 12 edge neighbours per face; 2 faces; symmetric matrix
    assert adj.sum() == 2 * 12 * 2
    corners = region_adjacency(lay, corners=True)
    assert corners[1, 5] and corners[3, 5] and not corners[1, 9]
    assert corners.sum() == 2 * (12 + 8) * 2  # plus 8 diagonal neighbours per face


def test_touch_metrics_adjacent_confusions_and_worst_trial():
    adj = region_adjacency(default_layout())
    # 3 trials: region 2 (10 frames, 3 called 3), region 5 (10 frames, 1 called 9), none (10 ok)
    y_true = np.array([2] * 10 + [5] * 10 + [0] * 10)
    y_pred = y_true.copy()
    y_pred[:3] = 3  # 2 -> 3: adjacent (paper's example)
    y_pred[10] = 9  # 5 -> 9: diagonal, not adjacent
    group = np.repeat([0, 1, 2], 10)
    m = touch_metrics(y_true, y_pred, 19, adjacency=adj, group=group, group_names=["a", "b", "c"])
    assert m["n_misclassified"] == 4
    assert m["n_misclassified_adjacent"] == 3
    assert m["all_adjacent"] is False
    assert m["confusions"][0] == {"true": 2, "pred": 3, "count": 3, "adjacent": True}
    assert m["confusions"][1] == {"true": 5, "pred": 9, "count": 1, "adjacent": False}
    assert m["worst_trial"] == {"name": "a", "label": 2, "n_frames": 10, "accuracy": 0.7}
    assert [t["accuracy"] for t in m["per_trial"]] == [0.7, 0.9, 1.0]
    assert m["per_class_accuracy"][1] is None  # class absent from the test set
    assert np.asarray(m["confusion"]).sum() == 30
