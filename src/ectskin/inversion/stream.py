"""A stream's frames: the previous frame's fingers as this frame's start, and smaller counts
screened where that start explains the frame.

In a stream (the live engine's inversion head) each frame is fitted from the previous frame's
answer (:func:`warm_start`), and the counts are tried from the smallest as in every fit: the
smallest count whose fit explains the frame within the noise (the χ² gate) is the answer, else
the count with the least BIC. When two fingers press, the one-finger fit of each frame starts
from the coarse search and cannot explain the frame: it runs to the optimiser's evaluation
budget (40 evaluations of 50 on average, against some 5 for a warm fit), most of the frame's
time, to be discarded (BENCHMARKS.md, eighteenth session).

So where the warm start of more fingers explains the frame (it passes the gate, its fingers do
not overlap), a smaller count is fitted from the warm fit's strongest fingers (:func:`strongest`,
in place of the coarse search) on :data:`SCREEN_NFEV` evaluations first (:func:`screened`), and
on with the full budget only where that fit converged or came within :data:`SCREEN_FACTOR` times
its gate. If fewer fingers explain the frame (one lifted), the ones left are among the warm
fit's and carry the most signal, so that start is at the answer and a few evaluations bring it
near its gate; else the fit cannot explain the frame from any start. A smaller count can be
the answer only by passing its gate or by a BIC below the warm fit's; with the warm fit within
its gate, the latter asks for a χ² within that gate and the BIC's charge for the parameters it
saves (a few ln n), far below :data:`SCREEN_FACTOR` gates. What this leaves out: a fit that
after its first evaluations is more than that far from its gate and would still come below it
within the remaining budget.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ectskin._check import EctskinError
from ectskin.inversion.model import MODES, StateModel
from ectskin.inversion.result import Fit, InversionResult

#: the evaluations a smaller count's fit gets before it is screened
SCREEN_NFEV = 4
#: a screened fit goes on with the full budget where its χ² is within this many times its gate
SCREEN_FACTOR = 10.0

#: a start: (face index, mode index, (u, v, s)) per finger
Start = list[tuple[int, int, np.ndarray]]


def warm_start(m: StateModel, warm: InversionResult | None) -> Start | None:
    """The fingers of a previous result as a start (face index, mode index, (u, v, s)), or
    None (no result, no finger, or a face or mode this state's model lacks)."""
    if warm is None:
        return None
    if not isinstance(warm, InversionResult):
        raise EctskinError(
            f"Inversion: warm must be the InversionResult of the previous frame or None, got "
            f"{type(warm).__name__}"
        )
    start = []
    for f in warm.fingers:
        mode = "contact" if f.contact else "hover"
        if f.face not in m.faces or mode not in m.modes:
            return None
        s = f.force_n if f.contact else math.log(f.height_mm)
        start.append((m.faces.index(f.face), MODES.index(mode), np.array([f.u_mm, f.v_mm, s])))
    return start or None


def strongest(m: StateModel, fit: Fit, k: int, sigma: np.ndarray) -> Start:
    """The ``k`` fingers of ``fit`` whose signals are the largest in noise units (‖Δ / σ‖, in
    the fit's order): the start of a smaller count's screened fit."""
    if not 0 < k <= len(fit.fingers):
        raise EctskinError(f"strongest: k must be 1..{len(fit.fingers)}, got {k}")
    size = [float(np.linalg.norm(m.signal(m.faces[fi], MODES[mi], x)[0] / sigma))
            for fi, mi, x in fit.fingers]
    keep = sorted(np.argsort(size)[::-1][:k].tolist())
    return [(fit.fingers[j][0], fit.fingers[j][1], fit.fingers[j][2].copy()) for j in keep]


def screened(fit: Callable[..., Fit], m: StateModel, delta: np.ndarray, sigma: np.ndarray,
             start: Start, coupled: bool, gate: Callable[[Fit], float]) -> Fit:
    """The fit of ``start`` (``fit``: :func:`ectskin.inversion.lm.fit_fingers`) on
    :data:`SCREEN_NFEV` evaluations, and from where it stopped on the full budget where it did
    not converge and its χ² is within :data:`SCREEN_FACTOR` times ``gate(fit)`` (module
    docstring)."""
    f = fit(m, delta, sigma, start, coupled, max_nfev=SCREEN_NFEV)
    if f.converged or f.chi2 > SCREEN_FACTOR * gate(f):
        return f
    return fit(m, delta, sigma, f.fingers, coupled)
