"""Touch model choice (ectskin.learn.candidates, train(model=...), evaluate_run, TouchPredictor):
selection by validation only, the classical models' answers (one frame through their ONNX export,
batches through scikit-learn: both against scikit-learn's own), the files of the run, the
trusted-types load of model.skops and the resume / overwrite rules of a run folder."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

import ectskin.learn.candidates as cand
from ectskin._check import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.learn import classical_onnx
from ectskin.learn.candidates import (
    CLASSICAL,
    TOUCH_MODELS,
    fit_classical,
    load_classical,
    read_candidates,
    save_classical,
    select_candidate,
)
from ectskin.learn.classical_onnx import OnnxClassifier
from ectskin.learn.data import TouchData
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.predict import TouchPredictor
from ectskin.learn.train import TrainConfig, train, train_from_recording


@pytest.fixture(autouse=True)
def fast_settings(monkeypatch):
    """Fewer trees and boosting rounds than the defaults: the same models, fit in a fraction of
    the time (the tests are about the choice, not the classifiers' settings)."""
    monkeypatch.setitem(cand.SETTINGS, "gbt", {**cand.SETTINGS["gbt"], "max_iter": 30})
    monkeypatch.setitem(cand.SETTINGS, "random_forest", {"n_estimators": 20})


def _problem(kind: str, n_groups: int, per: int, seed: int) -> TouchData:
    """28 standard-normal channels; classes 1 and 2 by a rule: "xor" the signs of channels 0 and
    1 (axis-aligned thresholds: trees' home ground, a linear model cannot, an MLP trained for one
    epoch has not learnt it); "slab" whether the frame lies between two oblique parallel planes
    |sum(x)/sqrt(28)| < 0.67 (two ReLU units; trees and k-NN see a staircase and 27 distracting
    directions, a linear model cannot)."""
    rng = np.random.default_rng(seed)
    n = n_groups * per
    x = rng.standard_normal((n, 28)).astype(np.float32)
    if kind == "xor":
        y = 1 + ((x[:, 0] > 0) ^ (x[:, 1] > 0))
    else:
        y = 1 + (np.abs(x.sum(1) / np.sqrt(28)) > 0.67)
    return TouchData(
        x=x,
        y=y.astype(np.int64),
        group=np.repeat(np.arange(n_groups), per).astype(np.int64),
        group_names=[f"{kind}{seed}-{g}" for g in range(n_groups)],
        n_classes=3,
        pair_names=[f"p{i}" for i in range(28)],
    )


def _accuracy_of_files(run, val: TouchData) -> float:
    """The selected model's validation accuracy recomputed from the file alone."""
    model = load_classical(run / "model.skops")
    return float(np.mean(model.predict(val.x) == val.y))


# --------------------------------------------------------------------------- selection
def test_auto_selects_trees_by_validation_where_they_win(tmp_path):
    tr, va = _problem("xor", 8, 100, 1), _problem("xor", 4, 100, 2)
    run = tmp_path / "run"
    s = train(
        "touch", tr, va, run, TrainConfig(profile="quick", epochs=1, progress=False, model="auto")
    )
    doc = read_candidates(run)
    assert set(doc["candidates"]) == {"mlp", *CLASSICAL}
    vals = {k: c["val_accuracy"] for k, c in doc["candidates"].items()}
    assert doc["selected"] == s["selected_model"] == max(vals, key=vals.get)
    assert doc["selected"] in ("gbt", "random_forest")
    assert vals[doc["selected"]] > vals["mlp"] + 0.2 and vals["logreg"] < 0.65
    # the recorded accuracy is the one of the saved model on the validation split
    assert _accuracy_of_files(run, va) == pytest.approx(vals[doc["selected"]], abs=1e-12)
    assert (run / "model.pt").is_file()  # the MLP's weights stay
    c = doc["candidates"][doc["selected"]]
    assert c["n_train_used"] == tr.n_samples and c["fit_seconds"] > 0
    assert c["settings"]["seed"] == 0 and doc["selected_because"].startswith("highest")
    # inference answers with the selected model, with the MLP's output contract
    pred = TouchPredictor.from_run(run)
    assert pred.model_name == doc["selected"] and pred.n_classes == 3 and pred.n_pairs == 28
    one = pred.predict(va.x[0])
    assert one.shape == (3,) and one.dtype == np.float32 and one.sum() == pytest.approx(1, abs=1e-6)
    batch = pred.predict(va.x[:50])
    assert batch.shape == (50, 3) and np.allclose(batch[0], one)
    assert np.array_equal(
        pred.classify(va.x[:50]), load_classical(run / "model.skops").predict(va.x[:50])
    )
    assert pred.classify(va.x[0]) == int(one.argmax())


def test_auto_keeps_the_mlp_where_it_wins(tmp_path):
    tr, va = _problem("slab", 10, 200, 1), _problem("slab", 4, 200, 2)
    run = tmp_path / "run"
    s = train(
        "touch", tr, va, run, TrainConfig(profile="quick", epochs=30, progress=False, model="auto")
    )
    vals = s["candidates"]
    assert s["selected_model"] == "mlp" and vals["mlp"] > max(vals[k] for k in CLASSICAL) + 0.05
    assert not (run / "model.skops").exists()
    assert TouchPredictor.from_run(run).model_name == "mlp"


def test_select_candidate_ties_go_to_the_mlp_then_the_simpler():
    assert select_candidate({"gbt": 0.9, "mlp": 0.9, "knn": 0.8})[0] == "mlp"
    assert select_candidate({"gbt": 0.9, "random_forest": 0.9, "logreg": 0.5})[0] == "random_forest"
    assert select_candidate({"gbt": 0.9, "knn": 0.9, "logreg": 0.9})[0] == "logreg"
    name, why = select_candidate({"gbt": 0.91, "mlp": 0.9})
    assert name == "gbt" and "0.9100" in why
    assert select_candidate({"knn": 0.1})[1].startswith("the only candidate")
    assert select_candidate({"mlp": float("nan"), "knn": 0.2})[0] == "knn"
    with pytest.raises(EctskinError, match="unknown candidate"):
        select_candidate({"svm": 1.0})


@pytest.fixture
def data_file(tmp_path, make_recording):
    """2 inflation states x (no contact + 4 touch regions), 40 frames."""
    path = tmp_path / "data.h5"
    rec = make_recording(n_frames=40, regions=(1, 5, 10, 14), occluded=(), no_markers=())
    write_recording(rec, path)
    return path


def test_the_choice_never_looks_at_the_test_split(tmp_path, data_file):
    config = TrainConfig(profile="quick", epochs=2, counts=(6, 2, 2), progress=False, model="auto")
    train_from_recording("touch", data_file, tmp_path / "a", config)
    split = json.loads((tmp_path / "a" / "split.json").read_text())
    # the same recording with the test trials' frames labelled with another class
    rec = read_recording(data_file)
    for t in rec.trials:
        if t.name in split["test"]:
            t.labels = (t.labels + 3) % 15
    other = tmp_path / "permuted.h5"
    write_recording(rec, other)
    train_from_recording("touch", other, tmp_path / "b", config)
    a, b = (read_candidates(tmp_path / k) for k in "ab")
    assert json.loads((tmp_path / "b" / "split.json").read_text())["test"] == split["test"]
    assert a["selected"] == b["selected"]
    assert {k: c["val_accuracy"] for k, c in a["candidates"].items()} == {
        k: c["val_accuracy"] for k, c in b["candidates"].items()
    }
    # ... while the test metrics of the two runs do see the changed labels
    ta = evaluate_run(tmp_path / "a", figures=False, baselines=False, write=False)["touch"]
    tb = evaluate_run(tmp_path / "b", figures=False, baselines=False, write=False)["touch"]
    assert ta["confusion"] != tb["confusion"]


# --------------------------------------------------------------------------- evaluation
def test_evaluate_reports_every_candidate_and_the_selected_model(tmp_path, data_file):
    run = tmp_path / "run"
    config = TrainConfig(profile="quick", epochs=2, counts=(6, 2, 2), progress=False, model="auto")
    train_from_recording("touch", data_file, run, config)
    doc = read_candidates(run)
    t = evaluate_run(run, figures=False)["touch"]
    assert t["selected_model"] == doc["selected"]
    assert set(t["candidates"]) == {"mlp", *CLASSICAL}
    sel = t["candidates"][doc["selected"]]
    assert sel["selected"] and sel["test_accuracy"] == t["accuracy"]
    assert sel["n_misclassified"] == t["n_misclassified"]
    for name, c in t["candidates"].items():
        assert c["val_accuracy"] == doc["candidates"][name]["val_accuracy"]
        assert c["n_test_frames"] == t["n_test_frames"] == 80
        assert c["test_accuracy"] == pytest.approx(1 - c["n_misclassified"] / 80)
    assert set(t["baselines"]) == {"majority", "logreg", "random_forest", "knn"}


def test_a_classical_model_alone_trains_evaluates_and_predicts(tmp_path, data_file):
    run = tmp_path / "run"
    config = TrainConfig(profile="quick", counts=(6, 2, 2), progress=False, model="knn")
    s = train_from_recording("touch", data_file, run, config)
    assert s["selected_model"] == "knn" and set(s["candidates"]) == {"knn"}
    assert not (run / "model.pt").exists() and (run / "model.skops").is_file()
    assert json.loads((run / "config.json").read_text())["model_choice"] == "knn"
    t = evaluate_run(run, figures=False, baselines=False)["touch"]
    assert t["selected_model"] == "knn" and t["candidates"]["knn"]["model"] == "model.skops"
    # the refit of the evaluation = the model training saved (seeded, same split)
    rec = read_recording(data_file)
    pred = TouchPredictor.from_run(run, layout=rec.layout)
    assert pred.model_name == "knn" and pred.n_classes == 19


# --------------------------------------------------------------------------- answering frames
def _two_and_three_classes(kind: str) -> TouchData:
    """Training frames of classes {1, 2} of 3 (class 0 absent: its column must stay 0; boosted
    trees: one tree per iteration and a logit) or of all three (boosted trees: a tree per class
    and iteration and a softmax)."""
    data = _problem("xor", 4, 100, 3)
    if kind == "three":
        data.y[:8] = 0
    return data


def _unseen_frames() -> np.ndarray:
    """Frames drawn apart from the training frames, some of them far outside their range."""
    x = np.random.default_rng(7).standard_normal((150, 28)).astype(np.float32)
    x[::10] *= 4
    return x


@pytest.mark.parametrize("classes", ["two", "three"])
@pytest.mark.parametrize("name", CLASSICAL)
def test_one_frame_and_batches_answer_what_scikit_learn_answers(name, classes, tmp_path):
    model, _, _ = fit_classical(name, _two_and_three_classes(classes), seed=1)
    x = _unseen_frames()
    seen = model.estimator.classes_
    want = model.estimator.predict_proba(x.astype(np.float64))  # scikit-learn: the reference
    want_class = model.estimator.predict(x.astype(np.float64))
    top2 = np.sort(want, axis=1)[:, -2:]
    clear = top2[:, 1] - top2[:, 0] > 1e-5  # not a tie (a forest's 10 of 20 votes each)
    assert clear.mean() > 0.8
    # the live engine's path: one frame at a time (ONNX Runtime where there is an export)
    if name == "knn":
        assert model.single_frame() is None  # k-NN answers through scikit-learn
    else:
        assert isinstance(model.single_frame(), OnnxClassifier)
    for loaded in (model, load_classical(save_classical(tmp_path / "m.skops", model))):
        one = np.concatenate([loaded.predict_proba(f[None]) for f in x])
        assert one.dtype == np.float32 and one.shape == (len(x), 3)
        np.testing.assert_allclose(one[:, seen], want, rtol=0, atol=1e-5)
        assert not one[:, [c for c in range(3) if c not in seen]].any()  # unseen class: 0
        got_class = np.array([loaded.predict(f[None])[0] for f in x])
        assert (got_class[clear] == want_class[clear]).all()
    assert loaded.settings == model.settings  # model.skops keeps the settings as they were
    # batches: scikit-learn's own predict_proba
    np.testing.assert_allclose(model.predict_proba(x)[:, seen], want, rtol=0, atol=1e-6)
    assert model.predict(x).tolist() == want_class.tolist()
    assert model.predict_proba(x[:0]).shape == (0, 3)


def test_the_predictor_exports_before_the_first_frame_and_answers_frames(tmp_path, monkeypatch):
    made = []

    class Counted(OnnxClassifier):
        def __init__(self, *args, **kwargs):
            made.append(args[0])
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(classical_onnx, "OnnxClassifier", Counted)
    model, _, _ = fit_classical("gbt", _two_and_three_classes("three"), seed=1)
    pred = TouchPredictor.from_run(save_classical(tmp_path / "model.skops", model))
    assert len(made) == 1  # the live engine's first frame does not wait for the export
    x = _unseen_frames()[:30]
    got = np.stack([pred.predict(f) for f in x])  # (n_pairs,) → (n_classes,)
    want = model.estimator.predict_proba(x.astype(np.float64))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)  # classes 0, 1, 2 all seen
    assert len(made) == 1


def test_one_frame_falls_back_to_scikit_learn_saying_why(monkeypatch, caplog):
    model, _, _ = fit_classical("random_forest", _problem("xor", 4, 100, 3), seed=1)
    x = _unseen_frames()[:20]
    want = model.estimator.predict_proba(x.astype(np.float64))
    monkeypatch.setattr(classical_onnx, "available", lambda: False)
    caplog.set_level("WARNING")
    one = np.concatenate([model.predict_proba(f[None]) for f in x])
    assert model.single_frame() is None
    assert "through scikit-learn" in caplog.text and "ectskin[live]" in caplog.text
    assert caplog.text.count("through scikit-learn") == 1  # said once per model
    np.testing.assert_allclose(one[:, model.estimator.classes_], want, rtol=0, atol=1e-6)


def test_an_export_that_does_not_reproduce_scikit_learn_is_refused():
    gbt, _, _ = fit_classical("gbt", _problem("xor", 4, 100, 3), seed=1)
    other, _, _ = fit_classical("gbt", _problem("xor", 4, 100, 4), seed=2)
    export = OnnxClassifier(gbt.estimator, 28, name="touch model 'gbt'")
    with pytest.raises(EctskinError, match="'gbt': the ONNX export does not reproduce"):
        export._check(other.estimator)
    with pytest.raises(EctskinError, match=r"frames must have shape \(B, 28\), got \(1, 27\)"):
        export(np.zeros((1, 27), np.float32))


# --------------------------------------------------------------------------- model.skops
class Payload:
    """Not a type ectskin trusts."""


def _dump(path, obj):
    import skops.io

    path.write_bytes(skops.io.dumps(obj))


def test_an_untrusted_or_foreign_model_file_is_refused_naming_it(tmp_path):
    tr = _problem("xor", 4, 50, 3)
    model, _, _ = fit_classical("logreg", tr)
    good = tmp_path / "good.skops"
    save_classical(good, model)
    assert load_classical(good).name == "logreg"
    bad = tmp_path / "bad.skops"
    _dump(bad, {"format": cand.SKOPS_FORMAT, "version": 1, "name": "logreg", "x": Payload()})
    with pytest.raises(EctskinError, match=r"bad\.skops: holds type\(s\) outside the trusted"):
        load_classical(bad)
    from sklearn.svm import SVC

    svc = tmp_path / "svc.skops"
    payload = {"format": cand.SKOPS_FORMAT, "version": 1, "name": "logreg", "n_pairs": 28}
    _dump(svc, {**payload, "n_classes": 3, "estimator": SVC().fit(tr.x, tr.y)})
    with pytest.raises(EctskinError, match=r"svc\.skops: field 'estimator' must be a Pipeline"):
        load_classical(svc)
    junk = tmp_path / "junk.skops"
    junk.write_bytes(b"not a zip")
    with pytest.raises(EctskinError, match=r"junk\.skops: not a readable skops model file"):
        load_classical(junk)
    # a renamed candidate: the pipeline of another classifier
    with zipfile.ZipFile(good) as z:
        assert "schema.json" in z.namelist()
    wrong = tmp_path / "wrong.skops"
    _dump(wrong, {**payload, "name": "knn", "n_classes": 3, "estimator": model.estimator})
    with pytest.raises(EctskinError, match="KNeighborsClassifier"):
        load_classical(wrong)


def test_the_predictor_refuses_a_model_for_another_skin(tmp_path, data_file):
    run = tmp_path / "run"
    config = TrainConfig(profile="quick", counts=(6, 2, 2), progress=False, model="logreg")
    train_from_recording("touch", data_file, run, config)
    from ectskin.io.generic import virtual_layout

    with pytest.raises(EctskinError, match=r"model\.skops: config field 'n_pairs' is 28"):
        TouchPredictor.from_run(run, layout=virtual_layout(6))


# --------------------------------------------------------------------------- the run folder
def test_resume_and_overwrite_rules(tmp_path, data_file, caplog):
    run = tmp_path / "run"
    base = {"profile": "quick", "counts": (6, 2, 2), "progress": False}
    train_from_recording("touch", data_file, run, TrainConfig(**base, model="logreg"))
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    # the same again: nothing to do, nothing rewritten
    s = train_from_recording("touch", data_file, run, TrainConfig(**base, model="logreg"))
    assert s["selected_model"] == "logreg"
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before
    # another choice, seed or the MLP in this folder: refused, naming the file
    with pytest.raises(EctskinError, match="trained with --model logreg, not --model knn"):
        train_from_recording("touch", data_file, run, TrainConfig(**base, model="knn"))
    with pytest.raises(EctskinError, match="trained with --model logreg, not --model mlp"):
        train_from_recording("touch", data_file, run, TrainConfig(**base, epochs=1))
    with pytest.raises(EctskinError, match="another seed or other data"):
        train_from_recording(
            "touch", data_file, run, TrainConfig(**base, model="logreg", seed=1, split_seed=0)
        )
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before
    # an MLP run is not turned into an auto run without --overwrite
    mlp = tmp_path / "mlp"
    train_from_recording("touch", data_file, mlp, TrainConfig(**base, epochs=1))
    with pytest.raises(EctskinError, match="trained with --model mlp, not --model auto"):
        train_from_recording("touch", data_file, mlp, TrainConfig(**base, model="auto"))
    # --overwrite: the earlier selection and model are removed, never left beside the new run
    caplog.set_level("WARNING")
    train_from_recording("touch", data_file, run, TrainConfig(**base, epochs=1, resume=False))
    assert not (run / "candidates.json").exists() and not (run / "model.skops").exists()
    assert "removed" in caplog.text and "candidates.json" in caplog.text
    assert TouchPredictor.from_run(run).model_name == "mlp"
    train_from_recording("touch", data_file, run, TrainConfig(**base, model="knn", resume=False))
    assert not (run / "model.pt").exists() and not (run / "last.pt").exists()
    assert read_candidates(run)["selected"] == "knn"


def test_model_choice_errors_before_the_data_is_read(tmp_path):
    missing = tmp_path / "never-read.h5"
    with pytest.raises(EctskinError, match="allowed values are 'mlp', 'auto'"):
        train_from_recording("touch", missing, tmp_path / "a", TrainConfig(model="svm"))
    with pytest.raises(EctskinError, match="--model applies to 'touch' and 'contact' only"):
        train_from_recording("track", missing, tmp_path / "a", TrainConfig(model="gbt"))
    with pytest.raises(EctskinError, match="allowed values are 'contactnet', 'auto'"):
        train_from_recording("contact", missing, tmp_path / "a", TrainConfig(model="logreg"))


def test_the_command_offers_the_library_choices():
    from ectskin.commands.train import MODELS
    from ectskin.learn.contact_choice import CONTACT_MODELS

    assert set(MODELS) == set(TOUCH_MODELS) | set(CONTACT_MODELS) | {"mlp"}
    assert MODELS[: len(TOUCH_MODELS)] == TOUCH_MODELS
