"""Deformation-tracking test metrics of the paper, pure functions on plain arrays (numpy only).

:func:`marker_distances`, :func:`average_distance` and :func:`track_metrics`: the average distance
AD of Eq. 3 (mean ± std over test samples and markers), per marker, per trajectory and the worst
trajectory.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array

__all__ = ["average_distance", "marker_distances", "track_metrics"]


def marker_distances(pred: Any, true: Any) -> np.ndarray:
    """Euclidean distance per sample and marker, ||p_ij − p̂_ij|| of Eq. 3, shape (N, M), mm.

    ``pred`` and ``true`` are (N, M, 3) marker coordinates in mm (the same shape).
    """
    p = check_array("pred", pred, (None, None, 3))
    t = check_array("true", true, p.shape)
    if not np.all(np.isfinite(t)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(t))[0])
        raise EctskinError(
            f"true marker coordinates must be finite (occluded frames are not tracking test "
            f"samples); found {t[bad]} at sample {bad[0]}, marker {bad[1]}"
        )
    if not np.all(np.isfinite(p)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(p))[0])
        raise EctskinError(
            f"predicted marker coordinates are not finite: {p[bad]} at sample {bad[0]}, "
            f"marker {bad[1]}"
        )
    return np.linalg.norm(p - t, axis=-1)


def average_distance(pred: Any, true: Any) -> tuple[float, float]:
    """The paper's average distance AD (Eq. 3) and its standard deviation, mm.

    AD = 1/(N M) Σ_i Σ_j ||p_ij − p̂_ij||  (Eq. 3), over N samples and M markers; the std is
    the population standard deviation of the same N·M distances (the paper's "2.905 ± 2.207 mm").

    Parameters
    ----------
    pred, true : (N, M, 3) array
        Estimated and ground-truth marker coordinates, mm.
    """
    d = marker_distances(pred, true)
    if d.size == 0:
        raise EctskinError("average_distance: no samples (N·M = 0)")
    return float(d.mean()), float(d.std())


def track_metrics(
    pred: Any,
    true: Any,
    *,
    group: Any = None,
    group_names: Sequence[str] | None = None,
    marker_names: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Tracking metrics of a test set: AD (Eq. 3) overall, per marker and per trajectory.

    Parameters
    ----------
    pred, true : (N, M, 3) array
        Estimated and true marker coordinates, mm.
    group : (N,) int, optional
        Trajectory (trial) index of each sample; ``group_names`` names them.
    marker_names : list of str, optional
        Names of the M markers (default ``M1``…).

    Returns
    -------
    dict
        ``ad_mm_mean``, ``ad_mm_std`` (Eq. 3 over all samples and markers), ``ad_mm_median``,
        ``ad_mm_p95``, ``ad_mm_max``, ``n_test_samples``, ``n_markers``, ``per_marker`` ({name:
        {ad_mm_mean, ad_mm_std}}), and with ``group``: ``n_test_trajectories``, ``per_trajectory``
        (list of {name, n_samples, ad_mm_mean, ad_mm_std}) and ``worst_trajectory``.
    """
    d = marker_distances(pred, true)  # (N, M)
    n, m = d.shape
    if n == 0:
        raise EctskinError("track_metrics: the test set is empty (0 samples)")
    names = list(marker_names) if marker_names is not None else [f"M{k + 1}" for k in range(m)]
    if len(names) != m:
        raise EctskinError(f"marker_names has {len(names)} names for {m} markers")
    out: dict[str, Any] = {
        "ad_mm_mean": float(d.mean()),
        "ad_mm_std": float(d.std()),
        "ad_mm_median": float(np.median(d)),
        "ad_mm_p95": float(np.percentile(d, 95)),
        "ad_mm_max": float(d.max()),
        "n_test_samples": int(n),
        "n_markers": int(m),
        "per_marker": {
            name: {"ad_mm_mean": float(d[:, k].mean()), "ad_mm_std": float(d[:, k].std())}
            for k, name in enumerate(names)
        },
    }
    if group is not None:
        g = check_array("group", group, (n,), dtype=np.int64)
        trajs = []
        for gid in np.unique(g):
            dg = d[g == gid]
            trajs.append(
                {
                    "name": group_names[gid] if group_names is not None else str(int(gid)),
                    "n_samples": int(dg.shape[0]),
                    "ad_mm_mean": float(dg.mean()),
                    "ad_mm_std": float(dg.std()),
                }
            )
        out["n_test_trajectories"] = len(trajs)
        out["per_trajectory"] = trajs
        out["worst_trajectory"] = max(trajs, key=lambda t: t["ad_mm_mean"])
    return out
