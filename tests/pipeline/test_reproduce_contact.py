"""The reproduction's contact steps on a recording with finger ground truth: the contact model,
its baselines, ECT images and the report's sections, as metrics.json and report.md carry them."""

from __future__ import annotations

import json

import pytest

from ectskin.pipeline import ReproduceConfig, reproduce


@pytest.mark.slow
def test_reproduce_reports_contact_two_fingers_and_ect_images(tmp_path, contact_recording):
    out = tmp_path / "out"
    rec = contact_recording(n_frames=30, n_trials=24)
    config = ReproduceConfig(
        out,
        recording=rec,
        profile="quick",
        epochs={"touch": 2, "track": 1, "contact": 3},
        ablations=False,
        robust=False,
        progress=False,
    )
    reproduce(config)
    m = json.loads((out / "metrics.json").read_text())
    for key in ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "force_mae_n", "hover_detect_mm"):
        assert key in m["contact"], key
    assert m["contact"]["loc_mm_mean"] > 0
    # a recording from elsewhere does not say where its fingers were placed
    assert "n_touch_points" in m["contact"] and m["contact"]["n_touch_points"] is None
    assert set(m["contact"]["baselines"]) == {"region_centre", "knn", "ridge"}
    assert m["multi"]["count_accuracy"] is not None
    assert set(m["multi"]["baselines"]) == {"region_centre", "knn", "ridge"}
    ect = m["ect_image"]
    assert ect["loc_mm_mean"] > 0 and set(ect["methods"]) == {"lbp", "tikhonov", "landweber"}
    assert ect["learned_loc_mm_mean"] == pytest.approx(m["contact"]["loc_mm_mean"])
    report = (out / "report.md").read_text()
    for heading in ("Contact: where and how hard", "Two fingers", "ECT images without training"):
        assert heading in report, heading
    assert (out / "figures" / "contact_error_map.png").is_file()
    assert (out / "figures" / "ect_images.png").is_file()


def test_the_contact_data_joins_the_papers_trials_renamed(contact_recording):
    from dataclasses import replace

    from ectskin._check import EctskinError
    from ectskin.pipeline.contact import with_paper_trials

    paper = contact_recording(n_frames=5, n_trials=2)
    contact = contact_recording(n_frames=5, n_trials=3, seed=1)
    both = with_paper_trials(paper, contact)
    assert [t.name for t in both.trials] == [f"paper_{t.name}" for t in paper.trials] + [
        f"contact_{t.name}" for t in contact.trials
    ]
    assert both.trials[0].capacitance is paper.trials[0].capacitance
    with pytest.raises(EctskinError, match="frame rate"):
        with_paper_trials(paper, replace(contact, frame_rate_hz=60.0))
