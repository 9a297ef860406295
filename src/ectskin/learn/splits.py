"""Trial-exclusive train / val / test splits of a data set's groups (trials).

* :func:`split_groups`: the split of group ids (paper: :data:`TOUCH_SPLIT` 125/32/32 touch
  trials, :data:`TRACK_SPLIT` 108/18/20 tracking trials), scaled to recordings of other sizes,
  optionally stratified by a label per group.
* :func:`split_names` / :func:`split_from_names`: group ids ↔ the trial names that
  ``split.json`` stores.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np

from ectskin._check import EctskinError

log = logging.getLogger(__name__)

#: Paper §3: touch data 189 trials split 125 / 32 / 32 (train / val / test).
TOUCH_SPLIT = (125, 32, 32)
#: Paper §3: tracking data 146 trials split 108 / 18 / 20.
TRACK_SPLIT = (108, 18, 20)
SPLITS = ("train", "val", "test")

__all__ = [
    "SPLITS",
    "TOUCH_SPLIT",
    "TRACK_SPLIT",
    "split_from_names",
    "split_groups",
    "split_names",
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
