"""The Optuna search: empty spaces refused, sampled layouts manufacturable, the study resumes."""

from __future__ import annotations

import json

import optuna
import pytest

from ectskin._check import EctskinError
from ectskin.design.family import ManufacturingRules, build_layout, check_manufacturable
from ectskin.design.report import pareto_front
from ectskin.design.search import SearchSpace, run_search, sample_design
from ectskin.layout import default_layout


@pytest.mark.parametrize(
    "space, match",
    [
        (SearchSpace(min_wires=5, max_wires=3), r"empty: --min-wires 5 > --max-wires 3"),
        (SearchSpace(min_wires=1), r"--min-wires must be >= 2"),
        (SearchSpace(length_mm=(120.0, 130.0)), r"empty: --length-mm 120\.\.130"),
        (SearchSpace(width_mm=(0.1, 0.3)), r"empty: --width-mm 0\.1\.\.0\.3 .* 0\.5 mm"),
        (SearchSpace(min_wires=14, max_wires=16), r"14\.\.16 wires do not fit across a 40 mm"),
    ],
)
def test_an_empty_search_space_is_one_clear_error(space, match, tmp_path, fake_score):
    with pytest.raises(EctskinError, match=match):
        run_search(tmp_path, space=space, n_workers=0, objective="trained", score_fn=fake_score)
    assert not (tmp_path / "study.journal").exists()


def test_sampled_designs_are_manufacturable_across_the_space():
    # random samples of every parameter: the mapping onto feasible spans keeps them buildable
    space, rules, base = SearchSpace(), ManufacturingRules(), default_layout()
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=3))
    counts = set()
    for k in range(40):
        trial = study.ask()
        design = sample_design(trial, space, rules, base)
        layout = build_layout(design, f"s{k}", rules=rules)
        check_manufacturable(layout, rules)
        counts.add(layout.n_electrodes)
        study.tell(trial, 0.0)
    assert min(counts) < 8 < max(counts)


@pytest.mark.parametrize("routing", ["straight", "fan"])
def test_the_longest_widest_wires_stay_on_the_skin(routing):
    # the corner of the space: both wires as long as the room allows and 2 mm wide; the wire's
    # end cap (half its width past its end) must stay inside the skin (it did not: 1 mm out)
    params = {}
    for face in ("front", "back"):
        params.update({
            f"{face}_n_wires": 2, f"{face}_routing": routing, f"{face}_order": "ascending",
            f"{face}_width_mm": 2.0, f"{face}_span": 1.0, f"{face}_length_a_mm": 105.0,
            f"{face}_length_b_mm": 105.0,
        })
    rules, base = ManufacturingRules(), default_layout()
    design = sample_design(optuna.trial.FixedTrial(params), SearchSpace(), rules, base)
    layout = build_layout(design, "corner", rules=rules)
    check_manufacturable(layout, rules)
    top = max(sk.v_mm[1] for sk in base.skins)
    ends = [e.polyline_mm[:, 1].max() + e.width_mm / 2 for e in layout.electrodes]
    assert max(ends) == pytest.approx(top, abs=0.01)  # as long as fits, and no longer


def test_pareto_front_by_hand():
    pts = [
        {"name": "a", "n_electrodes": 4, "loc_mm_mean": 20.0},
        {"name": "b", "n_electrodes": 6, "loc_mm_mean": 15.0},
        {"name": "c", "n_electrodes": 6, "loc_mm_mean": 18.0},  # dominated by b
        {"name": "d", "n_electrodes": 8, "loc_mm_mean": 16.0},  # dominated by b
        {"name": "e", "n_electrodes": 12, "loc_mm_mean": 9.0},
    ]
    assert [p["name"] for p in pareto_front(pts)] == ["a", "b", "e"]


def test_the_study_resumes_and_a_killed_trial_is_scored_again(tmp_path, fake_score):
    fake_score.calls.clear()
    design = run_search(tmp_path, n_trials=2, n_workers=0, objective="trained", score_fn=fake_score)
    assert fake_score.calls[0] == "paper-2x4-wires" and len(fake_score.calls) == 3
    assert design["search"]["n_complete"] == 2
    assert (tmp_path / "figures" / "front.png").is_file() and (tmp_path / "design.md").is_file()
    for e in design["layouts"][1:]:  # the proposed layouts are layout files
        from ectskin.layout import load_layout

        assert load_layout(tmp_path / e["folder"] / "layout.json").n_electrodes == e["n_electrodes"]
    # one more trial: the finished ones (and the paper) are not scored again
    fake_score.calls.clear()
    design = run_search(tmp_path, n_trials=3, n_workers=0, objective="trained", score_fn=fake_score)
    assert len(fake_score.calls) == 1 and design["search"]["n_complete"] == 3
    # a run killed while scoring trial 3 leaves it running; the rerun scores it, then trial 4
    fake_score.calls.clear()

    def dies(layout, out_dir, config):
        if layout.name == "design-0003":
            raise KeyboardInterrupt
        return fake_score(layout, out_dir, config)

    with pytest.raises(KeyboardInterrupt):
        run_search(tmp_path, n_trials=5, n_workers=0, objective="trained", score_fn=dies)
    fake_score.calls.clear()
    design = run_search(tmp_path, n_trials=5, n_workers=0, objective="trained", score_fn=fake_score)
    assert fake_score.calls == ["design-0003", "design-0004"]
    assert [e["name"] for e in design["layouts"]] == [
        "paper",
        "design-0000",
        "design-0001",
        "design-0002",
        "design-0003",
        "design-0004",
    ]
    saved = json.loads((tmp_path / "design.json").read_text())
    assert saved["search"]["n_complete"] == 5


def test_a_rerun_with_other_settings_is_refused(tmp_path, fake_score):
    run_search(tmp_path, n_trials=1, n_workers=0, objective="trained", score_fn=fake_score)
    with pytest.raises(
        EctskinError, match=r"study\.journal: the study was started with other settings \(space\)"
    ):
        run_search(
            tmp_path, n_trials=1, n_workers=0, objective="trained", score_fn=fake_score,
            space=SearchSpace(max_wires=6),
        )


def test_pareto_front_in_three_objectives_by_hand():
    keys = ("bound_mm_p95", "n_electrodes", "wire_length_mm")
    pts = [
        {"name": "a", "bound_mm_p95": 1.0, "n_electrodes": 8, "wire_length_mm": 400.0},
        {"name": "b", "bound_mm_p95": 2.0, "n_electrodes": 6, "wire_length_mm": 300.0},
        {"name": "c", "bound_mm_p95": 2.0, "n_electrodes": 6, "wire_length_mm": 350.0},  # by b
        {"name": "d", "bound_mm_p95": 0.5, "n_electrodes": 12, "wire_length_mm": 200.0},
        {"name": "e", "bound_mm_p95": float("inf"), "n_electrodes": 4, "wire_length_mm": 100.0},
        {"name": "f", "bound_mm_p95": float("inf"), "n_electrodes": 4, "wire_length_mm": 120.0},
        {"name": "g", "bound_mm_p95": None, "n_electrodes": 2, "wire_length_mm": 50.0},  # left out
    ]
    # e: unresolved somewhere (inf), but the fewest electrodes and the least wire among the rest
    assert [p["name"] for p in pareto_front(pts, keys)] == ["d", "a", "b", "e"]
