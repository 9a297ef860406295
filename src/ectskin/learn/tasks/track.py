"""Deformation tracking: :class:`TrackTask`, marker coordinates from a window of frames (C2DT).

Training: squared error in units of the model's ``out_scale`` for the gradient, reported in mm²;
metric = average distance AD, paper Eq. 3 (:class:`TrackCriterion`). Evaluation: AD overall, per
marker and per trajectory (:func:`ectskin.learn.metrics.track.track_metrics`), six examples (Fig. 9)
and one marker over a test trajectory (Fig. 10); baselines of
:func:`ectskin.learn.baselines.track.track_baselines`.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from ectskin._check import EctskinError
from ectskin.io import Recording
from ectskin.learn.baselines.track import track_baselines
from ectskin.learn.data.track import TrackData, track_dataset
from ectskin.learn.engine import Tensors
from ectskin.learn.metrics.track import track_metrics
from ectskin.learn.models import C2DT, C2DTConfig
from ectskin.learn.models.c2dt import coordinate_stats
from ectskin.learn.normalizer import Normalizer
from ectskin.learn.predict.base import forward_batches
from ectskin.learn.profiles import TrainSettings
from ectskin.learn.splits import TRACK_SPLIT
from ectskin.learn.tasks.base import Criterion, EvalCase, Task, as_tensor, build_config
from ectskin.viz.learning import plot_marker_trajectory, plot_tracking_examples

#: windows per batch when predicting a test split
PREDICT_BATCH = 1024
#: examples shown in Fig. 9
N_EXAMPLES = 6


class TrackCriterion(Criterion):
    """Squared error in units of ``out_scale`` for the gradient; reported in mm².

    val_loss = mean squared error per coordinate (mm²); metric = average distance, paper Eq. 3:
    AD = 1/(N M) Σ_i Σ_j ‖p_ij − p̂_ij‖ (mm).
    """

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.scale = float(getattr(model, "module", model).out_scale)

    def loss(
        self, model: nn.Module, batch: tuple[torch.Tensor, ...], rng: np.random.Generator | None
    ) -> torch.Tensor:
        x, init, y = batch
        err = (model(x, init) - y) / self.scale  # (B, M, 3), dimensionless
        return err.square().mean()

    def loss_to_report(self, loss_mean: torch.Tensor) -> torch.Tensor:
        return loss_mean * self.scale**2  # mm²

    def eval_sums(self, model: nn.Module, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        x, init, y = batch
        err = model(x, init) - y  # (B, M, 3) mm
        se = err.square().sum(-1)  # (B, M) mm²
        dist_sum = se.sqrt().mean(1).sum()  # Eq. 3 numerator over this batch (per-sample mean)
        return torch.stack([se.mean(1).sum() / 3, dist_sum, se.new_tensor(len(y))])

    def finish(self, sums: torch.Tensor) -> tuple[float, float]:
        se, ad, n = sums.tolist()
        return se / n, ad / n


class TrackTask(Task[TrackData]):
    """Deformation tracking: :class:`~ectskin.learn.data.track.TrackData` → C2DT."""

    name = "track"
    model_kind = C2DT.kind
    data_type = "TrackData"
    arrays = ("x", "y", "init")
    batch_fields = ("x", "init", "y")
    metric_name = "ad_mm"
    lower_is_better_metric = True
    split_counts = TRACK_SPLIT
    figure_captions: ClassVar[dict[str, str]] = {
        "fig9_tracking": "Fig. 9: tracking examples, estimated (red) vs true (blue) markers",
        "fig10_trajectory": "Fig. 10: one marker over a test trajectory",
    }

    # ------------------------------------------------------------------ data
    def check_options(self, *, window: int, prior: bool) -> None:
        if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
            raise EctskinError(f"window must be an integer >= 1 (frames), got {window!r}")

    def dataset(
        self, rec: Recording, *, window: int = 10, prior: bool = True, reference: Any = "auto"
    ) -> TrackData:
        return track_dataset(rec, window=window, prior=prior, reference=reference)

    def dataset_options(self, config: C2DTConfig) -> dict[str, Any]:
        return {"window": int(config.window), "prior": bool(config.prior)}

    def uses_rest_reference(self, config: C2DTConfig) -> bool:
        """Only the ablation without prior knowledge: the paper's C2DT calibrates each
        trajectory against its own first frame."""
        return not bool(config.prior)

    def _check_shapes(self, data: TrackData, what: str) -> None:
        x, y = data.x, data.y
        n = x.shape[0]
        if x.ndim != 3 or y.ndim != 3 or y.shape[0] != n or y.shape[2] != 3:
            raise EctskinError(
                f"{what}: track data must have x (n, k, n_pairs) and y (n, n_markers, 3), got "
                f"x {x.shape}, y {y.shape}"
            )
        if data.init.shape != y.shape:
            raise EctskinError(
                f"{what}: init must have the shape of y {y.shape}, got {data.init.shape}"
            )

    def tensors(self, data: TrackData, device: torch.device) -> Tensors:
        return Tensors(
            (
                as_tensor(data.x, np.float32, device),
                as_tensor(data.init, np.float32, device),
                as_tensor(data.y, np.float32, device),
            )
        )

    # ------------------------------------------------------------------ model
    def build_model(self, data: TrackData, model_options: dict[str, Any] | None) -> C2DT:
        desc = getattr(data, "electrode_desc", None)
        pairs = getattr(data, "pairs", None)
        has_desc = desc is not None and pairs is not None and np.size(desc) > 0
        shape = {
            "n_pairs": int(data.x.shape[2]),
            "window": int(data.x.shape[1]),
            "n_markers": int(data.y.shape[1]),
            "prior": bool(getattr(data, "prior", True)),
            "desc_dim": int(np.shape(desc)[1]) if has_desc else 0,
            "n_electrodes": int(np.shape(desc)[0]) if has_desc else 0,
        }
        config = build_config(C2DTConfig, shape, model_options)
        if not shape["desc_dim"]:
            desc = pairs = None
        return C2DT(config, desc, pairs)

    def fit_normalization(self, model: nn.Module, data: TrackData) -> dict[str, Any]:
        """Per-pair mean / std of the training windows (a :class:`Normalizer` over samples and
        frames) and the coordinate scales of :func:`~ectskin.learn.models.c2dt.coordinate_stats`,
        held in the model's buffers; returned as ``{"x": Normalizer.to_dict(), "pos_mean": ...}``.
        """
        norm = Normalizer.fit(data.x)
        coords = coordinate_stats(data.init, data.y, prior=model.config.prior)
        model.set_normalization(x_mean=norm.mean, x_std=norm.std, **coords)
        return {"x": norm.to_dict(), **coords}

    # ------------------------------------------------------------------ training
    def criterion(
        self, model: nn.Module, settings: TrainSettings, train_data: TrackData, device: torch.device
    ) -> TrackCriterion:
        return TrackCriterion(model)

    # ------------------------------------------------------------------ evaluation
    def predict(self, model: nn.Module, data: TrackData) -> np.ndarray:
        """(n, M, 3) float32 marker coordinates, mm."""
        return forward_batches(model, [data.x, data.init], batch_size=PREDICT_BATCH)

    def test_metrics(self, case: EvalCase[TrackData]) -> dict[str, Any]:
        """:func:`track_metrics` plus ``window``, ``prior`` and ``examples``: the samples of
        Fig. 9 (:func:`pick_examples`) with their AD (Eq. 3 per example) and the worst of them."""
        ds, test, pred = case.data, case.test, case.pred
        marker_names = [mk.name for mk in case.recording.layout.markers] or None
        m = track_metrics(
            pred,
            test.y,
            group=test.group,
            group_names=ds.group_names,
            marker_names=marker_names
            if marker_names and len(marker_names) == test.n_markers
            else None,
        )
        m["window"] = int(case.config.window)
        m["prior"] = bool(case.config.prior)
        ex = pick_examples(test)
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
        return m

    def baseline_metrics(self, train: TrackData, test: TrackData, *, seed: int) -> dict[str, Any]:
        return {k: r.to_metrics() for k, r in track_baselines(train, test, seed=seed).items()}

    def figures(self, case: EvalCase[TrackData], metrics: dict[str, Any]) -> dict[str, Any]:
        """Fig. 9 (the examples of ``metrics``) and Fig. 10, whose trial, marker and AD are
        added to ``metrics["examples"]["trajectory"]``."""
        ds, test, pred = case.data, case.test, case.pred
        ex = pick_examples(test)
        titles = [f"{ds.group_names[int(test.group[i])]}, frame {int(test.frame[i])}" for i in ex]
        fig9 = plot_tracking_examples(
            pred[ex], test.y[ex], init=test.init[ex] if test.prior else None, titles=titles
        )
        marker, rows = trajectory_example(test)
        g = int(test.group[rows[0]])
        t_s = test.frame[rows] / float(case.recording.frame_rate_hz)
        name = list(metrics["per_marker"])[marker]
        ad_traj = float(np.linalg.norm(pred[rows, marker] - test.y[rows, marker], axis=-1).mean())
        fig10 = plot_marker_trajectory(
            t_s,
            pred[rows, marker],
            test.y[rows, marker],
            marker_name=name,
            title=f"{name} in {ds.group_names[g]}: AD = {ad_traj:.3f} mm",
        )
        metrics["examples"]["trajectory"] = {
            "trial": ds.group_names[g],
            "marker": name,
            "ad_mm": ad_traj,
        }
        return {"fig9_tracking": fig9, "fig10_trajectory": fig10}


def pick_examples(test: TrackData, n: int = N_EXAMPLES) -> np.ndarray:
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


def trajectory_example(test: TrackData) -> tuple[int, np.ndarray]:
    """Fig. 10's choice: the marker that moves most, in the test trajectory where it moves most.

    Returns the marker index and that trajectory's sample indices in frame order.
    """
    ref = test.init if test.prior else test.y.mean(axis=0, keepdims=True)
    marker = int(np.argmax(np.linalg.norm(test.y - ref, axis=-1).mean(axis=0)))
    groups = np.unique(test.group)
    spread = [float(test.y[test.group == g, marker].std(axis=0).sum()) for g in groups]
    g = int(groups[int(np.argmax(spread))])
    rows = np.flatnonzero(test.group == g)
    return marker, rows[np.argsort(test.frame[rows])]
