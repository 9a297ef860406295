"""Where the hand's other finger is while one finger touches: ``ContactData.other_height`` from
hand-made two-finger trials, and the localisation error split by it (``by_other_finger``), each
against values worked out by hand.

A finger hovering a few millimetres above the skin adds a signal of the order of a touch's (in
the twin, 10-15 mm above the skin about two thirds of it), so a model that mistakes it for the
touching finger errs by the distance between the two; the split makes such frames visible in
the metrics instead of hiding them in a state's mean."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import Recording
from ectskin.learn.data.contact import HOVER_MAX_MM, contact_dataset
from ectskin.learn.metrics.contact import OTHER_FINGER_PARTS, other_finger_split

N = 6


def _recording(contact_recording, layout) -> Recording:
    """Trial touch_0 with two fingers: finger 0 on the front at (5, 60) in frames 0..4 and 30 mm
    above it in frame 5; finger 1 over the back: away in frame 0, 30 mm above the skin in frame
    1, 4 mm in frame 2, on it in frame 3, 15 mm (the hover limit) in frame 4 and 2 mm in
    frame 5."""
    rec = contact_recording(layout, n_frames=N, n_trials=1)
    contact = np.zeros((N, 2), bool)
    contact[:5, 0] = True
    contact[3, 1] = True
    uv = np.full((N, 2, 2), np.nan)
    uv[:, 0] = [5.0, 60.0]
    uv[1:, 1] = [-3.0, 30.0]
    height = np.array(
        [[0.0, np.nan], [0.0, 30.0], [0.0, 4.0], [0.0, 0.0], [0.0, 15.0], [30.0, 2.0]]
    )
    fingers = {
        "contact": contact,
        "finger_uv_mm": uv,
        "finger_height_mm": height,
        "force": np.where(contact, [[1.0, 0.5]], 0.0),
        "finger_surface": ("front", "back"),
    }
    trials = [dataclasses.replace(t, **fingers) if t.name == "touch_0" else t for t in rec.trials]
    return Recording(rec.layout, trials, rec.frame_rate_hz, rec.meta)


def test_other_height_is_the_lowest_finger_above_the_skin_but_not_on_it(layout, contact_recording):
    d = contact_dataset(_recording(contact_recording, layout), window=1)
    rows = d.group == 1
    assert d.count[rows].tolist() == [1, 1, 1, 2, 1, 0]
    # frame 0: finger 1 away; 1, 2, 4: finger 1 over the skin at its height; 3: both on the
    # skin; 5: neither on it, the lower of 30 and 2 mm. The touching finger (height 0) never
    # counts as the other one.
    np.testing.assert_array_equal(d.other_height[rows], [np.nan, 30.0, 4.0, np.nan, 15.0, 2.0])
    # the no-contact trial has no finger: NaN throughout; the one-finger sample fields agree
    assert np.isnan(d.other_height[d.group == 0]).all()
    assert d.other_height.shape == d.count.shape
    # selecting samples keeps the field aligned with the others
    sub = d.take(np.flatnonzero(rows)[[4, 1]])
    np.testing.assert_array_equal(sub.other_height, [15.0, 30.0])


def test_the_error_split_by_the_other_finger_by_hand():
    # six one-finger frames of two states: errors (mm) and the other finger's height
    d = np.array([1.0, 2.0, 30.0, 10.0, 4.0, 50.0])
    h = np.array([np.nan, np.nan, 3.0, HOVER_MAX_MM, 20.0, 8.0])
    state = np.array([0, 1, 0, 0, 1, 1])
    out = other_finger_split(d, h, HOVER_MAX_MM, state=state, state_names=["rest", "full"])
    assert tuple(k for k in out if k != "hover_max_mm") == OTHER_FINGER_PARTS
    alone, hovering, above = (out[k] for k in OTHER_FINGER_PARTS)
    assert alone["loc_mm_mean"] == pytest.approx(1.5) and alone["n_frames"] == 2
    # the hover limit itself is hovering (as a hovering finger is, at most HOVER_MAX_MM high)
    assert hovering["n_frames"] == 3 and hovering["loc_mm_mean"] == pytest.approx(30.0)
    assert hovering["loc_mm_median"] == pytest.approx(30.0)
    assert above["n_frames"] == 1 and above["loc_mm_mean"] == pytest.approx(4.0)
    assert alone["share"] == pytest.approx(2 / 6) and hovering["share"] == pytest.approx(3 / 6)
    assert hovering["per_state"]["rest"]["loc_mm_mean"] == pytest.approx(20.0)
    assert hovering["per_state"]["full"]["loc_mm_mean"] == pytest.approx(50.0)
    assert set(above["per_state"]) == {"full"}  # only the states holding frames of the part
    # the parts add up to the whole
    assert sum(out[k]["n_frames"] for k in OTHER_FINGER_PARTS) == d.size
    empty = other_finger_split(np.zeros(0), np.zeros(0), HOVER_MAX_MM)
    assert empty["alone"]["loc_mm_mean"] is None and empty["alone"]["share"] is None
    with pytest.raises(EctskinError, match="one shape"):
        other_finger_split(d, h[:3], HOVER_MAX_MM)


def test_contact_report_splits_its_one_finger_frames(layout, contact_recording):
    """The report's split uses the over-the-skin error of the frames of ``loc_mm_mean``: a
    prediction 3 mm off in u at every one-finger frame of touch_0 (frames 0, 1, 2, 4) gives 3 mm
    in each part, and the parts hold 1 (alone), 2 (finger 1 at 4 and 15 mm) and 1 (30 mm)."""
    from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
    from ectskin.learn.tasks.contact import contact_report

    d = contact_dataset(_recording(contact_recording, layout), window=1)
    test = d.select([1])
    pred = np.zeros((test.n_samples, len(PRED_COLUMNS) + 2 * len(SLOT_COLUMNS)), np.float32)
    pred[:, 0] = test.count
    slot = len(PRED_COLUMNS)
    pred[:, slot : slot + 3] = [test.faces.index("front"), 8.0, 60.0]
    m = contact_report(test, pred, with_maps=False)
    split = m["by_other_finger"]
    assert m["n_single_contact_frames"] == 4 and m["loc_mm_mean"] == pytest.approx(3.0)
    assert [split[k]["n_frames"] for k in OTHER_FINGER_PARTS] == [1, 2, 1]
    for k in OTHER_FINGER_PARTS:
        assert split[k]["loc_mm_mean"] == pytest.approx(3.0)
