"""``design score`` over seeds: per metric its mean, 95 % interval and seeds, the paired
comparison with the paper's layout, the information score beside them, resumed; on a fake
trained score whose seed-to-seed luck is known and the point-charge model's bounds."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import pytest
from point_charge_model import CONFIG, point_charges  # tests/design/point_charge_model.py

from ectskin._check import EctskinError
from ectskin._files import write_json_atomic
from ectskin.design.family import FaceDesign, LayoutDesign, build_layout
from ectskin.design.information import information_layout
from ectskin.design.score import SCORE_FILE, ScoreConfig
from ectskin.design.stats import t_interval
from ectskin.design.sweep import score_layouts


class SeededFake:
    """A trained score in no time: loc_mm_mean = 20 + 3 seed (every layout's luck), 0.5 mm less
    for 6 electrodes, plus 0.01 × ((7 seed + n_electrodes) mod 3) (a layout's own noise)."""

    def __init__(self):
        self.calls = []

    def __call__(self, layout, out_dir, config):
        self.calls.append((layout.name, config.seed))
        assert config.protocol.seed == config.seed
        n, s = layout.n_electrodes, config.seed
        loc = 20 + 3 * s - 0.5 * (n == 6) + 0.01 * ((7 * s + n) % 3)
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        score = {
            "name": layout.name, "n_electrodes": n, "n_pairs": layout.n_pairs,
            "loc_mm_mean": loc, "region_accuracy": 0.5, "force_mae_n": 0.1, "track_ad_mm": None,
            "loc_mm_per_face": {}, "loc_map": {}, "sensor": {"snr_db_min": 60.0},
            "seconds": {"total": 1.0}, "settings": config.settings(), "layout": layout.to_dict(),
        }
        write_json_atomic(out / SCORE_FILE, score)
        return json.loads((out / SCORE_FILE).read_text())


def _layouts():
    three = build_layout(LayoutDesign(FaceDesign(3), FaceDesign(3)), "three")
    five = build_layout(LayoutDesign(FaceDesign(5), FaceDesign(5)), "five")
    return [("three", three), ("five", five)]


def test_seeds_give_means_intervals_and_the_paired_verdict(tmp_path):
    fake = SeededFake()
    info = partial(information_layout, providers=point_charges)
    run = partial(score_layouts, _layouts(), tmp_path, ScoreConfig(response="solve"), n_workers=0, score_fn=fake,
                  seeds=[0, 1, 2], information=CONFIG, information_fn=info)
    design = run()
    assert sorted(fake.calls) == sorted(
        (n, s) for n in ("paper-2x4-wires", "three", "five") for s in (0, 1, 2))
    assert design["seeds"] == [0, 1, 2]
    e = {x["name"]: x for x in design["layouts"]}
    paper = [20 + 3 * s + 0.01 * ((7 * s + 8) % 3) for s in range(3)]
    three = [20 + 3 * s - 0.5 + 0.01 * ((7 * s + 6) % 3) for s in range(3)]
    t = e["three"]["trained"]["loc_mm_mean"]
    assert t["values"] == pytest.approx(three) and t["seeds"] == [0, 1, 2]
    assert e["three"]["loc_mm_mean"] == pytest.approx(sum(three) / 3)
    assert t["ci"] == pytest.approx(t_interval(three)["ci"])
    # the seeds' luck (3 mm a seed) is shared: paired, the 0.5 mm is shown
    v = e["three"]["vs_paper"]["loc_mm_mean"]
    assert v["verdict"] == "better"
    assert v["difference"]["mean"] == pytest.approx(sum(a - b for a, b in zip(three, paper)) / 3)
    assert e["five"]["vs_paper"]["loc_mm_mean"]["verdict"] == "not shown"
    assert e["five"]["vs_paper"]["region_accuracy"]["verdict"] == "not shown"  # all equal
    assert "vs_paper" not in e["paper"] and "track_ad_mm" not in e["three"]["trained"]
    for x in e.values():  # the information score beside the trained metrics
        assert x["bound_mm_p95"] > 0 and x["ambiguity_sigma"] > 0 and "maps" not in x
        assert x["fit_error_mm_p95"] > 0 and x["fit_error_mm_median"] > 0
        assert "fit_error_mm_mean" in x  # (null when a point is unresolved: inf)
    # the rank agreement and the goal are in design.json (their arithmetic: test_stats.py)
    assert design["rank_agreement"]["n"] == 3
    assert design["rank_agreement"]["layouts"] == ["paper", "three", "five"]
    assert design["rank_agreement_fit"]["key"] == "fit_error_mm_p95"
    assert design["rank_agreement_fit"]["layouts"] == ["paper", "three", "five"]
    assert design["rank_agreement_fit_median"]["key"] == "fit_error_mm_median"
    assert design["rank_agreement_fit_median"]["layouts"] == ["paper", "three", "five"]
    assert design["goal"]["paper_bound_mm_p95"] == e["paper"]["bound_mm_p95"]
    md = (tmp_path / "design.md").read_text()
    assert "Spearman rho" in md and "At most 8 electrodes" in md
    for name in ("worst-case bound", "worst-case error of a fit", "median error of a fit"):
        assert f"The information score ({name}" in md
    assert "three is better than the paper's layout in loc_mm_mean" in md
    assert "five is better" not in md
    assert (tmp_path / "layouts" / "three" / "seed-2" / SCORE_FILE).is_file()
    assert (tmp_path / "figures" / "three_bound.png").is_file()
    # a rerun scores nothing again
    fake.calls.clear()
    again = run()
    assert fake.calls == []
    assert [x["loc_mm_mean"] for x in again["layouts"]] == [
        x["loc_mm_mean"] for x in design["layouts"]]


def test_repeated_seeds_are_refused(tmp_path):
    with pytest.raises(EctskinError, match="distinct seeds"):
        score_layouts([], tmp_path, n_workers=0, score_fn=SeededFake(), seeds=[1, 1])


def test_one_seed_with_the_information_score_beside_it(tmp_path, fake_score):
    info = partial(information_layout, providers=point_charges)
    run = partial(score_layouts, _layouts()[:1], tmp_path, ScoreConfig(response="solve"), n_workers=0,
                  score_fn=fake_score, information=CONFIG, information_fn=info)
    fake_score.calls.clear()
    design = run()
    assert fake_score.calls == ["paper-2x4-wires", "three"]
    assert design["information_settings"] == CONFIG.to_dict()
    for e in design["layouts"]:
        assert e["loc_mm_mean"] == 30.0 - e["n_electrodes"]  # the fake's trained metric
        assert e["bound_mm_p95"] > 0 and e["wire_length_mm"] > 0 and "maps" not in e
    assert (tmp_path / "figures" / "three_bound.png").is_file()
    fake_score.calls.clear()
    assert run()["layouts"] == design["layouts"] and fake_score.calls == []
