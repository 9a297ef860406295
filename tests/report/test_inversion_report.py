"""The report sets the training-free inversion beside ContactNet, the strongest baseline and the
bound when metrics.json carries an ``inversion`` block, and says nothing of it when not."""

from __future__ import annotations

from pathlib import Path

from ectskin.report import render_markdown
from ectskin.report.contact import contact_sections
from ectskin.report.inversion import inversion_sections, train_line


def _metrics():
    return {
        "contact": {
            "loc_mm_mean": 4.0, "force_mae_n": 0.36, "hover_detect_mm": 3.0,
            "baselines": {"knn": {"loc_mm_mean": 5.0, "force_mae_n": 0.30, "hover_detect_mm": 2.0},
                          "ridge": {"loc_mm_mean": 6.0, "force_mae_n": 0.34}},
        },
        "multi": {"count_accuracy": 0.7,
                  "baselines": {"knn": {"count_accuracy": 0.6}, "ridge": {"count_accuracy": 0.65}}},
        "bound": {"force_observable_share_near_wires": 0.6,
                  "force_observable_share_away_from_wires": 0.05},
        "inversion": {
            "loc_mm_mean": 1.25, "force_mae_n": 0.125, "count_accuracy": 0.875,
            "hover_detect_mm": 6.0, "n_frames": 40, "n_frames_in_field_states": 400,
            "contact_loc_mm_mean": 3.5, "baseline_loc_mm_mean": {"knn": 4.5, "ridge": 4.25},
            "bound_loc_mm_mean": 0.25, "bound_force_n_mean": 0.0625,
            "force_observable_share": 0.25, "force_mae_n_observable": 0.03125,
            "force_observable_threshold_n": 0.1,
            "ms_per_frame_median": 9.5, "ms_per_frame_p95": 21.0,
            "push": {"use": False, "val_loc_mm_mean": {"on": 2.5, "off": 2.0}, "n_frames": 30},
            "frames_without_field": {"10/10/10 ml": 90}, "share_without_field": 0.1875,
            "per_state": {"0/20/0 ml": {
                "loc_mm_mean": 1.5, "contact_loc_mm_mean": 3.0,
                "baseline_loc_mm_mean": {"knn": 5.5, "ridge": None},
                "bound_loc_mm_mean": 0.125, "force_mae_n": 0.25, "bound_force_n_mean": 0.5,
                "count_accuracy": 0.75, "n_single_contact_frames": 12}},
        },
    }


def _tables(items):
    return {p[0]: p[1] for k, p in items if k == "table"}


def test_the_inversion_stands_beside_contactnet_the_baselines_and_the_bound():
    items = inversion_sections(_metrics())
    tables = _tables(items)
    head = next(h for h in tables if h[0] == "metric")
    rows = {r[0]: dict(zip(head, r)) for r in tables[head]}
    loc = rows["Contact point: mean error"]
    assert (loc["inversion (no training)"], loc["ContactNet"], loc["strongest baseline"],
            loc["bound (CRB)"]) == ("1.25 mm", "3.50 mm", "ridge regression 4.25 mm", "0.25 mm")
    force = rows["Force: mean absolute error"]
    assert (force["inversion (no training)"], force["ContactNet"], force["strongest baseline"],
            force["bound (CRB)"]) == ("0.125 N", "0.360 N", "k-NN 0.300 N", "0.062 N")
    count = rows["Finger count (0, 1, 2) right"]
    assert (count["inversion (no training)"], count["ContactNet"], count["strongest baseline"]) == (
        "87.50 %", "70.00 %", "ridge regression 65.00 %")
    assert rows["Hover detected up to (≥ 90 % of frames)"]["strongest baseline"] == "k-NN 2.00 mm"
    state_head = next(h for h in tables if h[0] == "state")
    s = dict(zip(state_head, tables[state_head][0]))
    assert (s["state"], s["inversion"], s["ContactNet"], s["strongest baseline"],
            s["bound (CRB)"], s["inversion force MAE"], s["force bound"], s["count right"],
            s["one-finger frames"]) == ("0/20/0 ml", "1.50 mm", "3.00 mm", "k-NN 5.50 mm",
                                        "0.12 mm", "0.250 N", "0.500 N", "75.00 %", "12")
    text = " ".join(p for k, p in items if k == "p")
    assert "40 of its 400 test frames" in text
    assert "is not a nuisance of the fit, chosen on 30 validation frames (2.50 mm with it, " \
           "2.00 mm without)" in text
    assert "below 0.1 N) at 25.00 % of the one-finger test frames; there the inversion's " \
           "force MAE is 0.031 N" in text
    assert "60.00 % of the cells near a wire and on 5.00 % of those away" in text
    # without a model error the standard error is the bound's alone, and no coverage is told
    assert "(the fitted force's standard error, the bound at the solution, below" in text
    assert "within one standard error" not in text
    assert "median 9.5 ms, 95th percentile 21.0 ms" in text
    # the step's fits are cold (and twice where the person's finger is pooled), not a stream's
    assert "(this run, on its machine; each frame cold, from the coarse search)" in text
    assert "A live stream fits each frame from the previous frame's answer instead" in text
    assert "10/10/10 ml (90 frames), 18.75 % of the test frames" in text
    # the contact sections carry it, and so do the rendered report's
    assert ("h2", "The physical inversion (no training)") in contact_sections(_metrics())
    assert "The physical inversion (no training)" in render_markdown(_metrics(), [], Path("."))


def test_the_force_line_says_the_model_error_and_the_coverage():
    m = _metrics()
    m["inversion"].update(model_error={"source": "validation", "a_pf": 1.2e-4, "r": 0.0094},
                          force_coverage={"1sigma": 0.625, "2sigma": 0.84375})
    text = " ".join(p for k, p in inversion_sections(m) if k == "p")
    assert ("the bound at the solution with the field's model error, 0.12 fF and 0.94 % of the "
            "signal, estimated from the validation fits' residuals, below 0.1 N) at 25.00 %") in text
    assert ("62.50 % of the force errors lie within one standard error and 84.38 % within two "
            "(a Gaussian's: 68 % and 95 %)") in text


def test_without_an_inversion_the_report_says_nothing_of_it():
    m = _metrics()
    del m["inversion"]
    assert inversion_sections(m) == []
    md = render_markdown(m, [], Path("."))
    assert "inversion" not in md.lower()
    m["inversion"] = {"n_frames": 0}  # a step that inverted nothing
    assert inversion_sections(m) == []
    # nothing claimed where a number is missing: dashes, no sentence on force or time
    bare = {"inversion": {"n_frames": 10, "loc_mm_mean": 2.0}}
    items = inversion_sections(bare)
    text = " ".join(p for k, p in items if k == "p")
    assert "observable" not in text and "ms" not in text and "validation" not in text
    rows = {r[0]: r for r in next(iter(_tables(items).values()))}
    assert rows["Contact point: mean error"][1:] == ("2.00 mm", "—", "—", "—")


def test_the_report_says_what_the_fit_assumed_beyond_the_field():
    m = _metrics()
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "untouched readout" not in text and "refitted pressing" not in text
    m["inversion"]["settings"] = {
        "untouched": {"source": "auto", "trials": {"0/0/0 ml": ["a"], "0/20/0 ml": ["b"]}},
        "finger_scale_sd": 0.12, "press_check": True,
    }
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "the skin's own untouched readout" in text and "2 state(s) have one" in text
    assert "(prior sd 0.12)" in text and "refitted pressing" in text
    m["inversion"]["settings"] = {"untouched": {"source": "field"}, "finger_scale_sd": None,
                                  "press_check": False}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "untouched readout" not in text and "prior sd" not in text and "pressing" not in text


def test_the_report_says_whether_each_trial_pooled_the_persons_finger():
    m = _metrics()
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "fitted, alone," in text and "pulp" not in text
    m["inversion"]["finger"] = {"use": True, "n_frames": 240,
                                "val_loc_mm_mean": {"on": 0.46, "off": 0.83},
                                "val_force_mae_n": {"on": 0.264, "off": 0.288}}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "alone" not in text and "pulp modulus and radius are fitted and pooled" in text
    assert "chosen on 240 validation frames (0.46 mm and 0.264 N" in text
    m["inversion"]["finger"]["use"] = False
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "fitted, alone," in text and "are not fitted and pooled" in text


def test_the_report_gives_the_two_finger_frames_scored_apart():
    m = _metrics()
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "Two fingers on the skin" not in text
    m["inversion"]["two_finger"] = {"n_frames": 400, "n_trials": 3, "count_accuracy": 0.85,
                                    "loc_mm_mean": 4.5, "loc_mm_median": 3.0}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "Two fingers on the skin: 400 test frames of 3 trial(s)" in text
    assert "counted two on 85.00 %" in text and "4.50 mm" in text and "(median 3.00 mm)" in text
    assert "lowest in state" not in text
    m["inversion"]["two_finger"]["by_state"] = {
        "0/0/0 ml": {"count_accuracy": 1.0, "n_frames": 100, "n_trials": 1},
        "0/0/20 ml": {"count_accuracy": 0.625, "n_frames": 200, "n_trials": 2},
        "20/0/0 ml": {"count_accuracy": 0.75, "n_frames": 100, "n_trials": 1}}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "(median 3.00 mm); lowest in state 0/0/20 ml: 62.50 % of 200 frames (2 trial(s))." in text


def test_the_report_gives_the_training_trials_the_inversion_has_not_seen():
    m = _metrics()
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "training trials" not in text
    m["inversion"]["train_trials"] = {
        "n_trials": 40, "n_frames": 1000, "loc_mm_mean": 1.5, "loc_mm_median": 0.75,
        "count_accuracy_by_true": {"0": 0.96875, "1": 0.90625, "2": 0.8125}, "two_finger": None}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert ("The training trials, which the inversion has not seen" in text
            and "1000 frames spread over 40 trial(s), point error 1.50 mm (median 0.75 mm); "
                "counted right" in text)
    assert "0 / 1 / 2 fingers on the skin 96.88 % / 90.62 % / 81.25 %" in text
    assert "the learned models and baselines were fitted on them" in text
    line = train_line(m["inversion"]["train_trials"])
    assert "no other finger above" not in line and "the bound" not in line
    m["inversion"]["train_trials"]["alone"] = {"loc_mm_mean": 0.875, "n_frames": 300, "share": 0.6}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "(median 0.75 mm); with no other finger above the skin 0.88 mm over 300 frames; " in text
    m["inversion"]["train_trials"]["bound_alone_loc_mm_mean"] = 0.625
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert ("with no other finger above the skin 0.88 mm over 300 frames, the bound 0.62 mm at "
            "those trials' frames; counted right") in text
    assert "frames with two fingers from" not in text
    m["inversion"]["train_trials"]["two_finger"] = {
        "n_frames": 1250, "n_trials": 19, "count_accuracy": 0.8125, "loc_mm_mean": 3.25}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert "1250 frames with two fingers from 19 trial(s), counted two on 81.25 %" in text
    assert "each finger 3.25 mm from its true point." in text
    m["inversion"]["train_trials"]["two_finger"]["by_state"] = {
        "0/0/20 ml": {"count_accuracy": 0.5, "n_frames": 400, "n_trials": 6},
        "20/0/0 ml": {"count_accuracy": 0.875, "n_frames": 850, "n_trials": 13}}
    text = " ".join(str(p) for k, p in inversion_sections(m) if k == "p")
    assert ("each finger 3.25 mm from its true point; lowest in state 0/0/20 ml: 50.00 % of 400 "
            "frames (6 trial(s)).") in text


def test_the_point_error_without_another_finger_above_the_skin_has_its_own_row():
    m = _metrics()
    table = lambda metrics: next(  # noqa: E731
        t for h, t in _tables(inversion_sections(metrics)).items() if h[0] == "metric")
    assert not any(r[0].startswith("Contact point: mean error, no other") for r in table(m))
    m["inversion"]["alone"] = {"loc_mm_mean": 0.75, "n_frames": 30, "contact_loc_mm_mean": 2.5,
                               "baseline_loc_mm_mean": {"knn": 4.0, "ridge": None},
                               "bound_loc_mm_mean": 0.5}
    row = next(r for r in table(m) if r[0].startswith("Contact point: mean error, no other"))
    assert row[1:] == ("0.75 mm", "2.50 mm", "k-NN 4.00 mm", "0.50 mm")
    del m["inversion"]["alone"]["bound_loc_mm_mean"]  # a bound step made before the split
    row = next(r for r in table(m) if r[0].startswith("Contact point: mean error, no other"))
    assert row[-1] == "—"


def test_the_alone_split_weighs_each_model_over_the_inversions_states():
    from ectskin.pipeline.metrics import alone_beside

    part = lambda per_state: {"by_other_finger": {"alone": {"per_state": per_state}}}  # noqa: E731
    inv = {"by_other_finger": {"alone": {"loc_mm_mean": 0.8, "n_frames": 40, "per_state": {
        "0/0/0 ml": {"loc_mm_mean": 0.5, "n_frames": 30},
        "20/0/0 ml": {"loc_mm_mean": 1.7, "n_frames": 10},
        "0/20/0 ml": {"loc_mm_mean": None, "n_frames": 0}}}}}
    contact = {**part({"0/0/0 ml": {"loc_mm_mean": 2.0, "n_frames": 300},
                       "20/0/0 ml": {"loc_mm_mean": 6.0, "n_frames": 100},
                       "10/10/10 ml": {"loc_mm_mean": 100.0, "n_frames": 100}}),
               "baselines": {"knn": part({"0/0/0 ml": {"loc_mm_mean": 4.0, "n_frames": 300}})}}
    out = alone_beside(contact, inv)
    assert out["states"] == ["0/0/0 ml", "20/0/0 ml"]  # a state without such a frame is left out
    assert out["contact_loc_mm_mean"] == 3.0  # (2 · 300 + 6 · 100) / 400: not 10/10/10 ml
    assert out["baseline_loc_mm_mean"] == {"knn": None}  # it lacks 20/0/0 ml
    assert (out["loc_mm_mean"], out["n_frames"]) == (0.8, 40)
    assert out["bound_loc_mm_mean"] is None  # no bound given
    bound = {"test_alone": {"loc_mm_mean": 0.4}}
    assert alone_beside(contact, inv, bound)["bound_loc_mm_mean"] == 0.4
    assert alone_beside(contact, {}) is None
