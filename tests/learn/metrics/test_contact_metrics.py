"""Contact metrics against hand-computed cases: rest geometry, Hungarian matching, hover curve."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin.learn.metrics.contact import (
    error_map,
    force_metrics,
    hover_metrics,
    localisation_metrics,
    match_fingers,
    multi_metrics,
    rest_points,
)

FACES = ["front", "back"]


def test_rest_points_put_the_faces_a_thickness_apart():
    pts = rest_points(
        FACES, np.array([0, 1]), np.array([[3.0, 40.0], [3.0, 40.0]]), width_mm=50, thickness_mm=20
    )
    np.testing.assert_allclose(pts, [[3.0, 10.0, 40.0], [3.0, -10.0, 40.0]])
    # the same (u, v) on the other face is the body's thickness away; 3-4-5 on one face
    assert np.linalg.norm(pts[0] - pts[1]) == pytest.approx(20.0)
    a = rest_points(FACES, np.array([0]), np.array([[0.0, 0.0]]), width_mm=50, thickness_mm=20)
    b = rest_points(FACES, np.array([0]), np.array([[3.0, 4.0]]), width_mm=50, thickness_mm=20)
    assert np.linalg.norm(a - b) == pytest.approx(5.0)


def test_side_faces_sit_at_half_the_width():
    pts = rest_points(
        ["right", "left"],
        np.array([0, 1]),
        np.array([[2.0, 7.0], [2.0, 7.0]]),
        width_mm=50,
        thickness_mm=20,
    )
    np.testing.assert_allclose(pts, [[25.0, 2.0, 7.0], [-25.0, 2.0, 7.0]])


def test_hungarian_matching_of_two_fingers_by_hand():
    true = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    # predictions listed in the other order, each 1 mm off its finger
    pred = np.array([[10.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    r, c = match_fingers(true, pred)
    assert dict(zip(r.tolist(), c.tolist())) == {0: 1, 1: 0}
    # a greedy match (finger A takes its nearest prediction first) fails here: A at 0, B at 1,
    # predictions P at 0.6 and Q at -1. Greedy: A-P (0.6) + B-Q (2.0) = 2.6; optimal:
    # A-Q (1.0) + B-P (0.4) = 1.4
    true = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    pred = np.array([[0.6, 0, 0], [-1.0, 0, 0]])
    r, c = match_fingers(true, pred)
    assert dict(zip(r.tolist(), c.tolist())) == {0: 1, 1: 0}


def test_multi_metrics_count_and_matched_errors():
    tc = np.array([0, 1, 2, 2])
    pc = np.array([0, 1, 2, 1])
    true = np.zeros((4, 2, 3))
    pred = np.zeros((4, 2, 3))
    true[2] = [[0, 0, 0], [10, 0, 0]]
    pred[2] = [[10, 2, 0], [0, 1, 0]]  # swapped, 2 mm and 1 mm off
    m = multi_metrics(tc, pc, true, pred, max_fingers=2)
    assert m["count_accuracy"] == pytest.approx(0.75)
    assert m["count_confusion"] == [[1, 0, 0], [0, 1, 0], [0, 1, 1]]
    assert m["n_fingers"] == 2  # only the frame with both counts 2 is matched
    assert m["loc_mm_mean"] == pytest.approx(1.5)


def test_localisation_summary_per_face_and_state():
    true = np.array([[0.0, 0, 0], [0.0, 0, 0], [0.0, 0, 0], [0.0, 0, 0]])
    pred = np.array([[1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0], [10.0, 0, 0]])
    m = localisation_metrics(
        true,
        pred,
        true_face=np.array([0, 0, 1, 1]),
        pred_face=np.array([0, 0, 1, 0]),
        faces=FACES,
        state=np.array([0, 1, 0, 1]),
        state_names=["a", "b"],
    )
    assert m["loc_mm_mean"] == pytest.approx(4.0)
    assert m["loc_mm_median"] == pytest.approx(2.5)
    assert m["loc_mm_p90"] == pytest.approx(np.percentile([1, 2, 3, 10], 90))
    assert m["face_accuracy"] == pytest.approx(0.75)
    assert m["per_face"]["front"]["loc_mm_mean"] == pytest.approx(1.5)
    assert m["per_state"]["b"]["loc_mm_mean"] == pytest.approx(6.0)


def test_error_map_averages_per_cell():
    uv = np.array([[1.0, 1.0], [2.0, 2.0], [7.0, 1.0]])
    m = error_map(uv, np.array([1.0, 3.0, 5.0]), ((0.0, 10.0), (0.0, 5.0)), cell_mm=5.0)
    assert m["mean_mm"].shape == (1, 2)
    np.testing.assert_allclose(m["mean_mm"], [[2.0, 5.0]])
    assert m["count"].tolist() == [[2, 1]]


def test_force_metrics_by_hand():
    m = force_metrics(np.array([1.0, 2.0]), np.array([1.5, 1.0]))
    assert m["force_mae_n"] == pytest.approx(0.75)
    assert m["force_rel"] == pytest.approx(0.75 / 1.5)
    assert m["force_bias_n"] == pytest.approx(-0.25)


def test_hover_detection_height_is_the_last_bin_above_the_rate():
    # bins of 1 mm up to 5 mm: heights 0.5, 1.5, 2.5, 3.5, 4.5 (10 frames each)
    h = np.repeat([0.5, 1.5, 2.5, 3.5, 4.5], 10)
    truth = np.ones(h.size, bool)
    pred = truth.copy()
    pred[30:35] = False  # bin (3, 4]: 50 % detected
    m = hover_metrics(h, truth, pred, finger_present=np.ones(h.size, bool), hover_max_mm=5.0)
    assert m["hover_detect_mm"] == 3.0
    assert m["curve"]["rate"] == [1.0, 1.0, 1.0, 0.5, 1.0]
    pred[:] = True
    m = hover_metrics(h, truth, pred, finger_present=np.ones(h.size, bool), hover_max_mm=5.0)
    assert m["hover_detect_mm"] == 5.0
    # no finger anywhere, flagged: false alarms
    m = hover_metrics(
        np.full(4, np.nan),
        np.zeros(4, bool),
        np.array([1, 0, 0, 0], bool),
        finger_present=np.zeros(4, bool),
        hover_max_mm=5.0,
    )
    assert m["false_alarm_rate_no_finger"] == pytest.approx(0.25)
    assert m["hover_detect_mm"] is None
