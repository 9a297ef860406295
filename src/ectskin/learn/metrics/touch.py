"""Touch-recognition test metrics of the paper, pure functions on plain arrays (numpy only).

:func:`confusion_matrix`, :func:`region_adjacency` and :func:`touch_metrics`: accuracy, the
misclassified-frame count in the paper's "34 of 28 800" form (:func:`format_count`), the
n_classes × n_classes confusion map (Fig. 7) and which confusions are between adjacent regions.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array

__all__ = ["confusion_matrix", "format_count", "region_adjacency", "touch_metrics"]


def format_count(n_wrong: int, n_total: int) -> str:
    """The paper's wording of a misclassification count, e.g. ``"34 of 28 800"``.

    Thousands are separated by a space as in the paper (thin-space free, plain ASCII space).
    """
    return f"{int(n_wrong):,} of {int(n_total):,}".replace(",", " ")


def confusion_matrix(y_true: Any, y_pred: Any, n_classes: int) -> np.ndarray:
    """Counts of (true class, predicted class), shape (n_classes, n_classes) int64.

    Row ``i`` holds the frames whose true class is ``i``; column ``j`` those predicted as ``j``
    (the layout of the paper's Fig. 7). Class 0 is "no touch".
    """
    yt = check_array("y_true", y_true, (None,), dtype=np.int64)
    yp = check_array("y_pred", y_pred, (yt.shape[0],), dtype=np.int64)
    for name, y in (("y_true", yt), ("y_pred", yp)):
        bad = (y < 0) | (y >= n_classes)
        if bad.any():
            k = int(np.argmax(bad))
            raise EctskinError(
                f"{name}[{k}] = {y[k]} is not a class of 0..{n_classes - 1} (n_classes={n_classes})"
            )
    conf = np.zeros((n_classes, n_classes), dtype=np.int64)
    np.add.at(conf, (yt, yp), 1)
    return conf


def region_adjacency(layout: Any, *, corners: bool = False, tol_mm: float = 0.01) -> np.ndarray:
    """Which touch classes are adjacent regions, shape (n_classes, n_classes) bool.

    Two regions are adjacent when they lie on the same surface and their rectangles share a
    border segment of positive length (``corners=True`` also counts rectangles that meet at a
    corner only). Class 0 ("no touch") is adjacent to nothing; the diagonal is False.
    ``tol_mm`` absorbs rounding in the layout file (region borders like -6.6667 mm).
    """
    n = layout.n_classes
    adj = np.zeros((n, n), dtype=bool)
    regions = list(layout.regions)
    for a in regions:
        for b in regions:
            if a.id == b.id or a.surface != b.surface:
                continue
            # gap (> 0: apart) and overlap length (> 0: overlapping) along each axis
            du = max(a.u_mm[0], b.u_mm[0]) - min(a.u_mm[1], b.u_mm[1])
            dv = max(a.v_mm[0], b.v_mm[0]) - min(a.v_mm[1], b.v_mm[1])
            if du > tol_mm or dv > tol_mm:
                continue  # apart along one axis
            touch_u, touch_v = abs(du) <= tol_mm, abs(dv) <= tol_mm
            if touch_u and touch_v:
                adj[a.id, b.id] = corners  # meet at a corner only
            elif touch_u or touch_v:
                adj[a.id, b.id] = True  # share a border segment of positive length
            # else the rectangles overlap: not a layout the checks admit; leave False
    return adj


def touch_metrics(
    y_true: Any,
    y_pred: Any,
    n_classes: int,
    *,
    adjacency: np.ndarray | None = None,
    group: Any = None,
    group_names: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Touch-recognition metrics of a test set.

    Parameters
    ----------
    y_true, y_pred : (n,) int
        True and predicted class per frame (0 = no touch).
    n_classes : int
        Number of classes (19 in the paper).
    adjacency : (n_classes, n_classes) bool, optional
        From :func:`region_adjacency`; marks each confusion as between adjacent regions or not.
    group, group_names : (n,) int and list of str, optional
        Trial of each frame, for the per-trial accuracy and the worst trial.

    Returns
    -------
    dict
        ``accuracy`` (fraction), ``n_test_frames``, ``n_misclassified``, ``misclassified``
        ("34 of 28 800"), ``confusion`` (nested lists, rows = true class), ``per_class_accuracy``
        (None for a class absent from the test set), ``confusions`` (list of {true, pred, count,
        adjacent} sorted by count), ``n_misclassified_adjacent`` and ``all_adjacent`` (when
        ``adjacency`` is given), ``per_trial`` / ``worst_trial`` (when ``group`` is given).
    """
    conf = confusion_matrix(y_true, y_pred, n_classes)
    n = int(conf.sum())
    if n == 0:
        raise EctskinError("touch_metrics: the test set is empty (0 frames)")
    correct = int(np.trace(conf))
    support = conf.sum(axis=1)
    per_class = [(float(conf[k, k] / support[k]) if support[k] else None) for k in range(n_classes)]
    off = [(int(i), int(j), int(conf[i, j])) for i, j in zip(*np.nonzero(conf)) if i != j]
    off.sort(key=lambda t: (-t[2], t[0], t[1]))
    confusions = []
    for i, j, c in off:
        item: dict[str, Any] = {"true": i, "pred": j, "count": c}
        if adjacency is not None:
            item["adjacent"] = bool(adjacency[i, j])
        confusions.append(item)
    out: dict[str, Any] = {
        "accuracy": correct / n,
        "n_test_frames": n,
        "n_misclassified": n - correct,
        "misclassified": format_count(n - correct, n),
        "n_classes": int(n_classes),
        "confusion": conf.tolist(),
        "per_class_accuracy": per_class,
        "confusions": confusions,
    }
    if adjacency is not None:
        adjacency = np.asarray(adjacency, dtype=bool)
        if adjacency.shape != (n_classes, n_classes):
            raise EctskinError(
                f"adjacency must have shape ({n_classes}, {n_classes}), got {adjacency.shape}"
            )
        n_adj = int(conf[adjacency].sum())
        out["n_misclassified_adjacent"] = n_adj
        out["all_adjacent"] = n_adj == n - correct
    if group is not None:
        g = check_array("group", group, (n,), dtype=np.int64)
        yt = np.asarray(y_true, dtype=np.int64)
        ok = yt == np.asarray(y_pred, dtype=np.int64)
        trials = []
        for gid in np.unique(g):
            sel = g == gid
            name = group_names[gid] if group_names is not None else str(int(gid))
            trials.append(
                {
                    "name": name,
                    "label": int(np.bincount(yt[sel]).argmax()),
                    "n_frames": int(sel.sum()),
                    "accuracy": float(ok[sel].mean()),
                }
            )
        out["per_trial"] = trials
        out["worst_trial"] = min(trials, key=lambda t: t["accuracy"])
    return out
