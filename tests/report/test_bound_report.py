"""The report prints the physical limit beside the contact metrics when metrics.json carries a
``bound`` block, and says nothing about it when not."""

from __future__ import annotations

from pathlib import Path

from ectskin.report import render_markdown
from ectskin.report.contact import contact_sections


def _contact():
    return {
        "loc_mm_mean": 2.0,
        "loc_mm_median": 1.5,
        "force_mae_n": 0.30,
        "face_accuracy": 0.95,
        "window": 10,
        "baselines": {
            "knn": {"loc_mm_mean": 4.0, "force_mae_n": 0.25,
                    "per_state": {"0/20/0 ml": {"loc_mm_mean": 3.25}}},
        },
        "per_state": {
            "0/20/0 ml": {"loc_mm_mean": 1.5, "loc_mm_p90": 3.0, "n_frames": 10},
            "10/10/10 ml": {"loc_mm_mean": 2.5, "loc_mm_p90": 4.0, "n_frames": 7},
        },
    }


def _bound():
    return {
        "case": "all",
        "loc_mm_mean": 0.4,
        "force_n_mean": 0.2,
        "force_observable_share": 0.25,
        "force_observable_share_near_wires": 0.6,
        "force_observable_share_away_from_wires": 0.05,
        "per_face": {"front": {"force_observable_share": 0.3},
                     "back": {"force_observable_share": 0.2}},
        "per_state": {"0/20/0 ml": {"loc_mm_mean": 0.45, "force_n_mean": 0.21,
                                    "force_observable_share": 0.25,
                                    "test": {"loc_mm_mean": 0.125, "force_n_mean": 0.0625}}},
        "test": {"loc_mm_mean": 0.11, "loc_mm_median": 0.09, "force_n_mean": 0.07,
                 "n_points": 17, "states_without_field": {"10/10/10 ml": 7}},
        "settings": {"nuisances": ["push", "inflation", "finger"], "force_threshold_n": 0.1,
                     "force_n": 1.0, "near_wire_mm": 5.0},
    }


def _tables(items):
    return {p[0]: p[1] for k, p in items if k == "table"}


def test_the_contact_tables_carry_the_bound_column():
    items = contact_sections({"contact": _contact(), "bound": _bound()})
    tables = _tables(items)
    main = next(rows for head, rows in tables.items() if head[-1] == "bound (CRB)")
    rows = {r[0]: r for r in main}
    assert rows["Contact point: mean error"][-1] == "0.11 mm"
    assert rows["Contact point: median error"][-1] == "0.09 mm"
    assert rows["Force: mean absolute error"][-1] == "0.070 N"
    assert rows["Face (front / back) right"][-1] == "—"  # no bound for it
    head = next(h for h in tables if h[0] == "state" and "bound (CRB)" in h)
    per_state = {r[0]: dict(zip(head, r)) for r in tables[head]}
    s = per_state["0/20/0 ml"]
    assert (s["mean"], s["strongest baseline"], s["bound (CRB)"], s["force bound"]) == (
        "1.50 mm", "k-NN 3.25 mm", "0.12 mm", "0.062 N")
    assert per_state["10/10/10 ml"]["bound (CRB)"] == "—"  # no field for that state
    text = " ".join(p for k, p in items if k == "p")
    assert "Force is observable (bound < 0.1 N at 1.0 N) on 25.00 %" in text
    assert "on 60.00 % of the cells within 5.0 mm of a wire and on 5.00 % of those" in text
    assert "ContactNet reads 10" in text and "10/10/10 ml (7 frames)" in text
    assert "estimated alongside" in text


def test_without_a_bound_the_report_says_nothing_of_it():
    items = contact_sections({"contact": _contact()})
    heads = list(_tables(items))
    assert not any("bound" in " ".join(h) for h in heads)
    md = render_markdown({"contact": _contact()}, [], Path("."))
    assert "Cramér" not in md and "bound" not in md.lower() and "observable" not in md


def test_a_bound_without_test_frames_prints_the_maps_but_no_column():
    b = _bound()
    del b["test"]
    b["case"] = "none"
    items = contact_sections({"contact": _contact(), "bound": b})
    assert not any("bound (CRB)" in h for h in _tables(items))
    text = " ".join(p for k, p in items if k == "p")
    assert "every nuisance known" in text and "test frame" not in text
    assert "Force is observable" in text
