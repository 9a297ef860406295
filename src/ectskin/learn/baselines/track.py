"""Trivial and classical baselines of deformation tracking beside the paper's C2DT.

On :class:`~ectskin.learn.data.track.TrackData`, fit on train, evaluated on test:

==================  =====================================================================
``no_motion``       "markers do not move": prediction = the trajectory's initial coordinates
                    (needs ``prior=True`` data)
``mean_pose``       the mean training coordinates of every marker, for every sample (the
                    trivial baseline of the ``prior=False`` ablation)
``ridge``           ridge regression on the flattened, standardised windows (+ the initial
                    coordinates when ``prior``) predicting the displacement y − init
                    (the absolute coordinates when not ``prior``); all training samples, it is
                    one linear solve (``max_train`` optionally subsamples)
==================  =====================================================================

Every result holds per-sample predictions so that the evaluation computes the paper's Eq. 3
average distance (:func:`ectskin.learn.metrics.track.average_distance`) on exactly the same
samples.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.learn.baselines.base import subsample
from ectskin.learn.data.track import TrackData
from ectskin.learn.metrics.track import average_distance

log = logging.getLogger(__name__)

TRACK_BASELINES = ("no_motion", "mean_pose", "ridge")

__all__ = [
    "RIDGE_ALPHAS",
    "TRACK_BASELINES",
    "TrackBaselineResult",
    "mean_pose_baseline",
    "no_motion_baseline",
    "track_baselines",
    "track_ridge_baseline",
]


@dataclass
class TrackBaselineResult:
    """A tracking baseline evaluated on the test samples.

    ``pred`` is (n_test, n_markers, 3) float32 coordinates, mm; ``ad_mm_mean`` / ``ad_mm_std``
    the paper's Eq. 3 average distance and its standard deviation over samples and markers.
    """

    name: str
    pred: np.ndarray
    ad_mm_mean: float
    ad_mm_std: float
    n_test: int
    n_train_used: int
    fit_seconds: float
    params: dict[str, Any] = field(default_factory=dict)

    def to_metrics(self) -> dict[str, Any]:
        return {
            "ad_mm_mean": self.ad_mm_mean,
            "ad_mm_std": self.ad_mm_std,
            "n_test_samples": self.n_test,
            "n_train_used": self.n_train_used,
            "fit_seconds": self.fit_seconds,
            "params": dict(self.params),
        }


def _check_track(train: TrackData | None, test: TrackData) -> None:
    if test.n_samples == 0:
        raise EctskinError("tracking baselines: no test samples")
    if train is None:
        return
    if train.n_samples == 0:
        raise EctskinError("tracking baselines: no training samples")
    if train.x.shape[1:] != test.x.shape[1:] or train.y.shape[1:] != test.y.shape[1:]:
        raise EctskinError(
            f"tracking baselines: training windows {train.x.shape[1:]} / markers "
            f"{train.y.shape[1:]} differ from test {test.x.shape[1:]} / {test.y.shape[1:]}"
        )
    if train.prior != test.prior:
        raise EctskinError("tracking baselines: training and test data differ in 'prior'")


def _track_result(
    name: str, pred: np.ndarray, test: TrackData, n_used: int, t0: float, params: dict
) -> TrackBaselineResult:
    pred = np.asarray(pred, dtype=np.float32)
    mean, std = average_distance(pred, test.y)
    res = TrackBaselineResult(
        name=name,
        pred=pred,
        ad_mm_mean=mean,
        ad_mm_std=std,
        n_test=test.n_samples,
        n_train_used=int(n_used),
        fit_seconds=time.perf_counter() - t0,
        params=params,
    )
    log.info("tracking baseline %s: AD %.3f ± %.3f mm", name, mean, std)
    return res


def no_motion_baseline(test: TrackData) -> TrackBaselineResult:
    """ "Markers do not move": every prediction is the trajectory's initial coordinates.

    Its AD is the mean displacement norm ||y − init|| of the test samples. Needs ``prior=True``
    data (``init`` holds the first frame's markers).
    """
    _check_track(None, test)
    if not test.prior:
        raise EctskinError(
            "the no-motion baseline needs the initial coordinates (prior=True data); use "
            "mean_pose_baseline for the prior=False ablation"
        )
    t0 = time.perf_counter()
    return _track_result("no_motion", test.init.copy(), test, 0, t0, {})


def mean_pose_baseline(train: TrackData, test: TrackData) -> TrackBaselineResult:
    """Every prediction is the mean training coordinates of each marker, mm."""
    _check_track(train, test)
    t0 = time.perf_counter()
    mean = train.y.astype(np.float64).mean(axis=0)  # (M, 3)
    pred = np.broadcast_to(mean, test.y.shape).copy()
    return _track_result("mean_pose", pred, test, train.n_samples, t0, {})


def _track_features(d: TrackData, rows: np.ndarray) -> np.ndarray:
    """(len(rows), k·n_pairs [+ M·3]) float64: flattened window, plus init coordinates (prior)."""
    x = d.x[rows].reshape(rows.size, -1).astype(np.float64)
    if d.prior:
        x = np.concatenate([x, d.init[rows].reshape(rows.size, -1).astype(np.float64)], axis=1)
    return x


def _track_target(d: TrackData, rows: np.ndarray) -> np.ndarray:
    """(len(rows), M·3) float64: displacement y − init (prior) or absolute coordinates, mm."""
    y = d.y[rows].astype(np.float64)
    if d.prior:
        y = y - d.init[rows]
    return y.reshape(rows.size, -1)


def _chunks(idx: np.ndarray, size: int = 8192):
    for a in range(0, idx.size, size):
        yield idx[a : a + size]


#: Ridge penalties tried by grouped cross-validation (on standardised features).
RIDGE_ALPHAS = tuple(float(a) for a in 10.0 ** np.arange(-2, 7))


def track_ridge_baseline(
    train: TrackData,
    test: TrackData,
    *,
    alpha: float | None = None,
    alphas: Sequence[float] = RIDGE_ALPHAS,
    n_folds: int = 5,
    max_train: int | None = None,
    seed: int = 0,
) -> TrackBaselineResult:
    """Ridge regression from standardised flattened windows (+ init coordinates with prior) to the
    displacement y − init (prior) or the absolute coordinates (no prior), per marker and axis.

    Solved in float64 by the normal equations accumulated over chunks of samples (memory stays
    at a few MB for ~100 000 windows of 10 × 28): w = (ZᵀZ + α I)⁻¹ Zᵀ(Y − ȳ), with Z the
    standardised features (constant features only centred) and intercept ȳ.

    ``alpha=None`` (default) picks α from ``alphas`` by ``n_folds``-fold cross-validation over
    the training *trials* (folds are groups, so correlated frames of one trial never straddle a
    fold; the squared error of each fold follows from its own ZᵀZ, ZᵀY, YᵀY, no second pass).
    ``max_train`` optionally subsamples the training windows.
    """
    if alpha is not None and not (np.isfinite(alpha) and alpha >= 0):
        raise EctskinError(f"ridge alpha must be >= 0, got {alpha!r}")
    _check_track(train, test)
    rng = np.random.default_rng(seed)
    idx = subsample(train.n_samples, max_train, rng)
    t0 = time.perf_counter()
    # pass 1: feature and target means / stds
    s1 = s2 = t1 = None
    for rows in _chunks(idx):
        x = _track_features(train, rows)
        y = _track_target(train, rows)
        if s1 is None:
            s1, s2, t1 = x.sum(0), (x * x).sum(0), y.sum(0)
        else:
            s1 += x.sum(0)
            s2 += (x * x).sum(0)
            t1 += y.sum(0)
    n = idx.size
    mu = s1 / n
    sd = np.sqrt(np.maximum(s2 / n - mu * mu, 0.0))
    sd = np.where(sd > 1e-12 * np.maximum(1.0, np.abs(mu)), sd, 1.0)
    y_mean = t1 / n
    # pass 2: normal equations per fold of trials, on standardised features
    groups = np.unique(train.group[idx])
    folds = min(n_folds, groups.size) if alpha is None else 1
    fold_of_group = dict(
        zip(rng.permutation(groups).tolist(), np.arange(groups.size) % max(folds, 1))
    )
    d, q = mu.size, y_mean.size
    gram = np.zeros((max(folds, 1), d, d))
    cross = np.zeros((max(folds, 1), d, q))
    yy = np.zeros(max(folds, 1))
    for rows in _chunks(idx):
        z = (_track_features(train, rows) - mu) / sd
        yc = _track_target(train, rows) - y_mean
        fold = np.array([fold_of_group[g] for g in train.group[rows].tolist()])
        for f in np.unique(fold):
            m = fold == f
            gram[f] += z[m].T @ z[m]
            cross[f] += z[m].T @ yc[m]
            yy[f] += float((yc[m] ** 2).sum())
    g_all, c_all = gram.sum(0), cross.sum(0)

    def solve(g: np.ndarray, c: np.ndarray, a: float) -> np.ndarray:
        try:
            return np.linalg.solve(g + a * np.eye(d), c)  # (d, M·3)
        except np.linalg.LinAlgError:  # alpha = 0 with collinear features: minimum norm
            return np.linalg.lstsq(g, c, rcond=None)[0]

    cv = {}
    if alpha is None and folds >= 2:
        for a in alphas:
            sse = 0.0
            for f in range(folds):
                w = solve(g_all - gram[f], c_all - cross[f], a)
                # ||Y_f − Z_f w||² = YᵀY − 2 tr(wᵀ ZᵀY) + tr(wᵀ ZᵀZ w)
                sse += yy[f] - 2 * np.sum(w * cross[f]) + np.sum(w * (gram[f] @ w))
            cv[float(a)] = sse / n
        alpha = min(cv, key=cv.get)
        log.info("ridge: alpha %.3g chosen by %d-fold grouped CV", alpha, folds)
    elif alpha is None:
        alpha = 1.0
        log.info("ridge: fewer than 2 training trials, no cross-validation; alpha = 1")
    w = solve(g_all, c_all, alpha)
    out = np.empty((test.n_samples, q))
    for rows in _chunks(np.arange(test.n_samples)):
        out[rows] = ((_track_features(test, rows) - mu) / sd) @ w + y_mean
    out = out.reshape(test.y.shape)
    if test.prior:
        out = out + test.init
    params = {"alpha": float(alpha), "max_train": max_train, "cv_mse": cv}
    return _track_result("ridge", out, test, idx.size, t0, params)


def track_baselines(
    train: TrackData,
    test: TrackData,
    *,
    methods: Sequence[str] | None = None,
    seed: int = 0,
    alpha: float | None = None,
) -> dict[str, TrackBaselineResult]:
    """Run the tracking baselines (default: no_motion (prior data only), mean_pose, ridge)."""
    if methods is None:
        methods = TRACK_BASELINES if test.prior else ("mean_pose", "ridge")
    out: dict[str, TrackBaselineResult] = {}
    for m in methods:
        if m == "no_motion":
            out[m] = no_motion_baseline(test)
        elif m == "mean_pose":
            out[m] = mean_pose_baseline(train, test)
        elif m == "ridge":
            out[m] = track_ridge_baseline(train, test, alpha=alpha, seed=seed)
        else:
            raise EctskinError(
                f"unknown tracking baseline {m!r}; allowed: {', '.join(TRACK_BASELINES)}"
            )
    return out
