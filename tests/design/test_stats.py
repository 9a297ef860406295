"""Trained scores over seeds: the t-interval and the paired comparison on synthetic cases with
known answers (a hand-computed interval, the coverage of the true mean, a pairing that matters)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.design.stats import aggregate, compare_with, paired_comparison, t_interval


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
