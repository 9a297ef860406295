"""The inversion step's standard errors with the field's model error (``bound_error``).

The readout noise alone leaves the field's own model error out of the inversion's standard
errors (its coarser mesh, the person's fingertip, the hand), so a force's standard error would
cover a fraction of its errors. With ``bound_error="validation"`` (the default of
:func:`~ectskin.pipeline.inversion.inversion_step`) the inversion chosen is fitted to up to
:data:`MODEL_ERROR_FRAMES` frames of the validation trials (every frame, spread as the test
frames), the maximum-likelihood floor (a, r) of their residuals is estimated
(:func:`ectskin.inversion.estimate_model_error`: readouts only, no labels), and the test frames'
points', forces' and heights' standard errors carry it
(:meth:`~ectskin.inversion.Inversion.with_bound_error`; the fits are unchanged). The step's
``force_observable`` (force standard error below 0.1 N) is then where force can be known
through this field, and ``force.force_coverage_*`` says how far the standard errors hold.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin.inversion import Inversion, estimate_model_error, fit_frames
from ectskin.io import Recording
from ectskin.learn.data.contact import ContactData

#: validation frames (at most, evenly spread, every count) whose fits' residuals estimate the
#: field's model error
MODEL_ERROR_FRAMES = 300
#: where the standard errors' model error comes from (module docstring)
BOUND_ERROR_CHOICES = ("validation", "off")


def rows_frames(rec: Recording, data: ContactData, rows: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The readouts (rows, n_pairs) pF of the frames ``rows`` of ``data`` (samples of ``rec``'s
    trials, sorted by trial) and each one's inflation state."""
    readouts, states = [], []
    for g in np.unique(data.group[rows]):
        t = rec.trial(data.group_names[g])
        frames = data.frame[rows[data.group[rows] == g]]
        readouts.append(t.capacitance[frames])
        states.append(np.broadcast_to(np.asarray(t.inflation, np.float64), (frames.size,
                                                                             len(t.inflation))))
    return np.concatenate(readouts), np.concatenate(states)


def with_model_error(inv: Inversion, rec: Recording, data: ContactData | None,
                     rows: np.ndarray | None, workers: int = 1, person: bool = False
                     ) -> tuple[Inversion, dict[str, Any]]:
    """``inv`` with the standard errors' model error estimated from its fits of the frames
    ``rows`` of ``data`` (validation frames; readouts only), and what was estimated
    (``source``, :meth:`~ectskin.inversion.ModelError.to_dict`); ``inv`` itself where there is
    no frame. ``person``: each trial's frames pool the finger, as the step fits them."""
    if data is None or rows is None or rows.size == 0:
        return inv, {"source": None, "why": "no validation frame in a field state"}
    readouts, states = rows_frames(rec, data, rows)
    results, _ = fit_frames(inv, readouts, states, workers=workers,
                            person=data.group[rows].tolist() if person else None)
    est = estimate_model_error(inv, readouts, states, results)
    return inv.with_bound_error(est.floor), {"source": "validation", **est.to_dict()}


__all__ = ["BOUND_ERROR_CHOICES", "MODEL_ERROR_FRAMES", "rows_frames", "with_model_error"]
