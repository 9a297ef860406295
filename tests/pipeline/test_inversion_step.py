"""The reproduction's inversion step (ectskin.pipeline.inversion) on a tiny contact experiment read
from a coarse response field: the metrics against a hand computation from the inversion's own
fits of each frame and the trials' ground truth, the frames of states without a field, the cap
on frames, the push chosen on validation frames, resuming through the runner, and metrics.json's
``inversion`` block."""

from __future__ import annotations

import json
from dataclasses import replace
from functools import partial

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.inversion import Inversion
from ectskin.io import Recording, read_recording, write_recording
from ectskin.layout.geometry import on_skin_distance
from ectskin.learn.data.contact import contact_dataset
from ectskin.learn.tasks.contact import point_errors
from ectskin.pipeline import ReproduceConfig
from ectskin.pipeline import field as pfield
from ectskin.pipeline import inversion as pinv
from ectskin.pipeline.contact import _simulate_contact
from ectskin.pipeline.metrics import inversion_block
from ectskin.pipeline.runner import StepRunner
from ectskin.twin import Protocol
from ectskin.twin.field_finger import finger_tables
from ectskin.twin.field_spec import FieldGrid
from ectskin.twin.mechanics import recording_manipulator

#: a grid of few nodes: the step's code path and its scoring, not the inversion's accuracy
SMALL_GRID = FieldGrid(spacing_mm=(10.0, 27.5), force_nodes=4, height_nodes=4)
TEST = ["trial_0001", "trial_0002", "far_0003"]
VAL = ["trial_0004", "trial_0005"]


def make_world(root):
    """One state (0/0/0 ml), its field on a 10 × 27.5 mm grid, 2-s trials; ``far_0003`` is a copy
    of trial_0003 at a state without a field: (config, fields, the recording's path)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(pfield.FIELD_GRIDS, "quick", SMALL_GRID)
        protocol = Protocol(levels_ml=(0.0,), touch_trials=1, duration_s=2.0, touch_dwells=1)
        config = ReproduceConfig(root / "out", protocol=protocol, workers=1, progress=False,
                                 field_cache=root / "cache")
        rec = _simulate_contact(config.contact_protocol(), config, None)
        fields = pfield.contact_fields(config)
    far = replace(rec.trial("trial_0003"), name="far_0003", inflation=(20.0, 0.0, 0.0))
    rec = Recording(rec.layout, list(rec.trials) + [far], rec.frame_rate_hz, meta=rec.meta)
    write_recording(rec, root / "contact.h5", overwrite=True)
    return config, fields, root / "contact.h5"


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("inversion_step"))


def _out(tmp_path, config, test=TEST, val=VAL, train=()):
    out = tmp_path / "out"
    (out / "runs" / "contact").mkdir(parents=True)
    (out / "runs" / "contact" / "split.json").write_text(
        json.dumps({"train": list(train), "val": val, "test": test}))
    return replace(config, out_dir=out)


def _by_hand(fields, path, noise, trials):
    """Each frame fitted by Inversion.fit itself, scored from the trials' ground truth: the
    point error over the skin and the force error of the frames with one finger on the skin,
    and whether the count of pressing fingers is right, frame by frame."""
    rec = read_recording(path)
    body, _ = recording_manipulator(rec.meta)
    faces = [s.surface for s in rec.layout.skins]
    inv = Inversion(fields, noise)
    loc, force, count = [], [], []
    for name in trials:
        t = rec.trial(name)
        for i in range(t.n_frames):
            r = inv.fit(t.capacitance[i], t.inflation)
            pressing = [f for f in r.fingers if f.contact]
            count.append(len(pressing) == t.n_contacts[i])
            if t.n_contacts[i] != 1:
                continue
            k = next(k for k in range(t.n_fingers) if t.finger(k).contact[i])
            truth = t.finger(k)
            guess = (pressing or [f for f in r.fingers if not f.contact] or [None])[0]
            if guess is None:  # no finger: the middle of the first face
                ext = next(s for s in rec.layout.skins if s.surface == faces[0])
                face, uv = faces[0], (np.mean(ext.u_mm), np.mean(ext.v_mm))
            else:
                face, uv = guess.face, (guess.u_mm, guess.v_mm)
            loc.append(float(on_skin_distance(truth.surface, truth.uv_mm[i], face, uv,
                                              body.width_mm, body.thickness_mm)))
            force.append(abs((guess.force_n if guess is not None and guess.contact else 0.0)
                             - truth.force[i]))
    return np.array(loc), np.array(force), np.array(count)


def test_the_step_scores_the_test_frames_as_a_hand_computation(world, tmp_path):
    config, fields, path = world
    config = _out(tmp_path, config)
    runner = StepRunner(config.out_dir, force=False)
    m = pinv.inversion_step(runner, config, fields, (path, {"x": 1}), push="off", max_frames=None)
    noise = config.contact_protocol().readout
    loc, force, count = _by_hand(fields, path, noise, TEST[:2])
    assert loc.size > 5 and m["n_single_contact_frames"] == loc.size
    assert m["loc_mm_mean"] == pytest.approx(loc.mean(), rel=1e-6)  # float32 labels
    assert m["loc_mm_median"] == pytest.approx(np.median(loc), rel=1e-6)
    assert m["force_mae_n"] == pytest.approx(force.mean(), rel=1e-6)
    assert m["count_accuracy"] == pytest.approx(count.mean(), rel=1e-12)
    # the same frames split by another finger above the skin: the parts make up the whole
    split = [m["by_other_finger"][p] for p in ("alone", "other_hovering", "other_above")]
    assert sum(p["n_frames"] for p in split) == loc.size
    assert sum(p["loc_mm_mean"] * p["n_frames"] for p in split if p["n_frames"]) == (
        pytest.approx(loc.sum(), rel=1e-6))
    # one state with a field: its numbers are the overall ones; the other state is counted only
    assert list(m["per_state"]) == ["0/0/0 ml"]
    s = m["per_state"]["0/0/0 ml"]
    assert s["loc_mm_mean"] == m["loc_mm_mean"] and s["n_frames"] == m["n_frames"] == 120
    assert m["frames_without_field"] == {"20/0/0 ml": 60} and m["n_frames_without_field"] == 60
    assert m["share_without_field"] == pytest.approx(60 / 180)
    t = m["timing"]
    assert 0 < t["ms_per_frame_median"] <= t["ms_per_frame_p95"]
    assert m["push"]["use"] is False and m["n_test_trials"] == 3
    saved = json.loads((config.out_dir / "inversion" / "metrics.json").read_text())
    assert saved["loc_mm_mean"] == m["loc_mm_mean"]
    # every inverted frame's fit is kept, named by its trial and frame; scored again from the
    # file, the point error is the step's
    fits = np.load(config.out_dir / "inversion" / "fits.npz")
    assert fits["trial"].size == 120 and set(fits["trial"]) == set(TEST[:2]) and fits["spread"].all()
    rec = read_recording(path)
    data = contact_dataset(rec, window=1, trials=TEST[:2])
    assert fits["frame"].tolist() == data.frame.tolist()
    arrays = {k[4:]: fits[k] for k in fits.files if k.startswith("fit_")}
    errs = point_errors(data, pinv.prediction_columns(arrays, data.faces, data.face_extent))
    assert errs.mean() == pytest.approx(m["loc_mm_mean"], rel=1e-12)
    # the force figure is drawn; the error map beside the bound only where the bound step ran
    assert (config.out_dir / "inversion" / "force_sigma.png").is_file()
    assert not (config.out_dir / "inversion" / "error_vs_bound.png").exists()
    # the step is reused with the same settings, refused with others
    monkey = pytest.MonkeyPatch()
    monkey.setattr(Inversion, "fit", lambda *a, **k: pytest.fail("inverted again"))
    again = StepRunner(config.out_dir, force=False)
    assert pinv.inversion_step(again, config, fields, (path, {"x": 1}), push="off",
                               max_frames=None)["loc_mm_mean"] == m["loc_mm_mean"]
    assert again.reused == ["inversion"]
    monkey.undo()
    with pytest.raises(EctskinError, match="step 'inversion' would overwrite.*max_frames"):
        pinv.inversion_step(again, config, fields, (path, {"x": 1}), push="off", max_frames=50)


def test_the_frame_cap_spreads_over_the_test_frames(world, tmp_path):
    config, fields, path = world
    config = _out(tmp_path, config, test=TEST[:2])
    m = pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="off", max_frames=30)
    assert m["n_frames"] == 30 and m["n_frames_in_field_states"] == 120
    assert m["n_frames_without_field"] == 0 and m["share_without_field"] == 0
    # with a trial of a state without a field: its share is of all test frames, not of those
    # inverted
    config = _out(tmp_path / "b", world[0])
    m = pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="off", max_frames=30)
    assert m["n_frames"] == 30 and m["share_without_field"] == pytest.approx(60 / 180)


def test_the_training_trials_are_inverted_and_scored_apart(world, tmp_path, monkeypatch):
    """The inversion is not trained, so the contact run's training trials are frames it has not
    seen: with ``train_trials`` those in a field state (not far_0003) are inverted: the count by
    true count as a hand computation from Inversion.fit frame by frame, and every number as the
    step scores the same trials when they are its test trials (checked against a hand
    computation above); the test split's numbers stay the test trial's; the cap spreads the
    frames; metrics.json's block carries it. Without ``train_trials``: no block, and the
    step's key is the one cached before it existed."""
    config, fields, path = world
    train = ["trial_0006", "trial_0007", "trial_0008", "far_0003"]
    cfg = _out(tmp_path, config, test=TEST[1:2], train=train)
    m = pinv.inversion_step(StepRunner(cfg.out_dir, False), cfg, fields, (path, {}),
                            push="off", max_frames=None, train_trials=True)
    noise = cfg.contact_protocol().readout
    _, _, count = _by_hand(fields, path, noise, train[:3])
    rec = read_recording(path)
    true = np.concatenate([rec.trial(n).n_contacts for n in train[:3]])
    t = m["train_trials"]
    assert t["n_trials"] == 3 and t["n_frames"] == true.size == 180 and t["seconds"] > 0
    ref_cfg = _out(tmp_path / "ref", config, test=train[:3])
    ref = pinv.inversion_step(StepRunner(ref_cfg.out_dir, False), ref_cfg, fields, (path, {}),
                              push="off", max_frames=None)
    assert ref["n_single_contact_frames"] > 5
    assert t["loc_mm_mean"] == ref["loc_mm_mean"] and t["loc_mm_median"] == ref["loc_mm_median"]
    assert t["count_accuracy_by_true"] == ref["multi"]["count_accuracy_by_true"]
    assert t["two_finger"] == ref["two_finger"]
    alone = ref["by_other_finger"]["alone"]
    assert t["alone"] == {k: alone[k] for k in ("loc_mm_mean", "n_frames", "share")}
    by_true = {str(k): float(count[true == k].mean()) for k in range(3)}
    assert t["count_accuracy_by_true"] == {k: pytest.approx(v, rel=1e-12)
                                           for k, v in by_true.items()}
    two = t["two_finger"]
    assert two["n_frames"] == (true == 2).sum() == 30 and two["n_trials"] == 2
    assert two["count_accuracy"] == pytest.approx(by_true["2"], rel=1e-12)
    test_loc, _, _ = _by_hand(fields, path, noise, TEST[1:2])
    assert m["loc_mm_mean"] == pytest.approx(test_loc.mean(), rel=1e-6) != t["loc_mm_mean"]
    block = inversion_block(m, None, None)["train_trials"]
    assert "count_accuracy_by_trial" in two and "count_accuracy_by_trial" not in block["two_finger"]
    assert block["loc_mm_mean"] == t["loc_mm_mean"] and block["bound_alone_loc_mm_mean"] is None
    # the bound at the training frames alone (metrics.json's bound.train_alone) beside it
    bound = {"train_alone": {"loc_mm_mean": 0.25}, "test_alone": {"loc_mm_mean": 0.5}}
    assert inversion_block(m, None, bound)["train_trials"]["bound_alone_loc_mm_mean"] == 0.25
    # the caps: evenly spread over the training trials' frames, the two-finger ones besides
    monkeypatch.setattr(pinv, "TRAIN_FRAMES", 50)
    cfg = _out(tmp_path / "b", config, test=TEST[1:2], train=train)
    m = pinv.inversion_step(StepRunner(cfg.out_dir, False), cfg, fields, (path, {}),
                            push="off", max_frames=None, train_trials=True)
    assert m["train_trials"]["n_frames"] == 50 and m["train_trials"]["two_finger"]["n_frames"] == 30
    monkeypatch.setattr(pinv, "TRAIN_TWO_FINGER_FRAMES", 10)
    cfg = _out(tmp_path / "d", config, test=TEST[1:2], train=train)
    m = pinv.inversion_step(StepRunner(cfg.out_dir, False), cfg, fields, (path, {}),
                            push="off", max_frames=None, train_trials=True)
    data = contact_dataset(rec, window=1, trials=train[:3])
    in_spread = int((data.count[pinv._frames(data, False, 50)] == 2).sum())
    assert m["train_trials"]["two_finger"]["n_frames"] == in_spread + 10
    # off: no block, and the settings without it
    cfg = _out(tmp_path / "c", config, test=TEST[1:2], train=train)
    m = pinv.inversion_step(StepRunner(cfg.out_dir, False), cfg, fields, (path, {}),
                            push="off", max_frames=None)
    assert "train_trials" not in m and inversion_block(m, None, None)["train_trials"] is None
    assert "train_trials" not in (cfg.out_dir / "reproduce.json").read_text()


def test_the_push_is_chosen_on_the_validation_frames(world, tmp_path, monkeypatch):
    """The choice inverts the validation trials' one-finger frames only (never a test frame)
    and keeps the lower error; the test frames are then inverted with that choice."""
    config, fields, path = world
    config = _out(tmp_path, config)
    seen = []
    real = pinv.invert_rows

    def spy(inv, rec, data, rows, seeds=None, workers=1, person=False):
        assert not person
        seen.append((set(np.asarray(data.group_names)[np.unique(data.group[rows])]),
                     inv.model((0.0, 0.0, 0.0)).N.shape[1]))
        return real(inv, rec, data, rows, seeds, workers)

    monkeypatch.setattr(pinv, "invert_rows", spy)
    m = pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="auto", max_frames=None)
    rec = read_recording(path)
    n_val = sum(int(np.sum(rec.trial(n).n_contacts == 1)) for n in VAL)
    p = m["push"]
    assert p["n_frames"] == min(n_val, pinv.PUSH_CHOICE_FRAMES)
    off, on = p["val_loc_mm_mean"]["off"], p["val_loc_mm_mean"]["on"]
    assert p["use"] is bool(on < off)
    # two validation passes (2 drift columns, then + 3 push columns), then the test with the choice
    val_trials = {n for n in VAL if np.any(rec.trial(n).n_contacts == 1)}
    assert val_trials and [s for s, _ in seen] == [val_trials, val_trials, set(TEST[:2])]
    assert [n for _, n in seen] == [2, 5, 5 if p["use"] else 2]


def test_two_finger_frames_beyond_the_cap_are_inverted_and_scored_apart(world, tmp_path,
                                                                         monkeypatch):
    """Every test frame with two fingers on the skin is scored in ``two_finger``, those of the
    evenly spread frames and the others besides them, each counted as Inversion.fit counts it;
    the spread's metrics stay the spread's. (The tiny experiment has one finger: every third
    one-finger frame is labelled with a second finger 30 mm further along v.)"""
    config, fields, path = world
    config = _out(tmp_path, config, test=TEST[:2])
    real = pinv._dataset

    def marked(rec, trials):
        d = real(rec, trials)
        count, face, uv = d.count.copy(), d.face.copy(), d.uv.copy()
        on = np.flatnonzero(count == 1)[::3]
        count[on], face[on, 1], uv[on, 1] = 2, face[on, 0], uv[on, 0] + (0.0, 30.0)
        return replace(d, count=count, face=face, uv=uv)

    monkeypatch.setattr(pinv, "_dataset", marked)
    rec = read_recording(path)
    data = marked(rec, TEST[:2])
    two = np.flatnonzero(data.count == 2)
    spread = pinv._frames(data, False, 30)
    inv = Inversion(fields, config.contact_protocol().readout)
    by_hand = [sum(f.contact for f in inv.fit(rec.trial(data.group_names[data.group[i]])
                                              .capacitance[data.frame[i]], (0.0, 0.0, 0.0)).fingers)
               for i in two]
    m = pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="off", max_frames=30)
    b = m["two_finger"]
    assert two.size > np.isin(two, spread).sum() > 0
    assert b["n_frames"] == two.size and b["n_trials"] == np.unique(data.group[two]).size
    assert b["count_predicted"] == np.bincount(np.clip(by_hand, 0, 2), minlength=3).tolist()
    assert b["count_accuracy"] == pytest.approx(np.mean(np.asarray(by_hand) == 2))
    assert m["n_frames"] == 30 and m["multi"]["n_two_finger_frames"] == np.isin(two, spread).sum()
    # none besides the spread's: the spread's two-finger frames alone
    config = _out(tmp_path / "b", world[0], test=TEST[:2])
    m = pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="off", max_frames=30, two_finger_frames=0)
    assert m["two_finger"]["n_frames"] == np.isin(two, spread).sum()


def test_the_standard_errors_carry_the_model_error_of_the_validation_residuals(world, tmp_path):
    """By hand: the validation trials' frames (spread, every count) fitted by the step's
    inversion, the model error estimated from their residuals alone; the step reports it, and
    its test frames' force standard errors are those of the inversion with it. The fits, and so
    every error, are those without it; "off" leaves the standard errors the noise's."""
    from ectskin.inversion import estimate_model_error, fit_frames

    config, fields, path = world
    noise = config.contact_protocol().readout
    rec = read_recording(path)
    inv = Inversion(fields, noise)
    val = pinv._dataset(rec, VAL)
    rows = pinv._frames(val, False, pinv.MODEL_ERROR_FRAMES)
    y, states = pinv.rows_frames(rec, val, rows)
    est = estimate_model_error(inv, y, states, fit_frames(inv, y, states)[0])
    m = {}
    for mode in ("validation", "off"):
        c = _out(tmp_path / mode, config, test=TEST[:2])
        m[mode] = pinv.inversion_step(StepRunner(c.out_dir, False), c, fields, (path, {}),
                                      push="off", max_frames=None, bound_error=mode)
    me = m["validation"]["model_error"]
    assert me["source"] == "validation" and me["n_frames"] == rows.size == val.n_samples
    assert (me["a_pf"], me["r"]) == pytest.approx(est.floor, rel=1e-9)
    assert m["off"]["model_error"]["source"] is None
    assert m["validation"]["loc_mm_mean"] == m["off"]["loc_mm_mean"]
    assert m["validation"]["force_mae_n"] == m["off"]["force_mae_n"]
    test = pinv._dataset(rec, TEST[:2])
    ty, tst = pinv.rows_frames(rec, test, np.arange(test.n_samples))
    sigma = []
    for widened in (inv.with_bound_error(est.floor), inv):
        res, _ = fit_frames(widened, ty, tst)
        se = [f.force_se_n for r, n in zip(res, test.count) if n == 1
              for f in r.fingers[:1] if f.contact]
        sigma.append(float(np.median(se)))
    assert m["validation"]["force"]["force_sigma_n_median"] == pytest.approx(sigma[0], rel=1e-9)
    assert m["off"]["force"]["force_sigma_n_median"] == pytest.approx(sigma[1], rel=1e-9)
    assert sigma[0] > sigma[1]
    block = inversion_block(m["validation"], None, None)
    assert block["model_error"] == me and set(block["force_coverage"]) == {"1sigma", "2sigma"}


def test_bad_input_is_refused(world, tmp_path):
    config, fields, path = world
    runner = StepRunner(tmp_path, False)
    with pytest.raises(EctskinError, match="split.json is missing"):
        pinv.inversion_step(runner, replace(config, out_dir=tmp_path), fields, (path, {}))
    config = _out(tmp_path, config)
    runner = StepRunner(config.out_dir, False)
    with pytest.raises(EctskinError, match="push"):
        pinv.inversion_step(runner, config, fields, (path, {}), push="maybe")
    with pytest.raises(EctskinError, match="bound_error"):
        pinv.inversion_step(runner, config, fields, (path, {}), bound_error="labels")
    with pytest.raises(EctskinError, match="max_frames must be an integer >= 1"):
        pinv.inversion_step(runner, config, fields, (path, {}), max_frames=0)
    with pytest.raises(EctskinError, match="no response fields"):
        pinv.inversion_step(runner, config, {}, (path, {}))
    bad = _out(tmp_path / "b", world[0], test=["trial_0001", "nope"])
    with pytest.raises(EctskinError, match="trial 'nope' is not in"):
        pinv.inversion_step(StepRunner(bad.out_dir, False), bad, fields, (path, {}))


def test_the_metrics_block_sets_contactnet_and_the_bound_beside_each_state():
    """ContactNet's and a baseline's error on the inverted states are their per-state means
    weighted by their one-finger frames; a state the inversion did not score is left out."""
    inv = {
        "loc_mm_mean": 1.0, "force_mae_n": 0.2, "count_accuracy": 0.9, "n_frames": 50,
        "multi": {"count_accuracy_by_true": {"0": 1.0, "1": 0.8, "2": None}},
        "by_other_finger": {"alone": {"loc_mm_mean": 0.7, "n_frames": 3}},
        "force_observable": {"share": 0.25, "force_mae_n": 0.05, "threshold_n": 0.1},
        "timing": {"ms_per_frame_median": 4.0, "ms_per_frame_p95": 9.0, "total_s": 1.0},
        "per_state": {"0/0/0 ml": {"loc_mm_mean": 0.5, "n_single_contact_frames": 3},
                      "20/0/0 ml": {"loc_mm_mean": 1.5, "n_single_contact_frames": 1},
                      "0/20/0 ml": {"loc_mm_mean": None, "n_single_contact_frames": 0}},
    }
    contact = {"per_state": {"0/0/0 ml": {"loc_mm_mean": 2.0, "n_frames": 30},
                             "20/0/0 ml": {"loc_mm_mean": 6.0, "n_frames": 10},
                             "20/20/20 ml": {"loc_mm_mean": 100.0, "n_frames": 10}},
               "baselines": {"knn": {"per_state": {"0/0/0 ml": {"loc_mm_mean": 4.0, "n_frames": 30},
                                                   "20/0/0 ml": {"loc_mm_mean": 8.0,
                                                                 "n_frames": 10}}},
                             "ridge": {"per_state": {"0/0/0 ml": {"loc_mm_mean": 1.0,
                                                                  "n_frames": 30}}}}}
    bound = {"test": {"loc_mm_mean": 0.1, "force_n_mean": 0.3},
             "per_state": {"0/0/0 ml": {"test": {"loc_mm_mean": 0.05, "force_n_mean": 0.2}}}}
    b = inversion_block(inv, contact, bound)
    for key in ("loc_mm_mean", "force_mae_n", "count_accuracy", "per_state",
                "ms_per_frame_median", "ms_per_frame_p95", "n_frames"):
        assert key in b, key
    assert (b["ms_per_frame_median"], b["ms_per_frame_p95"], b["n_frames"]) == (4.0, 9.0, 50)
    assert b["contact_loc_mm_mean"] == pytest.approx((2.0 * 30 + 6.0 * 10) / 40)
    assert b["baseline_loc_mm_mean"] == {"knn": pytest.approx(5.0), "ridge": None}
    assert b["count_accuracy_by_true"]["1"] == 0.8 and b["force_mae_n_observable"] == 0.05
    assert b["by_other_finger"]["alone"]["loc_mm_mean"] == 0.7
    assert (b["bound_loc_mm_mean"], b["bound_force_n_mean"]) == (0.1, 0.3)
    s = b["per_state"]["0/0/0 ml"]
    assert (s["contact_loc_mm_mean"], s["bound_loc_mm_mean"], s["bound_force_n_mean"]) == (
        2.0, 0.05, 0.2)
    assert s["baseline_loc_mm_mean"] == {"knn": 4.0, "ridge": 1.0}
    assert b["per_state"]["20/0/0 ml"]["bound_loc_mm_mean"] is None
    assert inversion_block(inv, None, None)["contact_loc_mm_mean"] is None
    assert b["two_finger"] is None  # a step without two-finger frames
    two = {"count_accuracy": 0.75, "n_trials": 2, "count_accuracy_by_trial": {"a": 1.0, "b": 0.5}}
    assert inversion_block({**inv, "two_finger": two}, None, None)["two_finger"] == {
        "count_accuracy": 0.75, "n_trials": 2}


def test_the_persons_finger_is_chosen_on_the_validation_frames(world, tmp_path, monkeypatch):
    """``finger="auto"``: the finger tables are built from coarse fields of the state (10 ×
    27.5 mm here, for speed), the validation trials' one-finger frames are inverted without and
    then with the tables and per-trial pooling (never a test frame), the lower point error wins,
    and the test frames are inverted with that choice; "on" pools without asking; the settings
    name the option, so a step made without it is not reused."""
    config, fields, path = world
    config = _out(tmp_path, config)
    monkeypatch.setattr(pinv, "finger_tables", partial(finger_tables, spacing_mm=(10.0, 27.5)))
    seen = []
    real = pinv.invert_rows

    def spy(inv, rec, data, rows, seeds=None, workers=1, person=False):
        seen.append((set(np.asarray(data.group_names)[np.unique(data.group[rows])]), person,
                     sorted(inv.finger_prior_sd)))
        return real(inv, rec, data, rows, seeds, workers, person)

    monkeypatch.setattr(pinv, "invert_rows", spy)
    m = pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="off", max_frames=None, finger="auto", two_finger_frames=0)
    rec = read_recording(path)
    f = m["finger"]
    n_val = sum(int(np.sum(rec.trial(n).n_contacts == 1)) for n in VAL)
    assert f["n_frames"] == min(n_val, pinv.PUSH_CHOICE_FRAMES) and f["tables_s"] > 0
    off, on = f["val_loc_mm_mean"]["off"], f["val_loc_mm_mean"]["on"]
    assert f["use"] is bool(on < off) and set(f["val_force_mae_n"]) == {"on", "off"}
    val_trials = {n for n in VAL if np.any(rec.trial(n).n_contacts == 1)}
    both = ["modulus", "radius"]
    assert seen == [(val_trials, False, []), (val_trials, True, both),
                    (set(TEST[:2]), f["use"], both if f["use"] else [])]
    assert m["settings"]["finger"] == "auto"
    assert inversion_block(m, None, None)["finger"] == f
    seen.clear()
    on_dir = _out(tmp_path / "on", config)
    m_on = pinv.inversion_step(StepRunner(on_dir.out_dir, False), on_dir, fields, (path, {}),
                               push="off", max_frames=None, finger="on", two_finger_frames=0)
    assert m_on["finger"]["use"] and seen == [(set(TEST[:2]), True, both)]
    with pytest.raises(EctskinError, match="would overwrite.*finger"):
        pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            push="off", max_frames=None, two_finger_frames=0)
    with pytest.raises(EctskinError, match="finger"):
        pinv.inversion_step(StepRunner(config.out_dir, False), config, fields, (path, {}),
                            finger="maybe")


def test_the_two_finger_model_reaches_every_fit_and_the_settings(world, tmp_path, monkeypatch):
    config, fields, path = world
    config = _out(tmp_path, config)
    seen = []
    real = pinv.Inversion

    def spy(*a, **k):
        seen.append(k.get("two_fingers"))
        return real(*a, **k)

    monkeypatch.setattr(pinv, "Inversion", spy)
    runner = StepRunner(config.out_dir, force=False)
    m = pinv.inversion_step(runner, config, fields, (path, {"x": 1}), push="auto",
                            max_frames=20, two_fingers="coupled")
    # the push choice's two inversions, the chosen one reused for the test frames
    assert len(seen) == 2 and set(seen) == {"coupled"}
    field = next(iter(fields.values()))
    assert m["settings"]["two_fingers"] == "coupled"
    assert m["settings"]["min_separation_mm"] == 2 * field.spec.finger.radius_mm
    # a step made with one model is not reused for the other
    with pytest.raises(EctskinError, match="would overwrite.*two_fingers"):
        pinv.inversion_step(StepRunner(config.out_dir, force=False), config, fields,
                            (path, {"x": 1}), push="auto", max_frames=20)
    with pytest.raises(EctskinError, match="two_fingers"):
        pinv.inversion_step(runner, config, fields, (path, {"x": 1}), two_fingers="joined")


def test_the_reproduction_fits_two_fingers_as_coupled_conductors(tmp_path, monkeypatch):
    import importlib

    rep = importlib.import_module("ectskin.pipeline.reproduce")
    got = {}
    monkeypatch.setattr(rep, "contact_fields", lambda config, specs: {(0.0, 0.0, 0.0): object()})
    monkeypatch.setattr(rep, "physics_field_specs", lambda config: [])
    monkeypatch.setattr(rep, "bound_step", lambda *a, **k: {})
    monkeypatch.setattr(rep, "inversion_step", lambda *a, **k: got.update(k) or {})

    class Runner:
        timings: dict = {}

    rep._physics_steps(Runner(), ReproduceConfig(tmp_path), (tmp_path, {}), {})
    assert got["two_fingers"] == "coupled" and got["press_check"] and got["choice"]
    assert got["finger"] == "auto"  # ReproduceConfig.inversion_finger's default
