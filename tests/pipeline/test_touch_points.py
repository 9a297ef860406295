"""The count of distinct touch points in a contact recording, and the body it keeps."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import Recording, Trial
from ectskin.layout import default_layout
from ectskin.pipeline.contact import n_touch_points, with_paper_trials


def _trial(name: str, meta: dict) -> Trial:
    P = default_layout().n_pairs
    return Trial(name, capacitance=np.ones((3, P)), timestamps=np.arange(3) / 30.0,
                 labels=np.zeros(3, dtype=np.int16), meta=meta)


def test_distinct_points_are_counted_by_face_and_place():
    """Two dwells of one trial, the same point again in another trial (counted once), the same
    (u, v) on the other face (counted), a second finger's point, and a trial without points."""
    trials = [
        _trial("a", {"surface": "front", "touch_uv_mm": [[1.0, 50.0], [2.0, 60.0]]}),
        _trial("b", {"surface": "front", "touch_uv_mm": [[1.0, 50.0]],
                     "second_finger": {"surface": "back", "touch_uv_mm": [-3.0, 20.0]}}),
        _trial("c", {"surface": "back", "touch_uv_mm": [[1.0, 50.0]]}),
        _trial("d", {"kind": "no_contact"}),
    ]
    rec = Recording(default_layout(), trials, 30.0)
    assert n_touch_points(rec) == 4
    assert n_touch_points(Recording(default_layout(), trials[3:], 30.0)) is None


def test_the_joined_recording_keeps_the_body_both_were_made_on():
    """The same body read back from a file (lists) and fresh from the twin (tuples) is one body."""
    body = {"thickness_mm": 30.0, "chamber_z_mm": (20.0, 60.0, 100.0)}
    read_back = {"thickness_mm": 30.0, "chamber_z_mm": [20.0, 60.0, 100.0]}
    paper = Recording(default_layout(), [_trial("p", {})], 30.0, meta={"manipulator": read_back})
    contact = Recording(default_layout(), [_trial("c", {})], 30.0, meta={"manipulator": body})
    assert with_paper_trials(paper, contact).meta["manipulator"] == body
    other = Recording(default_layout(), [_trial("p", {})], 30.0, meta={"manipulator": {}})
    with pytest.raises(EctskinError, match="different manipulators"):
        with_paper_trials(other, contact)
