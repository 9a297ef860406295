"""Tracking baselines (ectskin.learn.baselines.track)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.learn.baselines.track import (
    no_motion_baseline,
    track_baselines,
    track_ridge_baseline,
)
from ectskin.learn.data import TrackData


def _track(n_groups=12, n_frames=40, k=4, n_pairs=6, n_markers=3, seed=0, prior=True, noise=0.0):
    """Displacement a linear function of the last frame's readouts (+ optional noise)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(0, 5, (n_pairs, n_markers * 3))
    x = rng.normal(0, 1, (n_groups * n_frames, k, n_pairs)).astype(np.float32)
    init = np.repeat(rng.normal(0, 50, (n_groups, n_markers, 3)), n_frames, axis=0)
    disp = (x[:, -1] @ a).reshape(-1, n_markers, 3) + noise * rng.normal(
        0, 1, (len(x), n_markers, 3)
    )
    y = init + disp
    return TrackData(
        x=x,
        init=(init if prior else np.zeros_like(init)).astype(np.float32),
        y=y.astype(np.float32),
        group=np.repeat(np.arange(n_groups), n_frames),
        frame=np.tile(np.arange(n_frames), n_groups),
        group_names=[f"g{i}" for i in range(n_groups)],
        electrode_desc=np.zeros((4, 6), np.float32),
        pairs=np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]),
        prior=prior,
    )


def _split_track(d, test_groups=(9, 10, 11)):
    return d.select([g for g in range(d.n_groups) if g not in test_groups]), d.select(
        list(test_groups)
    )


def test_no_motion_ad_is_mean_displacement_norm():
    d = _track()
    r = no_motion_baseline(d)
    norms = np.linalg.norm(d.y.astype(np.float64) - d.init, axis=-1)  # (N, M) by hand
    assert r.ad_mm_mean == pytest.approx(norms.mean(), rel=1e-6)
    assert r.ad_mm_std == pytest.approx(norms.std(), rel=1e-6)
    np.testing.assert_array_equal(r.pred, d.init)


def test_average_distance_two_samples_by_hand():
    d = _track(n_groups=1, n_frames=2, n_markers=1)
    d.init[:] = 0
    d.y[0, 0] = [3, 4, 0]  # distance 5
    d.y[1, 0] = [0, 0, 1]  # distance 1
    r = no_motion_baseline(d)
    assert r.ad_mm_mean == pytest.approx(3.0) and r.ad_mm_std == pytest.approx(2.0)


def test_ridge_learns_a_linear_displacement():
    train, test = _split_track(_track(noise=0.1))
    r = track_ridge_baseline(train, test)
    nm = no_motion_baseline(test)
    assert r.ad_mm_mean < 0.05 * nm.ad_mm_mean, (r.ad_mm_mean, nm.ad_mm_mean)
    assert r.pred.shape == test.y.shape
    assert r.params["alpha"] <= 10  # CV prefers little shrinkage on a noise-free linear law


def test_ridge_matches_scikit_learn_for_a_fixed_alpha():
    from sklearn.linear_model import Ridge
    from sklearn.preprocessing import StandardScaler

    train, test = _split_track(_track(noise=2.0, seed=4))
    r = track_ridge_baseline(train, test, alpha=30.0)

    def feats(d):
        flat = [d.x.reshape(d.n_samples, -1), d.init.reshape(d.n_samples, -1)]
        return np.concatenate(flat, axis=1).astype(np.float64)

    sc = StandardScaler().fit(feats(train))
    ref = Ridge(alpha=30.0).fit(
        sc.transform(feats(train)),
        (train.y - train.init).reshape(train.n_samples, -1).astype(np.float64),
    )
    want = ref.predict(sc.transform(feats(test))).reshape(test.y.shape) + test.init
    np.testing.assert_allclose(r.pred, want, rtol=1e-4, atol=1e-3)


def test_ridge_cv_shrinks_when_features_are_noise():
    d = _track(noise=0.0)
    d.x[:] = np.random.default_rng(9).normal(0, 1, d.x.shape)  # readouts unrelated to motion
    train, test = _split_track(d)
    r = track_ridge_baseline(train, test)
    assert r.params["alpha"] >= 1e3


def test_prior_false_baselines():
    train, test = _split_track(_track(prior=False))
    with pytest.raises(EctskinError, match="prior=True"):
        no_motion_baseline(test)
    res = track_baselines(train, test)
    assert set(res) == {"mean_pose", "ridge"}
    mean = train.y.astype(np.float64).mean(0)
    np.testing.assert_allclose(
        res["mean_pose"].pred, np.broadcast_to(mean, test.y.shape), rtol=1e-6
    )
    with pytest.raises(EctskinError, match="unknown tracking baseline"):
        track_baselines(train, test, methods=["kalman"])
    with pytest.raises(EctskinError, match="differ in 'prior'"):
        track_ridge_baseline(_track(prior=True), test)
