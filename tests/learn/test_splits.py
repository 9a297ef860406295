"""Trial-exclusive train / val / test splits (ectskin.learn.splits)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.learn.splits import (
    TOUCH_SPLIT,
    TRACK_SPLIT,
    split_from_names,
    split_groups,
    split_names,
)


@pytest.mark.parametrize("n, counts", [(189, TOUCH_SPLIT), (146, TRACK_SPLIT)])
def test_split_sizes_disjoint_cover(n, counts):
    s = split_groups(n, counts, seed=3)
    assert [len(s[k]) for k in ("train", "val", "test")] == list(counts)
    allg = np.concatenate([s["train"], s["val"], s["test"]])
    assert np.array_equal(np.sort(allg), np.arange(n))
    assert all(np.all(np.diff(v) > 0) for v in s.values())


def test_split_deterministic_and_seed_dependent():
    a = split_groups(50, seed=7)
    b = split_groups([f"t{i}" for i in range(50)], seed=7)
    c = split_groups(50, seed=8)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not all(np.array_equal(a[k], c[k]) for k in a)


@pytest.mark.parametrize(
    "n, counts, want",
    [
        (24, TOUCH_SPLIT, [16, 4, 4]),  # 125/32/32 scaled: 15.87, 4.06, 4.06
        (20, TRACK_SPLIT, [15, 2, 3]),  # 108/18/20 → 14.79, 2.47, 2.74
        (3, TOUCH_SPLIT, [1, 1, 1]),
        (10, (0.6, 0.2, 0.2), [6, 2, 2]),
    ],
)
def test_split_counts_scale(n, counts, want):
    s = split_groups(n, counts)
    assert [len(s[k]) for k in ("train", "val", "test")] == want


def test_split_errors():
    with pytest.raises(EctskinError, match="at least one trial"):
        split_groups(2)
    with pytest.raises(EctskinError, match="3 non-negative numbers"):
        split_groups(10, (5, 5))
    with pytest.raises(EctskinError, match="3 non-negative numbers"):
        split_groups(10, (5, -1, 6))
    with pytest.raises(EctskinError, match="one label per group"):
        split_groups(10, stratify=[1, 2])


def test_stratified_split_puts_every_class_in_train():
    # paper-like: 27 no-contact trials + 162 touch trials, region r touched 9 times
    labels = np.array([0] * 27 + [r for r in range(1, 19) for _ in range(9)])
    for seed in range(5):
        s = split_groups(189, TOUCH_SPLIT, seed=seed, stratify=labels)
        assert set(labels[s["train"]]) == set(range(19))
        assert [len(s[k]) for k in ("train", "val", "test")] == [125, 32, 32]
        # proportional spread: no-contact trials in val ≈ 27 * 32 / 189 = 4.6
        assert 3 <= np.count_nonzero(labels[s["val"]] == 0) <= 6
    # a region touched once always lands in train
    rare = labels.copy()
    rare[rare == 18] = 17
    rare[-1] = 18
    for seed in range(5):
        s = split_groups(189, TOUCH_SPLIT, seed=seed, stratify=rare)
        assert 188 in s["train"]


def test_split_names_round_trip():
    names = [f"trial_{i:03d}" for i in range(30)]
    s = split_groups(names, TRACK_SPLIT, seed=1)
    stored = json.loads(json.dumps(split_names(s, names)))
    back = split_from_names(stored, names)
    assert all(np.array_equal(back[k], s[k]) for k in s)
    stored["test"].append("trial_999")
    with pytest.raises(EctskinError, match="trial_999"):
        split_from_names(stored, names)
    stored["test"][-1] = stored["train"][0]
    with pytest.raises(EctskinError, match="in both train and test"):
        split_from_names(stored, names)
    with pytest.raises(EctskinError, match="missing split 'val'"):
        split_from_names({"train": [], "test": []}, names)


def _label_patterns(n: int, rng: np.random.Generator) -> dict[str, np.ndarray | None]:
    """Label patterns a recording can have: none, the paper's (a block of no-contact trials,
    regions touched equally often), one label, all distinct, one rare label, random labels with
    more labels than some splits have trials."""
    paper = np.resize(np.arange(19), n)
    rare = np.zeros(n, dtype=int)
    rare[-1] = 7
    return {
        "none": None,
        "paper": np.sort(paper),
        "one label": np.zeros(n, dtype=int),
        "all distinct": rng.permutation(n),
        "one rare": rare,
        "random": rng.integers(0, max(2, n // 2), n),
    }


@pytest.mark.parametrize(
    "n, counts",
    [
        (189, TOUCH_SPLIT),
        (146, TRACK_SPLIT),
        (24, TOUCH_SPLIT),
        (7, (0.6, 0.2, 0.2)),
        (3, (1, 1, 1)),
    ],
)
def test_splits_are_trial_exclusive_and_cover_every_trial(n, counts):
    """Over many seeds and label patterns, stratified or not: train, val and test are pairwise
    disjoint, together hold every trial exactly once, have the scaled sizes, and survive the
    round trip through the names split.json stores.

    Catches the audit's mutant: one trial put in two splits with the sizes unchanged (e.g.
    ``order[-1] = order[0]`` before the order is cut into splits, in the stratified path)."""
    rng = np.random.default_rng(n)
    names = [f"trial_{i:03d}" for i in range(n)]
    want = None
    for label_name, labels in _label_patterns(n, rng).items():
        for seed in range(25):
            s = split_groups(names, counts, seed=seed, stratify=labels)
            sets = {k: set(s[k].tolist()) for k in ("train", "val", "test")}
            where = (label_name, seed)
            assert not sets["train"] & sets["val"], where
            assert not sets["train"] & sets["test"], where
            assert not sets["val"] & sets["test"], where
            assert sets["train"] | sets["val"] | sets["test"] == set(range(n)), where
            sizes = [len(s[k]) for k in ("train", "val", "test")]
            assert sum(sizes) == n and all(len(v) == len(s[k]) for k, v in sets.items()), where
            want = want or sizes
            assert sizes == want, where  # the sizes depend on the counts only, not the labels
            back = split_from_names(split_names(s, names), names)
            assert all(np.array_equal(back[k], s[k]) for k in s), where
