"""What the baselines of every task share: :func:`subsample` of the training samples."""

from __future__ import annotations

import numpy as np

__all__ = ["subsample"]


def subsample(n: int, max_n: int | None, rng: np.random.Generator) -> np.ndarray:
    """Sorted indices of at most ``max_n`` of ``n`` samples drawn with ``rng`` without
    replacement (all of them, in order, when ``max_n`` is None or at least ``n``)."""
    if max_n is None or n <= max_n:
        return np.arange(n)
    return np.sort(rng.choice(n, size=max_n, replace=False))
