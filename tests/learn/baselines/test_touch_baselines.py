"""Touch baselines (ectskin.learn.baselines.touch)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.learn.baselines.touch import (
    majority_baseline,
    sklearn_touch_baseline,
    touch_baselines,
)
from ectskin.learn.data import TouchData


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
