"""ContactData from trials whose fingers are an axis: the slots, the faces and the hover height
of each frame, built from hand-made trials of two and three fingers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import Recording
from ectskin.learn.data.contact import MAX_FINGERS, contact_dataset

N = 6


def _with_fingers(rec: Recording, name: str, **fingers) -> Recording:
    """``rec`` with trial ``name`` given the finger fields ``fingers`` (on the axis)."""
    trials = [
        dataclasses.replace(t, **fingers) if t.name == name else t for t in rec.trials
    ]
    return Recording(rec.layout, trials, rec.frame_rate_hz, rec.meta)


def _two_fingers():
    """Finger 0 on the front in frames 0..3, then 20 mm above it; finger 1 on the back in
    frames 2..3, 4 mm above it in frame 4 and away in frames 0, 1 and 5."""
    contact = np.zeros((N, 2), bool)
    contact[:4, 0] = True
    contact[2:4, 1] = True
    uv = np.full((N, 2, 2), np.nan)
    uv[:, 0] = [5.0, 60.0]
    uv[2:5, 1] = [[-3.0, 30.0], [-3.5, 31.0], [-3.5, 31.0]]
    height = np.where(contact, 0.0, np.nan)
    height[4:, 0] = 20.0
    height[4, 1] = 4.0
    force = np.where(contact, [[1.0, 0.5]], 0.0)
    return {
        "contact": contact,
        "finger_uv_mm": uv,
        "finger_height_mm": height,
        "force": force,
        "finger_surface": ("front", "back"),
    }


def test_two_fingers_fill_the_slots_in_the_order_of_the_axis(layout, contact_recording):
    rec = _with_fingers(contact_recording(layout, n_frames=N, n_trials=1), "touch_0",
                        **_two_fingers())
    d = contact_dataset(rec, window=1)
    rows = d.group == 1
    front, back = d.faces.index("front"), d.faces.index("back")
    assert MAX_FINGERS == 2
    assert d.count[rows].tolist() == [1, 1, 2, 2, 0, 0]
    assert d.face[rows].tolist() == [[front, -1]] * 2 + [[front, back]] * 2 + [[-1, -1]] * 2
    np.testing.assert_allclose(d.uv[rows][2], [[5.0, 60.0], [-3.0, 30.0]])
    np.testing.assert_allclose(d.force[rows][3], [1.0, 0.5])
    # the hover height is the lowest finger's: finger 1 at 4 mm in frame 4, finger 0 at 20 mm
    # alone in frame 5 (above HOVER_MAX_MM: no hover)
    assert d.height[rows].tolist() == [0, 0, 0, 0, 4.0, 20.0]
    assert d.hover[rows].tolist() == [0, 0, 0, 0, 1, 0]


def test_more_fingers_on_the_skin_than_slots_is_an_error(layout, contact_recording):
    rec = contact_recording(layout, n_frames=N, n_trials=1)
    three = {
        "contact": np.ones((N, 3), bool),
        "finger_uv_mm": np.full((N, 3, 2), 5.0),
        "finger_height_mm": np.zeros((N, 3)),
        "force": np.ones((N, 3)),
        "finger_surface": ("front", "front", "back"),
    }
    with pytest.raises(EctskinError, match=r"trial 'touch_0': more than 2 fingers at once"):
        contact_dataset(_with_fingers(rec, "touch_0", **three), window=1)
    off_skin = {**_two_fingers(), "finger_surface": ("front", "left")}
    with pytest.raises(EctskinError, match=r"trial 'touch_0': finger 1 touches surface 'left', "
                       r"which holds no skin"):
        contact_dataset(_with_fingers(rec, "touch_0", **off_skin), window=1)


def test_a_wrong_face_is_charged_around_the_recordings_body(layout, contact_recording):
    """The distance from a predicted face to the true one goes around the body the recording was
    made on (``meta["manipulator"]``), not the default body: a point predicted on the back,
    straight behind a front touch at u = 20 mm on a 50 mm wide body, is 5 + t + 5 mm away over
    the skin for a body t mm thick (the metric ignored its over-the-skin distances once and
    charged the straight line through the body, t)."""
    from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
    from ectskin.learn.tasks.contact import contact_report

    base = contact_recording(layout, n_frames=N, n_trials=1)
    for meta, thickness, source in (({}, 20.0, "default"),
                                    ({"manipulator": {"thickness_mm": 30.0}}, 30.0, "recording")):
        rec = Recording(base.layout, base.trials, base.frame_rate_hz, meta)
        d = contact_dataset(rec, window=1)
        assert d.body_mm == (50.0, thickness) and d.body_source == source
        one = d.count == 1
        test = d.take(np.flatnonzero(one))
        pred = np.zeros((test.n_samples, len(PRED_COLUMNS) + 2 * len(SLOT_COLUMNS)), np.float32)
        pred[:, 0] = 1  # one finger
        front, back = test.faces.index("front"), test.faces.index("back")
        assert np.all(test.face[:, 0] == front)
        test.uv[:, 0] = [20.0, 60.0]
        slot = len(PRED_COLUMNS)
        pred[:, slot : slot + 3] = [back, 20.0, 60.0]
        report = contact_report(test, pred, with_maps=False)
        assert report["loc_mm_mean"] == pytest.approx(5.0 + thickness + 5.0)
