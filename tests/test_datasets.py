"""Touch / tracking data sets, trial-exclusive splits and the normaliser (ectskin.learn.datasets)."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.learn.datasets import (
    TOUCH_SPLIT,
    TRACK_SPLIT,
    Normalizer,
    split_from_names,
    split_groups,
    split_names,
    touch_dataset,
    track_dataset,
)

LAYOUT = default_layout()
P = LAYOUT.n_pairs


def make_recording(n_frames=12, seed=0, occluded=("s1_r2",), no_markers=("s1_r11",)):
    """Two inflation states; per state a no-contact trial and touch trials; random walk markers."""
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.5, 2.0, P)
    trials = []
    for s, infl in enumerate([(0.0, 0.0, 0.0), (20.0, 0.0, 10.0)]):
        scale = 1.0 + 0.2 * s
        n = n_frames
        trials.append(
            Trial(
                f"s{s}_rest",
                base * scale + rng.normal(0, 1e-3, (n, P)),
                np.arange(n) / 30,
                np.zeros(n),
                inflation=infl,
                markers=rng.normal(0, 1, (n, 5, 3)),
                meta={"kind": "no_contact"},
            )
        )
        for r in (2, 11, 7):
            markers = 10 * np.arange(5)[None, :, None] + np.cumsum(rng.normal(0, 0.3, (n, 5, 3)), 0)
            name = f"s{s}_r{r}"
            if name in occluded:
                markers[n // 2, 1, :] = np.nan
            trials.append(
                Trial(
                    name,
                    base * scale * (1 + 0.02 * r) + rng.normal(0, 1e-3, (n, P)),
                    np.arange(n) / 30,
                    np.full(n, r),
                    inflation=infl,
                    region=r,
                    markers=None if name in no_markers else markers,
                    meta={"kind": "touch"},
                )
            )
    return Recording(LAYOUT, trials, 30.0)


# --------------------------------------------------------------------------- touch
def test_touch_dataset_matches_eq2_against_rest_state():
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


def test_touch_dataset_nonfinite_frame_raise_or_drop(caplog):
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


def test_touch_dataset_subset_and_unmeasured_pairs():
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


# --------------------------------------------------------------------------- tracking
def _slow_windows(c, k, pad):
    """Obviously-correct reference: window of frame f = frames f−k+1..f, clamped at 0 (pad)."""
    out, last = [], []
    start = 0 if pad else k - 1
    for f in range(start, c.shape[0]):
        out.append(np.stack([c[max(0, f - k + 1 + i)] for i in range(k)]))
        last.append(f)
    return np.array(out), np.array(last)


@pytest.mark.parametrize("k, pad", [(10, True), (4, False), (1, True), (12, False)])
def test_track_windows_equal_slow_loop(k, pad):
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


def test_track_dataset_skips_no_contact_occluded_and_markerless(caplog):
    rec = make_recording()
    with caplog.at_level(logging.INFO, logger="ectskin.learn.datasets"):
        d = track_dataset(rec)
    assert "s1_r2" not in d.group_names and "s1_r11" not in d.group_names
    assert not any(n.endswith("rest") for n in d.group_names)
    assert len(d.group_names) == 4
    text = caplog.text
    assert "skipped 2 trial(s) without contact" in text
    assert "skipped 1 trial(s) with occluded markers" in text
    assert "skipped 1 trial(s) without markers" in text
    assert "4 of 8 trial(s) used" in text


def test_track_dataset_without_prior_is_absolute():
    rec = make_recording()
    d = track_dataset(rec, prior=False, window=3)
    ref = rec.trial("s0_rest").capacitance.mean(axis=0)
    t = rec.trial(d.group_names[0])
    m = d.group == 0
    np.testing.assert_allclose(d.x[m][:, -1], (t.capacitance - ref) / ref, rtol=1e-5, atol=1e-7)
    assert not d.prior and np.all(d.init == 0)


def test_track_dataset_drops_windows_with_nonfinite_frames():
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


def test_track_dataset_bad_window_and_no_trials():
    rec = make_recording()
    for bad in (0, -2, 2.5, True):
        with pytest.raises(EctskinError, match="window"):
            track_dataset(rec, window=bad)
    with pytest.raises(EctskinError, match="no usable tracking trial"):
        track_dataset(rec, trials=["s0_rest", "s1_r2"])
    with pytest.raises(EctskinError, match="shorter than window"):
        track_dataset(rec, window=50, pad=False)


def test_track_select_keeps_alignment():
    d = track_dataset(make_recording())
    s = d.select([2])
    assert s.n_samples == 12 and np.all(s.group == 2)
    np.testing.assert_array_equal(s.y, d.y[d.group == 2])
    np.testing.assert_array_equal(s.frame, np.arange(12))
    with pytest.raises(EctskinError, match="group ids"):
        d.select([99])


# --------------------------------------------------------------------------- splits
@pytest.mark.parametrize("n, counts", [(189, TOUCH_SPLIT), (146, TRACK_SPLIT)])
def test_split_sizes_disjoint_cover(n, counts):
    s = split_groups(n, counts, seed=3)
    assert [len(s[k]) for k in ("train", "val", "test")] == list(counts)
    allg = np.concatenate([s["train"], s["val"], s["test"]])
    assert np.array_equal(np.sort(allg), np.arange(n))
    assert all(np.all(np.diff(v) > 0) for v in s.values())


def test_split_deterministic_and_seed_dependent():
    a = split_groups(50, seed=7)
    b = split_groups([f"t{i}" for i in range(50)], seed=7)
    c = split_groups(50, seed=8)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not all(np.array_equal(a[k], c[k]) for k in a)


@pytest.mark.parametrize(
    "n, counts, want",
    [
        (24, TOUCH_SPLIT, [16, 4, 4]),  # 125/32/32 scaled: 15.87, 4.06, 4.06
        (20, TRACK_SPLIT, [15, 2, 3]),  # 108/18/20 → 14.79, 2.47, 2.74
        (3, TOUCH_SPLIT, [1, 1, 1]),
        (10, (0.6, 0.2, 0.2), [6, 2, 2]),
    ],
)
def test_split_counts_scale(n, counts, want):
    s = split_groups(n, counts)
    assert [len(s[k]) for k in ("train", "val", "test")] == want


def test_split_errors():
    with pytest.raises(EctskinError, match="at least one trial"):
        split_groups(2)
    with pytest.raises(EctskinError, match="3 non-negative numbers"):
        split_groups(10, (5, 5))
    with pytest.raises(EctskinError, match="3 non-negative numbers"):
        split_groups(10, (5, -1, 6))
    with pytest.raises(EctskinError, match="one label per group"):
        split_groups(10, stratify=[1, 2])


def test_stratified_split_puts_every_class_in_train():
    # paper-like: 27 no-contact trials + 162 touch trials, region r touched 9 times
    labels = np.array([0] * 27 + [r for r in range(1, 19) for _ in range(9)])
    for seed in range(5):
        s = split_groups(189, TOUCH_SPLIT, seed=seed, stratify=labels)
        assert set(labels[s["train"]]) == set(range(19))
        assert [len(s[k]) for k in ("train", "val", "test")] == [125, 32, 32]
        # proportional spread: no-contact trials in val ≈ 27 * 32 / 189 = 4.6
        assert 3 <= np.count_nonzero(labels[s["val"]] == 0) <= 6
    # a region touched once always lands in train
    rare = labels.copy()
    rare[rare == 18] = 17
    rare[-1] = 18
    for seed in range(5):
        s = split_groups(189, TOUCH_SPLIT, seed=seed, stratify=rare)
        assert 188 in s["train"]


def test_split_names_round_trip():
    names = [f"trial_{i:03d}" for i in range(30)]
    s = split_groups(names, TRACK_SPLIT, seed=1)
    stored = json.loads(json.dumps(split_names(s, names)))
    back = split_from_names(stored, names)
    assert all(np.array_equal(back[k], s[k]) for k in s)
    stored["test"].append("trial_999")
    with pytest.raises(EctskinError, match="trial_999"):
        split_from_names(stored, names)
    stored["test"][-1] = stored["train"][0]
    with pytest.raises(EctskinError, match="in both train and test"):
        split_from_names(stored, names)
    with pytest.raises(EctskinError, match="missing split 'val'"):
        split_from_names({"train": [], "test": []}, names)


# --------------------------------------------------------------------------- normaliser
def test_normalizer_fitted_on_train_only():
    rec = make_recording()
    d = touch_dataset(rec)
    s = split_groups(d.group_names, (4, 2, 2), seed=0)
    train, val = d.select(s["train"]), d.select(s["val"])
    val.x[:] += 100.0  # a val set far away must not move the statistics
    norm = Normalizer.fit(train.x)
    np.testing.assert_allclose(norm.mean, train.x.astype(np.float64).mean(0), rtol=1e-12)
    np.testing.assert_allclose(norm.std, train.x.astype(np.float64).std(0), rtol=1e-12)
    z = norm.transform(train.x)
    np.testing.assert_allclose(z.mean(0), 0, atol=1e-4)
    np.testing.assert_allclose(z.std(0), 1, atol=1e-4)
    assert norm.transform(val.x).mean() > 100
    np.testing.assert_allclose(norm.inverse_transform(z), train.x, rtol=1e-5, atol=1e-6)


def test_normalizer_dict_round_trip_plain_lists():
    x = np.random.default_rng(1).normal(3, 2, (500, 10, 4))
    norm = Normalizer.fit(x)  # windows: per channel over samples and frames
    assert norm.shape == (4,)
    np.testing.assert_allclose(norm.mean, x.reshape(-1, 4).mean(0))
    d = norm.to_dict()
    text = json.dumps(d)  # plain lists / floats only
    back = Normalizer.from_dict(json.loads(text))
    np.testing.assert_array_equal(back.transform(x), norm.transform(x))
    disp = Normalizer.fit(x[:, :5, :3], channel_ndim=2)
    assert disp.shape == (5, 3)


def test_normalizer_constant_channel_and_errors():
    x = np.ones((10, 3))
    x[:, 0] = np.arange(10)
    norm = Normalizer.fit(x)
    np.testing.assert_array_equal(norm.std[1:], [1.0, 1.0])
    np.testing.assert_array_equal(norm.transform(x)[:, 1:], 0)
    with pytest.raises(EctskinError, match="trailing shape"):
        norm.transform(np.ones((4, 5)))
    with pytest.raises(EctskinError, match="non-finite"):
        Normalizer.fit(np.array([[1.0], [np.nan]]))
    with pytest.raises(EctskinError, match="normalizer"):
        Normalizer.from_dict({"mean": [0.0]})
    with pytest.raises(EctskinError, match="std finite and > 0"):
        Normalizer.from_dict({"mean": [0.0], "std": [0.0]})
    with pytest.raises(EctskinError, match="same"):
        Normalizer.from_dict({"mean": [0.0, 1.0], "std": [1.0]})
