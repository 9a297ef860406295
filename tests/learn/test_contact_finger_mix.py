"""The finger mix of the contact training (:mod:`ectskin.learn.tasks.contact_mix`): the signals
of hovering and touching fingers taken from hand-made windows, the mixed batch against a
frame-by-frame reference, and the criterion's loss of a mixed batch against the plain loss of
that batch built by hand."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from ectskin import EctskinError
from ectskin.learn.data.contact import contact_dataset
from ectskin.learn.models.contact import ContactNet, ContactNetConfig
from ectskin.learn.tasks import get_task
from ectskin.learn.tasks.contact import ContactCriterion
from ectskin.learn.tasks.contact_mix import (
    MIX_APART_MM,
    MIX_FAR_MM,
    MIX_HOVER_MAX_MM,
    MIX_TOUCH_SHARE,
    FingerSignals,
    finger_signals,
    mix_fingers,
)

NAN = np.nan


def _data(layout, contact_recording):
    """Three trials of four frames, windows of 2 frames, x = the sample's row number: trial 1
    starts with its finger 100 mm away, hovers at 10 mm (frame 1), touches (frame 2) and is
    40 mm high (frame 3, above the mix's hover limit); trial 2 starts in contact (no window
    without a finger) and hovers at 5 mm; trial 3 starts without a finger (NaN), hovers at
    exactly the limit (frame 1), touches (frame 2) and hovers at 2 mm (frame 3). The
    no-contact trial 0 has no finger."""
    d = contact_dataset(contact_recording(layout, n_frames=4, n_trials=3), window=2)
    assert d.n_groups == 4 and d.n_samples == 16
    height = np.array(
        [NAN] * 4
        + [100.0, 10.0, 0.0, 40.0]
        + [0.0, 5.0, 0.0, 0.0]
        + [NAN, MIX_HOVER_MAX_MM, 0.0, 2.0]
    )
    count = np.where(height == 0, 1, 0)
    x = np.arange(16, dtype=np.float32)[:, None, None] * np.ones((1, 2, d.n_pairs), np.float32)
    return dataclasses.replace(d, x=x, count=count, height=height.astype(np.float32))


def test_finger_signals_by_hand(layout, contact_recording):
    d = _data(layout, contact_recording)
    s = finger_signals(d)
    # hover: trial 1 frame 1 less frame 0 (rows 5 - 4), trial 3 frames 1 and 3 less frame 0
    # (13 - 12, 15 - 12); trial 2 gives none (it starts in contact), nor the 40 mm frame
    assert s.hover.shape == (3, 2, d.n_pairs) and s.hover.dtype == torch.float32
    np.testing.assert_array_equal(s.hover[:, 0, 0].numpy(), [1.0, 1.0, 3.0])
    # touch: rows 6 - 4 and 14 - 12, with the finger's labels of those rows
    np.testing.assert_array_equal(s.touch[:, 1, -1].numpy(), [2.0, 2.0])
    np.testing.assert_array_equal(s.face.numpy(), d.face[[6, 14], 0])
    np.testing.assert_allclose(s.uv.numpy(), d.uv[[6, 14], 0])
    np.testing.assert_allclose(s.force.numpy(), d.force[[6, 14], 0])
    assert len(s) == 2
    # a first frame with its finger closer than MIX_FAR_MM is no window without a finger:
    # trials 1 and 3 starting 50 mm above the skin give nothing, unless the limit is lower
    assert MIX_FAR_MM > 50.0
    near = d.height.copy()
    near[[4, 12]] = 50.0
    near_d = dataclasses.replace(d, height=near)
    assert len(finger_signals(near_d)) == 0
    np.testing.assert_array_equal(
        finger_signals(near_d, far_mm=40.0).hover[:, 0, 0].numpy(), [1.0, 1.0, 3.0]
    )
    # a seeded subsample of at most max_signals of each kind
    a, b = finger_signals(d, max_signals=2, seed=3), finger_signals(d, max_signals=2, seed=3)
    assert a.hover.shape[0] == 2 and a.touch.shape[0] == 2
    torch.testing.assert_close(a.hover, b.hover)


def _signals() -> FingerSignals:
    """Two hovering fingers (signals 100, 200) and two touching ones (1000 on face 0 at
    (0, 50); 2000 on face 0 at (5, 55), 7 mm from the batch's first fingers: never added)."""
    ones = torch.ones(1, 2, 3)
    return FingerSignals(
        hover=torch.cat([100 * ones, 200 * ones]),
        touch=torch.cat([1000 * ones, 2000 * ones]),
        face=torch.tensor([0, 0]),
        uv=torch.tensor([[0.0, 50.0], [5.0, 55.0]]),
        force=torch.tensor([0.7, 0.9]),
    )


def _batch(n: int):
    """n windows: counts cycling 0, 1, 1, 2, 1; the first finger on face 1 at (0, 50) (so every
    touch signal is on another face) except every fifth from row 2 on, on face 0 at (0, 52)."""
    count = torch.tensor([0, 1, 1, 2, 1] * (n // 5))
    face = torch.full((n, 2), -1)
    face[count > 0, 0] = 1
    face[2::5, 0] = 0
    face[count == 2, 1] = 0
    uv = torch.zeros(n, 2, 2)
    uv[count > 0, 0] = torch.tensor([0.0, 50.0])
    uv[2::5, 0] = torch.tensor([0.0, 52.0])
    force = torch.where(face >= 0, 1.0, 0.0)
    x = torch.arange(n, dtype=torch.float32)[:, None, None].expand(n, 2, 3).clone()
    return x, count, face, uv, force, torch.zeros(n)


def test_mix_fingers_against_a_frame_by_frame_reference():
    n, s = 60, _signals()
    batch = _batch(n)
    x, count, face, uv, force, hover = mix_fingers(batch, s, 0.8, np.random.default_rng(11))
    # the reference: the same random numbers, drawn in the documented order, frame by frame
    rng = np.random.default_rng(11)
    pick, as_touch = rng.random(n) < 0.8, rng.random(n) < MIX_TOUCH_SHARE
    jh, jt = rng.integers(0, 2, n), rng.integers(0, 2, n)
    seen = set()
    for i in range(n):
        x0, c0, f0, uv0, F0 = (t[i] for t in batch[:5])
        near = s.face[jt[i]] == f0[0] and float((s.uv[jt[i]] - uv0[0]).norm()) < MIX_APART_MM
        if not pick[i] or c0 != 1:
            case, want_x, want_c = "kept", x0, c0
        elif not as_touch[i]:
            case, want_x, want_c = "hover", x0 + s.hover[jh[i]], c0
        elif near:
            case, want_x, want_c = "too close", x0, c0
        else:
            case, want_x, want_c = "touch", x0 + s.touch[jt[i]], 2
        seen.add(case)
        torch.testing.assert_close(x[i], want_x)
        assert count[i] == want_c
        if case == "touch":
            assert face[i].tolist() == [f0[0], s.face[jt[i]]]
            torch.testing.assert_close(uv[i], torch.stack([uv0[0], s.uv[jt[i]]]))
            torch.testing.assert_close(force[i], torch.stack([F0[0], s.force[jt[i]]]))
        else:  # the labels stay
            assert face[i].tolist() == f0.tolist()
            torch.testing.assert_close(uv[i], uv0)
            torch.testing.assert_close(force[i], F0)
    assert seen == {"kept", "hover", "touch", "too close"}  # the case reaches every branch
    torch.testing.assert_close(hover, batch[5])
    # the batch itself is left as it was
    torch.testing.assert_close(batch[0], _batch(n)[0])
    assert batch[2].tolist() == _batch(n)[2].tolist()


def test_the_criterion_mixes_training_batches_only():
    """loss(batch, rng) is the plain loss of the batch mix_fingers makes with the same random
    numbers; without them (validation), or with probability 0, the plain loss."""
    torch.manual_seed(0)
    model = ContactNet(ContactNetConfig(n_pairs=3, window=2, n_faces=2)).eval()  # no dropout
    batch, s = _batch(20), _signals()
    crit = ContactCriterion(model, 20.0, signals=s, finger_mix=0.5)
    assert crit.augments
    got = crit.loss(model, batch, np.random.default_rng(5))
    mixed = mix_fingers(batch, s, 0.5, np.random.default_rng(5))
    torch.testing.assert_close(got, crit._per_sample(model, mixed)[0].mean())
    plain = crit._per_sample(model, batch)[0].mean()
    assert not torch.allclose(got, plain)
    torch.testing.assert_close(crit.loss(model, batch, None), plain)
    off = ContactCriterion(model, 20.0, signals=s, finger_mix=0.0)
    assert not off.augments and off.signals is None
    torch.testing.assert_close(off.loss(model, batch, np.random.default_rng(5)), plain)
    with pytest.raises(EctskinError, match=r"finger_mix must be a probability in \[0, 1\]"):
        ContactCriterion(model, 20.0, signals=s, finger_mix=1.5)


def test_the_task_builds_the_mix_from_its_settings(layout, contact_recording):
    d = _data(layout, contact_recording)
    task = get_task("contact")
    model = task.build_model(d, None)
    task.fit_normalization(model, d)
    mix = SimpleNamespace(inflation_shift=False, finger_mix=0.25)
    on = task.criterion(model, mix, d, "cpu")
    assert on.finger_mix == 0.25 and on.augments
    torch.testing.assert_close(on.signals.touch, finger_signals(d).touch)
    # settings without the field, or a training split without a hovering finger: no mix
    off = task.criterion(model, SimpleNamespace(inflation_shift=False, finger_mix=0.0), d, "cpu")
    assert off.signals is None and not off.augments
    none = dataclasses.replace(d, height=np.where(d.count > 0, 0.0, NAN).astype(np.float32))
    crit = task.criterion(model, mix, none, "cpu")
    assert crit.signals is None and any("finger mix skipped" in m for m in crit.notes)
