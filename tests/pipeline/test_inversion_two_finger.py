"""The inversion step's two-finger block (``two_finger``): which test frames are added, and their
count and per-finger point error against a hand computation from given fits (no inversion)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ectskin.inversion.frames import SLOTS
from ectskin.learn.data.contact import ContactData
from ectskin.pipeline import inversion as pinv

FACE_EXTENT = {"front": ((-20.0, 20.0), (0.0, 120.0)), "back": ((-20.0, 20.0), (0.0, 120.0))}


def _data(count: list[int], group: list[int]) -> ContactData:
    """Labels of frames on the front face: finger 0 at (0, 10 + frame), finger 1 at (10, 60)."""
    n = len(count)
    c = np.asarray(count)
    face = np.where(np.arange(2)[None, :] < c[:, None], 0, -1)
    uv = np.zeros((n, 2, 2))
    uv[:, 0] = np.c_[np.zeros(n), 10.0 + np.arange(n)]
    uv[:, 1] = (10.0, 60.0)
    uv[face < 0] = 0.0
    return ContactData(
        x=np.zeros((n, 1, 3), np.float32), count=c, face=face, uv=uv.astype(np.float32),
        force=np.where(face >= 0, 1.0, 0.0), hover=np.zeros(n), height=np.zeros(n),
        other_height=np.full(n, np.nan), group=np.asarray(group), frame=np.arange(n),
        state=np.zeros(n, int), group_names=["a", "b", "c"], pair_names=["p0", "p1", "p2"],
        faces=["front", "back"], states=[(0.0,)], face_extent=FACE_EXTENT,
        body_mm=(40.0, 20.0), body_source="default",
    )


def _arrays(fingers: list[list[tuple[float, float, bool]]]) -> dict[str, np.ndarray]:
    """results_to_arrays-like arrays of fits on the front face: per frame [(u, v, pressing)]."""
    n = len(fingers)
    out = {
        "n_fingers": np.array([len(f) for f in fingers]), "face": np.full((n, SLOTS), "", "<U16"),
        "contact": np.zeros((n, SLOTS), bool), "uv_mm": np.full((n, SLOTS, 2), np.nan),
        "force_n": np.full((n, SLOTS), np.nan), "height_mm": np.full((n, SLOTS), np.nan),
        "uv_se_mm": np.full((n, SLOTS, 2), 0.1), "force_se_n": np.full((n, SLOTS), 0.05),
    }
    for i, fs in enumerate(fingers):
        for k, (u, v, press) in enumerate(fs):
            out["face"][i, k] = "front"
            out["contact"][i, k] = press
            out["uv_mm"][i, k] = (u, v)
            out["force_n"][i, k] = 1.0 if press else 0.0
            out["height_mm"][i, k] = 0.0 if press else 3.0
    return out


def test_the_two_finger_frames_not_spread_are_added_evenly():
    data = _data([2, 2, 1, 2, 2, 2, 2, 0], [0, 0, 0, 1, 1, 1, 2, 2])
    spread = np.array([0, 2, 4])
    assert pinv.two_finger_rows(data, spread, None).tolist() == [1, 3, 5, 6]
    assert pinv.two_finger_rows(data, spread, 2).tolist() == [1, 6]
    assert pinv.two_finger_rows(data, np.array([0, 1, 3, 4, 5, 6]), 10).size == 0


def test_the_two_finger_score_is_the_hand_count_and_the_matched_error():
    data = _data([2, 2, 2, 2], [0, 0, 1, 1])
    fits = [
        [(10.0, 63.0, True), (0.0, 14.0, True)],  # both, in the other order: 3 and 4 mm off
        [(1.0, 11.0, True), (10.0, 60.0, False)],  # the second hovers: counted 1
        [(0.0, 12.0, True), (16.0, 68.0, True)],  # both: 0 and 10 mm off
        [],  # no finger: counted 0
    ]
    m = pinv.two_finger_score(data, _arrays(fits))
    assert m["count_predicted"] == [1, 1, 2] and m["count_accuracy"] == pytest.approx(0.5)
    assert m["count_accuracy_by_trial"] == {"a": 0.5, "b": 0.5}
    assert m["n_frames"] == 4 and m["n_trials"] == 2
    errors = [3.0, 4.0, 0.0, math.hypot(6.0, 8.0)]
    assert m["n_fingers"] == 4
    assert m["loc_mm_mean"] == pytest.approx(np.mean(errors), abs=1e-5)
    assert m["loc_mm_median"] == pytest.approx(np.median(errors), abs=1e-5)


def test_the_two_finger_count_is_told_per_inflation_state():
    """Frames of two states: the count accuracy, frames and trials of each, by hand."""
    data = _data([2, 2, 2, 2], [0, 0, 1, 2])
    data = dataclasses.replace(data, state=np.array([1, 1, 1, 0]),
                               states=[(0.0, 0.0, 20.0), (20.0, 0.0, 0.0)])
    fits = [
        [(0.0, 10.0, True), (10.0, 60.0, True)],  # counted 2
        [(1.0, 11.0, True), (10.0, 60.0, False)],  # counted 1
        [(0.0, 12.0, True), (10.0, 60.0, True)],  # counted 2
        [(0.0, 13.0, True)],  # counted 1
    ]
    m = pinv.two_finger_score(data, _arrays(fits))
    assert m["by_state"] == {
        "20/0/0 ml": {"count_accuracy": pytest.approx(2 / 3), "n_frames": 3, "n_trials": 2},
        "0/0/20 ml": {"count_accuracy": 0.0, "n_frames": 1, "n_trials": 1},
    }
    assert m["count_accuracy"] == pytest.approx(0.5)


def test_the_step_refuses_a_bad_number_of_two_finger_frames(tmp_path):
    with pytest.raises(pinv.EctskinError, match="two_finger_frames must be an integer >= 0"):
        pinv.inversion_step(None, None, {}, (tmp_path, {}), two_finger_frames=-1)  # type: ignore[arg-type]
    with pytest.raises(pinv.EctskinError, match="two_finger_frames must be an integer >= 0"):
        pinv.inversion_step(None, None, {}, (tmp_path, {}), two_finger_frames=True)  # type: ignore[arg-type]



def test_force_is_observable_by_the_standard_error_of_the_force_scored():
    """A one-finger frame fitted as two pressing fingers is scored by the best-located one
    (slot 0); whether its force is observable is that finger's standard error, not the first
    fitted finger's."""
    data = _data([1, 1], [0, 1])  # finger at (0, 10) and (0, 11), 1 N
    a = _arrays([[(9.0, 70.0, True), (0.0, 10.0, True)], [(0.0, 11.0, True)]])
    a["uv_se_mm"][0, 0] = 5.0  # the phantom: its point hardly told
    a["force_se_n"][0] = (0.05, 0.3)  # the phantom's force well told, the finger's not
    a["force_n"][0] = (1.5, 1.2)
    a["force_n"][1, 0] = 0.9
    a["converged"] = np.ones(2, bool)
    m = pinv.score(data, a, np.full(2, 1e-3))
    fo = m["force_observable"]
    assert fo["n_frames"] == 1 and fo["share"] == pytest.approx(0.5)
    assert fo["force_mae_n"] == pytest.approx(0.1)  # frame 1 alone
    assert fo["force_mae_n_not_observable"] == pytest.approx(0.2)  # frame 0's scored finger
