"""Tracking data sets from recordings (ectskin.learn.data.track)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.layout import default_layout
from ectskin.learn.data import track_dataset

LAYOUT = default_layout()
P = LAYOUT.n_pairs


def _slow_windows(c, k, pad):
    """Obviously-correct reference: window of frame f = frames f−k+1..f, clamped at 0 (pad)."""
    out, last = [], []
    start = 0 if pad else k - 1
    for f in range(start, c.shape[0]):
        out.append(np.stack([c[max(0, f - k + 1 + i)] for i in range(k)]))
        last.append(f)
    return np.array(out), np.array(last)


@pytest.mark.parametrize("k, pad", [(10, True), (4, False), (1, True), (12, False)])
def test_track_windows_equal_slow_loop(k, pad, make_recording):
    rec = make_recording(n_frames=12)
    d = track_dataset(rec, window=k, pad=pad)
    used = [
        t
        for t in rec.trials
        if t.meta["kind"] == "touch" and t.markers is not None and not t.has_occlusion
    ]
    assert d.group_names == [t.name for t in used]
    pos = 0
    for g, t in enumerate(used):
        cap = t.capacitance
        c = ((cap - cap[0]) / cap[0]).astype(np.float32)  # prior: first frame is the reference
        w, last = _slow_windows(c, k, pad)
        m = len(last)
        np.testing.assert_allclose(d.x[pos : pos + m], w, rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(d.frame[pos : pos + m], last)
        np.testing.assert_array_equal(d.group[pos : pos + m], g)
        np.testing.assert_allclose(d.y[pos : pos + m], t.markers[last], rtol=1e-6)
        np.testing.assert_allclose(
            d.init[pos : pos + m], np.broadcast_to(t.markers[0], (m, 5, 3)), rtol=1e-6
        )
        pos += m
    assert pos == d.n_samples
    assert d.x.shape == (d.n_samples, k, P) and d.x.dtype == np.float32
    assert d.prior and d.window == k and d.n_markers == 5
    np.testing.assert_array_equal(d.pairs, LAYOUT.pairs)
    np.testing.assert_allclose(d.electrode_desc, LAYOUT.electrode_descriptors(), rtol=1e-6)
    # prior: the first frame calibrates to exactly zero
    assert np.all(d.x[d.frame == 0] == 0)


def test_track_dataset_skips_no_contact_occluded_and_markerless(caplog, make_recording):
    rec = make_recording()
    with caplog.at_level(logging.INFO, logger="ectskin.learn.data.track"):
        d = track_dataset(rec)
    assert "s1_r2" not in d.group_names and "s1_r11" not in d.group_names
    assert not any(n.endswith("rest") for n in d.group_names)
    assert len(d.group_names) == 4
    text = caplog.text
    assert "skipped 2 trial(s) without contact" in text
    assert "skipped 1 trial(s) with occluded markers" in text
    assert "skipped 1 trial(s) without markers" in text
    assert "4 of 8 trial(s) used" in text


def test_track_dataset_without_prior_is_absolute(make_recording):
    rec = make_recording()
    d = track_dataset(rec, prior=False, window=3)
    ref = rec.trial("s0_rest").capacitance.mean(axis=0)
    t = rec.trial(d.group_names[0])
    m = d.group == 0
    np.testing.assert_allclose(d.x[m][:, -1], (t.capacitance - ref) / ref, rtol=1e-5, atol=1e-7)
    assert not d.prior and np.all(d.init == 0)


def test_track_dataset_drops_windows_with_nonfinite_frames(make_recording):
    rec = make_recording(n_frames=12)
    t = rec.trial("s0_r7")
    t.capacitance[6, 3] = np.nan
    with pytest.raises(EctskinError, match="frame 6"):
        track_dataset(rec, window=4)
    d = track_dataset(rec, window=4, nonfinite="drop")
    g = d.group_names.index("s0_r7")
    # windows ending at frames 6..9 contain frame 6
    np.testing.assert_array_equal(d.frame[d.group == g], [0, 1, 2, 3, 4, 5, 10, 11])
    assert np.all(np.isfinite(d.x))
    t.capacitance[0, 3] = np.nan
    with pytest.raises(EctskinError, match="first frame"):
        track_dataset(rec, window=4, nonfinite="drop")


def test_track_dataset_bad_window_and_no_trials(make_recording):
    rec = make_recording()
    for bad in (0, -2, 2.5, True):
        with pytest.raises(EctskinError, match="window"):
            track_dataset(rec, window=bad)
    with pytest.raises(EctskinError, match="no usable tracking trial"):
        track_dataset(rec, trials=["s0_rest", "s1_r2"])
    with pytest.raises(EctskinError, match="shorter than window"):
        track_dataset(rec, window=50, pad=False)


def test_track_select_keeps_alignment(make_recording):
    d = track_dataset(make_recording())
    s = d.select([2])
    assert s.n_samples == 12 and np.all(s.group == 2)
    np.testing.assert_array_equal(s.y, d.y[d.group == 2])
    np.testing.assert_array_equal(s.frame, np.arange(12))
    with pytest.raises(EctskinError, match="group ids"):
        d.select([99])
