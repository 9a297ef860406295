"""The robust recipe's augmentation (ectskin.learn.augment) checked by hand on tiny batches,
and the touch criterion that composes it (ectskin.learn.tasks.touch)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from ectskin.learn.augment import augment_touch_batch, mixup_cross_entropy, no_contact_means
from ectskin.learn.data import TouchData
from ectskin.learn.models import TouchMLP, TouchMLPConfig
from ectskin.learn.profiles import profile_settings
from ectskin.learn.tasks import TouchCriterion


def test_no_contact_means_and_the_inflation_shift_by_hand():
    # group 0: no contact, frames 1 and 3 -> mean 2; group 1: touch; group 2: no contact, 0.5
    x = np.array([[1.0] * 4, [3.0] * 4, [9.0] * 4, [0.5] * 4, [0.5] * 4], np.float32)
    x[:, 1] *= 2  # a second channel with other values: means (2, 4, 2, 2) and (.5, 1, .5, .5)
    data = TouchData(
        x=x,
        y=np.array([0, 0, 3, 0, 0]),
        group=np.array([0, 0, 1, 2, 2]),
        group_names=["rest_a", "touch", "rest_b", "rest_c"],
        n_classes=4,
        pair_names=list("abcd"),
        group_region=np.array([0, 3, 0, 0]),  # rest_c (id 3) is not in this split
    )
    means = no_contact_means(data)
    np.testing.assert_array_equal(means, [[2, 4, 2, 2], [0.5, 1, 0.5, 0.5]])
    d = means[0] - means[1]  # (1.5, 3, 1.5, 1.5)
    assert no_contact_means(TouchData(x, data.y, data.group, [], 4, [])).shape == (0, 4)

    xb = torch.arange(400, dtype=torch.float32).reshape(100, 4)
    yb = torch.zeros(100, dtype=torch.int64)
    out, ya, yb2, lam = augment_touch_batch(
        xb, yb, np.random.default_rng(5), state_means=torch.from_numpy(means)
    )
    assert ya is yb and yb2 is None and lam is None  # no mixup
    shift = (out - xb).numpy()
    a, b = np.random.default_rng(5).integers(0, 2, size=(2, 100))  # the same draws
    sign = (a < b).astype(np.float32) - (a > b)  # +d when a = 0, b = 1; -d reversed; else 0
    np.testing.assert_allclose(shift, sign[:, None] * d, atol=1e-4)
    assert set(sign.tolist()) == {-1.0, 0.0, 1.0}
    # exactly the float32 sum of x and the difference of the two drawn means
    np.testing.assert_array_equal(out.numpy(), xb.numpy() + (means[a] - means[b]))
    # fewer than two states: no shift
    same, *_ = augment_touch_batch(
        xb, yb, np.random.default_rng(5), state_means=torch.from_numpy(means[:1])
    )
    assert torch.equal(same, xb)


def test_mixup_and_label_smoothing_loss_by_hand():
    logits = torch.tensor([[2.0, 0.0, -1.0], [0.5, 1.5, 0.0]])
    ya, yb = torch.tensor([0, 1]), torch.tensor([2, 0])
    lam = torch.tensor([0.7, 0.25])
    eps, c = 0.1, 3

    def smoothed_ce(z, y):  # -sum q log softmax, q = (1 - eps) onehot + eps / C
        logp = z - np.log(np.exp(z).sum())
        q = np.full(c, eps / c)
        q[y] += 1 - eps
        return -(q * logp).sum()

    z = logits.numpy().astype(np.float64)
    hand = np.mean(
        [
            lam[i].item() * smoothed_ce(z[i], ya[i].item())
            + (1 - lam[i].item()) * smoothed_ce(z[i], yb[i].item())
            for i in range(2)
        ]
    )
    got = mixup_cross_entropy(logits, ya, yb, lam, label_smoothing=eps)
    assert got.item() == pytest.approx(hand, rel=1e-6)
    plain = np.mean([smoothed_ce(z[i], ya[i].item()) for i in range(2)])
    assert mixup_cross_entropy(logits, ya, label_smoothing=eps).item() == pytest.approx(plain)

    # the mixed batch: lambda and partner replayed from the same generator
    x = torch.randn(6, 4, generator=torch.Generator().manual_seed(0))
    y = torch.arange(6)
    out, y_a, y_b, lam = augment_touch_batch(x, y, np.random.default_rng(3), mixup_alpha=0.4)
    rng = np.random.default_rng(3)
    lam_h = rng.beta(0.4, 0.4, size=6).astype(np.float32)
    perm = rng.permutation(6)
    np.testing.assert_array_equal(lam.numpy(), lam_h)
    assert torch.equal(y_a, y) and y_b.tolist() == perm.tolist()
    hand_x = lam_h[:, None] * x.numpy() + (1 - lam_h[:, None]) * x.numpy()[perm]
    np.testing.assert_allclose(out.numpy(), hand_x, rtol=1e-6, atol=1e-6)

    # the batch statistics of Beta(0.4, 0.4): mean 1/2, variance 1 / (4 (2 alpha + 1)) = 0.1389
    _, _, y_b, lam = augment_touch_batch(
        torch.zeros(20000, 2), torch.arange(20000), np.random.default_rng(0), mixup_alpha=0.4
    )
    assert float(lam.mean()) == pytest.approx(0.5, abs=0.01)
    assert float(lam.var()) == pytest.approx(1 / 7.2, abs=0.005)
    assert sorted(y_b.tolist()) == list(range(20000))  # a permutation of the batch

    # the task's training loss is this composition (dropout off: no other randomness)
    model = TouchMLP(TouchMLPConfig(n_pairs=4, n_classes=3, dropout=0.0))
    s = profile_settings("touch", "robust")
    means = torch.tensor([[0.0, 1, 2, 3], [1.0, 1, 1, 1], [2.0, 0, 0, 0]])
    task = TouchCriterion(s, means)
    xb, yb = torch.randn(8, 4), torch.tensor([0, 1, 2, 0, 1, 2, 0, 1])
    got = task.loss(model, (xb, yb), np.random.default_rng(9))
    xa, y_a, y_b, lam = augment_touch_batch(
        xb,
        yb,
        np.random.default_rng(9),
        state_means=means,
        mixup_alpha=1.0,
        mixup_pairs="class",
        channel_gain=0.1,
    )
    want = mixup_cross_entropy(model(xa), y_a, y_b, lam, 0.1)
    assert torch.equal(got, want)
    assert torch.equal(TouchCriterion().loss(model, (xb, yb), None), F.cross_entropy(model(xb), yb))


def test_the_gain_per_channel_by_hand():
    """``channel_gain``: every value times its own exp(g), g ~ N(0, sigma²) drawn (B, P) after
    the shift's draws and before mixup's, replayed here from the same generator. Catches one
    gain per frame (all channels alike), gains drawn in another order (the shift's or mixup's
    numbers), a gain added instead of multiplied; and the spread of log-gains is sigma."""
    x = torch.arange(1, 13, dtype=torch.float32).reshape(3, 4)
    y = torch.tensor([1, 1, 2])
    means = torch.tensor([[0.0, 0, 0, 0], [1.0, 2, 3, 4]])
    out, _, y_b, lam = augment_touch_batch(
        x, y, np.random.default_rng(8), state_means=means, mixup_alpha=1.0, channel_gain=0.1
    )
    rng = np.random.default_rng(8)
    a, b = rng.integers(0, 2, size=(2, 3))
    g = np.exp(rng.normal(0.0, 0.1, size=(3, 4))).astype(np.float32)
    lam_h = rng.beta(1.0, 1.0, size=3).astype(np.float32)
    perm = rng.permutation(3)
    scaled = (x.numpy() + (means.numpy()[a] - means.numpy()[b])) * g
    want = lam_h[:, None] * scaled + (1 - lam_h[:, None]) * scaled[perm]
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-6)
    np.testing.assert_array_equal(lam.numpy(), lam_h)
    assert y_b.tolist() == y.numpy()[perm].tolist()

    ones = torch.ones(4000, 5)
    got, *_ = augment_touch_batch(
        ones, torch.zeros(4000), np.random.default_rng(0), channel_gain=0.2
    )
    logs = np.log(got.numpy())
    assert logs.std() == pytest.approx(0.2, rel=0.03) and abs(logs.mean()) < 0.01
    assert np.abs(np.corrcoef(logs[:, 0], logs[:, 1])[0, 1]) < 0.05  # channels independent
    same, *_ = augment_touch_batch(ones, torch.zeros(4000), np.random.default_rng(0))
    assert torch.equal(same, ones)  # 0: no gain
