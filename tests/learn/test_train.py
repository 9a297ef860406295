"""Training (ectskin.learn.train, ectskin.learn.engine): files, best weights, resume,
determinism, errors, sharding, and train_from_recording on a small recording file."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import torch

from ectskin._check import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.layout import default_layout
from ectskin.learn.checkpoint import load_checkpoint, read_checkpoint
from ectskin.learn.engine import epoch_indices
from ectskin.learn.runfiles import read_metrics
from ectskin.learn.train import TrainConfig, train, train_from_recording

LAYOUT = default_layout()


# ============================================================================ touch
def test_touch_training_writes_the_run_and_keeps_the_best_weights(tmp_path, blobs):
    tr, va, te = blobs(20, 50, seed=0), blobs(5, 50, seed=1), blobs(5, 50, seed=2)
    out = tmp_path / "run"
    s = train(
        "touch",
        tr,
        va,
        out,
        TrainConfig(profile="quick", epochs=6, settings={"step_size": 2}, progress=False),
    )
    assert sorted(p.name for p in out.iterdir()) == [
        "config.json",
        "last.pt",
        "metrics.csv",
        "model.pt",
        "split.json",
    ]
    rows = read_metrics(out / "metrics.csv")
    with open(out / "metrics.csv") as fh:
        assert next(csv.reader(fh)) == [
            "epoch",
            "train_loss",
            "val_loss",
            "val_metric",
            "lr",
            "seconds",
        ]
    assert [r["epoch"] for r in rows] == [1, 2, 3, 4, 5, 6]
    # StepLR: lr 1e-3 divided by 1.2 every step_size (2) epochs
    assert [r["lr"] for r in rows] == pytest.approx([1e-3 / 1.2 ** (e // 2) for e in range(6)])
    best = min(range(6), key=lambda i: rows[i]["val_loss"])
    assert s["best_epoch"] == best + 1 and s["best_val_loss"] == pytest.approx(
        rows[best]["val_loss"]
    )
    model, config, payload = load_checkpoint(out / "model.pt", kind="touch_mlp", n_pairs=28)
    assert payload["extra"]["epoch"] == best + 1 and config.n_classes == 5
    # the model takes calibrated readouts: normalisation fitted on train only, held inside
    np.testing.assert_allclose(model.x_mean.numpy(), tr.x.mean(0), atol=1e-6)
    np.testing.assert_allclose(payload["normalizer"]["x"]["std"], tr.x.std(0), rtol=1e-4)
    with torch.no_grad():
        acc = (model(torch.from_numpy(te.x)).argmax(1).numpy() == te.y).mean()
    assert acc > 0.97
    # val_metric is the accuracy of the validation set
    with torch.no_grad():
        vacc = (model(torch.from_numpy(va.x)).argmax(1).numpy() == va.y).mean()
    assert rows[best]["val_metric"] == pytest.approx(vacc)
    split = json.loads((out / "split.json").read_text())
    assert split == {"train": tr.group_names, "val": va.group_names}
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["task"] == "touch" and cfg["settings"]["epochs"] == 6 and cfg["n_train"] == 1000


def test_resume_equals_an_uninterrupted_run(tmp_path, blobs):
    tr, va = blobs(10, 40, seed=0), blobs(4, 40, seed=1)
    straight = train(
        "touch",
        tr,
        va,
        tmp_path / "a",
        TrainConfig(profile="quick", epochs=4, seed=3, settings={"step_size": 1}, progress=False),
    )
    first = train(
        "touch",
        tr,
        va,
        tmp_path / "b",
        TrainConfig(profile="quick", epochs=2, seed=3, settings={"step_size": 1}, progress=False),
    )
    assert first["epochs_run"] == 2
    resumed = train(
        "touch",
        tr,
        va,
        tmp_path / "b",
        TrainConfig(profile="quick", epochs=4, seed=3, settings={"step_size": 1}, progress=False),
    )
    assert resumed["resumed_from"] == 2 and resumed["epochs_run"] == 2
    for name in ("last.pt", "model.pt"):
        a = read_checkpoint(tmp_path / "a" / name)["state_dict"]
        b = read_checkpoint(tmp_path / "b" / name)["state_dict"]
        for k in a:
            assert torch.equal(a[k], b[k]), (name, k)
    ra, rb = (
        read_metrics(tmp_path / "a" / "metrics.csv"),
        read_metrics(tmp_path / "b" / "metrics.csv"),
    )
    for x, y in zip(ra, rb, strict=True):
        assert {k: v for k, v in x.items() if k != "seconds"} == {
            k: v for k, v in y.items() if k != "seconds"
        }
    assert straight["best_epoch"] == resumed["best_epoch"]
    # a finished run is not trained again
    again = train(
        "touch",
        tr,
        va,
        tmp_path / "b",
        TrainConfig(profile="quick", epochs=4, seed=3, settings={"step_size": 1}, progress=False),
    )
    assert again["epochs_run"] == 0 and again["best_val_loss"] == resumed["best_val_loss"]


def test_resume_drops_metrics_rows_written_after_last_checkpoint(tmp_path, blobs):
    tr, va = blobs(10, 20, seed=0), blobs(4, 20, seed=1)
    kw = {"profile": "quick", "progress": False}
    train("touch", tr, va, tmp_path, TrainConfig(epochs=2, **kw))
    with open(tmp_path / "metrics.csv", "a") as fh:  # a crash after the CSV, before last.pt
        fh.write("3,9,9,0,0.001,1\n")
    train("touch", tr, va, tmp_path, TrainConfig(epochs=3, **kw))
    rows = read_metrics(tmp_path / "metrics.csv")
    assert [r["epoch"] for r in rows] == [1, 2, 3] and rows[2]["train_loss"] != 9


def test_resume_refuses_other_settings_or_data(tmp_path, blobs):
    tr, va = blobs(10, 20, seed=0), blobs(4, 20, seed=1)
    train("touch", tr, va, tmp_path, TrainConfig(profile="quick", epochs=1, progress=False))
    with pytest.raises(EctskinError, match=r"last\.pt: training settings differ \(batch_size"):
        train(
            "touch",
            tr,
            va,
            tmp_path,
            TrainConfig(profile="quick", epochs=2, batch_size=64, progress=False),
        )
    with pytest.raises(EctskinError, match="different training data"):
        train(
            "touch",
            blobs(10, 20, seed=5),
            va,
            tmp_path,
            TrainConfig(profile="quick", epochs=2, progress=False),
        )
    with pytest.raises(EctskinError, match="seed"):
        train(
            "touch",
            tr,
            va,
            tmp_path,
            TrainConfig(profile="quick", epochs=2, seed=1, progress=False),
        )
    with pytest.raises(EctskinError, match="model differs"):
        train(
            "touch",
            tr,
            va,
            tmp_path,
            TrainConfig(profile="quick", epochs=2, progress=False, model_options={"hidden": 64}),
        )
    # resume=False starts over
    s = train(
        "touch",
        tr,
        va,
        tmp_path,
        TrainConfig(profile="quick", epochs=1, batch_size=64, resume=False, progress=False),
    )
    assert s["resumed_from"] == 0 and s["epochs_run"] == 1


def test_training_is_deterministic_for_a_seed(tmp_path, blobs):
    tr, va = blobs(10, 30, seed=0), blobs(4, 30, seed=1)
    kw = {"profile": "quick", "epochs": 2, "progress": False}
    train("touch", tr, va, tmp_path / "a", TrainConfig(seed=7, **kw))
    train("touch", tr, va, tmp_path / "b", TrainConfig(seed=7, **kw))
    train("touch", tr, va, tmp_path / "c", TrainConfig(seed=8, **kw))
    sd = {k: read_checkpoint(tmp_path / k / "last.pt")["state_dict"] for k in "abc"}
    assert all(torch.equal(sd["a"][k], sd["b"][k]) for k in sd["a"])
    assert not torch.equal(sd["a"]["net.0.weight"], sd["c"]["net.0.weight"])


def test_bad_inputs_are_clear_errors(tmp_path, blobs):
    tr, va = blobs(6, 10, seed=0), blobs(2, 10, seed=1)
    bad = blobs(6, 10, seed=0)
    bad.x[23, 4] = np.nan
    with pytest.raises(EctskinError, match=r"train_data: x of trial 's0-t2' \(sample 23\)"):
        train("touch", bad, va, tmp_path, TrainConfig(epochs=1, progress=False))
    bad = blobs(6, 10, seed=0)
    bad.y[5] = 9
    with pytest.raises(EctskinError, match="has label 9, expected 0..4"):
        train("touch", bad, va, tmp_path, TrainConfig(epochs=1, progress=False))
    narrow = blobs(2, 10, seed=1)
    narrow.x = narrow.x[:, :27]
    with pytest.raises(EctskinError, match="disagree"):
        train("touch", tr, narrow, tmp_path, TrainConfig(epochs=1, progress=False))
    with pytest.raises(EctskinError, match="allowed values are 'touch', 'track'"):
        train("shape", tr, va, tmp_path, TrainConfig(epochs=1, progress=False))
    with pytest.raises(EctskinError, match="TrackData"):
        train("track", tr, va, tmp_path, TrainConfig(epochs=1, progress=False))


def test_non_finite_loss_stops_naming_epoch_and_batch(tmp_path, blobs):
    tr, va = blobs(10, 40, seed=0), blobs(4, 40, seed=1)
    with pytest.raises(EctskinError, match=r"non-finite loss .* at epoch 1, batch \d+ of 13"):
        train(
            "touch",
            tr,
            va,
            tmp_path,
            TrainConfig(epochs=3, batch_size=32, settings={"lr": 1e38}, progress=False),
        )


# ============================================================================ track
def test_track_training_beats_no_motion(tmp_path, displacements, small_c2dt):
    tr, va = displacements(6, 200, seed=0), displacements(2, 200, seed=1)
    s = train(
        "track",
        tr,
        va,
        tmp_path,
        TrainConfig(
            profile="quick",
            epochs=8,
            batch_size=64,
            settings={"step_size": 4, "samples_per_epoch": None, "val_samples": None},
            model_options=small_c2dt,
            progress=False,
        ),
    )
    assert s["metric"] == "ad_mm"
    no_motion = np.linalg.norm(va.y - va.init, axis=-1).mean()
    assert s["best_val_metric"] < 0.5 * no_motion, (s["best_val_metric"], no_motion)
    model, config, _ = load_checkpoint(tmp_path / "model.pt", kind="c2dt")
    assert (config.window, config.n_markers, config.prior, config.desc_dim) == (4, 5, True, 6)
    np.testing.assert_array_equal(model.pairs.numpy(), LAYOUT.pairs)
    # val_metric is Eq. 3 on the validation set and val_loss the MSE per coordinate, mm²
    with torch.no_grad():
        pred = model(torch.from_numpy(va.x), torch.from_numpy(va.init)).numpy()
    rows = read_metrics(tmp_path / "metrics.csv")
    best = rows[s["best_epoch"] - 1]
    assert best["val_metric"] == pytest.approx(
        np.linalg.norm(pred - va.y, axis=-1).mean(), rel=1e-4
    )
    assert best["val_loss"] == pytest.approx(np.mean((pred - va.y) ** 2), rel=1e-4)


def test_track_without_prior_and_with_subsampled_epochs(
    tmp_path, monkeypatch, displacements, small_c2dt
):
    """The quick profile's epoch subsampling: each epoch trains on ``samples_per_epoch`` windows,
    a fresh random subset every epoch, and validates on the same ``val_samples`` windows. The
    criterion is spied on, so the test fails when training ignores either setting (e.g.
    ``samples=None`` passed to ``epoch_indices``, or ``val_indices`` given ``None``), whatever
    the loop does with them."""
    from ectskin.learn.tasks import TrackCriterion

    seen: list[tuple[str, list[float]]] = []  # ("train" | "val", first value of each window)
    loss, eval_sums = TrackCriterion.loss, TrackCriterion.eval_sums

    def spy_loss(self, model, batch, rng):
        seen.append(("train", batch[0][:, 0, 0].tolist()))
        return loss(self, model, batch, rng)

    def spy_eval(self, model, batch):
        seen.append(("val", batch[0][:, 0, 0].tolist()))
        return eval_sums(self, model, batch)

    monkeypatch.setattr(TrackCriterion, "loss", spy_loss)
    monkeypatch.setattr(TrackCriterion, "eval_sums", spy_eval)
    tr, va = displacements(4, 50, seed=0), displacements(2, 50, seed=1)
    tr.prior = va.prior = False
    s = train(
        "track",
        tr,
        va,
        tmp_path,
        TrainConfig(
            profile="quick",
            epochs=3,
            settings={"samples_per_epoch": 64, "val_samples": 30},
            batch_size=32,
            model_options=small_c2dt,
            progress=False,
        ),
    )
    # group the spied batches into epochs: a run of train batches, then a run of val batches
    epochs: list[dict[str, list[float]]] = []
    for split, values in seen:
        if split == "train" and (not epochs or epochs[-1]["val"]):
            epochs.append({"train": [], "val": []})
        epochs[-1][split] += values
    assert len(epochs) == 3
    assert [len(e["train"]) for e in epochs] == [64, 64, 64]  # not the 200 training windows
    assert [len(set(e["train"])) for e in epochs] == [64, 64, 64]  # each window once
    assert len({frozenset(e["train"]) for e in epochs}) == 3  # a fresh subset every epoch
    assert [len(e["val"]) for e in epochs] == [30, 30, 30]  # not the 100 validation windows
    assert len({frozenset(e["val"]) for e in epochs}) == 1  # the same subset every epoch
    assert set(epochs[0]["train"]) <= set(tr.x[:, 0, 0].tolist())
    assert math.isfinite(s["best_val_metric"])
    _, config, _ = load_checkpoint(tmp_path / "model.pt")
    assert config.prior is False
    cfg = json.loads((tmp_path / "config.json").read_text())
    assert cfg["settings"]["samples_per_epoch"] == 64 and cfg["settings"]["val_samples"] == 30


# ============================================================================ sharding
def test_epoch_indices_shard_one_permutation():
    n = 103
    for world in (1, 2, 3):
        shards = [epoch_indices(n, 4, 0, rank=r, world_size=world) for r in range(world)]
        assert len({len(s) for s in shards}) == 1  # equal steps on every rank
        allidx = torch.cat(shards)
        assert set(allidx.tolist()) == set(range(n))  # every sample in the epoch
        assert len(allidx) - n == (-n) % world  # padded only to a multiple of world
        if world > 1:
            assert not set(shards[0].tolist()) & set(shards[1].tolist()[: n // world - 1])
    # rank r's b-th batch of size B / world = the single-process b-th batch of size B
    single = epoch_indices(n, 4, 0)
    r0, r1 = (epoch_indices(n, 4, 0, rank=r, world_size=2) for r in (0, 1))
    assert sorted(torch.cat([r0[:8], r1[:8]]).tolist()) == sorted(single[:16].tolist())
    assert torch.equal(epoch_indices(n, 4, 0), single)
    assert not torch.equal(epoch_indices(n, 5, 0), single)
    assert len(epoch_indices(n, 4, 0, samples=10)) == 10


# ============================================================================ from a file
@pytest.fixture
def recording_file(tmp_path, make_recording):
    """2 inflation states x (no contact + 4 touch regions), 40 frames, markers everywhere."""
    path = tmp_path / "data.h5"
    write_recording(
        make_recording(n_frames=40, regions=(1, 5, 10, 14), occluded=(), no_markers=()), path
    )
    return path


def test_train_from_recording(tmp_path, recording_file, small_c2dt):
    data = recording_file
    config = TrainConfig(profile="quick", epochs=2, counts=(6, 2, 2), progress=False)
    s = train_from_recording("touch", data, tmp_path / "touch", config)
    split = json.loads((tmp_path / "touch" / "split.json").read_text())
    assert s["n_train"] == 6 * 40 and (s["n_val"], s["n_test"]) == (80, 80)
    assert [len(split[k]) for k in ("train", "val", "test")] == [6, 2, 2]
    # trial-exclusive: pairwise disjoint, together every trial of the recording
    parts = [set(split[k]) for k in ("train", "val", "test")]
    assert all(not a & b for i, a in enumerate(parts) for b in parts[i + 1 :]), split
    assert set().union(*parts) == {t.name for t in read_recording(data).trials}
    assert split["task"] == "touch"
    assert split["data"] == str(data.resolve()) and split["split_seed"] == 0
    config = TrainConfig(
        profile="quick",
        epochs=1,
        window=3,
        counts=(4, 2, 2),
        progress=False,
        model_options=small_c2dt,
    )
    s = train_from_recording("track", data, tmp_path / "track", config)
    _, model_config, _ = load_checkpoint(tmp_path / "track" / "model.pt")
    assert model_config.window == 3 and s["n_train"] == 4 * 40
    with pytest.raises(EctskinError, match="no such data file"):
        train_from_recording("touch", tmp_path / "nope.h5", tmp_path / "x")


def test_train_from_recording_refuses_before_reading_the_data(tmp_path):
    missing = tmp_path / "never-read.h5"  # every refusal comes before the data is read
    with pytest.raises(EctskinError, match="allowed values are 'touch', 'track'"):
        train_from_recording("shape", missing, tmp_path / "a")
    with pytest.raises(EctskinError, match="'epochs' must be a positive integer, got 0"):
        train_from_recording("touch", missing, tmp_path / "a", TrainConfig(epochs=0))
    with pytest.raises(EctskinError, match="apply to 'track' only"):
        train_from_recording("touch", missing, tmp_path / "a", TrainConfig(window=3))
    with pytest.raises(EctskinError, match="window must be an integer >= 1"):
        train_from_recording("track", missing, tmp_path / "a", TrainConfig(window=0))
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(EctskinError, match="not a run directory"):
        train_from_recording("touch", missing, other)
    half = tmp_path / "half"
    half.mkdir()
    (half / "model.pt").write_bytes(b"")
    with pytest.raises(EctskinError, match="model.pt without last.pt"):
        train_from_recording("touch", missing, half)
    with pytest.raises(EctskinError, match="threads must be an integer >= 1"):
        train_from_recording("touch", missing, tmp_path / "a", TrainConfig(threads=0))


def test_progress_bars_on_a_tty_and_epoch_logs_otherwise(tmp_path, monkeypatch, caplog, blobs):
    import io
    import logging
    import sys

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    tr, va = blobs(6, 20, seed=0), blobs(2, 20, seed=1)
    tty = Tty()
    monkeypatch.setattr(sys, "stderr", tty)
    train("touch", tr, va, tmp_path / "a", TrainConfig(profile="quick", epochs=2))
    assert "train touch" in tty.getvalue() and "2/2" in tty.getvalue()
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal: one log line per epoch
    with caplog.at_level(logging.INFO, logger="ectskin.learn.engine"):
        train("touch", tr, va, tmp_path / "b", TrainConfig(profile="quick", epochs=2))
    assert [r.getMessage()[:9] for r in caplog.records if "epoch" in r.getMessage()][:2] == [
        "epoch 1/2",
        "epoch 2/2",
    ]
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="ectskin.learn.engine"):
        train(
            "touch", tr, va, tmp_path / "c", TrainConfig(profile="quick", epochs=2, progress=False)
        )
    assert not [r for r in caplog.records if r.getMessage().startswith("epoch")]


def test_training_says_its_profile_and_warns_of_the_paper_profile_on_a_cpu(tmp_path, caplog, blobs):
    """``ectskin train`` defaults to the paper's profile, meant for a GPU: on a CPU it now says
    which profile runs, warns, and estimates the time left after the first epoch. Catches
    removing the warning or the estimate."""
    import logging

    tr, va = blobs(6, 20, seed=0), blobs(2, 20, seed=1)
    with caplog.at_level(logging.INFO, logger="ectskin.learn.train"):
        train(
            "touch", tr, va, tmp_path / "a", TrainConfig(profile="paper", epochs=3, progress=False)
        )
    text = "\n".join(r.getMessage() for r in caplog.records)
    assert "training touch with profile 'paper' (3 epochs, batch 256) on cpu" in text
    warning = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warning) == 1 and "--profile quick is the setting for a CPU" in text
    assert "epoch 1 took" in text and "left for the other 2 epoch(s)" in text
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="ectskin.learn.train"):
        train(
            "touch", tr, va, tmp_path / "b", TrainConfig(profile="quick", epochs=1, progress=False)
        )
    assert "with profile 'quick'" in caplog.text
    assert not [r for r in caplog.records if r.levelno == logging.WARNING]
