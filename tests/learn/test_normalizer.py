"""The training-set normalisation (ectskin.learn.normalizer)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.learn.data import touch_dataset
from ectskin.learn.normalizer import Normalizer
from ectskin.learn.splits import split_groups


def test_normalizer_fitted_on_train_only(make_recording):
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
