"""The report's lead paragraph on touch (``ectskin.report.reading``): this run's paper-recipe
accuracy, the reading the twin simulated, and the reading ablation's numbers, checked on a
hand-built ablation summary whose means and gains are computed by hand below."""

from __future__ import annotations

import json

import pytest

from ectskin import EctskinError
from ectskin.report import write_report
from ectskin.report.reading import (
    load_ablation,
    reading_description,
    reading_paragraph,
)
from ectskin.study.reading_table import SUMMARY_FORMAT, summary_document
from ectskin.twin import Protocol


def _cell(paper: float) -> dict:
    return {"paper": paper, "robust": 0.99, "baseline": "logreg", "baseline_accuracy": 0.95,
            "epoch": 1, "epochs": 30}


ABLATION = {
    "format": SUMMARY_FORMAT,
    "created_utc": "2026-11-26T12:00:00+00:00",
    "rows": {
        "one_point": {"split": "trial", "seeds": {"0": _cell(0.80), "1": _cell(0.90)}},
        # above on both seeds: +5 and +2 points
        "sliding": {"split": "trial", "seeds": {"0": _cell(0.85), "1": _cell(0.92)}},
        # above on seed 0 (+3), below on seed 1 (-1)
        "hand_off": {"split": "trial", "seeds": {"0": _cell(0.83), "1": _cell(0.89)}},
        "random_split": {"split": "frame", "seeds": {"0": _cell(1.0)}},
    },
}


def test_the_reading_in_words_follows_the_protocol():
    assert reading_description(Protocol(touch_dwells=1).to_dict()) == (
        "one point per trial, held for the whole 30-s trial")
    # the default: 8 points, sliding over the whole dwell (dwell_slide_s None)
    assert reading_description(Protocol().to_dict()) == (
        "8 points per trial, the finger sliding in contact from each to the next over the whole "
        "30-s trial")
    assert reading_description(Protocol(touch_dwells=4, dwell_slide_s=0.0).to_dict()).endswith(
        "moving to the next every 7.5 s")
    assert "over the last 2 s of each" in reading_description(
        Protocol(touch_dwells=4, dwell_slide_s=2.0).to_dict())
    # a metrics protocol of before the option: one point
    assert reading_description({"duration_s": 30.0}).startswith("one point per trial")


def test_the_paragraph_sets_the_run_beside_the_ablation():
    metrics = {"touch": {"accuracy": 0.9304, "baselines": {"logreg": {"accuracy": 0.9503},
                                                           "knn": {"accuracy": 0.5989}}},
               "protocol": Protocol().to_dict()}
    text = reading_paragraph(metrics, ABLATION)
    assert text is not None
    assert "93.04 % on this run's test trials, against the paper's 99.88 %" in text
    # the strongest baseline of the same test trials beside it (logreg, not k-NN)
    assert "strongest baseline on the same test trials, 'logistic regression', gets 95.03 %" in text
    assert "8 points per trial, the finger sliding" in text
    # means by hand: one_point (80 + 90) / 2, sliding (85 + 92) / 2, hand_off (83 + 89) / 2
    assert "`one_point` 85.00 % (2 seeds)" in text
    assert "`sliding` 88.50 % (2 seeds)" in text and "`hand_off` 86.00 % (2 seeds)" in text
    # sliding gains +5 and +2 points: above on every seed; hand_off +3 and -1: not
    assert "every seed they share (the least and the largest gain, points): `sliding` +2.00 to +5.00." in text
    assert "Not on every seed: `hand_off` -1.00 to +3.00" in text
    assert "spans 80.00 %–90.00 %" in text
    assert "Split by frame" in text and "100.00 %" in text
    assert "2026-11-26" in text


def test_a_run_without_touch_or_protocol():
    assert reading_paragraph({"contact": {}}, ABLATION) is None
    # a recording, not the twin: the accuracy only
    text = reading_paragraph({"touch": {"accuracy": 0.5}}, ABLATION)
    assert text is not None and "50.00 %" in text and "ablation" not in text


def test_the_shipped_ablation_and_bad_files(tmp_path):
    shipped = load_ablation()
    assert {"one_point", "sliding", "random_split"} <= set(shipped["rows"])
    assert shipped["rows"]["sliding"]["changes"] == {"touch_dwells": 8, "dwell_slide_s": None}
    bad = tmp_path / "a.json"
    bad.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(EctskinError, match=r"a\.json: format: expected .*found 'something else'"):
        load_ablation(bad)
    # the study's writer makes what the report reads
    doc = summary_document({"one_point": {0: {**_cell(0.8), "seconds": {}}}})
    good = tmp_path / "b.json"
    good.write_text(json.dumps(doc))
    assert load_ablation(good)["rows"]["one_point"]["seeds"]["0"]["paper"] == 0.8


def test_the_report_leads_with_it(tmp_path):
    metrics = {"touch": {"accuracy": 0.9304}, "protocol": Protocol().to_dict()}
    md, _ = write_report(tmp_path, metrics)
    text = md.read_text()
    assert text.index("## Paper recipe on this reading") < text.index("## Results")
    assert "8 points per trial" in text and "`sliding`" in text
