"""Fine-tuning a trained run on another skin (``--init-from RUN``): the normaliser is the base
run's, a fine-tune of 0 epochs answers exactly as the base run, the kept weights are never
worse than the base on the new validation split, and the refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from press_data import press_npz  # tests/learn/press_data.py

from ectskin import EctskinError
from ectskin.io import write_recording
from ectskin.io.generic import load_generic
from ectskin.learn.checkpoint import load_checkpoint
from ectskin.learn.data.contact import contact_dataset
from ectskin.learn.normalizer import Normalizer
from ectskin.learn.predict import ContactPredictor, TouchPredictor
from ectskin.learn.train import TrainConfig, train_from_recording

QUICK = {"profile": "quick", "progress": False, "window": 1}
#: buffers that are no normaliser: the force σ's scale, set on each epoch's validation pass
NOT_NORMALISER = ("force_sigma_scale",)


def _skin(tmp_path, name, **kw):
    """A press recording of one skin (seed: its channels' spots, gains and rest values)."""
    rec = load_generic(press_npz(tmp_path / f"{name}.npz", **kw))
    path = tmp_path / f"{name}.h5"
    write_recording(rec, path)
    return rec, path


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("base")
    _, path = _skin(tmp, "a", n_presses=40, n_channels=15, seed=1)
    run = tmp / "run"
    train_from_recording("contact", path, run, TrainConfig(epochs=3, **QUICK))
    return run


def _buffers(model):
    return {k: v.clone() for k, v in model.named_buffers()}


def test_zero_epochs_reproduce_the_base_bit_for_bit(tmp_path, base_run, cli):
    new, path = _skin(tmp_path, "b", n_presses=12, n_channels=15, seed=5)
    run = tmp_path / "ft0"
    argv = ["train", "contact", str(path), "-o", str(run), "--init-from", str(base_run)]
    assert cli([*argv, "--window", "1", "--epochs", "0", "--profile", "quick"]) == 0
    x = contact_dataset(new, window=1).x
    base = ContactPredictor.from_run(base_run).predict(x)
    tuned = ContactPredictor.from_run(run).predict(x)
    np.testing.assert_array_equal(tuned, base)
    _, _, payload = load_checkpoint(run / "model.pt")
    assert payload["extra"]["epoch"] == 0
    assert payload["extra"]["init_from"] == str((base_run / "model.pt").resolve())
    assert (
        json.loads((run / "config.json").read_text())["init_from"] == payload["extra"]["init_from"]
    )


def test_init_from_keeps_the_normaliser_and_never_keeps_worse_weights(tmp_path, base_run):
    new, path = _skin(tmp_path, "b", n_presses=20, n_channels=15, seed=5, noise=0.004)
    b_model, _, b_payload = load_checkpoint(base_run / "model.pt")
    zero = train_from_recording(
        "contact", path, tmp_path / "ft0", TrainConfig(epochs=0, init_from=str(base_run), **QUICK)
    )
    s = train_from_recording(
        "contact", path, tmp_path / "ft", TrainConfig(epochs=3, init_from=str(base_run), **QUICK)
    )
    model, _, payload = load_checkpoint(tmp_path / "ft" / "model.pt")
    assert payload["normalizer"] == b_payload["normalizer"]
    for k, v in _buffers(b_model).items():
        if k in NOT_NORMALISER:
            continue
        torch.testing.assert_close(_buffers(model)[k], v, rtol=0, atol=0)
    # not the statistics of the new frames: those differ
    refit = Normalizer.fit(contact_dataset(new, window=1).x)
    assert not np.allclose(refit.mean, payload["normalizer"]["x"]["mean"])
    # the weights did move, and the kept ones are no worse on validation than the base
    assert s["best_epoch"] > 0
    assert not all(
        torch.equal(a, b) for a, b in zip(model.parameters(), b_model.parameters(), strict=True)
    )
    assert s["best_val_metric"] <= zero["best_val_metric"]


def test_fine_tuning_refusals(tmp_path, base_run):
    _, path = _skin(tmp_path, "c", n_presses=6, n_channels=10, seed=5)
    with pytest.raises(
        EctskinError, match=r"reads 15 electrode pairs, the new data has 10; .*pair"
    ):
        train_from_recording(
            "contact", path, tmp_path / "x", TrainConfig(epochs=1, init_from=str(base_run), **QUICK)
        )
    _, path = _skin(tmp_path, "d", n_presses=6, n_channels=15, seed=5)
    with pytest.raises(EctskinError, match=r"windows of 1 frames, the new data 3; pass --window 1"):
        train_from_recording(
            "contact",
            path,
            tmp_path / "x",
            TrainConfig(epochs=1, init_from=str(base_run), **{**QUICK, "window": 3}),
        )
    with pytest.raises(EctskinError, match=r"fits a classical contact model alone"):
        train_from_recording(
            "contact",
            path,
            tmp_path / "x",
            TrainConfig(init_from=str(base_run), model="knn", **QUICK),
        )
    with pytest.raises(EctskinError, match=r"no model file"):
        train_from_recording(
            "contact", path, tmp_path / "x", TrainConfig(init_from=str(tmp_path), **QUICK)
        )
    with pytest.raises(EctskinError, match=r"holds a 'contact_net' model, expected a 'touch_mlp'"):
        train_from_recording(
            "touch", path, tmp_path / "x", TrainConfig(init_from=str(base_run), profile="quick")
        )
    with pytest.raises(EctskinError, match=r"'epochs' must be a positive integer"):
        train_from_recording("contact", path, tmp_path / "x", TrainConfig(epochs=0, **QUICK))


def test_touch_zero_epochs_reproduce_the_base(tmp_path, make_recording):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_recording(make_recording(n_frames=20, seed=0), a)
    write_recording(make_recording(n_frames=20, seed=3), b)
    counts = (4, 1, 1)
    config = TrainConfig(profile="quick", epochs=2, progress=False, counts=counts)
    train_from_recording("touch", a, tmp_path / "base", config)
    ft = TrainConfig(
        profile="quick", epochs=0, progress=False, counts=counts, init_from=str(tmp_path / "base")
    )
    train_from_recording("touch", b, tmp_path / "ft", ft)
    frames = np.random.default_rng(0).normal(0, 0.1, (50, 28))
    base = TouchPredictor.from_run(tmp_path / "base").predict(frames)
    np.testing.assert_array_equal(TouchPredictor.from_run(tmp_path / "ft").predict(frames), base)


def test_an_epoch_worse_than_the_base_does_not_replace_it(tmp_path, base_run):
    """A learning rate of 10 wrecks the weights in one epoch: the base (epoch 0) stays kept."""
    new, path = _skin(tmp_path, "b", n_presses=12, n_channels=15, seed=5)
    config = TrainConfig(epochs=1, init_from=str(base_run), settings={"lr": 10.0}, **QUICK)
    s = train_from_recording("contact", path, tmp_path / "ft", config)
    rows = (tmp_path / "ft" / "metrics.csv").read_text().splitlines()
    assert len(rows) == 2 and s["best_epoch"] == 0  # one epoch ran; it was not kept
    x = contact_dataset(new, window=1).x
    np.testing.assert_array_equal(
        ContactPredictor.from_run(tmp_path / "ft").predict(x),
        ContactPredictor.from_run(base_run).predict(x),
    )
