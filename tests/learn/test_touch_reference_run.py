"""A trained touch run stores its Eq. 2 reference and evaluation re-applies it, on its own data
and on another recording (ectskin.learn.train, ectskin.learn.evaluate, ``--reference``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from test_touch_reference import c0_true, quadratic_recording  # tests/learn

from ectskin._check import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.io.inflation_reference import InflationModel
from ectskin.learn.data.touch import touch_dataset
from ectskin.learn.evaluate import evaluate_run, read_run
from ectskin.learn.train import TrainConfig, train_from_recording

COUNTS = (15, 6, 6)


@pytest.fixture
def data_file(tmp_path):
    path = tmp_path / "data.h5"
    write_recording(quadratic_recording(), path)
    return path


def _train(data_file, run, reference, profile="quick"):
    config = TrainConfig(
        profile=profile, epochs=2, counts=COUNTS, progress=False, reference=reference
    )
    train_from_recording("touch", data_file, run, config)
    return run


def test_an_inflation_run_stores_its_model_and_reapplies_it_on_other_data(tmp_path, data_file):
    """The model fitted on the training recording is in split.json (JSON) and model.pt
    (torch.load weights_only=True), equal; evaluating another recording at unseen levels
    (5, 15 ml) without any no-contact trial uses it (no refit is possible there: such a refit
    fails) and predicts what the model gives on frames calibrated by it. Catches a run that
    does not store the model, an evaluation that refits or falls back to the rest state."""
    run = _train(data_file, tmp_path / "run", "inflation")
    split = json.loads((run / "split.json").read_text())
    doc = split["touch_reference"]
    assert doc["mode"] == "inflation"
    payload = torch.load(run / "model.pt", weights_only=True)
    assert payload["extra"]["reference"] == doc
    config = json.loads((run / "config.json").read_text())
    assert config["recipe"]["reference"] == "inflation"
    model = InflationModel.from_json(doc["model"])
    fitted = InflationModel.fit(read_recording(data_file))
    p = (5.0, 15.0, 5.0)
    np.testing.assert_allclose(model.predict(p), fitted.predict(p), rtol=1e-12)
    np.testing.assert_allclose(model.predict(p), c0_true(p), rtol=1e-9)

    other = quadratic_recording((5.0, 15.0), rest=False, seed=0)
    with pytest.raises(EctskinError, match="has no no-contact"):
        touch_dataset(other, reference="state")
    other_file = tmp_path / "unseen.h5"
    write_recording(other, other_file)
    m = evaluate_run(run, other_file, figures=False)["touch"]
    assert m["reference"]["source"] == "run"
    assert "inflation model" in m["reference"]["text"]
    r = read_run(run)
    ds = touch_dataset(read_recording(other_file), reference=model)
    with torch.no_grad():
        pred = r.model(torch.from_numpy(ds.x)).argmax(1).numpy()
    assert m["n_misclassified"] == int((pred != ds.y).sum())
    assert m["n_test_frames"] == ds.n_samples
    # the baselines are fit on the training trials calibrated the same way (they ran)
    assert set(m["baselines"]) >= {"logreg", "majority"}
    with pytest.raises(EctskinError, match="--reference does not apply"):
        evaluate_run(run, other_file, figures=False, write=False, reference=data_file)


def test_a_state_run_calibrates_other_data_by_its_states(tmp_path, data_file, cli, capsys):
    """``train --reference state`` (CLI): the run calibrates any recording against each of
    its states' no-contact trials; a recording with a state lacking one is an error naming it.
    The paper's profile keeps the rest reference (no touch_reference mode other than rest)."""
    run = tmp_path / "state"
    assert cli(["train", "touch", str(data_file), "-o", str(run), "--profile", "quick",
                "--epochs", "1", "--reference", "state", "--no-progress"]) == 0
    assert json.loads((run / "split.json").read_text())["touch_reference"] == {"mode": "state"}
    other = quadratic_recording((5.0, 15.0), seed=0)
    other_file = tmp_path / "unseen.h5"
    write_recording(other, other_file)
    assert cli(["evaluate", str(run), "--data", str(other_file), "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "calibration: each trial's own inflation state" in out
    m = json.loads((run / "metrics_unseen.json").read_text())["touch"]
    r = read_run(run)
    ds = touch_dataset(other, reference="state")
    with torch.no_grad():
        pred = r.model(torch.from_numpy(ds.x)).argmax(1).numpy()
    assert m["n_misclassified"] == int((pred != ds.y).sum())
    no_rest = quadratic_recording((5.0, 15.0), rest=False, seed=0)
    write_recording(no_rest, tmp_path / "no_rest.h5")
    with pytest.raises(EctskinError, match=r"state \(5, 5, 5\) ml has no no-contact"):
        evaluate_run(run, tmp_path / "no_rest.h5", figures=False, write=False)
    paper = _train(data_file, tmp_path / "paper", None)
    assert json.loads((paper / "split.json").read_text())["touch_reference"] == {"mode": "rest"}
