"""End to end: train / evaluate commands and the reproduce pipeline on tiny recordings.

The hand-made recording below follows the twin's conventions (a rest trial per inflation state
with ``meta["kind"] = "no_contact"``, touch trials labelled with their region, 5 markers that bend
with the touch force) but costs nothing to make, so the whole pipeline runs in seconds.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout

FPS = 30.0


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Tests share 2 cores with others: one torch thread avoids oversubscription."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def synthetic_recording(levels=(0.0, 20.0), touch_trials=4, n_frames=60, seed=0) -> Recording:
    """States = every combination of ``levels`` over 3 chambers; per state one rest trial and
    ``touch_trials`` touch trials (alternating front / back regions). Readouts (pF): a base per
    pair, a small inflation term (same-face pairs rise, cross-face pairs fall) and a touch term
    that lifts 4 region-specific pairs in proportion to the force (easy to learn). Markers bend in
    y with the force, more towards the tip."""
    lay = default_layout()
    rng = np.random.default_rng(seed)
    base = 1.0 + 0.05 * np.arange(lay.n_pairs)
    sign = np.where(lay.same_surface, 1.0, -1.0)
    pattern = 0.05 * rng.uniform(0.0, 1.0, (lay.n_regions + 1, lay.n_pairs))
    for r in range(1, lay.n_regions + 1):
        pattern[r, rng.choice(lay.n_pairs, 4, replace=False)] = 1.0
    z = np.array([m.uv_mm[1] for m in lay.markers])
    rest = np.stack([np.full_like(z, 25.0), np.zeros_like(z), z], axis=1)  # (5, 3) mm
    t = np.arange(n_frames) / FPS
    trials = []
    states = [(a, b, c) for a in levels for b in levels for c in levels]
    k = 0
    for p in states:
        infl = 1.0 + 0.002 * sum(p) * sign
        for j in range(touch_trials + 1):
            region = 0 if j == 0 else 1 + (k % 9) + (9 if j % 2 == 0 else 0)
            force = (
                np.zeros(n_frames) if region == 0 else 1.0 + 0.8 * np.sin(2 * np.pi * t / 1.5 + k)
            )
            cap = base * (infl + 0.3 * force[:, None] * pattern[region])
            cap = cap + rng.normal(0, 2e-4, cap.shape)
            side = 1.0 if region <= 9 else -1.0
            markers = np.repeat(rest[None], n_frames, axis=0)
            markers[:, :, 1] += side * 4.0 * force[:, None] * (z / z.max()) ** 2
            markers += rng.normal(0, 0.05, markers.shape)
            trials.append(
                Trial(
                    name=f"trial_{len(trials):04d}",
                    capacitance=cap,
                    timestamps=t,
                    labels=np.full(n_frames, region),
                    inflation=p,
                    region=region,
                    markers=markers,
                    force=force,
                    meta={"kind": "no_contact" if region == 0 else "touch"},
                )
            )
            k += region > 0
    return Recording(lay, trials, FPS, meta={"source": "test"})


@pytest.fixture(scope="module")
def data_file(tmp_path_factory):
    from ectskin.io.hdf5 import write_recording

    path = tmp_path_factory.mktemp("data") / "data.h5"
    write_recording(synthetic_recording(), path)
    return path


def cli(argv, monkeypatch=None) -> int:
    """``ectskin ARGV`` through the real entry point, with only the commands tested here (so the
    test does not depend on other command modules)."""
    import ectskin.cli

    if monkeypatch is not None:
        monkeypatch.setattr(
            ectskin.cli,
            "COMMANDS",
            (
                ("train", "train"),
                ("evaluate", "evaluate"),
                ("reproduce", "reproduce"),
                ("demo", "demo"),
            ),
        )
    return ectskin.cli.main(argv)


# ----------------------------------------------------------------------------- commands
def test_train_then_evaluate_commands(tmp_path, data_file, monkeypatch, capsys):
    run = tmp_path / "touch"
    argv = [
        "train",
        "touch",
        str(data_file),
        "--out",
        str(run),
        "--profile",
        "quick",
        "--epochs",
        "30",
        "--no-progress",
    ]
    assert cli(argv, monkeypatch) == 0
    for name in ("model.pt", "last.pt", "metrics.csv", "split.json", "config.json"):
        assert (run / name).is_file(), name
    # run again: resumes the finished run, trains nothing, keeps the model
    before = (run / "model.pt").stat().st_mtime_ns
    assert cli(argv, monkeypatch) == 0
    assert (run / "model.pt").stat().st_mtime_ns == before

    assert cli(["evaluate", str(run)], monkeypatch) == 0
    out = capsys.readouterr().out
    assert "touch: accuracy" in out and "baseline majority" in out
    m = json.loads((run / "metrics.json").read_text())
    t = m["touch"]
    split = json.loads((run / "split.json").read_text())
    # the test split re-created from split.json: 60 frames per test trial
    assert t["n_test_frames"] == 60 * len(split["test"])
    assert t["n_misclassified"] == round((1 - t["accuracy"]) * t["n_test_frames"])
    assert np.asarray(t["confusion"]).shape == (19, 19)
    assert set(t["baselines"]) == {"majority", "logreg", "random_forest", "knn"}
    assert t["training"]["epochs"] == 30
    assert (run / "fig7_confusion.png").is_file()
    # the touch signal is easy: the model must beat always answering the majority class
    assert t["accuracy"] > t["baselines"]["majority"]["accuracy"] + 0.2

    # independent check of the evaluation path: frame-by-frame predictions of the live predictor
    from ectskin.io.hdf5 import read_recording
    from ectskin.learn.datasets import split_from_names, touch_dataset
    from ectskin.learn.predict import TouchPredictor

    ds = touch_dataset(read_recording(data_file))
    test = ds.select(split_from_names(split, ds.group_names)["test"])
    pred = TouchPredictor.from_run(run)
    wrong = sum(int(np.argmax(pred.predict(x)) != y) for x, y in zip(test.x, test.y))
    assert wrong == t["n_misclassified"]


def test_track_command_with_ablation_options(tmp_path, data_file, monkeypatch):
    run = tmp_path / "track1"
    assert (
        cli(
            [
                "train",
                "track",
                str(data_file),
                "--out",
                str(run),
                "--profile",
                "quick",
                "--epochs",
                "1",
                "--window",
                "1",
                "--no-prior",
                "--no-progress",
            ],
            monkeypatch,
        )
        == 0
    )
    assert cli(["evaluate", str(run), "--data", str(data_file), "--no-baselines"], monkeypatch) == 0
    k = json.loads((run / "metrics.json").read_text())["track"]
    assert k["window"] == 1 and k["prior"] is False
    assert k["ad_mm_mean"] > 0 and "baselines" not in k
    assert len(k["examples"]["ad_mm"]) == 6
    assert (run / "fig9_tracking.png").is_file() and (run / "fig10_trajectory.png").is_file()

    # independent check: window-by-window predictions of the live predictor, Eq. 3 by hand
    from ectskin.io.hdf5 import read_recording
    from ectskin.learn.datasets import split_from_names, track_dataset
    from ectskin.learn.predict import TrackPredictor

    split = json.loads((run / "split.json").read_text())
    ds = track_dataset(read_recording(data_file), window=1, prior=False)
    test = ds.select(split_from_names(split, ds.group_names)["test"])
    pred = TrackPredictor.from_run(run)
    dist = [
        np.sqrt(((pred.predict(x, i) - y) ** 2).sum(-1))
        for x, i, y in zip(test.x, test.init, test.y)
    ]
    assert k["n_test_samples"] == len(dist)
    assert k["ad_mm_mean"] == pytest.approx(np.mean(dist), rel=1e-5)
    assert k["ad_mm_std"] == pytest.approx(np.std(dist), rel=1e-4)


def test_command_errors_are_clear(tmp_path, data_file, monkeypatch, capsys):
    assert cli(["evaluate", str(tmp_path / "nope")], monkeypatch) == 2
    assert "does not exist" in capsys.readouterr().err
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert cli(["train", "touch", str(data_file), "--out", str(other)], monkeypatch) == 2
    assert "not a run directory" in capsys.readouterr().err
    assert (
        cli(
            ["train", "touch", str(data_file), "--out", str(tmp_path / "r"), "--window", "3"],
            monkeypatch,
        )
        == 2
    )
    assert "apply to 'track' only" in capsys.readouterr().err
    assert cli(["reproduce", str(tmp_path / "x"), "--threads", "0"], monkeypatch) == 2
    assert "--threads must be a number >= 1, 'auto' or 'torch'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # refused before any work


def test_resolve_threads(monkeypatch):
    import os

    from ectskin.report.reproduce import resolve_threads

    assert resolve_threads(3) == 3 and resolve_threads(None) is None
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert resolve_threads("auto") == 1
    monkeypatch.setattr(os, "cpu_count", lambda: 16)
    assert resolve_threads("auto") is None
    with pytest.raises(EctskinError, match="threads must be"):
        resolve_threads(0)


# ----------------------------------------------------------------------------- reproduce
def test_reproduce_end_to_end_reuse_and_force(tmp_path):
    from ectskin.report.reproduce import reproduce

    rec = synthetic_recording()
    out = tmp_path / "out"
    epochs = {"touch": 30, "track": 1}
    m = reproduce(out, recording=rec, profile="quick", epochs=epochs, progress=False)
    for name in ("report.md", "report.html", "metrics.json", "data.h5", "reproduce.json"):
        assert (out / name).is_file(), name
    for fig in ("fig7_confusion.png", "fig9_tracking.png", "fig10_trajectory.png"):
        assert (out / "figures" / fig).is_file(), fig
    saved = json.loads((out / "metrics.json").read_text())
    for key in (
        "touch.accuracy",
        "touch.n_test_frames",
        "touch.n_misclassified",
        "track.ad_mm_mean",
        "track.ad_mm_std",
        "track.baselines.no_motion.ad_mm_mean",
        "track.ablations.no_prior.ad_mm_mean",
        "track.ablations.window_1.ad_mm_mean",
        "timings_s.train_touch",
        "timings_s.train_track",
        "timings_s.simulate",
        "timings_s.total",
        "machine.cpu_count",
    ):
        cur = saved
        for part in key.split("."):
            assert part in cur, key
            cur = cur[part]
        assert cur is not None, key
    assert saved["track"]["ablations"]["window_1"]["window"] == 1
    assert saved["track"]["ablations"]["no_prior"]["prior"] is False
    # the no-motion AD equals the mean displacement of the test samples, so it is > 0 here
    assert saved["track"]["baselines"]["no_motion"]["ad_mm_mean"] > 0.5
    md = (out / "report.md").read_text()
    assert f"{100 * m['touch']['accuracy']:.2f} %" in md
    assert f"{m['track']['ad_mm_mean']:.3f} ± {m['track']['ad_mm_std']:.3f} mm" in md
    assert "![Fig. 9" in md

    # same call again: every step is reused, nothing retrained
    mtime = (out / "runs" / "track" / "model.pt").stat().st_mtime_ns
    m2 = reproduce(out, recording=rec, profile="quick", epochs=epochs, progress=False)
    assert set(m2["reused"]) >= {
        "simulate",
        "train_touch",
        "train_track",
        "evaluate_touch",
        "train_track_no_prior",
        "train_track_window_1",
    }
    assert (out / "runs" / "track" / "model.pt").stat().st_mtime_ns == mtime
    assert m2["track"]["ad_mm_mean"] == m["track"]["ad_mm_mean"]

    # an interrupted training (step started, not finished) resumes from last.pt in place
    state = json.loads((out / "reproduce.json").read_text())
    state["steps"]["train_track"]["done"] = False
    (out / "reproduce.json").write_text(json.dumps(state))
    m_res = reproduce(out, recording=rec, profile="quick", epochs=epochs, progress=False)
    assert "train_track" not in m_res["reused"] and "train_touch" in m_res["reused"]
    assert (out / "runs" / "track" / "model.pt").stat().st_mtime_ns == mtime  # nothing retrained
    assert json.loads((out / "reproduce.json").read_text())["steps"]["train_track"]["done"]

    # other settings: refused without force, redone with it
    with pytest.raises(EctskinError, match=r"train_touch.*--force"):
        reproduce(out, recording=rec, profile="quick", epochs=1, progress=False, ablations=False)
    m3 = reproduce(
        out,
        recording=rec,
        profile="quick",
        epochs=1,
        progress=False,
        ablations=False,
        baselines=False,
        force=True,
    )
    assert "train_touch" not in m3["reused"] and "simulate" in m3["reused"]
    assert m3["touch"]["training"]["epochs"] == 1
    assert "ablations" not in m3["track"]


def test_reproduce_refuses_a_foreign_data_file(tmp_path):
    from ectskin.report.reproduce import reproduce

    out = tmp_path / "out"
    out.mkdir()
    (out / "data.h5").write_bytes(b"not mine")
    with pytest.raises(EctskinError, match="data.h5.*--force"):
        reproduce(out, recording=synthetic_recording(levels=(0.0,)), progress=False)
    assert (out / "data.h5").read_bytes() == b"not mine"


def test_demo_and_reproduce_defaults():
    import argparse

    from ectskin.commands import demo, reproduce

    p = argparse.ArgumentParser()
    demo.add_arguments(p)
    args = p.parse_args([])
    assert (args.out, args.profile, args.force, args.threads) == (
        "demo-output",
        "quick",
        False,
        "auto",
    )
    p = argparse.ArgumentParser()
    reproduce.add_arguments(p)
    args = p.parse_args(["out", "--profile", "quick", "--workers", "2"])
    assert (args.out_dir, args.profile, args.workers) == ("out", "quick", 2)
    with pytest.raises(SystemExit):
        p.parse_args(["out", "--profile", "fast"])


@pytest.mark.slow
def test_reproduce_tiny_twin_experiment(tmp_path, monkeypatch):
    """The real chain: the digital twin simulates a tiny protocol (levels 0/20 ml, one touch trial
    per state, 2-s trials), characterises the skin, trains, evaluates and reports (~30 s)."""
    from ectskin.twin import Protocol

    out = tmp_path / "tiny"
    protocol = Protocol(levels_ml=(0.0, 20.0), touch_trials=1, duration_s=2.0, seed=0)
    from ectskin.report.reproduce import reproduce

    m = reproduce(
        out,
        protocol=protocol,
        workers=1,
        profile="quick",
        epochs={"touch": 5, "track": 1},
        progress=False,
    )
    assert m["data"]["trials"] == protocol.n_trials == 16
    assert m["protocol"]["levels_ml"] == [0.0, 20.0]
    for rel in (
        "characterize/fig3_inflation.png",
        "characterize/fig4_touch.png",
        "figures/fig7_confusion.png",
        "figures/fig9_tracking.png",
        "report.html",
    ):
        assert (out / rel).is_file(), rel
    md = (out / "report.md").read_text()
    assert "(characterize/fig3_inflation.png)" in md and "(characterize/fig4_touch.png)" in md
    assert {"simulate", "characterize", "train_touch", "evaluate_track"} <= set(m["timings_s"])
    # the same protocol is found in data.h5 by a fresh output folder's state: reuse, no simulation
    (out / "reproduce.json").unlink()
    import ectskin.twin

    monkeypatch.setattr(
        ectskin.twin, "simulate_experiment", lambda *a, **k: pytest.fail("simulated again")
    )
    with pytest.raises(EctskinError, match="origin is unknown"):
        reproduce(
            out,
            protocol=protocol,
            workers=1,
            profile="quick",
            epochs={"touch": 5, "track": 1},
            progress=False,
        )


def test_evaluate_run_errors_name_the_file(tmp_path, data_file):
    import shutil

    from ectskin.learn.evaluate import evaluate_run
    from ectskin.learn.train import main_from_args

    run = tmp_path / "run"
    main_from_args("touch", data_file, run, profile="quick", epochs=1, progress=False)
    broken = tmp_path / "broken"
    shutil.copytree(run, broken)
    (broken / "split.json").write_text("{not json")
    with pytest.raises(EctskinError, match=r"broken/split.json: split file is not valid JSON"):
        evaluate_run(broken)
    split = json.loads((run / "split.json").read_text())
    (broken / "split.json").write_text(json.dumps({**split, "test": "trial_0001"}))
    with pytest.raises(EctskinError, match="'test' must be a list of trial names"):
        evaluate_run(broken)
    (broken / "split.json").write_text(json.dumps({**split, "test": ["no_such_trial"]}))
    with pytest.raises(EctskinError, match="no_such_trial"):
        evaluate_run(broken)
    (broken / "split.json").write_text(json.dumps({**split, "task": "track"}))
    with pytest.raises(EctskinError, match="does not match the model"):
        evaluate_run(broken)
    (broken / "split.json").write_text(json.dumps({**split, "data": str(tmp_path / "gone.h5")}))
    with pytest.raises(EctskinError, match="gone.h5 no longer exists; pass --data"):
        evaluate_run(broken)
    # the right data passed explicitly works, without writing anything when write=False
    m = evaluate_run(broken, data_file, baselines=False, figures=False, write=False)
    assert m["touch"]["n_test_frames"] == 60 * len(split["test"])
    assert not (broken / "metrics.json").exists()
