"""Evaluation of trained runs: touch accuracy and confusions, tracking average distance (Eq. 3).

The metric functions are pure and work on plain arrays:

* :func:`confusion_matrix`, :func:`region_adjacency` and :func:`touch_metrics` give the paper's
  touch results: accuracy, the misclassified-frame count in the paper's "34 of 28 800" form, the
  19 × 19 confusion map (Fig. 7) and which confusions are between adjacent regions.
* :func:`marker_distances`, :func:`average_distance` and :func:`track_metrics` give the tracking
  results: the average distance AD of Eq. 3 (mean ± std over test samples and markers), per marker,
  per trajectory and the worst trajectory.

:func:`evaluate_run` ties them to a run directory written by ``ectskin train``: it rebuilds the
model from ``model.pt``, re-creates the data set and its test split from ``split.json``, predicts,
runs the baselines on the same split, writes ``metrics.json`` (atomically) and the figures.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array

log = logging.getLogger(__name__)

__all__ = [
    "average_distance",
    "confusion_matrix",
    "evaluate_run",
    "format_count",
    "marker_distances",
    "region_adjacency",
    "touch_metrics",
    "track_metrics",
    "write_json_atomic",
]


# --------------------------------------------------------------------------- touch
def format_count(n_wrong: int, n_total: int) -> str:
    """The paper's wording of a misclassification count, e.g. ``"34 of 28 800"``.

    Thousands are separated by a space as in the paper (thin-space free, plain ASCII space).
    """
    return f"{int(n_wrong):,} of {int(n_total):,}".replace(",", " ")


def confusion_matrix(y_true: Any, y_pred: Any, n_classes: int) -> np.ndarray:
    """Counts of (true class, predicted class), shape (n_classes, n_classes) int64.

    Row ``i`` holds the frames whose true class is ``i``; column ``j`` those predicted as ``j``
    (the layout of the paper's Fig. 7). Class 0 is "no touch".
    """
    yt = check_array("y_true", y_true, (None,), dtype=np.int64)
    yp = check_array("y_pred", y_pred, (yt.shape[0],), dtype=np.int64)
    for name, y in (("y_true", yt), ("y_pred", yp)):
        bad = (y < 0) | (y >= n_classes)
        if bad.any():
            k = int(np.argmax(bad))
            raise EctskinError(
                f"{name}[{k}] = {y[k]} is not a class of 0..{n_classes - 1} (n_classes={n_classes})"
            )
    conf = np.zeros((n_classes, n_classes), dtype=np.int64)
    np.add.at(conf, (yt, yp), 1)
    return conf


def region_adjacency(layout: Any, *, corners: bool = False, tol_mm: float = 0.01) -> np.ndarray:
    """Which touch classes are adjacent regions, shape (n_classes, n_classes) bool.

    Two regions are adjacent when they lie on the same surface and their rectangles share a
    border segment of positive length (``corners=True`` also counts rectangles that meet at a
    corner only). Class 0 ("no touch") is adjacent to nothing; the diagonal is False.
    ``tol_mm`` absorbs rounding in the layout file (region borders like -6.6667 mm).
    """
    n = layout.n_classes
    adj = np.zeros((n, n), dtype=bool)
    regions = list(layout.regions)
    for a in regions:
        for b in regions:
            if a.id == b.id or a.surface != b.surface:
                continue
            # gap (> 0: apart) and overlap length (> 0: overlapping) along each axis
            du = max(a.u_mm[0], b.u_mm[0]) - min(a.u_mm[1], b.u_mm[1])
            dv = max(a.v_mm[0], b.v_mm[0]) - min(a.v_mm[1], b.v_mm[1])
            if du > tol_mm or dv > tol_mm:
                continue  # apart along one axis
            touch_u, touch_v = abs(du) <= tol_mm, abs(dv) <= tol_mm
            if touch_u and touch_v:
                adj[a.id, b.id] = corners  # meet at a corner only
            elif touch_u or touch_v:
                adj[a.id, b.id] = True  # share a border segment of positive length
            # else the rectangles overlap: not a layout the checks admit; leave False
    return adj


def touch_metrics(
    y_true: Any,
    y_pred: Any,
    n_classes: int,
    *,
    adjacency: np.ndarray | None = None,
    group: Any = None,
    group_names: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Touch-recognition metrics of a test set.

    Parameters
    ----------
    y_true, y_pred : (n,) int
        True and predicted class per frame (0 = no touch).
    n_classes : int
        Number of classes (19 in the paper).
    adjacency : (n_classes, n_classes) bool, optional
        From :func:`region_adjacency`; marks each confusion as between adjacent regions or not.
    group, group_names : (n,) int and list of str, optional
        Trial of each frame, for the per-trial accuracy and the worst trial.

    Returns
    -------
    dict
        ``accuracy`` (fraction), ``n_test_frames``, ``n_misclassified``, ``misclassified``
        ("34 of 28 800"), ``confusion`` (nested lists, rows = true class), ``per_class_accuracy``
        (None for a class absent from the test set), ``confusions`` (list of {true, pred, count,
        adjacent} sorted by count), ``n_misclassified_adjacent`` and ``all_adjacent`` (when
        ``adjacency`` is given), ``per_trial`` / ``worst_trial`` (when ``group`` is given).
    """
    conf = confusion_matrix(y_true, y_pred, n_classes)
    n = int(conf.sum())
    if n == 0:
        raise EctskinError("touch_metrics: the test set is empty (0 frames)")
    correct = int(np.trace(conf))
    support = conf.sum(axis=1)
    per_class = [(float(conf[k, k] / support[k]) if support[k] else None) for k in range(n_classes)]
    off = [(int(i), int(j), int(conf[i, j])) for i, j in zip(*np.nonzero(conf)) if i != j]
    off.sort(key=lambda t: (-t[2], t[0], t[1]))
    confusions = []
    for i, j, c in off:
        item: dict[str, Any] = {"true": i, "pred": j, "count": c}
        if adjacency is not None:
            item["adjacent"] = bool(adjacency[i, j])
        confusions.append(item)
    out: dict[str, Any] = {
        "accuracy": correct / n,
        "n_test_frames": n,
        "n_misclassified": n - correct,
        "misclassified": format_count(n - correct, n),
        "n_classes": int(n_classes),
        "confusion": conf.tolist(),
        "per_class_accuracy": per_class,
        "confusions": confusions,
    }
    if adjacency is not None:
        adjacency = np.asarray(adjacency, dtype=bool)
        if adjacency.shape != (n_classes, n_classes):
            raise EctskinError(
                f"adjacency must have shape ({n_classes}, {n_classes}), got {adjacency.shape}"
            )
        n_adj = int(conf[adjacency].sum())
        out["n_misclassified_adjacent"] = n_adj
        out["all_adjacent"] = n_adj == n - correct
    if group is not None:
        g = check_array("group", group, (n,), dtype=np.int64)
        yt = np.asarray(y_true, dtype=np.int64)
        ok = yt == np.asarray(y_pred, dtype=np.int64)
        trials = []
        for gid in np.unique(g):
            sel = g == gid
            name = group_names[gid] if group_names is not None else str(int(gid))
            trials.append(
                {
                    "name": name,
                    "label": int(np.bincount(yt[sel]).argmax()),
                    "n_frames": int(sel.sum()),
                    "accuracy": float(ok[sel].mean()),
                }
            )
        out["per_trial"] = trials
        out["worst_trial"] = min(trials, key=lambda t: t["accuracy"])
    return out


# --------------------------------------------------------------------------- tracking
def marker_distances(pred: Any, true: Any) -> np.ndarray:
    """Euclidean distance per sample and marker, ||p_ij − p̂_ij|| of Eq. 3, shape (N, M), mm.

    ``pred`` and ``true`` are (N, M, 3) marker coordinates in mm (the same shape).
    """
    p = check_array("pred", pred, (None, None, 3))
    t = check_array("true", true, p.shape)
    if not np.all(np.isfinite(t)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(t))[0])
        raise EctskinError(
            f"true marker coordinates must be finite (occluded frames are not tracking test "
            f"samples); found {t[bad]} at sample {bad[0]}, marker {bad[1]}"
        )
    if not np.all(np.isfinite(p)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(p))[0])
        raise EctskinError(
            f"predicted marker coordinates are not finite: {p[bad]} at sample {bad[0]}, "
            f"marker {bad[1]}"
        )
    return np.linalg.norm(p - t, axis=-1)


def average_distance(pred: Any, true: Any) -> tuple[float, float]:
    """The paper's average distance AD (Eq. 3) and its standard deviation, mm.

    AD = 1/(N M) Σ_i Σ_j ||p_ij − p̂_ij||  (Eq. 3), over N samples and M markers; the std is
    the population standard deviation of the same N·M distances (the paper's "2.905 ± 2.207 mm").

    Parameters
    ----------
    pred, true : (N, M, 3) array
        Estimated and ground-truth marker coordinates, mm.
    """
    d = marker_distances(pred, true)
    if d.size == 0:
        raise EctskinError("average_distance: no samples (N·M = 0)")
    return float(d.mean()), float(d.std())


def track_metrics(
    pred: Any,
    true: Any,
    *,
    group: Any = None,
    group_names: Sequence[str] | None = None,
    marker_names: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Tracking metrics of a test set: AD (Eq. 3) overall, per marker and per trajectory.

    Parameters
    ----------
    pred, true : (N, M, 3) array
        Estimated and true marker coordinates, mm.
    group : (N,) int, optional
        Trajectory (trial) index of each sample; ``group_names`` names them.
    marker_names : list of str, optional
        Names of the M markers (default ``M1``…).

    Returns
    -------
    dict
        ``ad_mm_mean``, ``ad_mm_std`` (Eq. 3 over all samples and markers), ``ad_mm_median``,
        ``ad_mm_p95``, ``ad_mm_max``, ``n_test_samples``, ``n_markers``, ``per_marker`` ({name:
        {ad_mm_mean, ad_mm_std}}), and with ``group``: ``n_test_trajectories``, ``per_trajectory``
        (list of {name, n_samples, ad_mm_mean, ad_mm_std}) and ``worst_trajectory``.
    """
    d = marker_distances(pred, true)  # (N, M)
    n, m = d.shape
    if n == 0:
        raise EctskinError("track_metrics: the test set is empty (0 samples)")
    names = list(marker_names) if marker_names is not None else [f"M{k + 1}" for k in range(m)]
    if len(names) != m:
        raise EctskinError(f"marker_names has {len(names)} names for {m} markers")
    out: dict[str, Any] = {
        "ad_mm_mean": float(d.mean()),
        "ad_mm_std": float(d.std()),
        "ad_mm_median": float(np.median(d)),
        "ad_mm_p95": float(np.percentile(d, 95)),
        "ad_mm_max": float(d.max()),
        "n_test_samples": int(n),
        "n_markers": int(m),
        "per_marker": {
            name: {"ad_mm_mean": float(d[:, k].mean()), "ad_mm_std": float(d[:, k].std())}
            for k, name in enumerate(names)
        },
    }
    if group is not None:
        g = check_array("group", group, (n,), dtype=np.int64)
        trajs = []
        for gid in np.unique(g):
            dg = d[g == gid]
            trajs.append(
                {
                    "name": group_names[gid] if group_names is not None else str(int(gid)),
                    "n_samples": int(dg.shape[0]),
                    "ad_mm_mean": float(dg.mean()),
                    "ad_mm_std": float(dg.std()),
                }
            )
        out["n_test_trajectories"] = len(trajs)
        out["per_trajectory"] = trajs
        out["worst_trajectory"] = max(trajs, key=lambda t: t["ad_mm_mean"])
    return out


# --------------------------------------------------------------------------- files
def _jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and paths inside ``obj`` to plain JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not np.isfinite(obj):
        return None  # JSON has no NaN/inf
    return obj


def write_json_atomic(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON to ``path`` atomically (temp file + fsync + os.replace)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(_jsonable(obj), f, indent=1, allow_nan=False)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def read_json(path: str | Path, what: str = "file") -> Any:
    """Read a JSON file, turning a missing or malformed file into one clear EctskinError."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise EctskinError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise EctskinError(f"{path}: cannot read {what}: {exc.strerror}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise EctskinError(
            f"{path}: {what} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None


# --------------------------------------------------------------------------- runs
#: Figures ``evaluate_run`` writes into the run directory: file name → caption.
TOUCH_FIGURES = {"fig7_confusion.png": "Fig. 7: confusion map of the test set"}
TRACK_FIGURES = {
    "fig9_tracking.png": "Fig. 9: tracking examples, estimated (red) vs true (blue) markers",
    "fig10_trajectory.png": "Fig. 10: one marker over a test trajectory",
}
CURVES_FIGURE = "learning_curves.png"


def _predict_touch(model: Any, x: np.ndarray, batch: int = 8192) -> np.ndarray:
    """(n, n_pairs) calibrated frames → (n,) int64 predicted classes (argmax of the logits)."""
    import torch

    out = np.empty(x.shape[0], dtype=np.int64)
    model.eval()
    with torch.inference_mode():
        for a in range(0, x.shape[0], batch):
            xb = torch.from_numpy(np.ascontiguousarray(x[a : a + batch], dtype=np.float32))
            out[a : a + batch] = model(xb).argmax(dim=1).numpy()
    return out


def _predict_track(model: Any, x: np.ndarray, init: np.ndarray, batch: int = 1024) -> np.ndarray:
    """(n, k, n_pairs) windows and (n, M, 3) initial coordinates → (n, M, 3) coordinates, mm."""
    import torch

    n, m = x.shape[0], init.shape[1]
    out = np.empty((n, m, 3), dtype=np.float32)
    model.eval()
    with torch.inference_mode():
        for a in range(0, n, batch):
            xb = torch.from_numpy(np.ascontiguousarray(x[a : a + batch], dtype=np.float32))
            ib = torch.from_numpy(np.ascontiguousarray(init[a : a + batch], dtype=np.float32))
            out[a : a + batch] = model(xb, ib).numpy()
    return out


def read_split(run_dir: str | Path) -> dict[str, Any]:
    """Read and check ``run_dir/split.json``: train / val / test trial names (+ data settings)."""
    path = Path(run_dir) / "split.json"
    info = read_json(path, "split file")
    if not isinstance(info, dict):
        raise EctskinError(f"{path}: expected a JSON object, found {type(info).__name__}")
    for key in ("train", "val", "test"):
        names = info.get(key)
        if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
            raise EctskinError(f"{path}: field {key!r} must be a list of trial names")
    if not info["test"]:
        raise EctskinError(f"{path}: the test split is empty; nothing to evaluate")
    return info


def _load_data(data: Any, split: Mapping[str, Any], run: Path) -> tuple[Any, str]:
    """The recording to evaluate on: ``data`` (Recording or path) or the one named in split.json."""
    from ectskin.io.recording import Recording

    if isinstance(data, Recording):
        return data, "given Recording"
    if data is None:
        stored = split.get("data")
        if not stored:
            raise EctskinError(
                f"{run / 'split.json'}: names no data file; pass the recording (--data DATA.h5)"
            )
        path = Path(stored)
        if not path.is_absolute():
            path = run / path
        if not path.exists():
            raise EctskinError(
                f"{run / 'split.json'}: data file {path} no longer exists; pass --data DATA.h5"
            )
    else:
        path = Path(data)
    from ectskin.learn.train import load_recording  # HDF5, or a generic .npz / .csv import

    return load_recording(path), str(path)


def _run_config(run: Path) -> dict[str, Any]:
    """The run's ``config.json`` (written by ``ectskin train``), or {} when absent or unreadable."""
    path = run / "config.json"
    if not path.is_file():
        return {}
    try:
        cfg = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return cfg if isinstance(cfg, dict) else {}


def describe_recipe(recipe: Mapping[str, Any] | None, metric: str = "accuracy") -> str:
    """A phrase for a run's training recipe (``recipe`` of its config.json), e.g. "inflation
    shift over 25 no-contact training states, mixup (Beta 0.4, 0.4), label smoothing 0.1, weights
    of the best validation accuracy"; "the paper's recipe" for none of these."""
    if not recipe:
        return "the paper's recipe"
    parts = []
    if recipe.get("inflation_shift"):
        n = int(recipe.get("inflation_shift_states") or 0)
        parts.append(
            f"inflation shift over {n} no-contact training states"
            if n >= 2
            else "inflation shift skipped (fewer than 2 no-contact training trials)"
        )
    alpha = float(recipe.get("mixup_alpha") or 0)
    if alpha > 0:
        parts.append(f"mixup (Beta {alpha:g}, {alpha:g})")
    smoothing = float(recipe.get("label_smoothing") or 0)
    if smoothing > 0:
        parts.append(f"label smoothing {smoothing:g}")
    if recipe.get("select") == "val_metric":
        parts.append(f"weights of the best validation {metric}")
    elif parts:
        parts.append("weights of the lowest validation loss")
    return ", ".join(parts) or "the paper's recipe"


def _training_summary(run: Path, kept: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Epochs, best epoch and total time from the run's ``metrics.csv`` (if present).

    The best epoch, validation loss and metric are those of the kept weights, read from the
    checkpoint's metadata (``kept``: its ``extra``, written by ``train`` with ``epoch``,
    ``val_loss``, ``val_metric``), so they follow whatever rule chose them; without that
    metadata, the epoch of the lowest validation loss (the paper's rule). The run's selection
    rule and ``recipe`` (``config.json``) are passed on when present.
    """
    import csv

    path = run / "metrics.csv"
    if not path.is_file():
        return {}
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    cfg = _run_config(run)

    def col(name: str) -> np.ndarray:
        try:
            return np.array([float(r[name]) for r in rows])
        except (KeyError, TypeError, ValueError):
            return np.full(len(rows), np.nan)

    val = col("val_loss")
    out: dict[str, Any] = {}
    if cfg:
        out["select"] = (cfg.get("settings") or {}).get("select", "val_loss")
    if isinstance(cfg.get("recipe"), dict):
        out["recipe"] = cfg["recipe"]
    kept = kept or {}
    if all(k in kept for k in ("epoch", "val_loss", "val_metric")):
        best = {
            "best_epoch": int(kept["epoch"]),
            "best_val_loss": float(kept["val_loss"]),
            "best_val_metric": float(kept["val_metric"]),
        }
    else:
        i = int(np.nanargmin(val)) if np.isfinite(val).any() else len(rows) - 1
        epoch = col("epoch")[i]
        best = {
            "best_epoch": int(epoch) if np.isfinite(epoch) else i + 1,
            "best_val_loss": float(val[i]),
            "best_val_metric": float(col("val_metric")[i]),
        }
    return {
        **out,
        "epochs": len(rows),
        **best,
        "seconds": float(np.nansum(col("seconds"))),
        "history": {k: col(k).tolist() for k in ("epoch", "train_loss", "val_loss")},
    }


def _pick_examples(test: Any, n: int = 6) -> np.ndarray:
    """Indices of ``n`` test samples for Fig. 9: one per trajectory, spread evenly over the test
    trajectories, each at the frame where the markers moved most from their initial position
    (a deterministic, not hand-picked, choice). Fewer trajectories than ``n``: several frames each.
    """
    groups = np.unique(test.group)
    ref = test.init if test.prior else test.y.mean(axis=0, keepdims=True)
    motion = np.linalg.norm(test.y - ref, axis=-1).mean(axis=1)  # (n,) mean marker motion, mm
    picked: list[int] = []
    if groups.size >= n:
        for g in groups[np.round(np.linspace(0, groups.size - 1, n)).astype(int)]:
            rows = np.flatnonzero(test.group == g)
            picked.append(int(rows[np.argmax(motion[rows])]))
    else:
        per = int(np.ceil(n / groups.size))
        for g in groups:
            rows = np.flatnonzero(test.group == g)
            order = rows[np.argsort(-motion[rows], kind="stable")]
            picked += [
                int(i) for i in order[np.round(np.linspace(0, order.size - 1, per)).astype(int)]
            ]
        picked = sorted(set(picked))[:n]
    return np.asarray(picked, dtype=np.int64)


def _save(fig: Any, path: Path) -> None:
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def evaluate_run(
    run_dir: str | Path,
    data: Any = None,
    *,
    baselines: bool = True,
    figures: bool = True,
    write: bool = True,
    seed: int = 0,
) -> dict[str, Any]:
    """Evaluate a trained run on its test split; write ``metrics.json`` and figures into it.

    Parameters
    ----------
    run_dir : path
        A run directory of ``ectskin train`` (``model.pt``, ``split.json``, ``metrics.csv``).
    data : Recording or path, optional
        The recording; default the data file named in ``split.json``. The data set is rebuilt
        with the run's settings (task, window, prior, reference) and the split re-created from
        the trial names in ``split.json``.
    baselines : bool
        Also fit and score the baselines of :mod:`ectskin.learn.baselines` on the same split
        (touch: majority, logistic regression, random forest, k-NN; tracking: markers do not move,
        mean pose, ridge regression).
    figures : bool
        Write Fig. 7 (touch) or Fig. 9 and Fig. 10 (tracking) and the learning curves.
    write : bool
        Write ``metrics.json`` (atomically).

    Returns
    -------
    dict
        ``{"touch": {...}}`` for a TouchMLP run or ``{"track": {...}}`` for a C2DT run (see
        :func:`touch_metrics` / :func:`track_metrics`), each with ``baselines``, ``training``
        (epochs, best epoch, seconds from ``metrics.csv``), ``split`` (trial counts), the
        ``figures`` written ({file name: caption}) and ``evaluate_seconds``; tracking adds
        ``window``, ``prior`` and ``examples`` (the 6 samples of Fig. 9 with their AD, the
        worst of them, and the trajectory of Fig. 10).
    """
    from ectskin.learn.checkpoint import check_channels, load_checkpoint
    from ectskin.learn.datasets import split_from_names

    t0 = time.perf_counter()
    run = Path(run_dir)
    if not run.is_dir():
        raise EctskinError(f"run directory {run} does not exist")
    model, config, payload = load_checkpoint(run / "model.pt")
    split_info = read_split(run)
    rec, data_desc = _load_data(data, split_info, run)
    kind = payload["kind"]
    task = {"touch_mlp": "touch", "c2dt": "track"}[kind]
    if split_info.get("task", task) != task:
        raise EctskinError(
            f"{run / 'split.json'}: task {split_info.get('task')!r} does not match the model "
            f"in model.pt ({kind!r})"
        )
    src = f"{run / 'split.json'}"
    out: dict[str, Any] = {"data": data_desc}
    figs: dict[str, str] = {}
    if task == "touch":
        from ectskin.learn.datasets import touch_dataset

        ds = touch_dataset(rec, reference=split_info.get("reference", "auto"))
        check_channels(run / "model.pt", config, ds.n_pairs)
        split = split_from_names(split_info, ds.group_names, source=src)
        test = ds.select(split["test"])
        pred = _predict_touch(model, test.x)
        adjacency = region_adjacency(rec.layout) if rec.layout.n_classes == ds.n_classes else None
        m = touch_metrics(
            test.y,
            pred,
            ds.n_classes,
            adjacency=adjacency,
            group=test.group,
            group_names=ds.group_names,
        )
        if baselines:
            from ectskin.learn.baselines import touch_baselines

            train = ds.select(split["train"])
            m["baselines"] = {
                k: r.to_metrics() for k, r in touch_baselines(train, test, seed=seed).items()
            }
        if figures:
            from ectskin.viz.learning import plot_confusion

            _save(plot_confusion(np.asarray(m["confusion"])), run / "fig7_confusion.png")
            figs.update(TOUCH_FIGURES)
    else:
        from ectskin.learn.datasets import track_dataset

        ds = track_dataset(
            rec,
            window=int(config.window),
            prior=bool(config.prior),
            reference=split_info.get("reference", "auto"),
        )
        check_channels(run / "model.pt", config, ds.n_pairs)
        split = split_from_names(split_info, ds.group_names, source=src)
        test = ds.select(split["test"])
        pred = _predict_track(model, test.x, test.init)
        marker_names = [mk.name for mk in rec.layout.markers] or None
        m = track_metrics(
            pred,
            test.y,
            group=test.group,
            group_names=ds.group_names,
            marker_names=marker_names
            if marker_names and len(marker_names) == test.n_markers
            else None,
        )
        m["window"] = int(config.window)
        m["prior"] = bool(config.prior)
        ex = _pick_examples(test)
        ex_ad = np.linalg.norm(pred[ex] - test.y[ex], axis=-1).mean(axis=1)  # Eq. 3 per example
        m["examples"] = {
            "samples": [
                {
                    "trial": ds.group_names[int(test.group[i])],
                    "frame": int(test.frame[i]),
                    "ad_mm": float(a),
                }
                for i, a in zip(ex, ex_ad)
            ],
            "ad_mm": [float(a) for a in ex_ad],
            "worst_ad_mm": float(ex_ad.max()),
        }
        if baselines:
            from ectskin.learn.baselines import track_baselines

            train = ds.select(split["train"])
            m["baselines"] = {
                k: r.to_metrics() for k, r in track_baselines(train, test, seed=seed).items()
            }
        if figures:
            from ectskin.viz.learning import plot_marker_trajectory, plot_tracking_examples

            titles = [
                f"{ds.group_names[int(test.group[i])]}, frame {int(test.frame[i])}" for i in ex
            ]
            fig = plot_tracking_examples(
                pred[ex], test.y[ex], init=test.init[ex] if test.prior else None, titles=titles
            )
            _save(fig, run / "fig9_tracking.png")
            # Fig. 10: the marker that moves most, in the test trajectory where it moves most
            ref = test.init if test.prior else test.y.mean(axis=0, keepdims=True)
            marker = int(np.argmax(np.linalg.norm(test.y - ref, axis=-1).mean(axis=0)))
            groups = np.unique(test.group)
            spread = [float(test.y[test.group == g, marker].std(axis=0).sum()) for g in groups]
            g = int(groups[int(np.argmax(spread))])
            rows = np.flatnonzero(test.group == g)
            rows = rows[np.argsort(test.frame[rows])]
            t_s = test.frame[rows] / float(rec.frame_rate_hz)
            name = list(m["per_marker"])[marker]
            ad_traj = float(
                np.linalg.norm(pred[rows, marker] - test.y[rows, marker], axis=-1).mean()
            )
            fig = plot_marker_trajectory(
                t_s,
                pred[rows, marker],
                test.y[rows, marker],
                marker_name=name,
                title=f"{name} in {ds.group_names[g]}: AD = {ad_traj:.3f} mm",
            )
            _save(fig, run / "fig10_trajectory.png")
            m["examples"]["trajectory"] = {
                "trial": ds.group_names[g],
                "marker": name,
                "ad_mm": ad_traj,
            }
            figs.update(TRACK_FIGURES)
    training = _training_summary(run, payload.get("extra"))
    history = training.pop("history", None)
    if figures and history:
        from ectskin.viz.learning import plot_learning_curves

        _save(plot_learning_curves(history, title=f"{task}: {run.name}"), run / CURVES_FIGURE)
        figs[CURVES_FIGURE] = "training and validation loss per epoch"
    m["training"] = {
        **training,
        **{
            k: v
            for k, v in payload.get("extra", {}).items()
            if k in ("device", "profile", "seed", "world_size")
        },
    }
    m["split"] = {k: len(split_info[k]) for k in ("train", "val", "test")}
    m["figures"] = figs
    m["evaluate_seconds"] = time.perf_counter() - t0
    out[task] = m
    if write:
        write_json_atomic(run / "metrics.json", out)
        log.info("wrote %s", run / "metrics.json")
    return out
