"""Signals for the delay estimate: resampling onto a common grid, motion energy, and the scores
compared at every lag (a normalised cross-correlation, a lagged linear fit).

Shapes: readouts (n_frames, n_channels) and marker positions (n_samples, n_markers, 3), NaN
allowed in both (masked cells, occluded markers); every function here ignores NaN rather than
bridging it.
"""

from __future__ import annotations

import warnings

import numpy as np


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


def moving_average(x: np.ndarray, k: int) -> np.ndarray:
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
    z = np.apply_along_axis(moving_average, 0, z, smooth)
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
    p = np.apply_along_axis(moving_average, 0, p, smooth)
    v = np.gradient(p, grid_t, axis=0)
    speed = np.linalg.norm(v, axis=2)  # (n_grid, n_markers)
    return _weighted_mean(speed, w)


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


def lagged_fit(x: np.ndarray, y: np.ndarray, max_lag: int, min_overlap: int, ridge: float = 1e-3):
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


def standardised_channels(
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
    z = np.apply_along_axis(moving_average, 0, z, smooth)
    rows = np.isfinite(z).all(axis=1)
    q = max(1, int(rows.sum()) // 10)
    if z.shape[1] > q and rows.sum() > 1:
        _, _, vt = np.linalg.svd(z[rows], full_matrices=False)
        z = z @ vt[:q].T
    return z
