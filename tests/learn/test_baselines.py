"""Touch and tracking baselines (ectskin.learn.baselines)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.learn.baselines import (
    majority_baseline,
    no_motion_baseline,
    ridge_baseline,
    sklearn_touch_baseline,
    touch_baselines,
    track_baselines,
)
from ectskin.learn.datasets import TouchData, TrackData


def _touch(n_per_class=(300, 120, 80, 100), seed=0, sep=3.0, n_pairs=28):
    """Gaussian blobs, one centre per class, in groups of 20 frames (a "trial" each)."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(0, sep, (len(n_per_class), n_pairs))
    x, y = [], []
    for c, n in enumerate(n_per_class):
        x.append(centres[c] + rng.normal(0, 1, (n, n_pairs)))
        y.append(np.full(n, c))
    x = np.concatenate(x).astype(np.float32)
    y = np.concatenate(y).astype(np.int64)
    group = np.arange(len(y)) // 20
    names = [f"g{i}" for i in range(group.max() + 1)]
    return TouchData(x, y, group, names, len(n_per_class), [f"p{j}" for j in range(n_pairs)])


def _split_touch(d, seed=1):
    rng = np.random.default_rng(seed)
    test = rng.random(d.n_samples) < 0.3

    def pick(m):
        return TouchData(d.x[m], d.y[m], d.group[m], d.group_names, d.n_classes, d.pair_names)

    return pick(~test), pick(test)


def test_touch_baselines_beat_chance_on_separable_data():
    train, test = _split_touch(_touch())
    res = touch_baselines(train, test, seed=0, n_jobs=1)
    assert set(res) == {"majority", "logreg", "random_forest", "knn"}
    chance = np.bincount(test.y).max() / test.n_samples  # the majority rate, ~0.5
    for name in ("logreg", "random_forest", "knn"):
        r = res[name]
        assert r.accuracy > 0.95 > chance + 0.3, (name, r.accuracy)
        assert r.pred.shape == (test.n_samples,) and r.pred.dtype == np.int64
        assert r.n_misclassified == int(np.sum(r.pred != test.y))
        assert r.accuracy == pytest.approx(1 - r.n_misclassified / test.n_samples)
        m = r.to_metrics()
        assert m["n_test_frames"] == test.n_samples and "pred" not in m


def test_majority_baseline_by_hand():
    y_train = np.array([2, 2, 1, 0, 2, 1])
    y_test = np.array([2, 1, 2, 2, 0])

    def mk(y):
        n = len(y)
        return TouchData(
            np.zeros((n, 3), np.float32), y, np.zeros(n, np.int64), ["a"], 3, list("xyz")
        )

    r = majority_baseline(mk(y_train), mk(y_test))
    assert r.params["class"] == 2
    np.testing.assert_array_equal(r.pred, [2, 2, 2, 2, 2])
    assert r.n_misclassified == 2 and r.accuracy == pytest.approx(0.6)


def test_touch_subsample_and_errors():
    train, test = _split_touch(_touch())
    r = sklearn_touch_baseline("knn", train, test, max_train=100)
    assert r.n_train_used == 100 and r.accuracy > 0.9
    with pytest.raises(EctskinError, match="allowed values"):
        sklearn_touch_baseline("svm", train, test)
    with pytest.raises(EctskinError, match="unknown touch baseline"):
        touch_baselines(train, test, methods=["majority", "svm"])
    other = _touch(n_pairs=5)
    with pytest.raises(EctskinError, match="28 channels, test data 5"):
        majority_baseline(train, other)
    # a one-class training set is answered with that class, not a scikit-learn traceback
    one = TouchData(
        train.x[:10],
        np.zeros(10, np.int64),
        train.group[:10],
        train.group_names,
        4,
        train.pair_names,
    )
    assert np.all(sklearn_touch_baseline("logreg", one, test).pred == 0)


# --------------------------------------------------------------------------- tracking
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
    r = ridge_baseline(train, test)
    nm = no_motion_baseline(test)
    assert r.ad_mm_mean < 0.05 * nm.ad_mm_mean, (r.ad_mm_mean, nm.ad_mm_mean)
    assert r.pred.shape == test.y.shape
    assert r.params["alpha"] <= 10  # CV prefers little shrinkage on a noise-free linear law


def test_ridge_matches_scikit_learn_for_a_fixed_alpha():
    from sklearn.linear_model import Ridge
    from sklearn.preprocessing import StandardScaler

    train, test = _split_track(_track(noise=2.0, seed=4))
    r = ridge_baseline(train, test, alpha=30.0)

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
    r = ridge_baseline(train, test)
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
        ridge_baseline(_track(prior=True), test)
