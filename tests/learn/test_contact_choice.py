"""The contact model choice (``ectskin train contact --model auto|contactnet|knn|ridge|gbt|gp``):
the classical candidates against brute-force / closed-form references, the selection on the
validation split, model.skops, and whole runs on press data the twin did not make
(tests/learn/press_data.py: another layout, body, readout and noise)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from press_data import press_npz  # tests/learn/press_data.py

from ectskin import EctskinError
from ectskin.io import write_recording
from ectskin.io.generic import load_generic, virtual_layout
from ectskin.learn.baselines.contact import contact_knn_baseline, contact_ridge_baseline
from ectskin.learn.contact_choice import select_contact
from ectskin.learn.contact_classical import (
    fit_contact_classical,
    load_contact_classical,
    save_contact_classical,
)
from ectskin.learn.data.contact import contact_dataset
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.predict import ContactPredictor
from ectskin.learn.tasks.contact import contact_report
from ectskin.learn.train import TrainConfig, train, train_from_recording


def _press(tmp_path, name="press", window=1, **kw):
    rec = load_generic(press_npz(tmp_path / f"{name}.npz", **kw))
    return rec, contact_dataset(rec, window=window)


def _halves(d, frac=0.7, seed=0):
    g = np.random.default_rng(seed).permutation(d.n_groups)
    n = int(frac * d.n_groups)
    return d.select(np.sort(g[:n])), d.select(np.sort(g[n:]))


def _contact_frames(d):
    on = d.count > 0
    x = np.asarray(d.x[on, -1, :], np.float64)
    y = np.column_stack([d.uv[on, 0], d.force[on, 0]])
    return x, y


# --------------------------------------------------------------------------- the candidates
def test_knn_candidate_is_the_mean_of_the_five_nearest_frames(tmp_path):
    _, d = _press(tmp_path, n_presses=20, n_channels=10)
    tr, te = _halves(d)
    model, used, _ = fit_contact_classical("knn", tr)
    assert used == tr.n_samples
    pred = model.predict(te.x)
    # brute force: standardise with the contact frames' mean / std, average the 5 nearest
    x, y = _contact_frames(tr)
    mu, sd = x.mean(0), x.std(0)
    z, zt = (x - mu) / sd, (np.asarray(te.x[:, -1, :], np.float64) - mu) / sd
    dist = ((zt[:, None, :] - z[None, :, :]) ** 2).sum(-1)
    want = y[np.argsort(dist, axis=1)[:, :5]].mean(axis=1)
    np.testing.assert_allclose(pred[:, 4], want[:, 0], atol=1e-9)  # u
    np.testing.assert_allclose(pred[:, 5], want[:, 1], atol=1e-9)  # v
    np.testing.assert_allclose(pred[:, 7], want[:, 2], atol=1e-9)  # force
    # the k-NN baseline is this candidate
    np.testing.assert_array_equal(contact_knn_baseline(tr, te), pred)


def test_ridge_candidate_is_the_closed_form_ridge_solution(tmp_path):
    _, d = _press(tmp_path, n_presses=20, n_channels=10)
    tr, te = _halves(d)
    model, _, _ = fit_contact_classical("ridge", tr)
    pred = model.predict(te.x)
    alpha = model.parts["regress"][-1].alpha_
    assert alpha in model.settings["alphas"]
    x, y = _contact_frames(tr)
    mu, sd = x.mean(0), x.std(0)
    z = (x - mu) / sd
    w = np.linalg.solve(z.T @ z + alpha * np.eye(z.shape[1]), z.T @ (y - y.mean(0)))
    want = ((np.asarray(te.x[:, -1, :], np.float64) - mu) / sd) @ w + y.mean(0)
    # (float64 round-off of two solvers of a nearly singular system: 1e-5 of the values)
    np.testing.assert_allclose(pred[:, 4], want[:, 0], rtol=1e-5)
    np.testing.assert_allclose(pred[:, 5], want[:, 1], rtol=1e-5)
    np.testing.assert_allclose(pred[:, 7], np.maximum(want[:, 2], 0.0), rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(contact_ridge_baseline(tr, te), pred)


def test_select_contact_lowest_error_ties_to_contactnet_then_the_simpler():
    assert select_contact({"contactnet": 3.0, "knn": 2.0, "gbt": 2.5})[0] == "knn"
    assert select_contact({"gbt": 2.0, "knn": 2.0, "ridge": 2.0})[0] == "ridge"
    assert select_contact({"gbt": 2.0, "contactnet": 2.0})[0] == "contactnet"
    assert select_contact({"contactnet": math.nan, "gp": 4.0})[0] == "gp"
    name, why = select_contact({"gbt": math.nan, "knn": math.nan})
    assert name == "knn" and "no validation frame" in why
    assert select_contact({"gp": 9.0}) == ("gp", "the only candidate (--model asked for it)")


def test_model_skops_round_trip_and_refusals(tmp_path):
    import skops.io

    _, d = _press(tmp_path, n_presses=15, n_channels=6)
    tr, te = _halves(d)
    for name in ("gbt", "gp"):
        model, _, _ = fit_contact_classical(name, tr)
        path = save_contact_classical(tmp_path / f"{name}.skops", model)
        back = load_contact_classical(path)
        np.testing.assert_array_equal(back.predict(te.x), model.predict(te.x))
    sigma = back.predict(te.x)[:, 6]  # the Gaussian process's own uncertainty
    assert np.isfinite(sigma).all() and (sigma > 0).all()
    with pytest.raises(EctskinError, match=r"gp\.skops: config field 'n_pairs' is 6"):
        load_contact_classical(tmp_path / "gp.skops", layout=virtual_layout(3))
    # a file naming one candidate but holding another's parts
    knn, _, _ = fit_contact_classical("knn", tr)
    wrong = tmp_path / "wrong.skops"
    save_contact_classical(wrong, knn)
    doc = skops.io.load(wrong, trusted=skops.io.get_untrusted_types(file=wrong))
    doc["name"] = "ridge"
    wrong.write_bytes(skops.io.dumps(doc))
    with pytest.raises(EctskinError, match=r"wrong\.skops: part 'contact' must be a Pipeline"):
        load_contact_classical(wrong)
    doc["name"], doc["parts"]["hover"] = "knn", _Foreign()
    wrong.write_bytes(skops.io.dumps(doc))
    with pytest.raises(EctskinError, match=r"wrong\.skops: holds type\(s\) outside the trusted"):
        load_contact_classical(wrong)
    (tmp_path / "junk.skops").write_bytes(b"not a zip")
    with pytest.raises(EctskinError, match="not a readable skops model file"):
        load_contact_classical(tmp_path / "junk.skops")


class _Foreign:
    """Not a type ectskin trusts."""


# --------------------------------------------------------------------------- whole runs
def test_auto_answers_with_a_classical_model_where_contactnet_loses(tmp_path, cli):
    """A small press data set and a ContactNet of two epochs: it loses to the simple models on
    validation; auto must answer with one of them, and never with one that loses to the k-NN
    or ridge baseline on validation."""
    rec, _ = _press(tmp_path, n_presses=60, n_channels=15, seed=2)
    h5 = tmp_path / "press.h5"
    write_recording(rec, h5)
    run = tmp_path / "auto"
    argv = ["train", "contact", str(h5), "-o", str(run), "--model", "auto", "--window", "1"]
    assert cli([*argv, "--profile", "quick", "--epochs", "2", "--no-progress"]) == 0
    doc = json.loads((run / "candidates.json").read_text())
    cands = {k: c["val_loc_mm"] for k, c in doc["candidates"].items()}
    assert set(cands) == {"contactnet", "knn", "ridge", "gbt", "gp"}  # gp: <= 2 000 frames
    assert doc["selected"] != "contactnet"
    assert cands[doc["selected"]] == min(cands.values())
    assert (run / "model.skops").is_file() and (run / "model.pt").is_file()
    # the validation numbers are those of the baselines fit on the same split
    split = json.loads((run / "split.json").read_text())
    d = contact_dataset(rec, window=1)
    ids = {n: i for i, n in enumerate(d.group_names)}
    tr = d.select(np.array(sorted(ids[n] for n in split["train"])))
    va = d.select(np.array(sorted(ids[n] for n in split["val"])))
    for name, fn in (("knn", contact_knn_baseline), ("ridge", contact_ridge_baseline)):
        want = contact_report(va, fn(tr, va), with_maps=False)["loc_mm_mean"]
        assert cands[name] == pytest.approx(want, rel=1e-12)
        assert cands[doc["selected"]] <= want
    assert cli(["evaluate", str(run), "--no-figures"]) == 0
    m = json.loads((run / "metrics.json").read_text())["contact"]
    assert m["selected_model"] == doc["selected"]
    on_test = m["candidates"]
    assert set(on_test) == set(cands)
    assert all(c["test_loc_mm"] is not None for c in on_test.values())
    assert m["loc_mm_mean"] == on_test[doc["selected"]]["test_loc_mm"]
    assert on_test["knn"]["test_loc_mm"] == pytest.approx(m["baselines"]["knn"]["loc_mm_mean"])
    assert "region_centre" not in m["baselines"]  # a virtual layout: left out, with a note
    assert "no physical touch regions" in m["baselines_left_out"]["region_centre"]
    # the predictor answers with the selected model, as evaluation did
    p = ContactPredictor.from_run(run, layout=rec.layout)
    assert p.model_name == doc["selected"] and p.runtime == "skops" and p.window == 1
    te = d.select(np.array(sorted(ids[n] for n in split["test"])))
    want = load_contact_classical(run / "model.skops").predict(te.x).astype(np.float32)
    np.testing.assert_array_equal(p.predict(te.x), want)
    reading = p.read(te.x[int(np.argmax(te.count))])
    assert reading.count == 1 and reading.fingers[0].face == "front"
    # a run whose candidates.json selects ContactNet answers with model.pt
    doc["selected"] = "contactnet"
    (run / "candidates.json").write_text(json.dumps(doc))
    (run / "model.skops").unlink()
    m = evaluate_run(run, figures=False, overwrite=True)["contact"]
    assert m["selected_model"] == "contactnet"
    assert m["loc_mm_mean"] == pytest.approx(on_test["contactnet"]["test_loc_mm"])
    assert ContactPredictor.from_run(run).model_name == "contactnet"


@pytest.mark.slow
def test_auto_keeps_contactnet_where_it_wins(tmp_path):
    """Heavy-tailed noise on presses held for 20 frames: ContactNet reads a 10-frame window and
    averages the noise away, the classical candidates read the last frame alone."""
    rec, d = _press(tmp_path, window=10, n_presses=100, n_channels=15, hold=20, noise=0.03, seed=2)
    tr, va = _halves(d)
    config = TrainConfig(profile="quick", seed=0, progress=False, model="auto")
    summary = train("contact", tr, va, tmp_path / "run", config)
    cands = summary["candidates"]
    assert summary["selected_model"] == "contactnet"
    assert all(cands["contactnet"] < 0.9 * v for k, v in cands.items() if k != "contactnet")
    assert not (tmp_path / "run" / "model.skops").exists()
    p = ContactPredictor.from_run(tmp_path / "run")
    assert p.model_name == "contactnet" and p.window == 10


def test_a_classical_contact_model_alone(tmp_path):
    rec, _ = _press(tmp_path, n_presses=30, n_channels=10)
    h5 = tmp_path / "press.h5"
    write_recording(rec, h5)
    run = tmp_path / "ridge"
    config = TrainConfig(profile="quick", progress=False, model="ridge", window=1)
    s = train_from_recording("contact", h5, run, config)
    assert s["selected_model"] == "ridge" and not (run / "model.pt").exists()
    m = evaluate_run(run, figures=False)["contact"]
    assert m["selected_model"] == "ridge" and set(m["candidates"]) == {"ridge"}
    assert m["loc_mm_mean"] == pytest.approx(m["baselines"]["ridge"]["loc_mm_mean"])
    # starting over with ContactNet removes the classical model
    train_from_recording(
        "contact",
        h5,
        run,
        TrainConfig(profile="quick", epochs=1, progress=False, resume=False, window=1),
    )
    assert not (run / "model.skops").exists() and not (run / "candidates.json").exists()
    assert ContactPredictor.from_run(run).model_name == "contactnet"


def test_a_classical_run_is_not_refit_on_other_data_without_overwrite(tmp_path):
    for name, seed in (("a", 1), ("b", 2)):
        rec, _ = _press(tmp_path, name=name, n_presses=12, n_channels=6, seed=seed)
        write_recording(rec, tmp_path / f"{name}.h5")
    config = TrainConfig(profile="quick", progress=False, model="knn", window=1)
    train_from_recording("contact", tmp_path / "a.h5", tmp_path / "run", config)
    train_from_recording("contact", tmp_path / "a.h5", tmp_path / "run", config)  # same: fine
    with pytest.raises(EctskinError, match=r"candidates\.json: the run was fit with another"):
        train_from_recording("contact", tmp_path / "b.h5", tmp_path / "run", config)
