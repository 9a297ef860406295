"""The report's contact sections: each number beside the strongest baseline with the margin,
computed by hand here."""

from __future__ import annotations

from ectskin.report.contact import contact_sections, contact_table


def _metrics():
    return {
        "contact": {
            "loc_mm_mean": 2.0,
            "force_mae_n": 0.30,
            "face_accuracy": 0.95,
            "baselines": {
                "region_centre": {"loc_mm_mean": 5.0, "force_mae_n": 0.40, "face_accuracy": 0.97},
                "knn": {"loc_mm_mean": 4.0, "force_mae_n": 0.25, "face_accuracy": 0.90},
            },
            "per_state": {"0/0/0 ml": {"loc_mm_mean": 1.5, "loc_mm_p90": 3.0, "n_frames": 10}},
        },
        "multi": {"count_accuracy": 0.9, "baselines": {"knn": {"count_accuracy": 0.8}}},
        "ect_image": {"methods": {"tikhonov": {"loc_mm_mean": 6.0, "loc_mm_median": 4.0}}},
    }


def test_each_row_names_the_strongest_baseline_and_the_margin():
    rows = {r[0]: r for r in contact_table(_metrics()["contact"])}
    # lower is better: k-NN's 4 mm is the strongest, not the region centre's 5 mm
    assert rows["Contact point: mean error"][2:] == ("2.00 mm", "k-NN 4.00 mm", "better by 2.00 mm")
    assert rows["Force: mean absolute error"][2:] == ("0.300 N", "k-NN 0.250 N", "worse by 0.050 N")
    # higher is better: the region centre's 97 % is the strongest
    face = rows["Face (front / back) right"]
    assert face[2:] == ("95.00 %", "region centre 97.00 %", "−2.0 points")


def test_sections_cover_contact_two_fingers_and_ect_with_the_learned_ratio():
    items = contact_sections(_metrics())
    headings = [p for k, p in items if k == "h2"]
    assert headings == [
        "Contact: where and how hard (beyond the paper)",
        "Two fingers",
        "ECT images without training",
    ]
    ect_table = [p for k, p in items if k == "table"][-1]
    assert ect_table[1][0][-1] == "3.0 ×"  # 6.0 mm / 2.0 mm


def test_handling_table_sets_the_hand_off_beside_the_hand_on_with_each_strongest_baseline():
    m = _metrics()
    m["contact"]["handling_off"] = {
        "loc_mm_mean": 1.5,
        "force_mae_n": 0.2,
        "count_accuracy": 0.95,
        "baselines": {
            "knn": {"loc_mm_mean": 3.5, "count_accuracy": 0.7},
            "ridge": {"loc_mm_mean": 3.0, "count_accuracy": 0.9},
        },
    }
    items = contact_sections(m)
    table = next(p for k, p in items if k == "table" and p[0][1] == "hand on")
    rows = {r[0]: r for r in table[1]}
    # on: k-NN 4 mm is the strongest; off: ridge 3 mm (not k-NN's 3.5)
    assert rows["Contact point: mean error"][1:] == (
        "2.00 mm",
        "1.50 mm",
        "k-NN 4.00 mm",
        "ridge regression 3.00 mm",
    )
    # the count accuracy with the hand on comes from the multi block
    assert rows["Finger count right"][1:] == (
        "90.00 %",
        "95.00 %",
        "k-NN 80.00 %",
        "ridge regression 90.00 %",
    )
    assert rows["Hover detected up to (≥ 90 % of frames)"][1:] == ("—", "—", "—", "—")
    # without a hand-off block there is no such table
    assert not any(k == "table" and p[0][1] == "hand on" for k, p in contact_sections(_metrics()))
