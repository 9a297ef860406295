"""The contact model choice of the reproduction's inversion step (ectskin.pipeline.contact_pick):
the run's model, its k-NN and ridge baselines, the inversion and the hybrid, chosen on
validation frames only.

On a tiny contact experiment read from a coarse response field (as test_inversion_step). The
run's model is a stand-in whose answers are the frames' true fingers moved by a known offset
(its error is that offset on every frame, by construction): with no offset it must be chosen,
with a large one the candidate the one-standard-error rule takes; scrambling the test labels
leaves the choice and every validation number as they were. Just below the inversion's error,
by less than one paired standard error (known from the offset: the inversion's per-frame errors'
standard deviation / √n), the inversion is taken instead; by more, the run's model. The
per-frame errors the rule reads average to ``contact_report``'s ``loc_mm_mean``.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_inversion_step import TEST, VAL, make_world  # tests/pipeline

from ectskin.io import Recording, read_recording
from ectskin.layout.geometry import on_skin_distance
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.learn.tasks.contact import contact_report, point_errors
from ectskin.pipeline import contact_pick as cp
from ectskin.pipeline import inversion as pinv
from ectskin.pipeline.bound import state_key
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


def _rule_holds(c):
    """The choice ``c`` is the simplest of the candidates whose validation error is within their
    recorded paired standard error of the lowest; returns {name: validation error}."""
    val = {k: v["val"]["loc_mm_mean"] for k, v in c["candidates"].items()}
    best = min(val, key=val.get)
    assert c["best"] == best and c["rule"] == cp.RULE
    assert c["candidates"][best]["val_se_to_best_mm"] == 0.0
    within = [k for k in c["simplicity"]
              if val[k] - val[best] <= c["candidates"][k]["val_se_to_best_mm"]]
    assert [k for k in c["order"] if c["candidates"][k]["within_one_se"]] == [
        k for k in c["order"] if k in within]
    assert c["selected"] == within[0] and c["candidates"][within[0]]["selected"]
    return val


def test_the_rule_chooses_on_validation_frames_and_no_test_label_is_read(world):
    exact = _choice(world, 0.0)
    assert exact["order"] == ["contactnet", "ridge", "knn", "inversion", "hybrid"]
    assert exact["simplicity"] == ["ridge", "knn", "inversion", "contactnet", "hybrid"]
    assert exact["candidates"]["contactnet"]["val"]["loc_mm_mean"] == pytest.approx(0, abs=1e-5)
    assert exact["selected"] == "contactnet" and exact["candidates"]["contactnet"]["selected"]
    _rule_holds(exact)
    # moved further than the inversion misses (on this coarse field, by centimetres)
    du = 1.5 * exact["candidates"]["inversion"]["val"]["loc_mm_mean"] + 5.0
    far = _choice(world, du)
    val = _rule_holds(far)
    assert val["contactnet"] > val["inversion"] and far["selected"] != "contactnet"
    if far["selected"] == far["best"]:
        assert far["why"].startswith(
            f"the lowest {cp.METRIC}: {far['best']} {val[far['best']]:.3f}")
    else:
        assert far["why"].startswith("the simplest candidate within one paired standard error")
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


def test_a_model_better_by_less_than_one_paired_se_gives_way_to_the_inversion(world):
    config, fields, path = world
    rec = read_recording(path)
    from ectskin.inversion import Inversion

    val = pinv._dataset(rec, VAL)
    rows = pinv._frames(val, False, FRAMES)
    arrays, _ = pinv.invert_rows(Inversion(fields, config.contact_protocol().readout), rec, val,
                                 rows)
    errs = point_errors(val.take(rows), pinv.prediction_columns(arrays, val.faces,
                                                                val.face_extent))
    inv = float(errs.mean())
    # the stand-in errs by exactly du on every frame, so its paired difference to the inversion
    # has the inversion's own spread: SE = sd(inversion's errors) / √n whatever du is
    se = float(errs.std(ddof=1) / np.sqrt(errs.size))
    assert se > 0.05
    near = _choice(world, inv - 0.5 * se)
    val_near = _rule_holds(near)
    assert val_near["inversion"] == pytest.approx(inv, rel=1e-12)  # the same frames, the same fit
    assert near["best"] == "contactnet"
    # (the points pass through float32 on the way: its step at ~37 mm is 3.8e-6)
    assert val_near["contactnet"] == pytest.approx(inv - 0.5 * se, abs=1e-5)
    assert near["candidates"]["inversion"]["val_se_to_best_mm"] == pytest.approx(se, rel=1e-6)
    assert near["candidates"]["inversion"]["within_one_se"] is True
    assert near["selected"] == "inversion"
    assert near["why"].startswith("the simplest candidate within one paired standard error")
    beyond = _choice(world, inv - 2.0 * se)
    _rule_holds(beyond)
    assert beyond["best"] == "contactnet" and beyond["selected"] == "contactnet"
    assert beyond["candidates"]["inversion"]["val_se_to_best_mm"] == pytest.approx(se, rel=1e-6)
    assert beyond["candidates"]["inversion"]["within_one_se"] is False


def test_per_frame_errors_average_to_the_reports_point_error(world):
    config, fields, path = world
    rec = read_recording(path)
    from ectskin.inversion import Inversion

    data = pinv._dataset(rec, TEST[:2] + VAL)
    rows = pinv._frames(data, False, 40)
    sub = data.take(rows)
    arrays, _ = pinv.invert_rows(Inversion(fields, config.contact_protocol().readout), rec, data,
                                 rows)
    rng = np.random.default_rng(3)
    guess = np.zeros((sub.n_samples, NCOL))  # faces flipped at random, some outside the data's
    a = len(PRED_COLUMNS) + SLOT_COLUMNS.index("face")
    guess[:, a] = rng.integers(-1, len(sub.faces) + 1, sub.n_samples)
    guess[:, a + 1] = rng.uniform(-40, 40, sub.n_samples)  # u_mm, v_mm follow the face
    guess[:, a + 2] = rng.uniform(-60, 60, sub.n_samples)
    single = np.flatnonzero(sub.count == 1)
    assert single.size >= 10 and len(sub.faces) == 2 and (sub.count != 1).any()
    f = guess[single, a]  # the guess crosses faces, and names faces the data lack
    assert (np.clip(f, 0, 1) != sub.face[single, 0]).any() and ((f < 0) | (f > 1)).any()
    width, thickness = sub.body_mm
    for pred in (pinv.prediction_columns(arrays, sub.faces, sub.face_extent), guess):
        errs = point_errors(sub, pred)
        assert errs.mean() == contact_report(sub, pred, with_maps=False)["loc_mm_mean"]
        numbers, frame_errors = cp.scored(sub, pred)  # what the choice reads
        np.testing.assert_array_equal(frame_errors, errs)
        assert numbers["loc_mm_mean"] == errs.mean()
        # frame by frame, in row order: the distance over the skin, the face clipped into range
        by_hand = [on_skin_distance(
            sub.faces[sub.face[i, 0]], sub.uv[i, 0],
            sub.faces[int(np.clip(pred[i, a], 0, len(sub.faces) - 1))],
            pred[i, [a + 1, a + 2]], width, thickness) for i in single]
        np.testing.assert_allclose(errs, by_hand, rtol=1e-12)
        # their mean per inflation state, and the worst state
        st = sub.state[single]
        want = {state_key(sub.states[s]): float(np.mean(np.asarray(by_hand)[st == s]))
                for s in np.unique(st)}
        assert numbers["per_state_loc_mm_mean"].keys() == want.keys()
        for key, mm in want.items():
            assert numbers["per_state_loc_mm_mean"][key] == pytest.approx(mm, rel=1e-12)
        worst = max(want, key=want.__getitem__)
        assert numbers["worst_state"][0] == worst
        assert numbers["worst_state"][1] == pytest.approx(want[worst], rel=1e-12)
    with pytest.raises(Exception, match="pred must have shape"):
        point_errors(sub, guess[:-1])


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
    assert c["rule"] == cp.RULE and c["best"] in c["order"]
    assert sorted(c["simplicity"]) == sorted(c["order"])
    for name in c["order"]:
        assert {"kind", "val", "test", "selected", "val_se_to_best_mm",
                "within_one_se"} <= set(c["candidates"][name])
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
    assert "one-standard-error rule" in line
    assert choice_line({"choice": None}) is None
    settings = json.loads((out / "reproduce.json").read_text())["steps"]["inversion"]["settings"]
    assert settings["choice"] is True and settings["choice_frames"] == cp.CHOICE_FRAMES
    assert settings["choice_rule"] == cp.RULE  # a cached choice by another rule is made again


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
