"""The report's force split: each part's share, the model's MAE beside the strongest other
model's, the mean bound and the σ coverage, worded from metrics.json alone."""

from __future__ import annotations

from ectskin.report.contact import contact_sections, force_split_section


def _contact():
    part = {
        "share_observable": 0.4, "share_not_observable": 0.35, "share_no_bound": 0.25,
        "force_mae_n_observable": 0.05, "force_mae_n_not_observable": 0.42,
        "force_mae_n_no_bound": 0.31, "bound_force_n_mean_observable": 0.03,
        "bound_force_n_mean_not_observable": 0.4, "bound_force_n_mean_no_bound": None,
        "force_coverage_1sigma_observable": 0.7, "force_coverage_2sigma_observable": 0.96,
    }
    return {
        "loc_mm_mean": 2.0, "force_mae_n": 0.3,
        "force_coverage_1sigma": 0.69, "force_coverage_2sigma": 0.94,
        "baselines": {"ridge": {"force_mae_n": 0.31}},
        "force_split": {
            "threshold_n": 0.1, "case": "all", "model": "contactnet",
            "models": {
                "contactnet": part,
                "ridge": {"force_mae_n_observable": 0.2, "force_mae_n_not_observable": 0.40},
                "knn": {"force_mae_n_observable": 0.09, "force_mae_n_not_observable": 0.5},
            },
        },
    }


def test_force_split_rows_by_hand():
    items = force_split_section(_contact())
    text = items[0][1]
    assert "0.1 N" in text and "(all frames: 69.00 % / 94.00 %)" in text
    head, rows = items[1][1]
    assert head[2] == "this run's MAE"
    obs, not_obs, none = rows
    # the strongest other model where observable is k-NN (0.09 N), where not, ridge (0.40 N)
    assert obs == ("observable (bound < 0.1 N)", "40.00 %", "0.050 N", "k-NN 0.090 N",
                   "0.030 N", "70.00 % / 96.00 %")
    assert not_obs[2:4] == ("0.420 N", "ridge regression 0.400 N")
    assert none[0].startswith("no bound") and none[4] == "—" and none[3] == "—"


def test_the_split_stands_in_the_contact_section_and_only_with_one():
    m = {"contact": _contact()}
    tables = [p for k, p in contact_sections(m) if k == "table"]
    assert any(t[0][-1] == "within ±1σ / ±2σ" for t in tables)
    del m["contact"]["force_split"]
    assert force_split_section(m["contact"]) == []
    tables = [p for k, p in contact_sections(m) if k == "table"]
    assert not any(t[0][-1] == "within ±1σ / ±2σ" for t in tables)
