"""Estimate the constant delay between a readout and a motion-capture take, and resample the
markers onto the readout frames once it is known.

Convention: ``delay_s > 0`` means the markers lag, i.e. what the readout sees at time t the markers
show at t + delay_s. :func:`resample_markers` therefore samples the marker trajectories at
``frame_t + delay_s``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError, check_array, check_option
from ectskin.io.align.signals import (
    capacitance_energy,
    interp_linear,
    lagged_fit,
    marker_speed,
    moving_average,
    normalised_xcorr,
    standardised_channels,
)

log = logging.getLogger(__name__)

#: Below this :attr:`DelayEstimate.contrast` the estimate is logged as weak.
WEAK_CONTRAST = 0.2
#: Largest common grid :func:`estimate_delay` builds (samples), to refuse absurd grid steps.
MAX_GRID_SAMPLES = 2_000_000


@dataclass(frozen=True)
class DelayEstimate:
    """Result of :func:`estimate_delay`.

    ``delay_s``: markers lag the readout by this much (s; negative: they lead). ``score``: the
    method's score at the integer-step peak: for ``"regression"`` the pooled multiple correlation
    R (0…1) of the markers fitted from the readouts, for ``"energy"`` the Pearson r (-1…1) of the
    two motion-energy signals. ``at_bound``: the peak lies at ±max_delay_s, so the true delay may
    be larger. ``contrast``: how much the best lag beats the worst one, (s²_max - s²_min) /
    (1 - s²_min) with s the score (0…1): near 0 when the fit hardly depends on the lag (markers
    that barely move), which makes the delay unreliable. ``lags_s``/``scores``: the whole score
    curve (for plots and checks).
    """

    delay_s: float
    score: float
    contrast: float
    method: str
    grid_dt_s: float
    at_bound: bool
    n_overlap: int
    lags_s: np.ndarray
    scores: np.ndarray


def _median_dt(t: np.ndarray, name: str) -> float:
    if len(t) < 3:
        raise EctskinError(f"{name} needs at least 3 samples to estimate a delay, got {len(t)}")
    return float(np.median(np.diff(t)))


def _check_increasing(name: str, t: np.ndarray) -> None:
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise EctskinError(f"{name} must increase; sample {k} has {t[k]} after {t[k - 1]}")


def estimate_delay(
    cap_t: np.ndarray,
    cap_values: np.ndarray,
    mocap_t: np.ndarray,
    mocap_pos: np.ndarray,
    *,
    max_delay_s: float,
    grid_dt_s: float | None = None,
    smooth_s: float = 0.2,
    method: str = "regression",
) -> DelayEstimate:
    """Estimate the constant delay between the readout and the markers from their motion.

    Parameters
    ----------
    cap_t : (n_frames,) s, increasing. cap_values : (n_frames, n_channels) pF, NaN allowed.
    mocap_t : (n_samples,) s, increasing. mocap_pos : (n_samples, n_markers, 3) mm, NaN allowed.
    max_delay_s : search the delay in [-max_delay_s, +max_delay_s].
    grid_dt_s : step of the common grid; default the readout's median frame interval (the
        parabolic refinement resolves a fraction of a step).
    smooth_s : width (s) of the centred moving average applied to both signals: a low-pass that
        keeps the motion (a touch lasts ~1 s) and removes sample noise. Symmetric, so it does not
        shift the lag.
    method : ``"regression"`` (default): for every lag, a linear fit of the marker coordinates
        from the standardised readout channels (:func:`lagged_fit`); the score is the pooled
        multiple correlation R. ``"energy"``: Pearson correlation of the motion-energy signals
        (:func:`capacitance_energy`, :func:`marker_speed`). The regression uses the sign and size
        of every channel's response; the energy needs no linear relation at all
        (docs/instrument-import.md compares the two).

    Both clocks must be on the same time axis (e.g. each counted from its first sample when the
    devices were started together). Both recordings are resampled onto one grid and compared at
    every integer grid lag within ±max_delay_s; the best lag is refined to a fraction of a step
    by the vertex of the parabola through the peak score and its two neighbours. Positive
    ``delay_s``: the markers lag.
    """
    check_option("method", method, ("regression", "energy"))
    cap_t = check_array("cap_t", cap_t, (None,), finite=True)
    cap_values = check_array("cap_values", cap_values, (len(cap_t), None))
    mocap_t = check_array("mocap_t", mocap_t, (None,), finite=True)
    mocap_pos = check_array("mocap_pos", mocap_pos, (len(mocap_t), None, 3))
    if not (np.isfinite(max_delay_s) and max_delay_s > 0):
        raise EctskinError(f"max_delay_s must be > 0, got {max_delay_s!r}")
    _check_increasing("cap_t", cap_t)
    _check_increasing("mocap_t", mocap_t)
    grid, dt = _common_grid(cap_t, mocap_t, grid_dt_s)
    smooth = max(1, round(smooth_s / dt))
    max_lag = max(1, int(np.floor(max_delay_s / dt + 1e-9)))
    sig_cap, sig_mk, min_overlap = _signals(
        method, grid, cap_t, cap_values, mocap_t, mocap_pos, smooth
    )
    if method == "energy":
        lags, r, counts = normalised_xcorr(sig_cap, sig_mk, max_lag, min_overlap)
    else:
        lags, r, counts = lagged_fit(sig_cap, sig_mk, max_lag, min_overlap)
    if not np.isfinite(r).any():
        raise EctskinError(
            f"the readout and marker recordings overlap by fewer than {min_overlap} samples at "
            f"every lag within ±{max_delay_s} s (or one of them does not move); cannot estimate "
            f"the delay"
        )
    k, frac, contrast = _peak(r)
    est = DelayEstimate(
        delay_s=float((lags[k] + frac) * dt),
        score=float(r[k]),
        contrast=contrast,
        method=method,
        grid_dt_s=float(dt),
        at_bound=bool(k in (0, len(r) - 1)),
        n_overlap=int(counts[k]),
        lags_s=lags * dt,
        scores=r,
    )
    _log_estimate(est, max_delay_s)
    return est


def _common_grid(
    cap_t: np.ndarray, mocap_t: np.ndarray, grid_dt_s: float | None
) -> tuple[np.ndarray, float]:
    """The grid (step ``grid_dt_s``, default the readout's median step) spanning both clocks."""
    _median_dt(mocap_t, "mocap_t")
    dt = grid_dt_s or _median_dt(cap_t, "cap_t")
    if not (np.isfinite(dt) and dt > 0):
        raise EctskinError(f"grid_dt_s must be > 0, got {dt!r}")
    t0 = min(cap_t[0], mocap_t[0])
    t1 = max(cap_t[-1], mocap_t[-1])
    n_grid = int(np.floor((t1 - t0) / dt)) + 1
    if n_grid > MAX_GRID_SAMPLES:
        raise EctskinError(
            f"the common grid would hold {n_grid} samples (span {t1 - t0:.1f} s at {dt:g} s); "
            f"are both clocks on the same time axis? (clock offsets are removed with "
            f"clock='start' in build_recording)"
        )
    return t0 + dt * np.arange(n_grid), dt


def _signals(
    method: str,
    grid: np.ndarray,
    cap_t: np.ndarray,
    cap_values: np.ndarray,
    mocap_t: np.ndarray,
    mocap_pos: np.ndarray,
    smooth: int,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Both signals of ``method`` on the grid and the overlap (samples) a lag needs to count."""
    if method == "energy":
        sig_cap = capacitance_energy(grid, cap_t, cap_values, smooth)
        sig_mk = marker_speed(grid, mocap_t, mocap_pos, smooth)
        cap_ok, mk_ok = np.isfinite(sig_cap), np.isfinite(sig_mk)
    else:
        sig_cap = standardised_channels(grid, cap_t, cap_values, smooth)
        pos = interp_linear(mocap_t, mocap_pos, grid)  # (n_grid, n_markers, 3)
        sig_mk = np.apply_along_axis(moving_average, 0, pos, smooth)
        cap_ok = np.isfinite(sig_cap).all(axis=1) & (sig_cap.shape[1] > 0)
        mk_ok = np.isfinite(sig_mk).all(axis=2).any(axis=1)
    if not cap_ok.any():
        raise EctskinError(
            "the capacitance readouts never change (or are all masked); "
            "cannot estimate the delay; pass the delay explicitly"
        )
    if not mk_ok.any():
        raise EctskinError(
            "no marker is visible long enough to measure its motion; cannot "
            "estimate the delay; pass the delay explicitly"
        )
    min_overlap = max(8, min(int(cap_ok.sum()), int(mk_ok.sum())) // 4)
    return sig_cap, sig_mk, min_overlap


def _peak(r: np.ndarray) -> tuple[int, float, float]:
    """Index of the best score, its parabolic refinement (-0.5…0.5 steps) and the contrast."""
    k = int(np.nanargmax(r))
    frac = 0.0
    if 0 < k < len(r) - 1 and np.isfinite(r[k - 1]) and np.isfinite(r[k + 1]):
        den = r[k - 1] - 2.0 * r[k] + r[k + 1]
        if den < 0:  # vertex of the parabola through (-1, r[k-1]), (0, r[k]), (1, r[k+1])
            frac = float(np.clip(0.5 * (r[k - 1] - r[k + 1]) / den, -0.5, 0.5))
    s2 = np.clip(r, 0.0, 1.0) ** 2
    lo = float(np.nanmin(s2))
    contrast = (float(s2[k]) - lo) / (1.0 - lo) if lo < 1.0 else 0.0
    return k, frac, contrast


def _log_estimate(est: DelayEstimate, max_delay_s: float) -> None:
    if est.at_bound:
        log.warning(
            "delay estimate %.4f s lies at the search bound ±%.3f s; the true delay may be larger "
            "(raise max_delay_s)",
            est.delay_s,
            max_delay_s,
        )
    if est.contrast < WEAK_CONTRAST:
        log.warning(
            "weak delay estimate %.4f s: the %s score hardly depends on the lag (contrast %.3f, "
            "score %.3f); do the markers move? check it or pass the delay explicitly",
            est.delay_s,
            est.method,
            est.contrast,
            est.score,
        )
    log.info(
        "estimated delay %.4f s (markers lag when > 0), %s score %.3f",
        est.delay_s,
        est.method,
        est.score,
    )


def resample_markers(
    mocap_t: np.ndarray,
    mocap_pos: np.ndarray,
    frame_t: np.ndarray,
    delay_s: float,
    *,
    max_gap_frames: int = 1,
) -> np.ndarray:
    """Marker positions at the readout frames, after removing the delay.

    Parameters
    ----------
    mocap_t : (n_samples,) s, increasing. mocap_pos : (n_samples, n_markers, 3) mm, NaN = occluded.
    frame_t : (n_frames,) s, the readout frames on the same time axis.
    delay_s : markers lag by this much; marker m at frame f is sampled at ``frame_t[f] + delay_s``.
    max_gap_frames : linear interpolation may bridge at most this many occluded motion-capture
        samples between two visible ones (0: never bridge an occlusion).

    Returns
    -------
    (n_frames, n_markers, 3) mm, linear interpolation between the visible samples around each
    time; NaN where the gap around it is longer than ``max_gap_frames`` samples or the time lies
    outside the take.
    """
    mocap_t = check_array("mocap_t", mocap_t, (None,), finite=True)
    mocap_pos = check_array("mocap_pos", mocap_pos, (len(mocap_t), None, 3))
    frame_t = check_array("frame_t", frame_t, (None,), finite=True)
    if not np.isfinite(delay_s):
        raise EctskinError(f"delay_s must be finite, got {delay_s!r}")
    if int(max_gap_frames) < 0:
        raise EctskinError(f"max_gap_frames must be >= 0, got {max_gap_frames!r}")
    if len(mocap_t) > 1 and np.any(np.diff(mocap_t) <= 0):
        k = int(np.argmax(np.diff(mocap_t) <= 0)) + 1
        raise EctskinError(
            f"mocap_t must increase; sample {k} has {mocap_t[k]} after {mocap_t[k - 1]}"
        )
    tau = frame_t + float(delay_s)
    n_markers = mocap_pos.shape[1]
    out = np.full((len(frame_t), n_markers, 3), np.nan)
    tol = 1e-6 * (float(np.median(np.diff(mocap_t))) if len(mocap_t) > 1 else 1.0)
    for m in range(n_markers):
        visible = np.flatnonzero(np.isfinite(mocap_pos[:, m]).all(axis=1))
        if len(visible) == 0:
            continue
        tv, pv = mocap_t[visible], mocap_pos[visible, m]
        j = np.searchsorted(tv, tau, side="right") - 1  # tv[j] <= tau < tv[j + 1]
        # a time on (or within rounding of) a visible sample takes that sample
        jl = np.clip(j, 0, len(tv) - 1)
        jr = np.clip(j + 1, 0, len(tv) - 1)
        on_l = (j >= 0) & (np.abs(tau - tv[jl]) <= tol)
        on_r = (j + 1 < len(tv)) & (np.abs(tv[jr] - tau) <= tol)
        out[on_l, m] = pv[jl[on_l]]
        out[on_r & ~on_l, m] = pv[jr[on_r & ~on_l]]
        # between two visible samples with at most max_gap_frames occluded ones between them
        inner = (j >= 0) & (j + 1 < len(tv)) & ~on_l & ~on_r
        inner &= (visible[jr] - visible[jl] - 1) <= int(max_gap_frames)
        w = ((tau[inner] - tv[jl[inner]]) / (tv[jr[inner]] - tv[jl[inner]]))[:, None]
        out[inner, m] = pv[jl[inner]] * (1.0 - w) + pv[jr[inner]] * w
    return out
