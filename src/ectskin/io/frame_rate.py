"""The frame rate of an imported file, checked the same way by every importer.

* :func:`stated_rate`: a rate the file or the caller states (a text such as Motive's
  ``Export Frame Rate,120.000000`` or ``# frame_rate_hz: 30``, a number, a one-element array):
  a finite number > 0, else an error naming the file and the field.
* :func:`frame_rate`: the stated rate, else one over the median of the time steps; a stated rate
  that the time steps contradict by more than 1 % is logged.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from ectskin._check import EctskinError

log = logging.getLogger(__name__)

#: Relative disagreement between a stated rate and the time steps that is logged.
RATE_TOLERANCE = 0.01


def stated_rate(value: Any, where: str) -> float:
    """``value`` as a frame rate in frames/s: a finite number > 0, else an :class:`EctskinError`
    ``"{where} must be a number > 0, got ..."`` (``where`` names the file and the field, e.g.
    ``"take.csv: line 1: Export Frame Rate"``)."""
    try:
        rate = float(np.asarray(value).reshape(())) if np.size(value) == 1 else math.nan
    except (TypeError, ValueError):
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0):
        raise EctskinError(f"{where} must be a number > 0, got {value!r}")
    return rate


def frame_rate(
    stated: float | None, steps: np.ndarray, src: str, *, no_rate: str, what: str = "time steps"
) -> float:
    """The frame rate: ``stated`` (checked by :func:`stated_rate`), else 1 / the median of the
    positive finite ``steps`` (s).

    With neither, the error is ``"{src}: {no_rate}"``. A stated rate that disagrees with the
    steps by more than :data:`RATE_TOLERANCE` is logged as a warning (``what`` names the steps).
    """
    steps = np.asarray(steps, dtype=np.float64)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    measured = 1.0 / float(np.median(steps)) if steps.size else math.nan
    if stated is None:
        if not math.isfinite(measured):
            raise EctskinError(f"{src}: {no_rate}")
        log.info("%s: frame rate %.4g Hz from the median of the %s", src, measured, what)
        return measured
    if math.isfinite(measured) and abs(measured / stated - 1) > RATE_TOLERANCE:
        log.warning(
            "%s: the %s give %.3f frames/s, the stated frame rate is %.3f", src, what, measured,
            stated,
        )
    return float(stated)
