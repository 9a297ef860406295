"""Align a capacitance-meter export with a motion-capture take and build a :class:`Recording`.

The readout and the cameras run on separate clocks started together (the paper's "auto-click
script"), which leaves a constant delay of a few frames between them. :func:`estimate_delay` finds
it from the data: both devices see the same touch-induced motion, so the marker coordinates are
best explained by the readouts (a linear fit, :func:`lagged_fit`) when the two are shifted by the
delay; alternatively the motion-energy signals of both (how fast the standardised readouts change,
how fast the markers move) correlate best at that shift.

Convention: ``delay_s > 0`` means the markers lag, i.e. what the readout sees at time t the markers
show at t + delay_s. :func:`resample_markers` therefore samples the marker trajectories at
``frame_t + delay_s``.
"""

from __future__ import annotations

import json
import logging
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array, check_option
from ectskin.io.capmeter import CapmeterData, read_capmeter_csv
from ectskin.io.motive import MocapData, read_motive_csv
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout, load_layout

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
    that barely move), which makes the delay unreliable; on the digital twin's trials every
    estimate more than 50 ms off had a contrast below 0.11. ``lags_s``/``scores``: the whole score
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


# --------------------------------------------------------------------------- signals
def interp_linear(t: np.ndarray, y: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``y`` (n, ...) sampled at increasing ``t`` (n,) onto ``t_new``.

    NaN outside [t[0], t[-1]] and wherever a bracketing sample is NaN (no bridging of gaps).
    """
    y2 = y.reshape(len(t), -1)
    if len(t) < 2:
        out = np.full((len(t_new), y2.shape[1]), np.nan)
        if len(t) == 1:
            out[t_new == t[0]] = y2[0]
        return out.reshape((len(t_new), *y.shape[1:]))
    i = np.clip(np.searchsorted(t, t_new, side="right") - 1, 0, len(t) - 2)
    w = ((t_new - t[i]) / (t[i + 1] - t[i]))[:, None]
    out = y2[i] * (1.0 - w) + y2[i + 1] * w
    # exact hits on a sample take that sample alone (its neighbour may be NaN)
    hit_l, hit_r = w[:, 0] == 0.0, w[:, 0] == 1.0
    out[hit_l] = y2[i[hit_l]]
    out[hit_r] = y2[i[hit_r] + 1]
    out[(t_new < t[0]) | (t_new > t[-1])] = np.nan
    return out.reshape((len(t_new), *y.shape[1:]))


def _moving_average(x: np.ndarray, k: int) -> np.ndarray:
    """Centred moving average over ``k`` samples that ignores NaN (NaN where all are NaN)."""
    if k <= 1:
        return x
    ok = np.isfinite(x)
    kern = np.ones(k)
    s = np.convolve(np.where(ok, x, 0.0), kern, mode="same")
    c = np.convolve(ok.astype(float), kern, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        out = s / c
    out[c < k / 2] = np.nan
    return out


def signal_weight(x: np.ndarray) -> np.ndarray:
    """Fraction of each column's variance that is not sample-to-sample noise, in [0, 1].

    ``x`` (n_samples, n_columns) at its native rate, NaN allowed. The noise variance is estimated
    from first differences, sigma_n^2 = mean(dx^2) / 2 (white noise doubles its variance in a
    difference; a slow signal adds little), and the weight is max(0, 1 - sigma_n^2 / var(x)): ~0
    for a column that holds only noise, ~1 for one that carries slow motion. Shape (n_columns,).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns give NaN
        var = np.nanvar(x, axis=0)
        noise = np.nanmean(np.diff(x, axis=0) ** 2, axis=0) / 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        w = 1.0 - noise / var
    return np.where(np.isfinite(w) & (var > 0), np.clip(w, 0.0, 1.0), 0.0)


def _weighted_mean(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Row-wise weighted mean of ``x`` (n, k) with weights ``w`` (k,), ignoring NaN entries."""
    ok = np.isfinite(x)
    den = (ok * w).sum(axis=1)
    num = np.where(ok, x, 0.0) @ w
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def capacitance_energy(
    grid_t: np.ndarray, cap_t: np.ndarray, cap_values: np.ndarray, smooth: int = 1
) -> np.ndarray:
    """Motion energy of the readouts on ``grid_t``: weighted mean of |d/dt z_k(t)|, 1/s.

    z_k is channel k standardised over the trial ((c_k - mean) / std, NaN ignored) and smoothed
    by a ``smooth``-sample moving average. Channels are weighted by :func:`signal_weight`, so the
    pairs that only see noise (a touch moves only some pairs) do not drown the ones that move.
    Shape (n_grid,), NaN where no weighted channel is available.
    """
    w = signal_weight(cap_values)
    live = w > 0
    if not live.any():
        return np.full(len(grid_t), np.nan)
    v = interp_linear(cap_t, cap_values[:, live], grid_t)  # (n_grid, n_live)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        z = (v - np.nanmean(v, axis=0)) / np.nanstd(v, axis=0)
    z = np.apply_along_axis(_moving_average, 0, z, smooth)
    dz = np.abs(np.gradient(z, grid_t, axis=0))
    return _weighted_mean(dz, w[live])


def marker_speed(
    grid_t: np.ndarray, mocap_t: np.ndarray, mocap_pos: np.ndarray, smooth: int = 1
) -> np.ndarray:
    """Motion energy of the markers on ``grid_t``: weighted mean marker speed |d/dt p_m|, mm/s.

    Positions are smoothed by a ``smooth``-sample moving average first; markers are weighted by
    :func:`signal_weight` of their three coordinates together (a marker near the clamped base
    that only jitters gets ~0). Shape (n_grid,), NaN where every weighted marker is occluded or
    the time lies outside the take.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        var = np.nanvar(mocap_pos, axis=0).sum(axis=1)  # (n_markers,)
        noise = (np.nanmean(np.diff(mocap_pos, axis=0) ** 2, axis=0) / 2.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(var > 0, np.clip(1.0 - noise / var, 0.0, 1.0), 0.0)
    w = np.where(np.isfinite(w), w, 0.0)
    p = interp_linear(mocap_t, mocap_pos, grid_t)  # (n_grid, n_markers, 3)
    p = np.apply_along_axis(_moving_average, 0, p, smooth)
    v = np.gradient(p, grid_t, axis=0)
    speed = np.linalg.norm(v, axis=2)  # (n_grid, n_markers)
    return _weighted_mean(speed, w)


def _median_dt(t: np.ndarray, name: str) -> float:
    if len(t) < 3:
        raise EctskinError(f"{name} needs at least 3 samples to estimate a delay, got {len(t)}")
    return float(np.median(np.diff(t)))


def normalised_xcorr(a: np.ndarray, b: np.ndarray, max_lag: int, min_overlap: int):
    """Pearson r between a[n] and b[n + L] for L = -max_lag…max_lag over samples where both exist.

    Returns (lags (2·max_lag+1,), r (same; NaN where the overlap is below ``min_overlap`` or a
    signal is constant there), overlap counts).
    """
    lags = np.arange(-max_lag, max_lag + 1)
    r = np.full(len(lags), np.nan)
    counts = np.zeros(len(lags), dtype=np.int64)
    n = len(a)
    for k, lag in enumerate(lags):
        if lag >= 0:
            x, y = a[: n - lag], b[lag:]
        else:
            x, y = a[-lag:], b[: n + lag]
        ok = np.isfinite(x) & np.isfinite(y)
        counts[k] = int(ok.sum())
        if counts[k] < min_overlap:
            continue
        xs, ys = x[ok] - x[ok].mean(), y[ok] - y[ok].mean()
        den = np.sqrt((xs * xs).sum() * (ys * ys).sum())
        if den > 0:
            r[k] = float((xs * ys).sum() / den)
    return lags, r, counts


def lagged_fit(
    x: np.ndarray, y: np.ndarray, max_lag: int, min_overlap: int, ridge: float = 1e-3
):
    """Multiple correlation R of a linear fit of y[n + L] from x[n], for L = -max_lag…max_lag.

    ``x`` (n, p) predictors (the readout channels), ``y`` (n, n_markers, 3) targets (marker
    coordinates), NaN allowed: rows with a NaN predictor, and per marker the rows where it is
    occluded, are left out. For each lag and marker an affine least-squares fit (ridge
    ``ridge`` · n_rows on the centred normal equations) is made; the residual and total sums of
    squares are pooled over markers: R = sqrt(1 - SSE / SST). A marker that moves more weighs
    more. Returns (lags, R (NaN where fewer than ``min_overlap`` rows), row counts).
    """
    n = len(x)
    lags = np.arange(-max_lag, max_lag + 1)
    r = np.full(len(lags), np.nan)
    counts = np.zeros(len(lags), dtype=np.int64)
    x_ok = np.isfinite(x).all(axis=1)
    y_ok = np.isfinite(y).all(axis=2)  # (n, n_markers)
    for k, lag in enumerate(lags):
        sx = slice(max(0, -lag), n - max(0, lag))
        sy = slice(max(0, lag), n + min(0, lag))
        xs, ys, okx, oky = x[sx], y[sy], x_ok[sx], y_ok[sy]
        sse = sst = 0.0
        groups: dict[bytes, list[int]] = {}  # markers visible on the same rows share one solve
        for m in range(y.shape[1]):
            groups.setdefault((okx & oky[:, m]).tobytes(), []).append(m)
        for markers in groups.values():
            ok = okx & oky[:, markers[0]]
            c = int(ok.sum())
            if c < min_overlap:
                continue
            counts[k] = max(counts[k], c)
            a = xs[ok] - xs[ok].mean(axis=0)
            b = ys[ok][:, markers].reshape(c, -1)  # (c, 3 * n_group)
            b = b - b.mean(axis=0)
            gram = a.T @ a
            gram[np.diag_indices_from(gram)] += ridge * c
            beta = np.linalg.solve(gram, a.T @ b)
            sse += float(((b - a @ beta) ** 2).sum())
            sst += float((b**2).sum())
        if sst > 0:
            r[k] = np.sqrt(max(0.0, 1.0 - sse / sst))
    return lags, r, counts


def _standardised_channels(
    grid_t: np.ndarray, cap_t: np.ndarray, cap_values: np.ndarray, smooth: int
) -> np.ndarray:
    """Readout channels on the grid, standardised and smoothed, as regression predictors.

    Channels masked on more than 10 % of the frames and channels that never change are left out;
    when more than n/10 channels remain, their leading principal components are used instead (so
    the fit never has more than one predictor per ten frames). Shape (n_grid, p).
    """
    nan_frac = np.isnan(cap_values).mean(axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sd = np.nanstd(cap_values, axis=0)
    keep = (nan_frac <= 0.1) & np.isfinite(sd) & (sd > 0)
    if not keep.any():
        return np.empty((len(grid_t), 0))
    v = interp_linear(cap_t, cap_values[:, keep], grid_t)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        z = (v - np.nanmean(v, axis=0)) / np.nanstd(v, axis=0)
    z = np.apply_along_axis(_moving_average, 0, z, smooth)
    rows = np.isfinite(z).all(axis=1)
    q = max(1, int(rows.sum()) // 10)
    if z.shape[1] > q and rows.sum() > 1:
        _, _, vt = np.linalg.svd(z[rows], full_matrices=False)
        z = z @ vt[:q].T
    return z


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
    grid_dt_s : step of the common grid; default the readout's median frame interval (finer
        grids gave no better estimates in our tests: the parabolic refinement already resolves
        a fraction of a frame).
    smooth_s : width (s) of the centred moving average applied to both signals: a low-pass that
        keeps the motion (a touch lasts ~1 s) and removes sample noise. Symmetric, so it does not
        shift the lag.
    method : ``"regression"`` (default): for every lag, a linear fit of the marker coordinates
        from the standardised readout channels (:func:`lagged_fit`); the score is the pooled
        multiple correlation R. ``"energy"``: Pearson correlation of the motion-energy signals
        (:func:`capacitance_energy`, :func:`marker_speed`). The regression uses the sign and size
        of every channel's response and was clearly more accurate on the digital twin's trials
        (see docs/instrument-import.md); the energy needs no linear relation at all.

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
    for name, t in (("cap_t", cap_t), ("mocap_t", mocap_t)):
        if len(t) > 1 and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise EctskinError(f"{name} must increase; sample {k} has {t[k]} after {t[k - 1]}")
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
    grid = t0 + dt * np.arange(n_grid)
    smooth = max(1, round(smooth_s / dt))
    max_lag = max(1, int(np.floor(max_delay_s / dt + 1e-9)))
    if method == "energy":
        sig_cap = capacitance_energy(grid, cap_t, cap_values, smooth)
        sig_mk = marker_speed(grid, mocap_t, mocap_pos, smooth)
        cap_ok, mk_ok = np.isfinite(sig_cap), np.isfinite(sig_mk)
    else:
        sig_cap = _standardised_channels(grid, cap_t, cap_values, smooth)
        pos = interp_linear(mocap_t, mocap_pos, grid)  # (n_grid, n_markers, 3)
        sig_mk = np.apply_along_axis(_moving_average, 0, pos, smooth)
        cap_ok = np.isfinite(sig_cap).all(axis=1) & (sig_cap.shape[1] > 0)
        mk_ok = np.isfinite(sig_mk).all(axis=2).any(axis=1)
    if not cap_ok.any():
        raise EctskinError("the capacitance readouts never change (or are all masked); "
                           "cannot estimate the delay; pass the delay explicitly")
    if not mk_ok.any():
        raise EctskinError("no marker is visible long enough to measure its motion; cannot "
                           "estimate the delay; pass the delay explicitly")
    min_overlap = max(8, min(int(cap_ok.sum()), int(mk_ok.sum())) // 4)
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
    k = int(np.nanargmax(r))
    frac = 0.0
    if 0 < k < len(r) - 1 and np.isfinite(r[k - 1]) and np.isfinite(r[k + 1]):
        den = r[k - 1] - 2.0 * r[k] + r[k + 1]
        if den < 0:  # vertex of the parabola through (-1, r[k-1]), (0, r[k]), (1, r[k+1])
            frac = float(np.clip(0.5 * (r[k - 1] - r[k + 1]) / den, -0.5, 0.5))
    at_bound = k in (0, len(r) - 1)
    s2 = np.clip(r, 0.0, 1.0) ** 2
    lo = float(np.nanmin(s2))
    contrast = (float(s2[k]) - lo) / (1.0 - lo) if lo < 1.0 else 0.0
    est = DelayEstimate(
        delay_s=float((lags[k] + frac) * dt),
        score=float(r[k]),
        contrast=contrast,
        method=method,
        grid_dt_s=float(dt),
        at_bound=bool(at_bound),
        n_overlap=int(counts[k]),
        lags_s=lags * dt,
        scores=r,
    )
    if at_bound:
        log.warning(
            "delay estimate %.4f s lies at the search bound ±%.3f s; the true delay may be larger "
            "(raise max_delay_s)", est.delay_s, max_delay_s,
        )
    if est.contrast < WEAK_CONTRAST:
        log.warning(
            "weak delay estimate %.4f s: the %s score hardly depends on the lag (contrast %.3f, "
            "score %.3f); do the markers move? check it or pass the delay explicitly",
            est.delay_s, method, est.contrast, est.score,
        )
    log.info("estimated delay %.4f s (markers lag when > 0), %s score %.3f", est.delay_s,
             method, est.score)
    return est


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


# --------------------------------------------------------------------------- recordings
def _match_markers(mocap: MocapData, layout: SensorLayout) -> np.ndarray:
    """Column order that puts the take's markers in the layout's marker order."""
    want = [m.name for m in layout.markers]
    have = list(mocap.marker_names)
    short = [n.split(":")[-1] for n in have]
    order = []
    for name in want:
        hits = [k for k, n in enumerate(have) if n == name] or [
            k for k, s in enumerate(short) if s == name
        ]
        if len(hits) != 1:
            order = None
            break
        order.append(hits[0])
    if order is not None and len(order) == len(have):
        return np.asarray(order, dtype=np.int64)
    if len(have) != len(want):
        raise EctskinError(
            f"{mocap.path}: {len(have)} markers ({', '.join(have)}), but layout {layout.name!r} "
            f"has {len(want)} ({', '.join(want)}); select the markers with marker_names"
        )
    log.info(
        "%s: marker names %s do not match layout markers %s; using the file order",
        mocap.path, have, want,
    )
    return np.arange(len(have))


def build_recording(
    capmeter: CapmeterData,
    mocap: MocapData | None,
    layout: SensorLayout,
    *,
    delay: str | float = "auto",
    trial_name: str | None = None,
    inflation: Sequence[float] = (),
    region: int = 0,
    max_delay_s: float = 0.5,
    delay_method: str = "regression",
    clock: str = "start",
    max_gap_frames: int = 1,
    meta: dict[str, Any] | None = None,
) -> Recording:
    """One-trial :class:`Recording` from a capacitance export and (optionally) a Motive take.

    Parameters
    ----------
    capmeter : from :func:`read_capmeter_csv`; its channels must be ``layout.n_pairs`` pairs in the
        ECT order. mocap : from :func:`read_motive_csv`, or None (no markers).
    layout : the sensor layout; markers are matched to ``layout.markers`` by name (``M1`` matches
        ``Skin:M1``) when all names match, else taken in file order.
    delay : ``"auto"`` (estimate with :func:`estimate_delay`) or the delay in s (markers lag > 0).
    max_delay_s, delay_method : search range and method of the estimate (``delay="auto"``).
    trial_name : default the capacitance file's stem. inflation : chamber volumes p, ml.
    region : the touched region for the whole trial (0 = no touch); labels every frame.
    clock : ``"start"``: both recordings count from their first sample (devices started together);
        ``"file"``: the two files' times are already on one clock.
    max_gap_frames : see :func:`resample_markers`.

    The trial's timestamps count from its first frame (s). ``Trial.meta`` records the sources, the
    delay (and how it was found), the masked cells and the occlusions.
    """
    check_option("clock", clock, ("start", "file"))
    if not (isinstance(delay, str) and delay == "auto"):
        try:
            delay = float(delay)
        except (TypeError, ValueError):
            raise EctskinError(
                f"delay must be 'auto' or a number of seconds, got {delay!r}"
            ) from None
        if not np.isfinite(delay):
            raise EctskinError(f"delay must be finite, got {delay!r}")
    if capmeter.n_channels != layout.n_pairs:
        raise EctskinError(
            f"{capmeter.path}: {capmeter.n_channels} capacitance channels "
            f"({', '.join(capmeter.channels)}), but layout {layout.name!r} has "
            f"{layout.n_electrodes} electrodes = {layout.n_pairs} pairs"
        )
    region = int(region)
    if region != 0:
        layout.region(region)  # raises a clear error for an unknown region
    values = capmeter.values
    if capmeter.channels != layout.pair_names and set(capmeter.channels) == set(layout.pair_names):
        order = [capmeter.channels.index(nm) for nm in layout.pair_names]
        values = values[:, order]
        log.info("%s: channels reordered to the layout's pair order by name", capmeter.path)
    elif capmeter.pairs is None and capmeter.channels != layout.pair_names:
        log.info(
            "%s: channel names (%s, ...) are neither the layout's pair names nor electrode pairs; "
            "taking the file's column order as the layout's pair order", capmeter.path,
            ", ".join(capmeter.channels[:3]),
        )
    name = trial_name or Path(capmeter.path).stem
    cap_t = capmeter.timestamps - (capmeter.timestamps[0] if clock == "start" else 0.0)
    trial_meta: dict[str, Any] = {
        "kind": "touch" if region else "no_contact",
        "source_capacitance": capmeter.path,
        "capacitance_units": sorted(set(capmeter.units)),
        "masked": capmeter.mask_report.to_dict(),
        "clock": clock,
    }
    markers = None
    if mocap is not None:
        order = _match_markers(mocap, layout)
        pos = mocap.positions[:, order]
        mk_t = mocap.timestamps - (mocap.timestamps[0] if clock == "start" else 0.0)
        if delay == "auto":
            est = estimate_delay(
                cap_t, values, mk_t, pos, max_delay_s=max_delay_s, method=delay_method
            )
            delay_s = est.delay_s
            trial_meta.update(
                delay_source="estimated", delay_method=est.method, delay_score=est.score,
                delay_contrast=est.contrast, delay_at_bound=est.at_bound,
            )
        else:
            delay_s = float(delay)
            trial_meta["delay_source"] = "given"
        markers = resample_markers(mk_t, pos, cap_t, delay_s, max_gap_frames=max_gap_frames)
        outside = (cap_t + delay_s < mk_t[0]) | (cap_t + delay_s > mk_t[-1])
        if outside.any():
            log.warning(
                "trial %r: %d of %d frames fall outside the motion-capture take (markers NaN)",
                name, int(outside.sum()), len(cap_t),
            )
        trial_meta.update(
            delay_s=float(delay_s),
            source_mocap=mocap.path,
            mocap_frame_rate_hz=mocap.frame_rate_hz,
            mocap_length_units=mocap.units,
            mocap_markers=[mocap.marker_names[k] for k in order],
            occluded_frames={
                mocap.marker_names[k]: mocap.occlusions[mocap.marker_names[k]].n_occluded
                for k in order
            },
            frames_without_markers=int(np.isnan(markers).any(axis=(1, 2)).sum()),
        )
    elif delay != "auto":
        log.info("no motion capture: the delay %r is not used", delay)
    trial_meta.update(meta or {})
    trial = Trial(
        name=name,
        capacitance=values,
        timestamps=cap_t - cap_t[0],
        labels=np.full(capmeter.n_frames, region, dtype=np.int16),
        inflation=tuple(float(v) for v in inflation),
        region=region,
        markers=markers,
        meta=trial_meta,
    )
    rate = capmeter.frame_rate_hz
    if not np.isfinite(rate):
        raise EctskinError(f"{capmeter.path}: need at least 2 frames to know the frame rate")
    return Recording(layout=layout, trials=[trial], frame_rate_hz=rate,
                     meta={"source": "ectskin import build"})


# --------------------------------------------------------------------------- manifests
_TRIAL_KEYS = {
    "name", "capacitance", "mocap", "inflation", "region", "delay", "marker_names",
    "time_unit", "value_unit", "length_units",
}
_TOP_KEYS = {"layout", "max_delay_s", "delay_method", "clock", "strict", "trials"}


def build_recording_from_manifest(
    path: str | Path, layout: SensorLayout | None = None, *, strict: bool | None = None
) -> Recording:
    """A multi-trial :class:`Recording` from a JSON manifest of instrument files.

    The manifest (format in ``docs/instrument-import.md``)::

        {"layout": "my_layout.json",          # optional; default: the layout argument
         "max_delay_s": 0.5, "delay_method": "regression", "clock": "start", "strict": true,
         "trials": [
           {"name": "p000_touch07", "capacitance": "cap/p000_07.csv", "mocap": "mocap/p000_07.csv",
            "inflation": [0, 0, 0], "region": 7, "delay": "auto"},
           {"name": "p000_rest", "capacitance": "cap/p000_rest.csv", "inflation": [0, 0, 0]}]}

    Paths are relative to the manifest. Every trial is read, aligned and checked; the first
    problem is an :class:`EctskinError` naming the manifest entry and the file.
    """
    from ectskin.layout import default_layout

    src = str(path)
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise EctskinError(f"cannot read manifest {src}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise EctskinError(
            f"{src}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    except UnicodeDecodeError:
        raise EctskinError(f"{src}: not UTF-8 text (is it a JSON manifest?)") from None
    if not isinstance(doc, dict):
        raise EctskinError(f"{src}: a manifest must be a JSON object with a 'trials' list")
    unknown = set(doc) - _TOP_KEYS
    if unknown:
        raise EctskinError(
            f"{src}: unknown field(s) {sorted(unknown)}; allowed: {sorted(_TOP_KEYS)}"
        )
    base = Path(path).parent
    if "layout" in doc:
        layout = load_layout(base / str(doc["layout"]))
    layout = layout or default_layout()
    strict = bool(doc.get("strict", True)) if strict is None else strict
    max_delay_s = float(doc.get("max_delay_s", 0.5))
    clock = doc.get("clock", "start")
    delay_method = doc.get("delay_method", "regression")
    entries = doc.get("trials")
    if not isinstance(entries, list) or not entries:
        raise EctskinError(f"{src}: 'trials' must be a non-empty list of trial objects")
    trials = []
    rate = None
    for k, e in enumerate(entries):
        where = f"{src}: trials[{k}]"
        if not isinstance(e, dict):
            raise EctskinError(f"{where} must be an object, got {type(e).__name__}")
        unknown = set(e) - _TRIAL_KEYS
        if unknown:
            raise EctskinError(
                f"{where}: unknown field(s) {sorted(unknown)}; allowed: {sorted(_TRIAL_KEYS)}"
            )
        if "capacitance" not in e:
            raise EctskinError(f"{where}: missing field 'capacitance' (the readout CSV)")
        try:
            cap = read_capmeter_csv(
                base / str(e["capacitance"]), n_pairs=layout.n_pairs, strict=strict,
                time_unit=e.get("time_unit"), value_unit=e.get("value_unit"),
            )
            mocap = None
            if e.get("mocap"):
                mocap = read_motive_csv(
                    base / str(e["mocap"]), e.get("marker_names"), strict=strict,
                    length_units=e.get("length_units"),
                )
            inflation = e.get("inflation", [])
            if not isinstance(inflation, list) or not all(
                isinstance(v, (int, float)) for v in inflation
            ):
                raise EctskinError(f"'inflation' must be a list of numbers (ml), got {inflation!r}")
            region = e.get("region", 0)
            if not isinstance(region, int) or isinstance(region, bool):
                raise EctskinError(f"'region' must be an integer, got {region!r}")
            rec = build_recording(
                cap, mocap, layout, delay=e.get("delay", "auto"), trial_name=e.get("name"),
                inflation=inflation, region=region, max_delay_s=max_delay_s, clock=clock,
                delay_method=delay_method,
            )
        except EctskinError as exc:
            raise EctskinError(f"{where} ({e.get('name', e['capacitance'])}): {exc}") from None
        if rate is not None and abs(rec.frame_rate_hz / rate - 1) > 0.01:
            raise EctskinError(
                f"{where}: frame rate {rec.frame_rate_hz:.3f} Hz differs from the first trial's "
                f"{rate:.3f} Hz"
            )
        rate = rate or rec.frame_rate_hz
        trials.extend(rec.trials)
    return Recording(layout=layout, trials=trials, frame_rate_hz=rate,
                     meta={"source": "ectskin import build", "manifest": src})
