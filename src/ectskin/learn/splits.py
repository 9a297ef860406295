"""Trial-exclusive train / val / test splits of a data set's groups (trials).

* :func:`split_groups`: the split of group ids (paper: :data:`TOUCH_SPLIT` 125/32/32 touch
  trials, :data:`TRACK_SPLIT` 108/18/20 tracking trials), scaled to recordings of other sizes,
  optionally stratified by a label per group.
* :func:`split_names` / :func:`split_from_names`: group ids ↔ the trial names that
  ``split.json`` stores.
* :func:`choose_test_trials`: the test trials of a trained run in any recording: the trials it
  was not trained or validated on, recognised by their readouts (:func:`trial_digests`, which
  ``split.json`` stores) or, for runs without digests, by name.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option

log = logging.getLogger(__name__)

#: Paper §3: touch data 189 trials split 125 / 32 / 32 (train / val / test).
TOUCH_SPLIT = (125, 32, 32)
#: Paper §3: tracking data 146 trials split 108 / 18 / 20.
TRACK_SPLIT = (108, 18, 20)
SPLITS = ("train", "val", "test")
#: ``choose_test_trials`` modes (``evaluate --test-trials``): which trials are test data
TEST_TRIALS = ("auto", "split", "all")

__all__ = [
    "SPLITS",
    "TEST_TRIALS",
    "TOUCH_SPLIT",
    "TRACK_SPLIT",
    "EvaluatedTrials",
    "choose_test_trials",
    "split_from_names",
    "split_groups",
    "split_names",
    "stored_trial_digests",
    "trial_digests",
]


def _scaled_counts(counts: Sequence[float], n: int) -> np.ndarray:
    """Scale (train, val, test) counts to ``n`` groups by largest remainder; none left empty."""
    c = np.asarray(counts, dtype=np.float64)
    total = float(c.sum())
    if total == float(n) and np.all(c == np.round(c)):
        out = c.astype(np.int64)
    else:
        exact = c * n / total
        out = np.floor(exact).astype(np.int64)
        rest = n - int(out.sum())
        # largest remainders first; ties broken by split order (train, val, test)
        order = np.lexsort((np.arange(3), -(exact - out)))
        out[order[:rest]] += 1
    # an empty split only where the caller asked for zero groups in it
    while np.any((out == 0) & (c > 0)) and out.max() > 1:
        out[int(np.argmax(out))] -= 1
        out[int(np.argmax((out == 0) & (c > 0)))] += 1
    return out


def split_groups(
    n_groups_or_names: int | Sequence[str],
    counts: Sequence[float] = TOUCH_SPLIT,
    *,
    seed: int = 0,
    stratify: Sequence[int] | np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Trial-exclusive train / val / test split of group ids 0..n_groups−1.

    Parameters
    ----------
    n_groups_or_names : int or sequence of str
        Number of groups, or their names (``data.group_names``).
    counts : (3,) numbers
        Groups per split (paper: :data:`TOUCH_SPLIT` 125/32/32, :data:`TRACK_SPLIT` 108/18/20).
        When they do not add up to the number of groups they are scaled proportionally (largest
        remainder rounding), so fractions like (0.7, 0.15, 0.15) work too. A split that would get
        no group takes one from the largest split.
    seed : int
        The split is a deterministic function of (n_groups, counts, seed, stratify).
    stratify : (n_groups,) ints, optional
        A label per group (e.g. ``data.group_region``). Every label gets at least one group in
        train first (where train is large enough), then the remaining groups are spread over the
        splits in proportion, label by label (systematic sampling).

    Returns
    -------
    {"train": ids, "val": ids, "test": ids}: sorted, disjoint int64 arrays covering all groups.

    Raises
    ------
    EctskinError
        Bad counts, fewer groups than non-empty splits, or a wrong-length ``stratify``.
    """
    if isinstance(n_groups_or_names, (int, np.integer)) and not isinstance(n_groups_or_names, bool):
        n = int(n_groups_or_names)
    else:
        try:
            n = len(n_groups_or_names)  # type: ignore[arg-type]
        except TypeError:
            raise EctskinError(
                f"split_groups: expected a number of groups or a list of names, got "
                f"{type(n_groups_or_names).__name__}"
            ) from None
    try:
        c = np.asarray(counts, dtype=np.float64)
    except (TypeError, ValueError):
        raise EctskinError(
            f"split counts must be 3 numbers (train, val, test), got {counts!r}"
        ) from None
    if c.shape != (3,) or not np.all(np.isfinite(c)) or np.any(c < 0) or c.sum() <= 0:
        raise EctskinError(
            f"split counts must be 3 non-negative numbers (train, val, test) with a positive "
            f"sum, got {counts!r}"
        )
    need = int(np.count_nonzero(c))
    if n < need:
        raise EctskinError(
            f"cannot split {n} group(s) (trials) into {need} non-empty splits "
            f"{dict(zip(SPLITS, c.tolist()))}: every split needs at least one trial"
        )
    sizes = _scaled_counts(c, n)
    if np.any((sizes == 0) & (c > 0)):
        raise EctskinError(
            f"split of {n} groups by {counts!r} leaves an empty split: {sizes.tolist()}"
        )
    if c.sum() != n:
        log.info(
            "split: %d groups, counts %s scaled to %s", n, [float(v) for v in c], sizes.tolist()
        )
    rng = np.random.default_rng(seed)
    if stratify is None:
        order = rng.permutation(n)
    else:
        order = _stratified_order(np.asarray(stratify), n, int(sizes[0]), rng)
    bounds = np.cumsum(sizes)
    parts = np.split(order, bounds[:-1])
    return {name: np.sort(p).astype(np.int64) for name, p in zip(SPLITS, parts)}


def _stratified_order(labels: np.ndarray, n: int, n_train: int, rng) -> np.ndarray:
    """An ordering of 0..n−1 such that the first ``n_train`` hold one group of every label (as far
    as they can) and every label is spread evenly along the rest (systematic sampling)."""
    if labels.shape != (n,):
        raise EctskinError(
            f"stratify must hold one label per group ({n}), got shape {labels.shape}"
        )
    strata = np.unique(labels)
    members = {s: rng.permutation(np.flatnonzero(labels == s)) for s in strata}
    firsts = np.array([members[s][0] for s in rng.permutation(strata)], dtype=np.int64)
    if firsts.size > n_train:
        log.warning(
            "split: %d labels but only %d training groups: %d label(s) get no training group",
            firsts.size,
            n_train,
            firsts.size - n_train,
        )
    rest, keys = [], []
    for s in strata:
        m = members[s][1:]
        if m.size:
            # fractional rank inside the label with a random phase: labels interleave evenly
            keys.append((np.arange(m.size) + rng.random()) / m.size)
            rest.append(m)
    if rest:
        rest_a = np.concatenate(rest)
        key = np.concatenate(keys)
        rest_a = rest_a[np.lexsort((rng.random(rest_a.size), key))]
    else:
        rest_a = np.zeros(0, dtype=np.int64)
    return np.concatenate([firsts, rest_a]).astype(np.int64)


def split_names(
    split: Mapping[str, np.ndarray], group_names: Sequence[str]
) -> dict[str, list[str]]:
    """Group ids → group names per split (what ``split.json`` stores)."""
    return {k: [group_names[int(i)] for i in v] for k, v in split.items()}


def split_from_names(
    names: Mapping[str, Sequence[str]], group_names: Sequence[str], *, source: str = "split"
) -> dict[str, np.ndarray]:
    """Re-create a split from the names stored in ``split.json`` (inverse of :func:`split_names`).

    Raises EctskinError for a missing split, a name that is not a group of the data, or a name in
    two splits.
    """
    index = {name: i for i, name in enumerate(group_names)}
    out: dict[str, np.ndarray] = {}
    seen: dict[str, str] = {}
    for k in SPLITS:
        if k not in names:
            raise EctskinError(f"{source}: missing split {k!r} (expected train, val, test)")
        ids = []
        for name in names[k]:
            if name not in index:
                raise EctskinError(
                    f"{source}: {k} trial {name!r} is not in the data ({len(group_names)} trials, "
                    f"e.g. {list(group_names)[:3]})"
                )
            if name in seen:
                raise EctskinError(f"{source}: trial {name!r} is in both {seen[name]} and {k}")
            seen[name] = k
            ids.append(index[name])
        out[k] = np.sort(np.asarray(ids, dtype=np.int64))
    return out


# --------------------------------------------------------------------------- trial digests
def trial_digests(rec: Any) -> dict[str, str]:
    """{trial name: a short hash of its readouts} of a recording: how a run recognises the
    trials it was trained on in any recording, whatever the file or the trials are called."""
    out = {}
    for t in rec.trials:
        a = np.ascontiguousarray(t.capacitance)
        h = hashlib.blake2b(digest_size=12)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
        out[t.name] = h.hexdigest()
    return out


def stored_trial_digests(split: Mapping[str, Any], source: str) -> dict[str, str] | None:
    """``split.json``'s ``trial_digests`` ({name: digest}), checked; None for a run that stores
    none (trained before runs stored them)."""
    digests = split.get("trial_digests")
    if digests is None:
        return None
    if not isinstance(digests, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in digests.items()
    ):
        raise EctskinError(f"{source}: field 'trial_digests' must map trial names to digests")
    return digests


# --------------------------------------------------------------------------- test trials
@dataclass(frozen=True)
class EvaluatedTrials:
    """The test trials of an evaluation (:func:`choose_test_trials`): their ``names`` (recording
    order), the trials ``left_out`` as the run's training or validation trials, the ``reading``
    ("test_split": the run's test split of its own recording; "whole": every trial; "partial":
    the trials other than training ones; "run_split": the run's test split by name), how
    training trials were recognised (``by``: "digests" or "names") and a sentence saying so."""

    names: list[str]
    left_out: list[str]
    reading: str
    by: str
    text: str

    def to_json(self) -> dict[str, Any]:
        return {
            "reading": self.reading,
            "by": self.by,
            "n_trials": len(self.names),
            "n_left_out": len(self.left_out),
            "text": self.text,
        }


def choose_test_trials(
    split: Mapping[str, Any],
    rec: Any,
    mode: str = "auto",
    *,
    source: str = "data",
    split_file: str = "split.json",
    trials: Sequence[str] | None = None,
) -> EvaluatedTrials:
    """Which trials of the recording ``rec`` are test data for a run whose ``split.json`` is
    ``split``, among ``trials`` (the names of the trials the task's data set holds; default all).

    ``mode`` (:data:`TEST_TRIALS`): "auto" leaves out every trial the run was trained or
    validated on: recognised by its readouts where ``split`` stores trial digests
    (:func:`trial_digests`, whatever the trial is called), else by its name; the rest are test
    data: on the training recording the run's test split, on another recording all of it.
    "split": the run's test split by name (every name must be there). "all": every trial
    (refused when some are recognised as training trials). An empty rest is an error naming
    ``source``.
    """
    check_option("test_trials", mode, TEST_TRIALS)
    names = [t.name for t in rec.trials] if trials is None else [str(n) for n in trials]
    seen = split["train"] + split["val"]
    digests = stored_trial_digests(split, split_file)
    if digests is not None:
        by = "digests"
        trained = {digests[n] for n in seen if n in digests}
        mine = trial_digests(rec)
        left_out = [n for n in names if mine[n] in trained]
    else:
        by = "names"
        trained_names = set(seen)
        left_out = [n for n in names if n in trained_names]
    how = (
        "recognised by their readouts"
        if by == "digests"
        else "recognised by name: the run stores no trial digests"
    )
    if mode == "split":
        split_from_names(split, names, source=split_file)  # every name must be there
        test = [n for n in names if n in set(split["test"])]
        text = (
            f"the run's test split by trial name (--test-trials split): {len(test)} of "
            f"{len(names)} trials of {source}"
        )
        others = [n for n in names if n not in set(test)]
        return EvaluatedTrials(test, others, "run_split", by, text)
    if mode == "all":
        if left_out and by == "digests":
            raise EctskinError(
                f"{source}: holds {len(left_out)} trial(s) the run was trained or validated on "
                f"(e.g. {left_out[:3]}, {how}); as test data they would report training "
                "accuracy: use --test-trials auto (they are left out) or split"
            )
        return EvaluatedTrials(
            names, [], "whole", by, f"the whole recording (--test-trials all): {len(names)} trials"
        )
    left = set(left_out)
    if left == set(seen):  # the training recording: its split must name its trials
        split_from_names(split, names, source=split_file)
    test = [n for n in names if n not in left]
    if not test:
        raise EctskinError(
            f"{source}: every trial ({len(names)}) is one the run was trained or validated on "
            f"({how}); nothing to evaluate"
        )
    if not left_out:
        reading = "whole"
        text = (
            f"the whole recording: all {len(names)} trials of {source} (none is one the run "
            f"was trained or validated on, {how})"
        )
        if set(names) == set(seen) | set(split["test"]):
            log.warning(
                "%s holds trials named like the run's, all of them, but with other readouts: it "
                "is evaluated whole, as another recording; if it simulates the same trials again "
                "(e.g. with --push-max 0), --test-trials split evaluates the run's test split",
                source,
            )
    else:
        own = set(test) == set(split["test"])
        reading = "test_split" if own else "partial"
        text = (
            f"{len(test)} of {len(names)} trials of {source} (the {len(left_out)} the run was "
            f"trained or validated on left out, {how})"
        )
        if own:
            text = "the run's test split: " + text
    return EvaluatedTrials(test, left_out, reading, by, text)
