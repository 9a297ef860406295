"""Trained scores over seeds: the t-interval and the paired comparison on synthetic cases with
known answers (a hand-computed interval, the coverage of the true mean, a pairing that matters)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.design.stats import (
    aggregate,
    compare_with,
    goal_layouts,
    paired_comparison,
    rank_agreement,
    t_interval,
)


def test_the_interval_of_a_hand_computed_sample():
    # 1..5: mean 3, sd sqrt(2.5), t_{0.975, 4} = 2.7764451 (tables), half-width t sd / sqrt(5)
    got = t_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    half = 2.7764451052 * np.sqrt(2.5) / np.sqrt(5)
    assert got["mean"] == 3.0 and got["sd"] == pytest.approx(np.sqrt(2.5))
    assert got["ci"] == pytest.approx([3 - half, 3 + half], rel=1e-9)
    # three seeds: t_{0.975, 2} = 4.3026527
    got = t_interval([10.0, 12.0, 14.0])
    assert got["ci"] == pytest.approx([12 - 4.3026527297 * 2 / np.sqrt(3),
                                       12 + 4.3026527297 * 2 / np.sqrt(3)], rel=1e-9)
    assert t_interval([7.0])["ci"] == [-np.inf, np.inf]


def test_the_interval_covers_the_true_mean_at_its_level():
    """3 normal draws per sample, 4000 samples: coverage 0.95 within 4 binomial sd (0.014)."""
    rng = np.random.default_rng(0)
    hits = 0
    n = 4000
    for _ in range(n):
        lo, hi = t_interval(rng.normal(5.0, 2.0, 3))["ci"]
        hits += lo <= 5.0 <= hi
    assert abs(hits / n - 0.95) < 4 * np.sqrt(0.95 * 0.05 / n)


def test_the_paired_comparison_sees_a_shift_that_the_seeds_spread_hides():
    """Both layouts share each seed's luck (a spread of 5 mm between seeds); the candidate is
    1 mm better on every seed, give or take 0.1 mm: paired, that is shown; unpaired it is not."""
    luck = np.array([20.0, 25.0, 30.0])
    paper = luck + np.array([0.05, -0.02, 0.0])
    cand = luck - 1.0 + np.array([-0.03, 0.08, -0.05])
    got = paired_comparison(cand, paper)
    lo, hi = got["difference"]["ci"]
    assert hi < 0 and lo < -1.0 < hi and got["verdict"] == "better"
    a, b = t_interval(cand)["ci"], t_interval(paper)["ci"]
    assert a[1] > b[0]  # the two intervals overlap: compared apart, no claim could be made
    # higher is better (an accuracy): the same numbers read as worse
    assert paired_comparison(cand, paper, lower_is_better=False)["verdict"] == "worse"
    # no shift: the interval holds zero, nothing is claimed
    assert paired_comparison(paper + [0.1, -0.1, 0.05], paper)["verdict"] == "not shown"


def test_aggregate_and_compare_over_seeds():
    per = {s: {"loc_mm_mean": 10.0 + s, "face_accuracy": None} for s in (0, 1, 2)}
    ref = {s: {"loc_mm_mean": 12.0 + s + 0.1 * (s == 1)} for s in (0, 1, 2)}
    agg = aggregate(per)
    assert set(agg) == {"loc_mm_mean"}  # a metric without values is left out
    assert agg["loc_mm_mean"]["values"] == [10.0, 11.0, 12.0] and agg["loc_mm_mean"]["mean"] == 11
    cmp = compare_with(per, ref)
    assert cmp["loc_mm_mean"]["verdict"] == "better" and cmp["loc_mm_mean"]["seeds"] == [0, 1, 2]
    with pytest.raises(EctskinError, match="same seeds"):
        paired_comparison([1.0, 2.0], [1.0])
    with pytest.raises(EctskinError, match="missing"):
        t_interval([1.0, None])


def _entries(bounds, errors):
    return [
        {"name": f"L{i}", "bound_mm_p95": b, "loc_mm_mean": t}
        for i, (b, t) in enumerate(zip(bounds, errors))
    ]


def test_the_rank_agreement_is_spearman_by_hand():
    # no ties: rho = 1 - 6 sum d^2 / (n (n^2 - 1)); d = (1, 1, 1, 1, 0): 1 - 24 / 120 = 0.8
    got = rank_agreement(_entries([1.0, 2.0, 3.0, 4.0, 5.0], [2.0, 1.0, 4.0, 3.0, 5.0]))
    assert got["rho"] == pytest.approx(0.8) and got["n"] == 5 and got["agree"]
    # reversed: -1, no agreement
    got = rank_agreement(_entries([1.0, 2.0, 3.0], [3.0, 2.0, 1.0]))
    assert got["rho"] == pytest.approx(-1.0) and not got["agree"]
    # ties take their mean rank: (1.5, 1.5, 3) against (1, 2, 3): 1.5 / sqrt(1.5 * 2)
    got = rank_agreement(_entries([1.0, 1.0, 2.0], [1.0, 2.0, 3.0]))
    assert got["rho"] == pytest.approx(1.5 / np.sqrt(3.0))
    # an unresolved bound (None) ranks as the worst, not dropped
    got = rank_agreement(_entries([None, 1.0, 2.0], [3.0, 1.0, 2.0]))
    assert got["rho"] == pytest.approx(1.0) and got["n"] == 3
    # layouts without a trained score are left out; fewer than 3: no ranking
    few = _entries([1.0, 2.0], [1.0, 2.0]) + [{"name": "x", "bound_mm_p95": 3.0}]
    assert rank_agreement(few) is None
    # one score ties all: no rho
    assert rank_agreement(_entries([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]))["rho"] is None


def test_the_goal_needs_few_electrodes_half_the_bound_and_a_shown_gain():
    def entry(name, n, p95, verdict=None):
        e = {"name": name, "n_electrodes": n, "bound_mm_p95": p95}
        if verdict:
            e["vs_paper"] = {"loc_mm_mean": {"verdict": verdict}}
        return e

    layouts = [
        entry("paper", 8, 2.0),
        entry("a", 8, 0.9, "better"),  # all three: met
        entry("b", 8, 1.0, "not shown"),  # exactly half the bound, the gain not shown
        entry("c", 10, 0.5, "better"),  # too many electrodes
        entry("d", 6, 1.1, "better"),  # bound above half
        entry("e", 4, None, "better"),  # unresolved bound
    ]
    got = goal_layouts(layouts)
    assert got["paper_bound_mm_p95"] == 2.0
    assert got["half_bound"] == ["a", "b"] and got["met"] == ["a"]
    assert goal_layouts(layouts[1:])["met"] == []  # no paper: nothing to compare with


def test_the_rank_agreement_of_the_fit_error_reads_its_own_key():
    # the bound ranks the layouts one way, the fit's error the trained way: each key its own rho
    entries = [
        {**e, "fit_error_mm_p95": f}
        for e, f in zip(_entries([1.0, 2.0, 3.0], [3.0, 2.0, 1.0]), [3.0, 2.0, 1.0])
    ]
    assert rank_agreement(entries)["rho"] == pytest.approx(-1.0)
    fit = rank_agreement(entries, key="fit_error_mm_p95")
    assert fit["rho"] == pytest.approx(1.0) and fit["agree"] and fit["key"] == "fit_error_mm_p95"
    from ectskin.design.report import rank_agreement as line

    text = line(entries)
    assert "(worst-case bound) and the trained score (mean localisation error) do not agree" in text
    assert "fit with one fingertip) and the trained score (mean localisation error) agree" in text


def _seeded(bounds, per_seed, seeds=None):
    """Entries whose trained score holds per-seed values (layouts × seeds)."""
    seeds = list(range(len(per_seed[0]))) if seeds is None else seeds
    return [{"name": f"L{i}", "bound_mm_p95": b, "loc_mm_mean": float(np.mean(v)),
             "trained": {"loc_mm_mean": {"seeds": seeds, "values": list(v)}}}
            for i, (b, v) in enumerate(zip(bounds, per_seed))]


def test_the_seeds_interval_is_the_bootstrap_by_hand():
    """Two seeds: a resample is (0, 0), (1, 1) with 1/4 each or one of each (the mean) with
    1/2, so rho takes three values, and the 95 % interval runs from the least to the greatest
    of them. Bound order (1, 2, 3); seed 0 ranks the layouts (1, 2, 3): rho 1; seed 1
    (2, 1, 3): rho 0.5; the mean (3.0, 2.5, 4.5) ranks (2, 1, 3): 0.5. Seed to seed: 0.5."""
    got = rank_agreement(_seeded([1.0, 2.0, 3.0], [[1.0, 5.0], [2.0, 3.0], [3.0, 6.0]]))
    assert got["rho"] == pytest.approx(0.5)
    s = got["seeds"]
    assert s["n_seeds"] == 2 and s["level"] == 0.95
    assert s["rho_ci"] == pytest.approx([0.5, 1.0])
    assert s["seed_to_seed_rho"] == pytest.approx(0.5)
    # every seed ranks as the bound does: the interval is the point, the seeds agree
    same = rank_agreement(_seeded([1.0, 2.0, 3.0, 4.0],
                                  [[1.0, 1.1, 0.9], [2.0, 2.2, 1.9], [3.0, 3.1, 2.8],
                                   [4.0, 4.3, 4.1]]))
    assert same["seeds"]["rho_ci"] == pytest.approx([1.0, 1.0])
    assert same["seeds"]["seed_to_seed_rho"] == pytest.approx(1.0)
    # deterministic: the same answer twice
    assert rank_agreement(_seeded([1.0, 2.0, 3.0], [[1.0, 5.0], [2.0, 3.0], [3.0, 6.0]])) == got


def test_the_seeds_are_left_out_where_the_layouts_do_not_share_them():
    entries = _seeded([1.0, 2.0, 3.0], [[1.0, 5.0], [2.0, 3.0], [3.0, 6.0]])
    other = {**_seeded([3.0], [[3.0, 6.0]], [4, 5])[0], "name": "L2"}  # seeds 4 and 5
    assert "seeds" not in rank_agreement(entries[:2] + [other])
    one = _seeded([1.0, 2.0, 3.0], [[1.0], [2.0], [3.0]])
    assert "seeds" not in rank_agreement(one)  # one seed: nothing to resample
    assert "seeds" not in rank_agreement(_entries([1.0, 2.0, 3.0], [3.0, 2.0, 1.0]))
    from ectskin.design.report import rank_agreement as line

    text = line(entries)
    assert "over the 2 seeds resampled, 95 % of rho in [0.50, 1.00]" in text
    assert "the trained rankings of two seeds agree at rho = 0.50 on average" in text
