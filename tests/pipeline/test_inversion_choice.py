"""The contact model choice of the reproduction's inversion step (ectskin.pipeline.contact_pick):
the run's model, its k-NN and ridge baselines, the inversion and the hybrid, chosen on
validation frames only.

On a tiny contact experiment read from a coarse response field (as test_inversion_step). The
run's model is a stand-in whose answers are the frames' true fingers moved by a known offset
(its error is that offset, by construction): with no offset it must be chosen, with a large one
the candidate of the lowest validation error; scrambling the test labels leaves the choice and
every validation number as they were.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_inversion_step import TEST, VAL, make_world  # tests/pipeline

from ectskin.io import Recording, read_recording
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.pipeline import contact_pick as cp
from ectskin.pipeline import inversion as pinv
from ectskin.pipeline.metrics import inversion_block
from ectskin.pipeline.runner import StepRunner
from ectskin.report.inversion import choice_line

TRAIN = ["trial_0003"]
NCOL = len(PRED_COLUMNS) + 2 * len(SLOT_COLUMNS)
#: validation and test frames of the choice (evenly spread): the code path, in seconds
FRAMES = 50


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """As test_inversion_step's: one state with a field, ``far_0003`` at a state without one."""
    return make_world(tmp_path_factory.mktemp("inversion_choice"))


class Offset(cp.LearnedModel):
    """The run's model's stand-in: the true fingers of each frame, moved ``du`` mm along u
    (count, faces and forces as they are); its window (3) and reference are its own."""

    def __init__(self, rec: Recording, du: float) -> None:  # no run folder: nothing to read
        self.rec, self.du, self.name, self.window, self.reference = rec, du, "contactnet", 3, "auto"

    def predict(self, sub):
        assert sub.window == self.window  # the run's own windows, not the step's
        out = np.zeros((sub.n_samples, NCOL))
        out[:, 0] = sub.count
        out[:, 1] = sub.count > 0
        for s in range(2):
            a = len(PRED_COLUMNS) + s * len(SLOT_COLUMNS)
            out[:, a + SLOT_COLUMNS.index("face")] = np.maximum(sub.face[:, s], 0)
            out[:, a + SLOT_COLUMNS.index("u_mm")] = sub.uv[:, s, 0] + self.du
            out[:, a + SLOT_COLUMNS.index("v_mm")] = sub.uv[:, s, 1]
            out[:, a + SLOT_COLUMNS.index("force_n")] = sub.force[:, s]
        return out


def _choice(world, du, scramble=False):
    config, fields, path = world
    rec = read_recording(path)
    from ectskin.inversion import Inversion

    inv = Inversion(fields, config.contact_protocol().readout)
    val = pinv._dataset(rec, VAL)
    test = pinv._dataset(rec, TEST[:2])
    rows = pinv._frames(test, False, FRAMES)
    arrays, seconds = pinv.invert_rows(inv, rec, test, rows)
    if scramble:  # the test labels shuffled: frames keep their readouts, lose their truth
        p = np.random.default_rng(0).permutation(test.n_samples)
        test = replace(test, count=test.count[p], face=test.face[p], uv=test.uv[p],
                       force=test.force[p])

    def invert(data, rows, seeds):
        a, sec = pinv.invert_rows(inv, rec, data, rows, seeds)
        return pinv.prediction_columns(a, data.faces, data.face_extent), sec

    own = (pinv.prediction_columns(arrays, test.faces, test.face_extent), seconds)
    return cp.contact_choice(
        Offset(rec, du), invert, val=val, val_rows=pinv._frames(val, False, FRAMES),
        test=test, test_rows=rows, inversion_test=own, train_trials=TRAIN, seed=0,
        share_without_field=0.25)


def test_the_lowest_validation_error_is_chosen_and_no_test_label_is_read(world):
    exact = _choice(world, 0.0)
    assert exact["order"] == ["contactnet", "ridge", "knn", "inversion", "hybrid"]
    assert exact["candidates"]["contactnet"]["val"]["loc_mm_mean"] == pytest.approx(0, abs=1e-5)
    assert exact["selected"] == "contactnet" and exact["candidates"]["contactnet"]["selected"]
    # moved further than the inversion misses (on this coarse field, by centimetres)
    du = 1.5 * exact["candidates"]["inversion"]["val"]["loc_mm_mean"] + 5.0
    far = _choice(world, du)
    val = {k: v["val"]["loc_mm_mean"] for k, v in far["candidates"].items()}
    assert val["contactnet"] > val["inversion"]
    assert far["selected"] == min(val, key=val.get) != "contactnet"
    assert far["why"].startswith(f"the lowest {cp.METRIC}: {val[far['selected']]:.3f}")
    scrambled = _choice(world, du, scramble=True)
    assert (scrambled["selected"], scrambled["why"]) == (far["selected"], far["why"])
    timing = {"ms_per_frame_median", "ms_per_frame_mean"}
    for k, v in far["candidates"].items():
        theirs = scrambled["candidates"][k]["val"]
        assert {q: x for q, x in theirs.items() if q not in timing} == {
            q: x for q, x in v["val"].items() if q not in timing}, k
    assert any(scrambled["candidates"][k]["test"]["loc_mm_mean"] != v["test"]["loc_mm_mean"]
               for k, v in far["candidates"].items())  # the test numbers do read them
    assert far["n_test_frames"] == far["n_val_frames"] == FRAMES
    assert far["answers"]["states_without_field"] == {
        "model": "contactnet", "share_of_test_frames": 0.25,
        "why": "a frame of a state without a response field can only be answered by the "
               "learned model"}
    assert far["answers"]["field_states"] == {"model": far["selected"],
                                              "share_of_test_frames": 0.75}


def test_the_step_reports_the_choice_in_its_metrics_and_metrics_json(world, tmp_path,
                                                                      monkeypatch):
    config, fields, path = world
    out = tmp_path / "out"
    (out / "runs" / "contact").mkdir(parents=True)
    (out / "runs" / "contact" / "split.json").write_text(
        json.dumps({"train": TRAIN, "val": VAL, "test": TEST}))
    config = replace(config, out_dir=out)
    loaded = []

    def load(run_dir, rec, source):
        loaded.append((run_dir, source))
        return Offset(rec, 40.0)

    monkeypatch.setattr(pinv, "load_learned", load)
    m = pinv.inversion_step(StepRunner(out, False), config, fields, (path, {}), push="off",
                            max_frames=60, choice=True)
    assert loaded == [(out / "runs" / "contact", str(path))]
    c = m["choice"]
    for key in ("selected", "why", "metric", "order", "candidates", "n_val_frames",
                "n_test_frames", "answers", "baselines_fit_s", "seconds"):
        assert key in c, key
    for name in c["order"]:
        assert {"kind", "val", "test", "selected"} <= set(c["candidates"][name])
        assert c["candidates"][name]["test"]["n_frames"] == m["n_frames"] == 60
    # the inversion's candidate is the step's own inversion of its test frames
    assert c["candidates"]["inversion"]["test"]["loc_mm_mean"] == pytest.approx(m["loc_mm_mean"])
    a = c["answers"]
    assert a["states_without_field"]["share_of_test_frames"] == pytest.approx(
        m["share_without_field"]) == pytest.approx(60 / 180)
    assert a["field_states"]["share_of_test_frames"] == pytest.approx(120 / 180)
    assert inversion_block(m, None, None)["choice"] == c
    line = choice_line(inversion_block(m, None, None))
    assert line is not None and "validation frames" in line and "ContactNet" in line
    assert choice_line({"choice": None}) is None
    settings = json.loads((out / "reproduce.json").read_text())["steps"]["inversion"]["settings"]
    assert settings["choice"] is True and settings["choice_frames"] == cp.CHOICE_FRAMES


def _row(count, slots):
    row = np.zeros(NCOL)
    row[0] = count
    for s, (face, u, v, f) in enumerate(slots):
        a = len(PRED_COLUMNS) + s * len(SLOT_COLUMNS)
        row[a + SLOT_COLUMNS.index("face")] = face
        row[a + SLOT_COLUMNS.index("u_mm")], row[a + SLOT_COLUMNS.index("v_mm")] = u, v
        row[a + SLOT_COLUMNS.index("force_n")] = f
    return row


def test_seeds_from_predictions_follow_the_models_count():
    faces = ["front", "back"]
    pred = np.stack([
        _row(0, [(0, 1.0, 2.0, 0.5), (0, 3.0, 4.0, 0.5)]),    # no finger pressing: no seed
        _row(1, [(1, 1.0, 2.0, -0.2), (0, 3.0, 4.0, 0.5)]),   # one: the first slot, force >= 0
        _row(2, [(0, 1.0, 2.0, 0.5), (1, 3.0, 4.0, 0.7)]),    # two: one finger, and both
        _row(1, [(5, 1.0, 2.0, 0.5), (0, 3.0, 4.0, 0.5)]),    # a face the data lack: none
    ])
    s = cp.seeds_from_predictions(pred, faces)
    assert s[0] == [] and s[3] == []
    (g,), = s[1]
    assert (g.face, g.u_mm, g.v_mm, g.force_n, g.height_mm) == ("back", 1.0, 2.0, 0.0, None)
    assert [len(x) for x in s[2]] == [1, 2]
    assert [(g.face, g.u_mm, g.force_n) for g in s[2][1]] == [("front", 1.0, 0.5),
                                                              ("back", 3.0, 0.7)]
    assert len(cp.seeds_from_predictions(pred, faces, pressing_only=False)[0]) == 1
    with pytest.raises(Exception, match="pred must have shape"):
        cp.seeds_from_predictions(pred[:, :5], faces)


def test_choose_takes_the_lowest_finite_error_ties_to_the_earlier():
    order = ["contactnet", "ridge", "knn", "inversion", "hybrid"]
    assert cp.choose({"contactnet": 3.0, "ridge": 8.0, "knn": 6.0, "inversion": 1.0,
                      "hybrid": 0.9}, order)[0] == "hybrid"
    assert cp.choose({"contactnet": 1.0, "inversion": 1.0, "hybrid": np.nan}, order)[0] == (
        "contactnet")
    name, why = cp.choose({"contactnet": np.nan, "inversion": np.nan}, order)
    assert name == "contactnet" and why.startswith("no validation frame")
