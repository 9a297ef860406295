"""``ectskin evaluate`` as the README uses it: a trained run on another day's recording, on a
recording of unseen inflation states (no rest-state trial), a file given for the run directory,
and an output that is one of the inputs (ectskin.learn.evaluate, ectskin.commands.evaluate)."""

from __future__ import annotations

import json
import logging
import shutil
from dataclasses import replace

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import write_recording
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.train import TrainConfig, train_from_recording

REGIONS = (1, 5, 10, 14)


@pytest.fixture
def data_file(tmp_path, make_recording):
    """2 inflation states x (no contact + 4 touch regions), 40 frames: 10 trials."""
    path = tmp_path / "data.h5"
    write_recording(make_recording(n_frames=40, regions=REGIONS, occluded=(), no_markers=()), path)
    return path


@pytest.fixture
def touch_run(tmp_path, data_file):
    run = tmp_path / "touch"
    config = TrainConfig(profile="quick", epochs=2, counts=(6, 2, 2), progress=False)
    train_from_recording("touch", data_file, run, config)
    return run


def _day2(make_recording, path, *, rename: bool = True, **kw):
    """Another session of the same skin: other readouts (another seed), and (``rename``) other
    trial names, as another day's file has."""
    rec = make_recording(n_frames=40, regions=REGIONS, occluded=(), no_markers=(), seed=1, **kw)
    if rename:
        rec = replace(rec, trials=[replace(t, name=f"day2_{t.name}") for t in rec.trials])
    write_recording(rec, path)
    return path


def test_another_days_recording_is_test_data_whole(tmp_path, touch_run, make_recording, cli,
                                                   capsys):
    """Defect 6: ``evaluate RUN --data day2.h5`` failed with "split.json: train trial ... is not
    in the data". Another recording is test data, whole; the baselines are fit on the run's
    training trials (from the training recording). Catches re-creating the run's split by name
    on any data."""
    day2 = _day2(make_recording, tmp_path / "day2.h5")
    m = evaluate_run(touch_run, day2, figures=False)["touch"]
    assert m["test_data"]["reading"] == "whole" and m["test_data"]["by"] == "digests"
    assert m["test_data"]["n_trials"] == 10 and m["test_data"]["n_left_out"] == 0
    assert m["n_test_frames"] == 10 * 40
    assert m["split"] == {"train": 6, "val": 2, "test": 10}
    assert set(m["baselines"]) == {"majority", "logreg", "random_forest", "knn"}
    assert m["reference"]["source"] == "recording" and m["reference"]["trials"] == ["day2_s0_rest"]
    saved = json.loads((touch_run / "metrics_day2.json").read_text())["touch"]
    assert saved["test_data"] == m["test_data"] and saved["reference"] == m["reference"]
    # the command says which reading it took
    assert cli(["evaluate", str(touch_run), "--data", str(day2), "--no-figures", "--overwrite",
                "--no-baselines"]) == 0
    out = capsys.readouterr().out
    assert "test data: the whole recording: all 10 trials of" in out
    assert "calibration: the rest state of" in out and "itself (trial(s) day2_s0_rest)" in out


def test_the_training_recording_anywhere_is_read_as_the_runs_test_split(tmp_path, touch_run,
                                                                         data_file):
    """Same recording -> the run's test split, recognised by its readouts wherever the file is;
    as test data "all" would count training trials, and is refused."""
    copy = tmp_path / "moved.h5"
    shutil.copyfile(data_file, copy)
    split = json.loads((touch_run / "split.json").read_text())
    m = evaluate_run(touch_run, copy, figures=False, baselines=False, write=False)["touch"]
    assert m["test_data"]["reading"] == "test_split" and m["n_test_frames"] == 40 * 2
    assert m["test_data"]["n_left_out"] == len(split["train"]) + len(split["val"])
    assert m["test_data"]["text"].startswith("the run's test split: 2 of 10 trials")
    with pytest.raises(EctskinError, match=r"holds 8 trial\(s\) the run was trained or validated"):
        evaluate_run(touch_run, copy, write=False, test_trials="all")


def test_the_same_trials_recorded_again_take_split_by_name(tmp_path, touch_run, make_recording,
                                                            caplog):
    """Trials named like the training trials with other readouts (the same protocol simulated
    again, e.g. without the hand) are another recording by default, with a warning naming
    ``--test-trials split``, which takes the run's test split by name (docs/contact.md)."""
    again = _day2(make_recording, tmp_path / "again.h5", rename=False)
    with caplog.at_level(logging.WARNING, logger="ectskin.learn.splits"):
        m = evaluate_run(touch_run, again, figures=False, baselines=False, write=False)
    assert m["touch"]["test_data"]["reading"] == "whole"
    assert "--test-trials split evaluates the run's test split" in caplog.text
    m = evaluate_run(touch_run, again, figures=False, write=False, test_trials="split")["touch"]
    assert m["test_data"]["reading"] == "run_split" and m["n_test_frames"] == 2 * 40
    assert set(m["baselines"]) == {"majority", "logreg", "random_forest", "knn"}


def test_unseen_inflation_without_a_rest_trial_uses_the_runs_reference(tmp_path, touch_run,
                                                                         data_file, make_recording,
                                                                         cli, capsys):
    """Defect 6: the README's ``simulate unseen.h5 --levels 5,15`` has no 0 ml trial, and
    ``evaluate`` failed with "no rest-state trial". Now the training recording's rest reference,
    stored in the run at training, calibrates it (or ``--reference REC.h5``), and the metrics
    and the summary say which. Catches calibrating against the evaluated recording only."""
    unseen = tmp_path / "unseen.h5"
    rec = make_recording(n_frames=40, regions=REGIONS, occluded=(), no_markers=(), seed=5,
                         states=((5.0, 5.0, 5.0), (15.0, 5.0, 15.0)))
    write_recording(rec, unseen)
    m = evaluate_run(touch_run, unseen, figures=False, baselines=False)["touch"]
    ref = m["reference"]
    assert ref["source"] == "run" and ref["trials"] == ["s0_rest"]
    assert "stored in the run" in ref["text"] and "has no rest-state trial of its own" in ref["text"]
    assert m["test_data"]["reading"] == "whole" and m["n_test_frames"] == 10 * 40
    # the stored reference is the training recording's rest state: --reference data.h5 agrees
    by_file = evaluate_run(touch_run, unseen, figures=False, baselines=False, write=False,
                           reference=data_file)["touch"]
    assert by_file["reference"]["source"] == "file" and by_file["reference"]["file"] == str(
        data_file
    )
    assert by_file["confusion"] == m["confusion"]
    assert cli(["evaluate", str(touch_run), "--data", str(unseen), "--reference", str(data_file),
                "--no-figures", "--no-baselines", "-o", str(tmp_path / "ev")]) == 0
    assert f"calibration: the rest state of {data_file} (--reference" in capsys.readouterr().out
    # a run that stores no reference (trained before runs stored one) names the option
    split = json.loads((touch_run / "split.json").read_text())
    del split["rest_reference"]
    (touch_run / "split.json").write_text(json.dumps(split))
    with pytest.raises(EctskinError, match=r"no rest-state trial .* pass --reference REC.h5"):
        evaluate_run(touch_run, unseen, figures=False, baselines=False, write=False)


def test_a_file_given_as_the_run_directory_is_named_as_such(tmp_path, data_file, cli, capsys):
    """Defect 4: ``evaluate data.h5`` said "run directory data.h5 does not exist"."""
    assert cli(["evaluate", str(data_file)]) == 2
    err = capsys.readouterr().err
    assert f"{data_file} is a file, not a run directory: evaluate expects the folder" in err
    assert f"a recording goes with --data (ectskin evaluate RUN_DIR --data {data_file})" in err
    with pytest.raises(EctskinError, match="does not exist"):
        evaluate_run(tmp_path / "nowhere")


def test_an_output_that_is_an_input_is_refused_before_any_work(tmp_path, touch_run, data_file,
                                                                monkeypatch, cli, capsys):
    """Defect 5: ``evaluate RUN --data X.h5 -o X.h5`` ran the whole evaluation before refusing
    to write. Now the output is checked against the inputs first. Catches a check after the
    recording is read."""
    import ectskin.learn.evaluate as ev

    def no_work(*args, **kwargs):
        raise AssertionError("the evaluation started")

    monkeypatch.setattr(ev, "read_recording", no_work)
    before = data_file.read_bytes()
    assert cli(["evaluate", str(touch_run), "--data", str(data_file), "-o", str(data_file)]) == 2
    err = capsys.readouterr().err
    assert f"-o/--out {data_file} is the recording given with --data; expected a folder" in err
    assert data_file.read_bytes() == before
    with pytest.raises(EctskinError, match=r"model.pt is the run's model.pt"):
        evaluate_run(touch_run, data_file, out=touch_run / "model.pt")
    other = tmp_path / "notes.txt"
    other.write_text("mine")
    with pytest.raises(EctskinError, match=r"notes.txt is a file; expected a folder"):
        evaluate_run(touch_run, data_file, out=other)
    with pytest.raises(EctskinError, match=r"--data .*gone.h5 does not exist"):
        evaluate_run(touch_run, tmp_path / "gone.h5")
    assert other.read_text() == "mine"


def test_the_commands_test_trials_choices_are_the_librarys():
    from ectskin.commands.evaluate import TEST_TRIALS as CLI
    from ectskin.learn.evaluate import TEST_TRIALS

    assert CLI == TEST_TRIALS


def test_trial_digests_recognise_training_trials_by_their_readouts(tmp_path, touch_run, data_file,
                                                                   make_recording):
    """The run stores a digest per trial; renamed training trials are still left out, a
    recording holding a few of them and new trials is evaluated on the new ones only."""
    rec = make_recording(n_frames=40, regions=REGIONS, occluded=(), no_markers=())
    split = json.loads((touch_run / "split.json").read_text())
    assert set(split["trial_digests"]) == {t.name for t in rec.trials}
    new = make_recording(n_frames=40, regions=REGIONS, occluded=(), no_markers=(), seed=3)
    train_names = set(split["train"])
    mixed = [replace(t, name=f"old_{t.name}") for t in rec.trials if t.name in train_names]
    mixed += [replace(t, name=f"new_{t.name}") for t in new.trials]
    path = tmp_path / "mixed.h5"
    write_recording(replace(rec, trials=mixed), path)
    m = evaluate_run(touch_run, path, figures=False, baselines=False, write=False)["touch"]
    assert m["test_data"]["reading"] == "partial"
    assert m["test_data"]["n_left_out"] == len(train_names) and m["test_data"]["n_trials"] == 10
    assert np.isfinite(m["accuracy"])
