"""The noise a fit weighs its channels by, and the floors that widen it (``model_error``,
``bound_error`` of :class:`~ectskin.inversion.Inversion`; :mod:`ectskin.inversion.model_error`
estimates one)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ectskin._check import EctskinError


def widened_sigma(m: Any, y: np.ndarray, w: int, *floors: tuple[float, float]) -> np.ndarray:
    """The readout noise of state model ``m`` at y (w frames averaged), each floor (a pF, r) of
    ``floors`` added: √(σ² + Σ (a² + (r (y − c_u))²))."""
    s = m.sigma(y, w)
    for a, r in floors:
        if a or r:
            s = np.sqrt(s**2 + a**2 + (r * (y - m.untouched)) ** 2)
    return s


def check_floor(name: str, value: Any) -> tuple[float, float]:
    """(a, r) of an inversion's σ floor ``name``, checked: two finite numbers >= 0."""
    try:
        a, r = (float(x) for x in value)
    except (TypeError, ValueError):
        a = r = math.nan
    if not (a >= 0 and r >= 0 and math.isfinite(a) and math.isfinite(r)):
        raise EctskinError(f"Inversion: {name} must be (pF >= 0, ratio >= 0), got {value!r}")
    return a, r


__all__ = ["check_floor", "widened_sigma"]
