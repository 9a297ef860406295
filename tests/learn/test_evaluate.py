"""evaluate_run on tiny trained runs (ectskin.learn.evaluate): metrics, baselines, figures, the
run files it reads, and the figures of the evaluation (ectskin.viz)."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.learn.checkpoint import read_checkpoint
from ectskin.learn.data import touch_dataset, track_dataset
from ectskin.learn.evaluate import evaluate_run, read_run
from ectskin.learn.predict import TouchPredictor, TrackPredictor
from ectskin.learn.runfiles import read_metrics
from ectskin.learn.splits import split_from_names
from ectskin.learn.train import TrainConfig, train_from_recording


@pytest.fixture
def data_file(tmp_path, make_recording):
    """2 inflation states x (no contact + 4 touch regions), 40 frames, markers everywhere."""
    path = tmp_path / "data.h5"
    rec = make_recording(n_frames=40, regions=(1, 5, 10, 14), occluded=(), no_markers=())
    write_recording(rec, path)
    return path


@pytest.fixture
def touch_run(tmp_path, data_file):
    run = tmp_path / "touch"
    config = TrainConfig(profile="quick", epochs=3, counts=(6, 2, 2), progress=False)
    train_from_recording("touch", data_file, run, config)
    return run


def test_touch_run_metrics_baselines_figures(touch_run, data_file):
    m = evaluate_run(touch_run)
    assert set(m) == {"data", "touch"} and m["data"] == str(data_file.resolve())
    t = m["touch"]
    split = json.loads((touch_run / "split.json").read_text())
    assert t["n_test_frames"] == 40 * len(split["test"]) == 80
    assert t["n_misclassified"] == round((1 - t["accuracy"]) * t["n_test_frames"])
    assert np.asarray(t["confusion"]).shape == (19, 19)
    assert set(t["baselines"]) == {"majority", "logreg", "random_forest", "knn"}
    assert t["split"] == {"train": 6, "val": 2, "test": 2}
    assert set(t["figures"]) == {"fig7_confusion.png", "learning_curves.png"}
    assert all((touch_run / name).is_file() for name in t["figures"])
    assert (
        json.loads((touch_run / "metrics.json").read_text())["touch"]["accuracy"] == (t["accuracy"])
    )
    # training: metrics.csv and the kept weights' metadata; the profile from the checkpoint
    rows = read_metrics(touch_run / "metrics.csv")
    kept = read_checkpoint(touch_run / "model.pt")["extra"]
    tr = t["training"]
    assert (tr["epochs"], tr["best_epoch"], tr["profile"]) == (3, kept["epoch"], "quick")
    assert tr["seconds"] == pytest.approx(sum(r["seconds"] for r in rows))
    assert tr["select"] == "val_loss" and tr["recipe"]["mixup_alpha"] == 0.0
    # the evaluation's batched inference = frame-by-frame predictions of the live predictor
    ds = touch_dataset(read_recording(data_file))
    test = ds.select(split_from_names(split, ds.group_names)["test"])
    pred = TouchPredictor.from_run(touch_run)
    wrong = sum(int(pred.classify(x) != y) for x, y in zip(test.x, test.y))
    assert wrong == t["n_misclassified"]


def test_track_run_metrics_examples_and_figures(tmp_path, data_file, small_c2dt):
    run = tmp_path / "track"
    config = TrainConfig(
        profile="quick",
        epochs=1,
        window=3,
        prior=False,
        counts=(4, 2, 2),
        progress=False,
        model_options=small_c2dt,
    )
    train_from_recording("track", data_file, run, config)
    m = evaluate_run(run, data_file, baselines=False)
    k = m["track"]
    assert k["window"] == 3 and k["prior"] is False and "baselines" not in k
    assert len(k["examples"]["ad_mm"]) == 6
    assert k["examples"]["trajectory"]["marker"] in k["per_marker"]
    assert set(k["figures"]) == {"fig9_tracking.png", "fig10_trajectory.png", "learning_curves.png"}
    assert all((run / name).is_file() for name in k["figures"])
    # window-by-window predictions of the live predictor, Eq. 3 by hand
    split = json.loads((run / "split.json").read_text())
    ds = track_dataset(read_recording(data_file), window=3, prior=False)
    test = ds.select(split_from_names(split, ds.group_names)["test"])
    pred = TrackPredictor.from_run(run)
    dist = [np.sqrt(((pred.predict(x) - y) ** 2).sum(-1)) for x, y in zip(test.x, test.y)]
    assert k["n_test_samples"] == len(dist)
    assert k["ad_mm_mean"] == pytest.approx(np.mean(dist), rel=1e-5)
    assert k["ad_mm_std"] == pytest.approx(np.std(dist), rel=1e-4)
    # without figures: nothing drawn, nothing about Fig. 10 in the metrics
    m = evaluate_run(run, data_file, baselines=False, figures=False, write=False)
    assert m["track"]["figures"] == {} and "trajectory" not in m["track"]["examples"]


def test_read_run_reads_each_file_once_and_checks_it(touch_run):
    run = read_run(touch_run)
    assert run.task.name == "touch" and run.run_config["profile"] == "quick"
    assert [r["epoch"] for r in run.metrics_rows] == [1, 2, 3]
    assert run.split["task"] == "touch"
    (touch_run / "metrics.csv").write_text("epoch,train_loss\n1,nan-ish\n")
    with pytest.raises(EctskinError, match=r"metrics\.csv: malformed metrics file"):
        read_run(touch_run)
    with pytest.raises(EctskinError, match="does not exist"):
        read_run(touch_run / "nope")


@pytest.mark.parametrize(
    "text, found",
    [
        ("{not json", r"run config is not valid JSON \(line 1, column 2"),
        ("[1, 2]", "run config must hold a JSON object, found a JSON list"),
        ('{"task": "track"}', r"expected the config of a 'touch' run .*found task 'track'"),
        ('{"profile": "robust"}', r"expected the config of a 'touch' run .*found no field 'task'"),
        ('{"task": "touch", "recipe": [0.4]}', "field 'recipe' must be a JSON object"),
    ],
)
def test_a_corrupt_config_json_is_an_error_naming_the_file(touch_run, text, found):
    """A run's config.json that cannot be its own (unreadable, not an object, another task) is
    an error naming the file, never a silent fallback to "the paper's recipe"."""
    (touch_run / "config.json").write_text(text)
    with pytest.raises(EctskinError, match=rf"touch/config\.json: {found}"):
        evaluate_run(touch_run, baselines=False, figures=False, write=False)
    assert not (touch_run / "metrics.json").exists()


def test_a_run_without_config_json_has_no_recipe(touch_run):
    (touch_run / "config.json").unlink()
    m = evaluate_run(touch_run, baselines=False, figures=False, write=False)
    assert "recipe" not in m["touch"]["training"] and "select" not in m["touch"]["training"]


def test_evaluate_run_errors_name_the_file(tmp_path, touch_run, data_file):
    broken = tmp_path / "broken"
    shutil.copytree(touch_run, broken)
    (broken / "split.json").write_text("{not json")
    with pytest.raises(EctskinError, match=r"broken/split.json: split file is not valid JSON"):
        evaluate_run(broken)
    split = json.loads((touch_run / "split.json").read_text())
    (broken / "split.json").write_text(json.dumps({**split, "test": "s0_r1"}))
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
    assert m["touch"]["n_test_frames"] == 40 * len(split["test"])
    assert not (broken / "metrics.json").exists()


def test_train_then_evaluate_commands(tmp_path, data_file, cli, capsys):
    run = tmp_path / "run"
    argv = ["train", "touch", str(data_file), "--out", str(run), "--profile", "quick"]
    argv += ["--epochs", "2", "--no-progress"]
    assert cli(argv) == 0
    before = (run / "model.pt").stat().st_mtime_ns
    assert cli(argv) == 0  # resumes the finished run: trains nothing, keeps the model
    assert (run / "model.pt").stat().st_mtime_ns == before
    assert cli(["evaluate", str(run), "--no-baselines", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "touch: accuracy" in out and "trained with profile 'quick': the paper's recipe" in out
    (run / "config.json").write_text("[]")
    assert cli(["evaluate", str(run)]) == 2
    assert "config.json: run config must hold a JSON object" in capsys.readouterr().err
    assert cli(["train", "touch", str(data_file), "--out", str(run), "--window", "3"]) == 2
    assert "apply to 'track' only" in capsys.readouterr().err


def test_figures_draw_and_return_figures(tmp_path):
    from ectskin.viz import plot_confusion, plot_marker_trajectory, plot_tracking_examples

    conf = np.diag([5, 6, 7])
    conf[1, 2] = 2
    fig = plot_confusion(conf)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert sorted(texts) == sorted(["5", "6", "7", "2"])  # non-zero cells annotated
    assert "2 of 20" in fig.axes[0].get_title()
    fig.savefig(tmp_path / "c.png")

    true = np.zeros((6, 5, 3))
    true[..., 2] = np.arange(5) * 24
    pred = true + 1.0  # every marker sqrt(3) mm off
    fig = plot_tracking_examples(pred, true, titles=[f"s{i}" for i in range(6)])
    assert len(fig.axes) == 6
    assert all(f"AD = {math.sqrt(3):.3f} mm" in ax.get_title() for ax in fig.axes)
    fig.savefig(tmp_path / "t.png")

    t = np.arange(30) / 30
    fig = plot_marker_trajectory(t, true[0, :1].repeat(30, 0) + 2.0, true[0, :1].repeat(30, 0))
    assert len(fig.axes) == 3
    with pytest.raises(EctskinError, match="shape"):
        plot_marker_trajectory(t, np.zeros((29, 3)), np.zeros((30, 3)))


def test_a_trial_region_outside_the_layout_is_refused_naming_the_trial(
    tmp_path, touch_run, make_recording
):
    """Defect 17: a trial with region 500 on an 18-region layout was accepted by train and
    evaluate (and stratified the split by it). Catches removing ``check_regions`` from the data
    sets."""
    from dataclasses import replace

    rec = make_recording(n_frames=40, regions=(1, 5, 10, 14), occluded=(), no_markers=())
    bad = replace(rec.trials[3], region=500)
    rec = replace(rec, trials=[*rec.trials[:3], bad, *rec.trials[4:]])
    path = tmp_path / "bad.h5"
    write_recording(rec, path)
    msg = rf"trial '{bad.name}': region 500 is not a region of layout .*1\.\.18, or 0"
    for task in ("touch", "track"):
        with pytest.raises(EctskinError, match=msg):
            train_from_recording(task, path, tmp_path / f"new_{task}", TrainConfig(progress=False))
        assert not (tmp_path / f"new_{task}").exists()
    with pytest.raises(EctskinError, match=msg):
        evaluate_run(touch_run, path, write=False)


def test_evaluating_other_data_never_replaces_earlier_results(tmp_path, touch_run, data_file):
    """Defect 16: ``evaluate RUN --data other.h5`` replaced RUN/metrics.json (the run's own test
    results) and its figures. Now other data goes to metrics_<stem>.json and suffixed figures,
    and no evaluation replaces an earlier one without ``overwrite``. Catches writing every
    evaluation to metrics.json, and a missing existence check."""
    own = evaluate_run(touch_run, baselines=False)
    before = {p.name: p.read_bytes() for p in touch_run.iterdir() if p.suffix in (".json", ".png")}
    assert {"metrics.json", "fig7_confusion.png", "learning_curves.png"} <= set(before)
    other = tmp_path / "day2.h5"
    shutil.copyfile(data_file, other)
    m = evaluate_run(touch_run, other, baselines=False)
    assert m["data"] == str(other) and set(m["touch"]["figures"]) == {"fig7_confusion_day2.png"}
    assert json.loads((touch_run / "metrics_day2.json").read_text())["data"] == str(other)
    assert (touch_run / "fig7_confusion_day2.png").is_file()
    for name, content in before.items():  # the run's own evaluation is untouched
        assert (touch_run / name).read_bytes() == content, name
    # again: refused before any work, naming the file and the flag
    for data in (other, None):
        with pytest.raises(
            EctskinError, match=r"written by an earlier evaluation; pass --overwrite"
        ):
            evaluate_run(touch_run, data, baselines=False)
    again = evaluate_run(touch_run, other, baselines=False, overwrite=True)
    assert again["touch"]["accuracy"] == m["touch"]["accuracy"] == own["touch"]["accuracy"]
    # -o/--out: another folder, plain names; the data file named in split.json is "own" data
    out = tmp_path / "elsewhere"
    evaluate_run(touch_run, data_file, baselines=False, out=out)
    assert sorted(p.name for p in out.iterdir()) == [
        "fig7_confusion.png",
        "learning_curves.png",
        "metrics.json",
    ]
    # out=RUN (what reproduce passes, whose folder may have moved): plain names in the run folder
    m = evaluate_run(touch_run, other, baselines=False, out=touch_run, overwrite=True)
    assert set(m["touch"]["figures"]) == {"fig7_confusion.png", "learning_curves.png"}
    assert json.loads((touch_run / "metrics.json").read_text())["data"] == str(other)
    # a run folder holding evaluations and figures of any format is still resumed by train
    (touch_run / "fig7_confusion.svg").write_text("<svg/>")
    config = TrainConfig(profile="quick", epochs=3, counts=(6, 2, 2), progress=False)
    train_from_recording("touch", data_file, touch_run, config)


def test_figures_in_the_format_and_resolution_asked_for(tmp_path, touch_run, cli, capsys):
    argv = ["evaluate", str(touch_run), "--no-baselines", "--format", "pdf", "-o"]
    assert cli(argv + [str(tmp_path / "pdf")]) == 0
    names = sorted(p.name for p in (tmp_path / "pdf").iterdir())
    assert names == ["fig7_confusion.pdf", "learning_curves.pdf", "metrics.json"]
    assert (tmp_path / "pdf" / "fig7_confusion.pdf").read_bytes()[:5] == b"%PDF-"
    m = json.loads((tmp_path / "pdf" / "metrics.json").read_text())
    assert set(m["touch"]["figures"]) == {"fig7_confusion.pdf", "learning_curves.pdf"}
    # the command refuses to replace them, naming the flag, before any work
    assert cli(argv + [str(tmp_path / "pdf")]) == 2
    err = capsys.readouterr().err
    assert "metrics.json and 2 more: written by an earlier evaluation; pass --overwrite" in err
    assert cli(["evaluate", str(touch_run), "--dpi", "5"]) == 2
    assert "dpi must be an integer from 30 to 1200, got 5" in capsys.readouterr().err
    evaluate_run(touch_run, baselines=False, out=tmp_path / "svg", figure_format="svg", write=False)
    assert (tmp_path / "svg" / "fig7_confusion.svg").read_text().lstrip().startswith("<?xml")
    from PIL import Image

    from ectskin.viz import plot_confusion

    evaluate_run(touch_run, baselines=False, out=tmp_path / "png", write=False, dpi=60)
    width_in = plot_confusion(np.eye(19, dtype=int)).get_size_inches()[0]
    with Image.open(tmp_path / "png" / "fig7_confusion.png") as im:
        assert im.size[0] == pytest.approx(width_in * 60, abs=2)
