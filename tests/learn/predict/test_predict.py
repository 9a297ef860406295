"""Batched inference and the predictors for live use (ectskin.learn.predict)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ectskin._check import EctskinError
from ectskin.layout import default_layout
from ectskin.learn.checkpoint import save_checkpoint
from ectskin.learn.predict import TouchPredictor, TrackPredictor, forward_batches


def test_touch_predictor(tmp_path, make_touch_mlp):
    model = make_touch_mlp()
    names = list(default_layout().pair_names)
    save_checkpoint(tmp_path / "model.pt", model, extra={"pair_names": names})
    pred = TouchPredictor.from_run(tmp_path)
    assert (pred.n_pairs, pred.n_classes, pred.pair_names) == (28, 19, names)
    x = np.random.default_rng(0).normal(size=(6, 28)).astype(np.float32)
    probs = pred.predict(x)
    expected = torch.softmax(model(torch.from_numpy(x)), dim=1).detach().numpy()
    np.testing.assert_allclose(probs, expected, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(probs.sum(1), 1, rtol=1e-6)
    np.testing.assert_allclose(pred.predict(x[2].tolist()), probs[2], rtol=1e-6, atol=1e-7)
    assert pred.classify(x[2]) == int(probs[2].argmax())
    np.testing.assert_array_equal(pred.classify(x), probs.argmax(1))
    with pytest.raises(EctskinError, match=r"shape \(28\) or \(B, 28\), got \(27,\)"):
        pred.predict(np.zeros(27))
    bad = x[0].copy()
    bad[3] = np.nan
    with pytest.raises(EctskinError, match=f"channel {names[3]!r}"):
        pred.predict(bad)
    with pytest.raises(EctskinError, match="expected a 'c2dt' model"):
        TrackPredictor.from_run(tmp_path)


def test_track_predictor(tmp_path, make_c2dt, randomise_head):
    model = make_c2dt().eval()
    randomise_head(model)
    save_checkpoint(tmp_path / "model.pt", model)
    pred = TrackPredictor.from_run(tmp_path / "model.pt")
    assert (pred.n_pairs, pred.window, pred.n_markers, pred.prior) == (28, 10, 5, True)
    rng = np.random.default_rng(1)
    w, init = rng.normal(size=(3, 10, 28)), rng.normal(size=(3, 5, 3)) * 10
    out = pred.predict(w, init)
    expected = model(torch.tensor(w, dtype=torch.float32), torch.tensor(init, dtype=torch.float32))
    np.testing.assert_allclose(out, expected.detach().numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(pred.predict(w[1], init[1]), out[1], rtol=1e-5, atol=1e-5)
    with pytest.raises(EctskinError, match="uses prior knowledge; pass init"):
        pred.predict(w[0])
    with pytest.raises(EctskinError, match="disagree in batch size"):
        pred.predict(w, init[:2])
    with pytest.raises(EctskinError, match=r"window must have shape \(10, 28\)"):
        pred.predict(w[:, :9], init)


def test_forward_batches_equals_one_call_and_passes_none(make_c2dt, randomise_head):
    model = make_c2dt(prior=False).eval()
    randomise_head(model)
    x = np.random.default_rng(2).normal(size=(7, 10, 28)).astype(np.float32)
    with torch.no_grad():
        want = model(torch.from_numpy(x), None).numpy()
    np.testing.assert_allclose(forward_batches(model, [x, None]), want, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(
        forward_batches(model, [x, None], batch_size=3), want, rtol=1e-6, atol=1e-6
    )
    norms = forward_batches(model, [x, None], batch_size=2, output=lambda z: z.norm(dim=-1))
    np.testing.assert_allclose(norms, np.linalg.norm(want, axis=-1), rtol=1e-5)
    assert forward_batches(model, [x[:0], None], batch_size=4).shape == (0, 5, 3)


def test_predictors_refuse_a_model_for_another_skin(tmp_path, make_touch_mlp, layout):
    from dataclasses import replace

    save_checkpoint(tmp_path / "model.pt", make_touch_mlp())
    assert TouchPredictor.from_run(tmp_path, layout=layout).n_classes == 19
    with pytest.raises(EctskinError, match=r"model\.pt: config field 'n_classes' is 19"):
        TouchPredictor.from_run(tmp_path, layout=replace(layout, regions=layout.regions[:4]))
