"""What the response field does not model, estimated from the fits' own residuals (no labels).

A fit's residual e = y − ŷ (pF per channel: the frame less the chosen fit's readout,
:attr:`~ectskin.inversion.InversionResult.fitted`) holds the readout's noise σ and all that the
fit's model does not describe: the field's coarser mesh, the person's fingertip beyond its
nuisance columns, the hand beyond its push columns, the interpolation. Where the model were
exact, Σ (e / σ)² per channel would be about 1; on the twin's contact data it is tens.

The variance of a channel is modelled as σ² + a² + (r d)², d = y − c_u (the fingers' signal
and the nuisances', as :class:`~ectskin.inversion.Inversion`'s ``model_error`` floor has it):
a floor a (pF) and a share r of the signal. :func:`ml_model_error` estimates (a, r) by maximum
likelihood over the channels of many frames (the Gaussian log-likelihood of e under that
variance, maximised over ln a and ln r). A fit takes part of each channel's variance out of
its residual, the channel's leverage h (the hat matrix's diagonal at the solution,
:attr:`~ectskin.inversion.InversionResult.leverage`; 17 of 28 parameters on the twin with the
hand's push and the person's finger): e is read as e / √(1 − h), whose variance is the
channel's (exactly so where the weights are the variance's, the regression's HC2
correction); :func:`estimate_model_error` fits the frames with an inversion and estimates it
from their residuals. Readouts only: a recording without ground truth (a real skin) gives it
as well as the twin.

Each channel of each frame counts as one independent draw, which the model error is not (it is
smooth over the skin and repeats between frames of a trial); the estimate is a variance, and
the standard errors built from it (:meth:`~ectskin.inversion.Inversion.with_bound_error`) are
checked by their coverage on labelled frames (the reproduction's ``force.force_coverage_*``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize

from ectskin._check import EctskinError

#: 1 − h is floored here: a channel the fit all but sets tells nothing of its variance
MIN_FREEDOM = 0.05
#: the search's start (a pF, r) and its bounds in ln: a from 1e-9 pF (none) to 1 pF, r from
#: 1e-6 (none) to 1 (the whole signal)
START = (1e-4, 1e-2)
LN_BOUNDS = ((math.log(1e-9), 0.0), (math.log(1e-6), 0.0))


@dataclass(frozen=True)
class ModelError:
    """(a pF, r) of the variance σ² + a² + (r d)² (module docstring), with ``chi2_per_channel``
    of the residuals under the readout noise alone and ``chi2_per_channel_with`` under the
    estimate (about 1 where the model fits), over ``n_frames`` frames of ``n_channels``
    channels in all."""

    a_pf: float
    r: float
    chi2_per_channel: float
    chi2_per_channel_with: float
    n_frames: int
    n_channels: int

    @property
    def floor(self) -> tuple[float, float]:
        """(a, r), the ``model_error`` / ``bound_error`` of an inversion."""
        return (self.a_pf, self.r)

    def to_dict(self) -> dict[str, Any]:
        return {"a_pf": self.a_pf, "r": self.r, "chi2_per_channel": self.chi2_per_channel,
                "chi2_per_channel_with": self.chi2_per_channel_with,
                "n_frames": self.n_frames, "n_channels": self.n_channels}


def ml_model_error(residual: Any, sigma: Any, signal: Any, leverage: Any = None) -> ModelError:
    """The maximum-likelihood (a, r) of residuals ``residual`` (frames, channels) pF, whose
    readout noise is ``sigma`` and signal ``signal`` d (the same shape; NaN: a channel left
    out): e / √(1 − h) ~ N(0, σ² + a² + (r d)²), each channel independent, h the channels'
    ``leverage`` (None: 0; module docstring)."""
    arrays = {}
    h = np.zeros(np.shape(residual)) if leverage is None else leverage
    for name, value in (("residual", residual), ("sigma", sigma), ("signal", signal),
                        ("leverage", h)):
        a = np.asarray(value, dtype=np.float64)
        if a.ndim != 2:
            raise EctskinError(f"ml_model_error: {name} must be (frames, channels), got shape "
                               f"{a.shape}")
        arrays[name] = a
    e, s, d, h = (arrays[k] for k in ("residual", "sigma", "signal", "leverage"))
    if not (e.shape == s.shape == d.shape == h.shape):
        raise EctskinError(f"ml_model_error: residual, sigma, signal and leverage must have one "
                           f"shape, got {e.shape}, {s.shape}, {d.shape} and {h.shape}")
    ok = np.isfinite(e) & np.isfinite(s) & np.isfinite(d) & np.isfinite(h)
    if (s[ok] <= 0).any():
        raise EctskinError("ml_model_error: sigma must be > 0 on every channel used")
    if ((h[ok] < 0) | (h[ok] > 1)).any():
        raise EctskinError("ml_model_error: leverage must lie in [0, 1]")
    rows = ok.any(axis=1)
    if not rows.any():
        raise EctskinError("ml_model_error: no finite channel to estimate from")
    e2 = e[ok] ** 2 / np.maximum(1.0 - h[ok], MIN_FREEDOM)
    s2, d2 = s[ok] ** 2, d[ok] ** 2

    def nll(p: np.ndarray) -> tuple[float, np.ndarray]:
        a2, r2 = np.exp(2 * p)
        v = s2 + a2 + r2 * d2
        q = e2 / v
        # d nll / d ln a = sum (1 − q) a² / v, and likewise for r with r² d²
        g = 1.0 - q
        return (0.5 * float(np.sum(q + np.log(v))),
                np.array([float(np.sum(g * a2 / v)), float(np.sum(g * r2 * d2 / v))]))

    best = minimize(nll, np.log(START), jac=True, method="L-BFGS-B", bounds=LN_BOUNDS)
    a_pf, r = (float(x) for x in np.exp(best.x))
    return ModelError(
        a_pf=a_pf, r=r, chi2_per_channel=float(np.mean(e2 / s2)),
        chi2_per_channel_with=float(np.mean(e2 / (s2 + a_pf * a_pf + r * r * d2))),
        n_frames=int(rows.sum()), n_channels=int(ok.sum()),
    )


def residuals(inversion: Any, readouts: Any, states: Any, results: Sequence[Any],
              kind: str = "absolute") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(residual, σ, d, h) (frames, channels) of ``results``, the fits of ``readouts``
    (frames, channels) pF at ``states`` (one state, or one per frame) by ``inversion``, one
    frame each (window 1; ``kind``: "absolute" or "difference" readouts, as the fits had them):
    y − fitted, the readout noise at y, y − c_u (pF) and the fit's leverage."""
    y = np.asarray(readouts, dtype=np.float64)
    if y.ndim != 2:
        raise EctskinError(f"residuals: readouts must be (frames, channels), got shape {y.shape}")
    st = np.atleast_1d(np.asarray(states, dtype=np.float64))
    st = np.broadcast_to(st, (y.shape[0], st.size)) if st.ndim == 1 else st
    if st.ndim != 2:
        raise EctskinError(f"residuals: states must be one inflation state or one per frame "
                           f"(frames, chambers), got shape {st.shape}")
    if st.shape[0] != y.shape[0] or len(results) != y.shape[0]:
        raise EctskinError(f"residuals: {y.shape[0]} frames, {st.shape[0]} states and "
                           f"{len(results)} results: one of each per frame")
    e, s, d, h = (np.full(y.shape, np.nan) for _ in range(4))
    for i, res in enumerate(results):
        fitted = np.asarray(res.fitted, dtype=np.float64)
        hat = np.asarray(res.leverage, dtype=np.float64)
        if fitted.shape != (y.shape[1],) or hat.shape != (y.shape[1],):
            raise EctskinError(f"residuals: result {i} holds no fitted readout and leverage of "
                               f"{y.shape[1]} channels (got shapes {fitted.shape}, {hat.shape})")
        m = inversion.model(tuple(st[i]))
        obs, _ = inversion.observed(y[i], tuple(st[i]), kind)
        e[i] = obs - fitted
        s[i] = m.sigma(obs, 1)
        d[i] = obs - m.untouched
        h[i] = hat
    return e, s, d, h


def estimate_model_error(inversion: Any, readouts: Any, states: Any,
                         results: Sequence[Any] | None = None, **fit_kw: Any) -> ModelError:
    """(a, r) of ``inversion``'s model error on ``readouts`` (frames, channels) pF at
    ``states``: :func:`ml_model_error` of the residuals of ``results`` (their fits; None: fitted
    here, :func:`~ectskin.inversion.fit_frames` with ``fit_kw``). Every frame counts, touched
    or not: the floor a is what the untouched frames leave."""
    if results is None:
        from ectskin.inversion.frames import fit_frames

        results, _ = fit_frames(inversion, readouts, states, **fit_kw)
    return ml_model_error(*residuals(inversion, readouts, states, results))


class RunningModelError:
    """The model error of a stream's fits, learnt as the frames come (no labels): the residuals
    (:func:`residuals`) of the last ``window`` frames given to :meth:`add`, estimated
    (:func:`ml_model_error`) once ``first`` frames have come and again after every ``every``
    more; :attr:`estimate` is the latest (None before the first).

    A live session's standard errors carry it (``ectskin live --inversion-bound-error
    session``): its own skin, person and hand, whatever the field's mesh leaves. The window
    follows a skin that drifts or a hand that changes; each estimate is a few ms."""

    def __init__(self, first: int = 100, every: int = 100, window: int = 1000) -> None:
        for name, v in (("first", first), ("every", every), ("window", window)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise EctskinError(f"RunningModelError: {name} must be an integer >= 1 (frames), "
                                   f"got {v!r}")
        if window < first:
            raise EctskinError(f"RunningModelError: window ({window}) must hold the first "
                               f"estimate's {first} frames")
        self.first, self.every, self.window = first, every, window
        self._rows: deque[np.ndarray] = deque(maxlen=window)
        self._since = 0
        self.n_added = 0
        self.estimate: ModelError | None = None

    def add(self, residual: Any, sigma: Any, signal: Any, leverage: Any) -> bool:
        """One frame's (residual, σ, d, h) (channels,) (:func:`residuals`' rows; NaN: a channel
        left out); whether it made a new :attr:`estimate`."""
        parts = [np.asarray(x, dtype=np.float64) for x in (residual, sigma, signal, leverage)]
        want = (self._rows[0].shape[1],) if self._rows else parts[0].shape
        if len(want) != 1 or any(x.shape != want for x in parts):
            raise EctskinError(f"RunningModelError.add: residual, sigma, signal and leverage must "
                               f"each be one frame's channels {want}, got shapes "
                               f"{[x.shape for x in parts]}")
        self._rows.append(np.stack(parts))
        self.n_added += 1
        self._since += 1
        if self._since < (self.every if self.estimate is not None else self.first):
            return False
        stack = np.stack(self._rows, axis=1)  # (4, frames, channels)
        if not np.isfinite(stack).all(axis=0).any():
            return False  # every channel masked so far: the next frames may bring some
        self.estimate = ml_model_error(*stack)
        self._since = 0
        return True

    def reset(self) -> None:
        """Forget every frame and the estimate (another skin, another session)."""
        self._rows.clear()
        self._since = self.n_added = 0
        self.estimate = None


__all__ = ["ModelError", "RunningModelError", "estimate_model_error", "ml_model_error",
           "residuals"]
