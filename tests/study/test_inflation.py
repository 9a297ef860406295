"""The unseen-inflation study (``ectskin study unseen-inflation``, ectskin.study.inflation) on
small hand-made recordings: a skin whose rest readout is an analytic quadratic in the chamber
volumes and whose touch multiplies it by a per-region pattern.

What each test catches:

* the test protocol: test trials drawn again from the training streams (same ``stream``), or a
  test experiment that differs from the training one in anything but its levels;
* the study: a document whose numbers are not those of ``evaluate_run`` on the same run and
  data, per-state accuracies that do not add up to the overall one, a summary that is not the
  seeds' results, a missing file; a test recording that repeats a training trial.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import Recording, Trial, write_recording
from ectskin.layout import default_layout
from ectskin.learn.evaluate import evaluate_run
from ectskin.study import inflation
from ectskin.study.inflation import UnseenInflationConfig, unseen_inflation, unseen_protocol
from ectskin.twin.protocol import Protocol

LAYOUT = default_layout()
P = LAYOUT.n_pairs


def _recording(levels, seed) -> Recording:
    """Per state (levels³) a no-contact trial and two touch trials, 8 frames each, with noise."""
    phys = np.random.default_rng(99)
    base, lin = phys.uniform(0.5, 2.0, P), phys.uniform(-0.3, 0.3, (3, P))
    quad = phys.uniform(-0.1, 0.1, (3, 3, P))
    patterns = phys.uniform(0.2, 1.0, (19, P))
    rng = np.random.default_rng(seed)
    trials = []
    for k, p in enumerate(itertools.product(levels, repeat=3)):
        q = np.asarray(p) / 20
        c0 = base * (1 + q @ lin + np.einsum("i,j,ijp->p", q, q, quad))
        for j, region in enumerate((0, 1 + k % 6, 10 + k % 6)):
            c = c0 * (1 + 0.05 * patterns[region]) + rng.normal(0, 1e-4, (8, P))
            trials.append(
                Trial(
                    f"s{k}_t{j}",
                    c,
                    np.arange(8) / 30,
                    np.full(8, region),
                    inflation=p,
                    region=region,
                    meta={"kind": "touch" if region else "no_contact"},
                )
            )
    return Recording(LAYOUT, trials, 30.0)


def test_the_test_protocol_is_the_training_one_at_other_levels_with_new_draws():
    train = Protocol(seed=3, touch_trials=2, push_max_n=1.0)
    test = unseen_protocol(train, (0.0, 5.0, 15.0), inflation.TEST_STREAM)
    assert test.levels_ml == (0.0, 5.0, 15.0) and test.stream == inflation.TEST_STREAM
    assert test.seed == 3 and test.touch_trials == 2 and test.push_max_n == 1.0
    a, b = train.rng(7).random(4), test.rng(7).random(4)
    assert not np.allclose(a, b)  # other random streams
    same = Protocol(seed=3, stream=inflation.TEST_STREAM)
    assert unseen_protocol(same, (5.0,), inflation.TEST_STREAM).stream == inflation.TEST_STREAM + 1


@pytest.fixture
def files(tmp_path):
    train, test = tmp_path / "train_0.h5", tmp_path / "test_0.h5"
    write_recording(_recording((0.0, 10.0, 20.0), seed=0), train)
    write_recording(_recording((0.0, 5.0, 15.0), seed=1), test)
    return str(tmp_path / "train_{seed}.h5"), str(tmp_path / "test_{seed}.h5")


def test_the_study_reports_what_evaluate_gives_per_state_and_overall(tmp_path, files):
    """The study's accuracy of each run is evaluate_run's on the whole test recording; the
    per-state accuracies, weighted by frames, give it back; the groups name the unseen levels;
    the summary is the results; the JSON and the figure are written."""
    config = UnseenInflationConfig(
        seeds=(0,),
        profiles=("quick",),
        references=("state", "inflation"),
        train_data=files[0],
        test_data=files[1],
        epochs=2,
        counts=(45, 18, 18),
    )
    out = tmp_path / "study"
    doc = unseen_inflation(out, config)
    saved = json.loads((out / inflation.RESULT_FILE).read_text())
    assert saved["complete"] is True and saved["results"] == doc["results"]
    assert (out / inflation.FIGURE_FILE).stat().st_size > 0
    assert [(r["profile"], r["reference"]) for r in doc["results"]] == [
        ("quick", "state"),
        ("quick", "inflation"),
    ]
    for r in doc["results"]:
        m = evaluate_run(r["run"], files[1].format(seed=0), figures=False, write=False)["touch"]
        assert r["accuracy"] == m["accuracy"] and r["n_test_frames"] == 27 * 3 * 8
        assert r["test_trials"] == 81
        n = np.array([p["n_frames"] for p in r["per_state"]])
        acc = np.array([p["accuracy"] for p in r["per_state"]])
        assert len(r["per_state"]) == 27 and n.sum() == r["n_test_frames"]
        assert np.isclose((acc * n).sum() / n.sum(), r["accuracy"])
        groups = {p["group"] for p in r["per_state"]}
        assert groups == {"seen levels", "5 ml", "15 ml", "5 and 15 ml"}
        assert r["own_split"]["accuracy"] is not None and r["baselines"]
    s = doc["summary"][0]
    assert s["accuracy"] == [doc["results"][0]["accuracy"]]
    best = max(doc["results"][0]["baselines"].values())
    assert s["strongest_baseline"][0]["accuracy"] == best
    assert s["beats_strongest_baseline"] == (s["accuracy"][0] > best)
    assert inflation.summary_lines(doc)[0].startswith("  quick / state")
    # a second call resumes: the runs are not trained again, the evaluations are reused
    stamp = {r["run"]: (out / r["run"] / "model.pt").stat().st_mtime_ns for r in doc["results"]}
    again = unseen_inflation(out, config)
    assert again["results"] == doc["results"]
    assert stamp == {r: (out / r / "model.pt").stat().st_mtime_ns for r in stamp}


def test_a_test_recording_that_repeats_a_training_trial_is_refused(tmp_path, files):
    """The same file as training and test data: every test trial is a training trial."""
    config = UnseenInflationConfig(
        seeds=(0,), train_data=files[0], test_data=files[0], profiles=("quick",), epochs=1
    )
    with pytest.raises(EctskinError, match=r"81 trial\(s\) have the readouts of a trial"):
        unseen_inflation(tmp_path / "s", config)


def test_config_refusals():
    with pytest.raises(EctskinError, match="'reference'"):
        UnseenInflationConfig(references=("pump",))
    with pytest.raises(EctskinError, match="no level outside the training levels"):
        UnseenInflationConfig(test_levels_ml=(0.0, 10.0))
    with pytest.raises(EctskinError, match="'profile'"):
        UnseenInflationConfig(profiles=("fast",))


def test_a_simulated_recording_of_another_protocol_is_not_replaced_without_overwrite(tmp_path):
    """OUT/data/<name>.h5 holding another protocol (here: a recording with the protocol of
    seed 5) is refused with the differing fields named, before any simulation; it was
    re-simulated in place silently before."""
    path = tmp_path / "data" / "train_s0.h5"
    path.parent.mkdir()
    rec = _recording((0.0, 10.0, 20.0), seed=0)
    rec.meta["protocol"] = Protocol(seed=5).to_dict()
    write_recording(rec, path)
    before = path.read_bytes()
    with pytest.raises(EctskinError, match=r"train_s0\.h5: protocol: .*\['seed'\].*--overwrite"):
        inflation._simulated(path, Protocol(seed=0), None, UnseenInflationConfig(seeds=(0,)))
    assert path.read_bytes() == before


def test_robust_runs_also_train_on_the_coverage_trials_of_the_training_protocol(
    tmp_path, monkeypatch
):
    """A training recording that names its twin protocol: the robust run's training split is
    joined by the coverage trials of that protocol (its levels only, so the test levels stay
    unseen); the paper's recipe and coverage=False train without them."""
    from ectskin.io import read_recording
    from ectskin.twin.coverage import coverage_protocol

    base = Protocol(seed=0, touch_trials=2)
    rec = _recording((0.0, 10.0, 20.0), seed=0)
    rec = Recording(rec.layout, rec.trials, 30.0, meta={"protocol": base.to_dict()})
    train, test = tmp_path / "train_0.h5", tmp_path / "test_0.h5"
    write_recording(rec, train)
    write_recording(_recording((0.0, 5.0, 15.0), seed=1), test)
    asked = []

    def fake_simulated(path, protocol, like, config):  # the twin's coverage trials, stood in for
        asked.append(protocol)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_recording(_recording((0.0, 10.0, 20.0), seed=2), path)
        return path

    monkeypatch.setattr(inflation, "_simulated", fake_simulated)
    config = UnseenInflationConfig(
        seeds=(0,), profiles=("quick", "robust"), references=("state-offset",),
        train_data=str(tmp_path / "train_{seed}.h5"), test_data=str(tmp_path / "test_{seed}.h5"),
        epochs=1, counts=(45, 18, 18), baselines=False, own_split=False,
    )
    doc = unseen_inflation(tmp_path / "study", config)
    assert asked == [coverage_protocol(base, LAYOUT)]
    cover = doc["data"]["0"]["coverage"]
    quick, robust = doc["results"]
    assert quick["extra_train"] == [] and robust["extra_train"] == [cover]
    split = json.loads((tmp_path / "study" / robust["run"] / "split.json").read_text())
    assert [e["file"] for e in split["extra_train"]] == [str(Path(cover).resolve())]
    assert len(split["extra_train"][0]["trial_digests"]) == read_recording(cover).n_trials
    off = unseen_inflation(tmp_path / "off", replace(config, coverage=False))
    assert "coverage" not in off["data"]["0"] and off["results"][1]["extra_train"] == []
