"""Touch data sets from recordings (ectskin.learn.data.touch)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.layout import default_layout
from ectskin.learn.data import touch_dataset

LAYOUT = default_layout()


def test_touch_dataset_matches_eq2_against_rest_state(make_recording):
    rec = make_recording()
    d = touch_dataset(rec)
    ref = rec.trial("s0_rest").capacitance.mean(axis=0)
    want = np.concatenate([(t.capacitance - ref) / ref for t in rec.trials])  # Eq. 2, float64
    np.testing.assert_allclose(d.x, want, rtol=1e-6, atol=1e-7)
    assert d.x.dtype == np.float32 and d.y.dtype == np.int64 and d.group.dtype == np.int64
    np.testing.assert_array_equal(d.y, np.concatenate([t.labels for t in rec.trials]))
    np.testing.assert_array_equal(d.group, np.repeat(np.arange(rec.n_trials), 12))
    assert d.group_names == [t.name for t in rec.trials]
    assert d.n_classes == 19 and d.pair_names == list(LAYOUT.pair_names)
    np.testing.assert_array_equal(d.group_region, [t.region for t in rec.trials])
    sub = d.select([1, 3])
    assert sub.n_samples == 24 and set(sub.group.tolist()) == {1, 3}
    np.testing.assert_array_equal(sub.x, d.x[(d.group == 1) | (d.group == 3)])


def test_touch_dataset_nonfinite_frame_raise_or_drop(caplog, make_recording):
    rec = make_recording()
    rec.trials[2].capacitance[5, 9] = np.nan
    with pytest.raises(EctskinError) as e:
        touch_dataset(rec)
    msg = str(e.value)
    assert f"trial {rec.trials[2].name!r}" in msg and "frame 5" in msg and "channel 9" in msg
    with caplog.at_level(logging.WARNING):
        d = touch_dataset(rec, nonfinite="drop")
    assert d.n_samples == rec.n_frames - 1 and np.all(np.isfinite(d.x))
    assert "dropped 1 frames" in caplog.text
    with pytest.raises(EctskinError, match="nonfinite"):
        touch_dataset(rec, nonfinite="zero")


def test_touch_dataset_subset_and_unmeasured_pairs(make_recording):
    rec = make_recording()
    rec.meta["unmeasured_pairs"] = [0, 27]
    for t in rec.trials:
        t.capacitance[:, [0, 27]] = np.nan  # not measured at all
    d = touch_dataset(rec, trials=["s0_rest", 3])
    assert d.group_names == ["s0_rest", rec.trials[3].name]
    assert d.n_pairs == 26 and d.pair_names == list(LAYOUT.pair_names[1:27])
    assert np.all(np.isfinite(d.x))
    with pytest.raises(EctskinError, match="no trial 'nope'"):
        touch_dataset(rec, trials=["nope"])
