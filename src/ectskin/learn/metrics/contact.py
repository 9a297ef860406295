"""Contact metrics, pure functions on plain arrays (numpy, and scipy's Hungarian matching).

Positions are points on the faces of the body, (face, u, v) in mm. The distance between two
points is by default the straight line between them on the body at rest (:func:`rest_points`):
on one face the distance in (u, v), across faces through the body; a caller may pass its own
distances (the contact task measures a single finger's error over the skin, around the body's
side edge). A model that names the wrong face is thus charged at least the body's thickness.

* :func:`localisation_metrics`: the error of one finger's point (mean / median / p90, per face,
  per inflation state, and a map over each face);
* :func:`other_finger_split`: that error split by where the hand's other finger is (none
  above the skin, hovering close to it, or higher);
* :func:`force_metrics`: MAE and relative error of the force;
* :func:`force_coverage`: the share of frames whose true force lies within ±1σ and ±2σ of the
  predicted force, σ the model's own standard deviation of it;
* :func:`force_split`: the force MAE (and coverage) where a per-frame bound says force is
  observable, where it says it is not, and where there is no bound;
* :func:`hover_metrics`: detection rate of a hovering finger against its height, and the height
  up to which it is detected;
* :func:`match_fingers` and :func:`multi_metrics`: count accuracy and per-finger error after
  matching predictions to fingers with the Hungarian algorithm.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from ectskin._check import EctskinError

#: where each face lies at rest and which body axes its (u, v) run along (see ectskin.layout)
_FACE_AXES = {
    "front": ("u", "+t", "v"),
    "back": ("u", "-t", "v"),
    "right": ("+w", "u", "v"),
    "left": ("-w", "u", "v"),
}
#: a hovering finger counts as detected in a height bin when at least this share of its frames
#: are flagged
HOVER_RATE = 0.9
#: height bins of the hover curve (mm)
HOVER_BIN_MM = 1.0
#: cell size of the error maps (mm)
MAP_CELL_MM = 5.0


def rest_points(
    faces: Sequence[str], face: np.ndarray, uv: np.ndarray, *, width_mm: float, thickness_mm: float
) -> np.ndarray:
    """(..., 3) points (x, y, z) mm of face indices ``face`` (...) at (u, v) ``uv`` (..., 2) on
    the body at rest (width ``width_mm`` along x, thickness ``thickness_mm`` along y)."""
    face = np.asarray(face)
    uv = np.asarray(uv, dtype=np.float64)
    out = np.zeros(face.shape + (3,))
    for k, name in enumerate(faces):
        if name not in _FACE_AXES:
            raise EctskinError(f"unknown face {name!r}; known: {', '.join(_FACE_AXES)}")
        m = face == k
        for axis, code in enumerate(_FACE_AXES[name]):
            if code == "u":
                out[m, axis] = uv[m, 0]
            elif code == "v":
                out[m, axis] = uv[m, 1]
            else:
                half = (thickness_mm if code[1] == "t" else width_mm) / 2
                out[m, axis] = half if code[0] == "+" else -half
    return out


def point_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance between rest points (..., 3)."""
    return np.linalg.norm(np.asarray(a) - np.asarray(b), axis=-1)


def _summary(d: np.ndarray) -> dict[str, float | int]:
    if d.size == 0:
        return {"loc_mm_mean": None, "loc_mm_median": None, "loc_mm_p90": None, "n_frames": 0}
    return {
        "loc_mm_mean": float(d.mean()),
        "loc_mm_median": float(np.median(d)),
        "loc_mm_p90": float(np.percentile(d, 90)),
        "n_frames": int(d.size),
    }


def error_map(
    uv: np.ndarray,
    err: np.ndarray,
    extent: tuple[tuple[float, float], tuple[float, float]],
    cell_mm: float = MAP_CELL_MM,
) -> dict[str, Any]:
    """Mean error per ``cell_mm`` cell of a face: {u_edges, v_edges, mean_mm (nv, nu; NaN where
    no frame fell), count (nv, nu)}."""
    (u0, u1), (v0, v1) = extent
    ue = np.arange(u0, u1 + cell_mm * 0.999, cell_mm)
    ve = np.arange(v0, v1 + cell_mm * 0.999, cell_mm)
    iu = np.clip(np.searchsorted(ue, uv[:, 0], side="right") - 1, 0, len(ue) - 2)
    iv = np.clip(np.searchsorted(ve, uv[:, 1], side="right") - 1, 0, len(ve) - 2)
    total = np.zeros((len(ve) - 1, len(ue) - 1))
    count = np.zeros_like(total)
    np.add.at(total, (iv, iu), err)
    np.add.at(count, (iv, iu), 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return {"u_edges": ue, "v_edges": ve, "mean_mm": mean, "count": count.astype(int)}


def localisation_metrics(
    true_pts: np.ndarray,
    pred_pts: np.ndarray,
    *,
    true_face: np.ndarray,
    pred_face: np.ndarray,
    faces: Sequence[str],
    state: np.ndarray | None = None,
    state_names: Sequence[str] | None = None,
    true_uv: np.ndarray | None = None,
    face_extent: dict[str, Any] | None = None,
    distance: np.ndarray | None = None,
) -> dict[str, Any]:
    """Error of one finger's predicted point over frames (rest points (n, 3), see
    :func:`rest_points`): ``loc_mm_mean`` / ``_median`` / ``_p90``, ``face_accuracy``,
    ``per_face``, ``per_state`` (with ``state``) and ``map`` (per face, with ``true_uv`` and
    ``face_extent``; arrays, for the figure). ``distance`` (n,) mm: the errors to use instead of
    the straight line between the rest points (e.g. over the skin, around the body's edge)."""
    d = point_distance(true_pts, pred_pts)
    if distance is not None:
        d = np.asarray(distance, dtype=np.float64)
        if d.shape != (len(true_pts),):
            raise ValueError(f"distance must be ({len(true_pts)},), got {d.shape}")
    out: dict[str, Any] = dict(_summary(d))
    out["face_accuracy"] = float(np.mean(true_face == pred_face)) if d.size else None
    out["per_face"] = {f: _summary(d[true_face == k]) for k, f in enumerate(faces)}
    if state is not None:
        names = list(state_names) if state_names is not None else None
        out["per_state"] = {
            (names[s] if names else str(int(s))): _summary(d[state == s]) for s in np.unique(state)
        }
    if true_uv is not None and face_extent is not None:
        out["map"] = {
            f: error_map(true_uv[true_face == k], d[true_face == k], face_extent[f])
            for k, f in enumerate(faces)
            if f in face_extent and np.any(true_face == k)
        }
    return out


#: the parts of :func:`other_finger_split`
OTHER_FINGER_PARTS = ("alone", "other_hovering", "other_above")


def other_finger_split(
    distance: np.ndarray,
    other_height_mm: np.ndarray,
    hover_max_mm: float,
    *,
    state: np.ndarray | None = None,
    state_names: Sequence[str] | None = None,
) -> dict[str, Any]:
    """The error ``distance`` (n,) mm of frames with one finger on the skin, split by the height
    ``other_height_mm`` (n,) of the lowest other finger above the skin (NaN: none there):
    ``alone`` (none), ``other_hovering`` (one at most ``hover_max_mm`` above it: its own signal
    adds to the touch's) and ``other_above`` (higher). Each part: the mean / median / p90 error,
    ``n_frames``, ``share`` (of all frames) and, with ``state``, ``per_state`` (the states
    holding frames of the part, named by ``state_names``)."""
    d, h = np.asarray(distance, float), np.asarray(other_height_mm, float)
    if d.shape != h.shape or d.ndim != 1:
        raise EctskinError(
            f"other_finger_split: distance and other_height_mm must be one-dimensional of one "
            f"shape, got {d.shape} and {h.shape}"
        )
    near = np.isfinite(h) & (h <= hover_max_mm)
    parts = {
        "alone": ~np.isfinite(h),
        "other_hovering": near,
        "other_above": np.isfinite(h) & ~near,
    }
    out: dict[str, Any] = {"hover_max_mm": float(hover_max_mm)}
    for name, m in parts.items():
        part: dict[str, Any] = dict(_summary(d[m]))
        part["share"] = float(m.mean()) if d.size else None
        if state is not None:
            st = np.asarray(state)
            part["per_state"] = {
                (state_names[s] if state_names is not None else str(int(s))): _summary(
                    d[m & (st == s)]
                )
                for s in np.unique(st[m])
            }
        out[name] = part
    return out


def force_metrics(true_n: np.ndarray, pred_n: np.ndarray) -> dict[str, Any]:
    """Force error over frames in contact: ``force_mae_n``, ``force_rel`` (MAE / mean true
    force), ``force_median_rel`` (median of |error| / true force), ``force_bias_n``."""
    t, p = np.asarray(true_n, float), np.asarray(pred_n, float)
    if t.size == 0:
        return {"force_mae_n": None, "force_rel": None, "force_median_rel": None, "n_frames": 0}
    err = p - t
    return {
        "force_mae_n": float(np.abs(err).mean()),
        "force_rel": float(np.abs(err).mean() / max(t.mean(), 1e-12)),
        "force_median_rel": float(np.median(np.abs(err) / np.maximum(t, 1e-12))),
        "force_bias_n": float(err.mean()),
        "n_frames": int(t.size),
    }


def force_coverage(
    true_n: np.ndarray, pred_n: np.ndarray, sigma_n: np.ndarray
) -> dict[str, Any]:
    """Calibration of a predicted force standard deviation: ``force_coverage_1sigma`` /
    ``_2sigma``, the share of frames with |pred − true| ≤ 1σ / 2σ (a Gaussian error of that σ
    gives 68.3 % / 95.4 %), and ``force_sigma_n_median``, over the frames with a finite σ > 0;
    None where no frame has one (a model that gives no σ), with ``n_frames`` those frames."""
    t, p, s = (np.asarray(a, float) for a in (true_n, pred_n, sigma_n))
    if not t.shape == p.shape == s.shape:
        raise EctskinError(
            f"force_coverage: true, pred and sigma must have one shape, got {t.shape}, "
            f"{p.shape}, {s.shape}"
        )
    ok = np.isfinite(s) & (s > 0)
    if not ok.any():
        return {"force_coverage_1sigma": None, "force_coverage_2sigma": None,
                "force_sigma_n_median": None, "n_frames": 0}
    z = np.abs(p[ok] - t[ok]) / s[ok]
    return {
        "force_coverage_1sigma": float(np.mean(z <= 1.0)),
        "force_coverage_2sigma": float(np.mean(z <= 2.0)),
        "force_sigma_n_median": float(np.median(s[ok])),
        "n_frames": int(ok.sum()),
    }


#: the parts of :func:`force_split`: (suffix of its keys, which frames)
FORCE_SPLIT_PARTS = ("observable", "not_observable", "no_bound")


def force_split(
    true_n: np.ndarray,
    pred_n: np.ndarray,
    bound_sd_n: np.ndarray,
    threshold_n: float,
    sigma_n: np.ndarray | None = None,
) -> dict[str, Any]:
    """The force error split by a per-frame bound on the force's standard deviation
    ``bound_sd_n`` (n,) N (NaN: no bound at that frame): frames with a bound below
    ``threshold_n`` are *observable*, those with one at or above it *not observable*, the rest
    *no bound*. Per part P of :data:`FORCE_SPLIT_PARTS`: ``force_mae_n_P`` (None without
    frames), ``share_P`` (of all frames), ``n_frames_P``, ``bound_force_n_mean_P`` (the mean
    bound there) and, with ``sigma_n`` (the model's own σ, NaN where it gives none), the
    :func:`force_coverage` ``force_coverage_1sigma_P`` / ``_2sigma_P``."""
    t, p, b = (np.asarray(a, float) for a in (true_n, pred_n, bound_sd_n))
    if not t.shape == p.shape == b.shape or t.ndim != 1:
        raise EctskinError(
            f"force_split: true, pred and bound_sd must be one-dimensional of one shape, got "
            f"{t.shape}, {p.shape}, {b.shape}"
        )
    if not (np.isfinite(threshold_n) and threshold_n > 0):
        raise EctskinError(f"force_split: threshold_n must be a number > 0, got {threshold_n!r}")
    has = np.isfinite(b)
    parts = {
        "observable": has & (b < threshold_n),
        "not_observable": has & ~(b < threshold_n),
        "no_bound": ~has,
    }
    err = np.abs(p - t)
    out: dict[str, Any] = {"threshold_n": float(threshold_n), "n_frames": int(t.size)}
    for name, m in parts.items():
        out[f"force_mae_n_{name}"] = float(err[m].mean()) if m.any() else None
        out[f"share_{name}"] = float(m.mean()) if t.size else None
        out[f"n_frames_{name}"] = int(m.sum())
        out[f"bound_force_n_mean_{name}"] = float(b[m].mean()) if (m & has).any() else None
        if sigma_n is not None:
            cov = force_coverage(t[m], p[m], np.asarray(sigma_n, float)[m])
            out[f"force_coverage_1sigma_{name}"] = cov["force_coverage_1sigma"]
            out[f"force_coverage_2sigma_{name}"] = cov["force_coverage_2sigma"]
    return out


def hover_metrics(
    height_mm: np.ndarray,
    hover_true: np.ndarray,
    hover_pred: np.ndarray,
    *,
    finger_present: np.ndarray,
    hover_max_mm: float,
    bin_mm: float = HOVER_BIN_MM,
    rate: float = HOVER_RATE,
) -> dict[str, Any]:
    """Hover detection over frames with no finger on the skin.

    ``height_mm`` (n,) the finger's height (NaN without a finger), ``hover_true``/``hover_pred``
    (n,) bool, ``finger_present`` (n,) bool (a finger somewhere above). Returns ``curve`` (bin
    edges and the detection rate per bin of height up to ``hover_max_mm``), ``hover_detect_mm``
    (the greatest height h such that every bin below h is detected at ``rate`` or more; 0 when
    the first bin is not), ``detection_rate`` (all hover frames), ``false_alarm_rate`` (frames
    with no finger within ``hover_max_mm`` flagged as hover).
    """
    h = np.asarray(height_mm, float)
    ht, hp = np.asarray(hover_true, bool), np.asarray(hover_pred, bool)
    edges = np.arange(0.0, hover_max_mm + bin_mm * 0.999, bin_mm)
    rates, counts = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = ht & (h > lo) & (h <= hi)
        counts.append(int(m.sum()))
        rates.append(float(hp[m].mean()) if m.any() else None)
    detect = 0.0
    for hi, r in zip(edges[1:], rates):
        if r is None:
            continue
        if r < rate:
            break
        detect = float(hi)
    far = ~ht
    out = {
        "hover_detect_mm": detect if ht.any() else None,
        "detection_rate": float(hp[ht].mean()) if ht.any() else None,
        "false_alarm_rate": float(hp[far].mean()) if far.any() else None,
        "false_alarm_rate_no_finger": (
            float(hp[far & ~np.asarray(finger_present, bool)].mean())
            if (far & ~np.asarray(finger_present, bool)).any()
            else None
        ),
        "curve": {"edges_mm": edges.tolist(), "rate": rates, "count": counts},
        "rate_threshold": rate,
        "n_hover_frames": int(ht.sum()),
    }
    return out


def match_fingers(true_pts: np.ndarray, pred_pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Match predicted points (m, 3) to true ones (k, 3) minimising the summed distance
    (Hungarian algorithm); returns (true index, pred index) of the matched pairs
    (min(k, m) of them)."""
    cost = point_distance(np.asarray(true_pts)[:, None, :], np.asarray(pred_pts)[None, :, :])
    return linear_sum_assignment(cost)


def multi_metrics(
    true_count: np.ndarray,
    pred_count: np.ndarray,
    true_pts: np.ndarray,
    pred_pts: np.ndarray,
    max_fingers: int,
) -> dict[str, Any]:
    """Finger count and per-finger error.

    ``true_pts``/``pred_pts`` (n, S, 3) rest points of the slots (only the first ``count`` slots
    of a frame are read). Returns ``count_accuracy`` (all frames), ``count_confusion``
    ((S+1) × (S+1), true rows), ``count_accuracy_by_true`` and, over frames with two or more true
    fingers and as many predicted, the error of each finger after Hungarian matching
    (``loc_mm_mean``, ``loc_mm_median``, ``loc_mm_p90``, ``n_fingers``).
    """
    tc, pc = np.asarray(true_count, int), np.asarray(pred_count, int)
    if tc.size == 0:
        raise EctskinError("multi_metrics: no frames")
    k = max_fingers + 1
    conf = np.zeros((k, k), int)
    np.add.at(conf, (np.clip(tc, 0, k - 1), np.clip(pc, 0, k - 1)), 1)
    errors = []
    for i in np.flatnonzero((tc >= 2) & (pc == tc)):
        n = tc[i]
        r, c = match_fingers(true_pts[i, :n], pred_pts[i, :n])
        errors.extend(point_distance(true_pts[i, r], pred_pts[i, c]).tolist())
    errors = np.asarray(errors)
    by_true = {
        str(c): (float(conf[c, c] / conf[c].sum()) if conf[c].sum() else None) for c in range(k)
    }
    summary = _summary(errors)
    summary["n_fingers"] = summary.pop("n_frames")
    return {
        "count_accuracy": float(np.mean(tc == pc)),
        "count_confusion": conf.tolist(),
        "count_accuracy_by_true": by_true,
        "n_frames": int(tc.size),
        "n_two_finger_frames": int((tc >= 2).sum()),
        **summary,
    }
