"""How the report writes values: nested look-up, percentages, millimetres, counts, durations and
baseline names, with "—" for anything missing."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

BASELINE_NAMES = {
    "majority": "majority class",
    "logistic": "logistic regression",
    "logreg": "logistic regression",
    "random_forest": "random forest",
    "knn": "k-NN",
    "no_motion": "markers do not move",
    "ridge": "ridge regression",
}

DASH = "—"


def lookup(d: Any, path: str, default: Any = None) -> Any:
    """``lookup(m, "track.baselines.no_motion.ad_mm_mean")``: nested lookup, ``default`` if absent."""
    cur = d
    for key in path.split("."):
        if not isinstance(cur, Mapping) or key not in cur or cur[key] is None:
            return default
        cur = cur[key]
    return cur


def pct(x: Any, digits: int = 2) -> str:
    return DASH if x is None else f"{100.0 * float(x):.{digits}f} %"


def mm(mean: Any, std: Any = None) -> str:
    if mean is None:
        return DASH
    return (
        f"{float(mean):.3f} ± {float(std):.3f} mm" if std is not None else f"{float(mean):.3f} mm"
    )


def count(n_wrong: Any, n_total: Any) -> str:
    if n_wrong is None or n_total is None:
        return DASH
    return f"{int(n_wrong):,} of {int(n_total):,}".replace(",", " ")


def duration(seconds: Any) -> str:
    if seconds is None:
        return DASH
    s = float(seconds)
    if s < 120:
        return f"{s:.1f} s"
    if s < 7200:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.2f} h"


def baseline_name(key: str) -> str:
    return BASELINE_NAMES.get(key, key.replace("_", " "))
