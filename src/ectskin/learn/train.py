"""Training of the paper's models with named profiles, exact resume and optional DDP.

:func:`train` fits :class:`~ectskin.learn.models.TouchMLP` (``task="touch"``) or
:class:`~ectskin.learn.models.C2DT` (``task="track"``) on in-memory data and writes a run
directory::

    out_dir/model.pt      best-validation weights (a checkpoint, see ectskin.learn.checkpoint)
    out_dir/last.pt       the same plus optimizer, scheduler and epoch, to resume
    out_dir/metrics.csv   epoch, train_loss, val_loss, val_metric, lr, seconds
    out_dir/config.json   task, profile, training settings, recipe, model config, data sizes
    out_dir/split.json    trial (group) names per split

Profiles (:data:`PROFILES`):

* ``paper`` — the paper's settings (§4): Adam, lr 1e-3 divided by 1.2 every 15 epochs
  (StepLR, gamma 1/1.2); touch 100 epochs of batch 256, track 150 epochs of batch 255; the
  weights with the lowest validation loss are kept.
* ``quick`` — for a laptop CPU (the ``demo``: ~75 000 touch frames and ~65 000 tracking windows
  in the training split): touch 30 epochs of batch 256 with the learning rate divided by 1.2
  every 5 epochs (~0.3 s per epoch on one core); track 20 epochs, each on a fresh random subset
  of 8 192 training windows (windows of one trajectory are strongly correlated, so a subset per
  epoch loses little: on the twin's demo data the validation error had levelled off after ~6 such
  epochs), batch 256, divided by 1.2 every 2 epochs, validated on a fixed subset of 4 096
  windows (~5-6 s per epoch on one loaded core). Both keep the paper's optimizer and
  best-validation rule; together they train in about 2 minutes.
* ``robust`` (touch only; ours, not the paper's) — the paper's TouchMLP, unchanged, trained with
  a recipe that generalises to unseen (inflation state, touch placement) combinations. On the
  twin's paper-protocol data with a trial-exclusive split the paper's recipe fits the training
  trials exactly (best validation loss at epoch 1 for seeds 0 and 1) and reaches 74-92 %; this
  one reached 97.1, 93.8 and 96.2 % for seeds 0-2 (20 epochs, ~11 s on one core). Per training
  frame it adds an *inflation shift*, the difference between the mean no-contact frames of two
  training inflation states drawn at random ("the same touch seen at another inflation"; see
  :func:`no_contact_means`, :func:`augment_touch_batch`), then mixes the batch up (mixup,
  Beta(0.4, 0.4), a λ per sample), uses cross-entropy with label smoothing 0.1, Adam 1e-3
  divided by 1.2 every 5 epochs, batch 256, 20 epochs, and keeps the weights with the best
  validation *accuracy*, ties broken by the lower validation loss (under the paper's recipe the
  validation loss rises from epoch 1 on while the validation accuracy still improves).

Loop structure (DETR ``engine.py`` style): :func:`train_one_epoch` and :func:`evaluate` are
separate; a non-finite loss stops training with an error naming the epoch and batch.

Determinism and resume: the epoch permutation and every random draw of an epoch (dropout, and
the augmentation's draws from its own numpy generator) are seeded from ``(seed, epoch, rank)``,
so a run that is stopped and resumed from ``last.pt`` produces the same weights, bit for bit on
CPU, as an uninterrupted one.

Distributed data parallel: the same :func:`train` runs unchanged under
``torchrun --nproc_per_node N`` (detected from ``WORLD_SIZE``/``RANK``/``LOCAL_RANK``; gloo on CPU,
nccl on CUDA). Each rank takes every N-th index of the same epoch permutation (the
``DistributedSampler`` scheme, padded to a multiple of N), with a per-rank batch of
``ceil(batch_size / N)``, so the global batch matches the single-process one (exactly when
``batch_size`` is divisible by N). Losses and metrics are all-reduced; only rank 0 writes
files and shows progress. Each rank augments its own shard (mixup pairs frames within the rank's
batch).
"""

from __future__ import annotations

import atexit
import csv
import hashlib
import inspect
import json
import logging
import math
import os
import sys
import time
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch import nn

from ectskin._check import EctskinError, check_option
from ectskin.learn.checkpoint import (
    config_from_dict,
    read_checkpoint,
    save_checkpoint,
    to_plain,
)
from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP, TouchMLPConfig
from ectskin.learn.models import c2dt as c2dt_module

logger = logging.getLogger(__name__)

TASKS = ("touch", "track")
METRICS_COLUMNS = ("epoch", "train_loss", "val_loss", "val_metric", "lr", "seconds")
SELECT = ("val_loss", "val_metric")


@dataclass(frozen=True)
class TrainSettings:
    """Optimisation settings of one profile and task (Adam + StepLR, paper §4), and the touch
    recipe: augmentation, label smoothing and the rule that picks the kept weights (defaults:
    the paper's; the ``robust`` profile sets them, see the module docstring)."""

    epochs: int
    batch_size: int  # global batch (split over DDP ranks)
    lr: float = 1e-3
    step_size: int = 15  # StepLR: epochs between learning-rate decays
    gamma: float = 1 / 1.2  # "decayed by a factor of 1.2 every 15 epochs"
    samples_per_epoch: int | None = None  # None: every training sample once per epoch
    val_samples: int | None = None  # None: the whole validation set each epoch
    eval_batch_size: int = 2048
    # --- touch recipe (defaults: the paper's, no augmentation) --------------------------------
    inflation_shift: bool = False  # add mean(no-contact state a) - mean(state b) per frame
    mixup_alpha: float = 0.0  # > 0: mixup with Beta(alpha, alpha), one lambda per sample
    label_smoothing: float = 0.0  # of the training cross-entropy (validation loss: plain CE)
    select: str = "val_loss"  # keep the weights of the lowest val_loss or the best val_metric

    @property
    def augments(self) -> bool:
        return self.inflation_shift or self.mixup_alpha > 0


#: profile → task → settings. See the module docstring for the reasoning of ``quick``.
PROFILES: dict[str, dict[str, TrainSettings]] = {
    "paper": {
        "touch": TrainSettings(epochs=100, batch_size=256),
        "track": TrainSettings(epochs=150, batch_size=255),
    },
    "quick": {
        "touch": TrainSettings(epochs=30, batch_size=256, step_size=5),
        "track": TrainSettings(
            epochs=20, batch_size=256, step_size=2, samples_per_epoch=8192, val_samples=4096
        ),
    },
    "robust": {
        "touch": TrainSettings(
            epochs=20,
            batch_size=256,
            step_size=5,
            inflation_shift=True,
            mixup_alpha=0.4,
            label_smoothing=0.1,
            select="val_metric",
        ),
    },
}
#: the fields of the touch recipe, stored as ``recipe`` in config.json and metrics.json
RECIPE_FIELDS = ("inflation_shift", "mixup_alpha", "label_smoothing", "select")


def profiles_for(task: str) -> tuple[str, ...]:
    """The names of the profiles that have settings for ``task``."""
    return tuple(name for name, per_task in PROFILES.items() if task in per_task)


def profile_settings(task: str, profile: str = "paper", **overrides: Any) -> TrainSettings:
    """The :class:`TrainSettings` of ``profile`` for ``task`` with ``overrides`` applied
    (e.g. ``samples_per_epoch=None`` to use every training sample in the quick profile)."""
    check_option("task", task, TASKS)
    check_option("profile", profile, tuple(PROFILES))
    if task not in PROFILES[profile]:
        available = ", ".join(repr(p) for p in profiles_for(task))
        raise EctskinError(
            f"profile {profile!r} has no settings for task {task!r} (it exists for "
            f"{', '.join(repr(t) for t in PROFILES[profile])} only); profiles for {task!r}: "
            f"{available}"
        )
    settings = PROFILES[profile][task]
    names = {f.name for f in fields(TrainSettings)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise EctskinError(f"unknown training setting(s): {', '.join(unknown)}")
    settings = replace(settings, **overrides)
    for name in ("epochs", "batch_size", "step_size", "eval_batch_size"):
        v = getattr(settings, name)
        if not isinstance(v, int | np.integer) or isinstance(v, bool) or v < 1:
            raise EctskinError(f"training setting {name!r} must be a positive integer, got {v!r}")
    for name in ("samples_per_epoch", "val_samples"):
        v = getattr(settings, name)
        if v is not None and (not isinstance(v, int | np.integer) or v < 1):
            raise EctskinError(f"training setting {name!r} must be None or >= 1, got {v!r}")
    if not (settings.lr > 0 and math.isfinite(settings.lr)):
        raise EctskinError(f"training setting 'lr' must be > 0, got {settings.lr!r}")
    if not 0 < settings.gamma <= 1:
        raise EctskinError(f"training setting 'gamma' must be in (0, 1], got {settings.gamma!r}")
    if not isinstance(settings.inflation_shift, bool | np.bool_):
        raise EctskinError(
            f"training setting 'inflation_shift' must be True or False, got "
            f"{settings.inflation_shift!r}"
        )
    if not (settings.mixup_alpha >= 0 and math.isfinite(settings.mixup_alpha)):
        raise EctskinError(
            f"training setting 'mixup_alpha' must be >= 0 (0: no mixup), got "
            f"{settings.mixup_alpha!r}"
        )
    if not 0 <= settings.label_smoothing < 1:
        raise EctskinError(
            f"training setting 'label_smoothing' must be in [0, 1), got "
            f"{settings.label_smoothing!r}"
        )
    check_option("select", settings.select, SELECT)
    if task != "touch" and (settings.augments or settings.label_smoothing > 0):
        raise EctskinError(
            "training settings 'inflation_shift', 'mixup_alpha' and 'label_smoothing' apply to "
            f"task 'touch' only, got {settings.inflation_shift!r}, {settings.mixup_alpha!r}, "
            f"{settings.label_smoothing!r} for {task!r}"
        )
    return settings


# ============================================================================ distributed
@dataclass
class _Dist:
    rank: int = 0
    world_size: int = 1
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def main(self) -> bool:
        return self.rank == 0


def _setup(device: str | torch.device | None) -> _Dist:
    """Detect torchrun (``WORLD_SIZE`` > 1), initialise the process group, pick the device."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    if device is None:
        device = f"cuda:{local_rank}" if torch.cuda.is_available() else "cpu"
    device = torch.device(device)
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", local_rank if world > 1 else 0)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise EctskinError(f"device {str(device)!r} requested, but CUDA is not available")
    if world <= 1:
        return _Dist(device=device)
    if not dist.is_initialized():
        # one process group for the life of the process (a later train() call reuses it)
        backend = "nccl" if device.type == "cuda" else "gloo"
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group(backend=backend)
        atexit.register(_destroy_group)
    return _Dist(dist.get_rank(), dist.get_world_size(), device)


def _destroy_group() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def _all_reduce(t: torch.Tensor, d: _Dist, op=None) -> torch.Tensor:
    if d.enabled:
        dist.all_reduce(t, op=op or dist.ReduceOp.SUM)
    return t


# ============================================================================ data
@dataclass
class _Tensors:
    """One split as tensors on the training device (touch: init is None)."""

    x: torch.Tensor  # touch (n, P) / track (n, k, P) calibrated
    y: torch.Tensor  # touch (n,) int64 / track (n, M, 3) mm
    init: torch.Tensor | None = None  # track (n, M, 3) mm

    @property
    def n(self) -> int:
        return int(self.x.shape[0])

    def batch(self, idx: torch.Tensor) -> tuple[torch.Tensor, ...]:
        if self.init is None:
            return self.x[idx], self.y[idx]
        return self.x[idx], self.init[idx], self.y[idx]


def _group_name(data: Any, i: int) -> str:
    """Where sample i comes from, for error messages: "trial 'name' (sample i, frame f)"."""
    try:
        where = f"trial {data.group_names[int(data.group[i])]!r} (sample {i}"
    except (AttributeError, IndexError, TypeError, ValueError):
        return f"sample {i}"
    frame = getattr(data, "frame", None)
    return where + (f", frame {int(frame[i])})" if frame is not None else ")")


def _check_data(task: str, data: Any, what: str) -> None:
    """Validate a TouchData / TrackData at the door, naming the split, trial and sample."""
    need = ("x", "y") if task == "touch" else ("x", "y", "init")
    for name in need:
        if not isinstance(getattr(data, name, None), np.ndarray):
            raise EctskinError(
                f"{what}: expected a {'TouchData' if task == 'touch' else 'TrackData'} with "
                f"array field {name!r}, got {type(data).__name__}"
            )
    x, y = data.x, data.y
    n = x.shape[0]
    if n == 0:
        raise EctskinError(f"{what}: the split holds no samples")
    if task == "touch":
        if x.ndim != 2 or y.shape != (n,):
            raise EctskinError(
                f"{what}: touch data must have x (n, n_pairs) and y (n,), got x {x.shape}, "
                f"y {y.shape}"
            )
        n_classes = int(getattr(data, "n_classes", 0) or 0)
        bad = (y < 0) | (y >= n_classes) if n_classes else (y < 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise EctskinError(
                f"{what}: {_group_name(data, i)} has label {y[i]}, expected 0..{n_classes - 1}"
            )
    else:
        if x.ndim != 3 or y.ndim != 3 or y.shape[0] != n or y.shape[2] != 3:
            raise EctskinError(
                f"{what}: track data must have x (n, k, n_pairs) and y (n, n_markers, 3), got "
                f"x {x.shape}, y {y.shape}"
            )
        if data.init.shape != y.shape:
            raise EctskinError(
                f"{what}: init must have the shape of y {y.shape}, got {data.init.shape}"
            )
    for name in need:
        arr = getattr(data, name)
        if np.issubdtype(arr.dtype, np.floating):
            finite = np.isfinite(arr.reshape(n, -1)).all(axis=1)
            if not finite.all():
                i = int(np.argmin(finite))
                raise EctskinError(
                    f"{what}: {name} of {_group_name(data, i)} is not finite (NaN/inf); "
                    f"check calibration and occluded markers"
                )


def _to_tensors(task: str, data: Any, device: torch.device) -> _Tensors:
    x = torch.from_numpy(np.ascontiguousarray(data.x, dtype=np.float32)).to(device)
    if task == "touch":
        y = torch.from_numpy(np.ascontiguousarray(data.y, dtype=np.int64)).to(device)
        return _Tensors(x, y)
    y = torch.from_numpy(np.ascontiguousarray(data.y, dtype=np.float32)).to(device)
    init = torch.from_numpy(np.ascontiguousarray(data.init, dtype=np.float32)).to(device)
    return _Tensors(x, y, init)


def _fingerprint(*arrays: np.ndarray) -> str:
    """A short hash of the training arrays, to refuse resuming on different data."""
    h = hashlib.blake2b(digest_size=12)
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def _split_names(data: Any) -> list[str]:
    names = list(getattr(data, "group_names", []) or [])
    group = getattr(data, "group", None)
    if group is None or not names:
        return []
    return [str(names[g]) for g in np.unique(group) if 0 <= g < len(names)]


# ============================================================================ tasks
def _build_model(task: str, data: Any, model_options: dict[str, Any] | None) -> nn.Module:
    """The model for ``task`` with its shape fields taken from the data."""
    opts = dict(model_options or {})
    if task == "touch":
        shape = {"n_pairs": int(data.x.shape[1]), "n_classes": int(data.n_classes)}
        config_cls = TouchMLPConfig
    else:
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
        config_cls = C2DTConfig
    clash = {k: (opts[k], v) for k, v in shape.items() if k in opts and opts[k] != v}
    if clash:
        detail = ", ".join(f"{k}={a!r} but the data gives {b!r}" for k, (a, b) in clash.items())
        raise EctskinError(f"model options disagree with the training data: {detail}")
    names = {f.name for f in fields(config_cls)}
    unknown = sorted(set(opts) - names)
    if unknown:
        raise EctskinError(f"unknown {config_cls.__name__} option(s): {', '.join(unknown)}")
    config = config_cls(**{**opts, **shape})
    if task == "touch":
        return TouchMLP(config)
    return C2DT(config, desc if shape["desc_dim"] else None, pairs if shape["desc_dim"] else None)


def _fit_normalization(task: str, model: nn.Module, data: Any) -> dict[str, Any]:
    """Fit the model's scaling buffers on the training split only; returns them as plain data.

    The input statistics are a :class:`~ectskin.learn.datasets.Normalizer` per pair (over
    samples and, for windows, frames); tracking adds the coordinate scales of
    :func:`~ectskin.learn.models.c2dt.coordinate_stats`. The model holds them in buffers, so it
    takes calibrated readouts directly; the returned dict is stored in the checkpoint for
    reference (``{"x": Normalizer.to_dict(), ...}``).
    """
    from ectskin.learn.datasets import Normalizer

    norm = Normalizer.fit(data.x)
    stats: dict[str, Any] = {"x_mean": norm.mean, "x_std": norm.std}
    if task == "track":
        stats.update(c2dt_module.coordinate_stats(data.init, data.y, prior=model.config.prior))
    model.set_normalization(**stats)
    return {"x": norm.to_dict(), **to_plain({k: v for k, v in stats.items() if k[0] != "x"})}


class _TouchTask:
    """Cross-entropy on class logits; metric = accuracy.

    With ``settings`` of a recipe (:class:`TrainSettings` ``inflation_shift``, ``mixup_alpha``,
    ``label_smoothing``) the training loss augments the batch (:func:`augment_touch_batch`) and
    uses :func:`mixup_cross_entropy`; validation stays plain cross-entropy on unchanged frames.
    """

    metric_name = "accuracy"
    lower_is_better_metric = False

    def __init__(
        self,
        model: nn.Module,
        settings: TrainSettings | None = None,
        state_means: torch.Tensor | None = None,
    ) -> None:
        del model
        self.label_smoothing = float(settings.label_smoothing) if settings is not None else 0.0
        self.mixup_alpha = float(settings.mixup_alpha) if settings is not None else 0.0
        self.state_means = state_means  # (n_states, P) or None: no inflation shift

    def loss(self, model: nn.Module, batch: tuple, rng: np.random.Generator | None = None):
        x, y = batch
        if rng is None:
            if self.label_smoothing:
                return F.cross_entropy(model(x), y, label_smoothing=self.label_smoothing)
            return F.cross_entropy(model(x), y)  # mean over the batch (the paper's loss)
        x, y_a, y_b, lam = augment_touch_batch(
            x, y, rng, state_means=self.state_means, mixup_alpha=self.mixup_alpha
        )
        return mixup_cross_entropy(model(x), y_a, y_b, lam, self.label_smoothing)

    def loss_to_report(self, loss_sum: torch.Tensor) -> torch.Tensor:
        return loss_sum

    def eval_sums(self, model: nn.Module, batch: tuple) -> torch.Tensor:
        x, y = batch
        logits = model(x)  # (B, C)
        ce = F.cross_entropy(logits, y, reduction="sum")
        correct = (logits.argmax(1) == y).sum()
        return torch.stack([ce, correct.to(ce.dtype), ce.new_tensor(len(y))])

    def finish(self, sums: torch.Tensor) -> tuple[float, float]:
        ce, correct, n = sums.tolist()
        return ce / n, correct / n


class _TrackTask:
    """Squared error in units of ``out_scale`` for the gradient; reported in mm².

    val_loss = mean squared error per coordinate (mm²); metric = average distance, paper Eq. 3:
    AD = 1/(N M) Σ_i Σ_j ‖p_ij − p̂_ij‖ (mm).
    """

    metric_name = "ad_mm"
    lower_is_better_metric = True

    def __init__(self, model: nn.Module) -> None:
        self.scale = float(getattr(model, "module", model).out_scale)

    def loss(self, model: nn.Module, batch: tuple) -> torch.Tensor:
        x, init, y = batch
        err = (model(x, init) - y) / self.scale  # (B, M, 3), dimensionless
        return err.square().mean()

    def loss_to_report(self, loss_sum: torch.Tensor) -> torch.Tensor:
        return loss_sum * self.scale**2  # mm²

    def eval_sums(self, model: nn.Module, batch: tuple) -> torch.Tensor:
        x, init, y = batch
        err = model(x, init) - y  # (B, M, 3) mm
        se = err.square().sum(-1)  # (B, M) mm²
        dist_sum = se.sqrt().mean(1).sum()  # Eq. 3 numerator over this batch (per-sample mean)
        return torch.stack([se.mean(1).sum() / 3, dist_sum, se.new_tensor(len(y))])

    def finish(self, sums: torch.Tensor) -> tuple[float, float]:
        se, ad, n = sums.tolist()
        return se / n, ad / n


def _task_obj(
    task: str,
    model: nn.Module,
    settings: TrainSettings | None = None,
    state_means: torch.Tensor | None = None,
):
    if task == "touch":
        return _TouchTask(model, settings, state_means)
    return _TrackTask(model)


# ============================================================================ touch recipe
def no_contact_means(data: Any) -> np.ndarray:
    """The mean calibrated frame of each no-contact trial of ``data``: (n_states, n_pairs) float32.

    A no-contact trial is a group present in ``data.group`` whose ``data.group_region`` is 0; in
    the paper's protocol there is one per inflation state, so the rows are the inflation states
    of the data (the ``robust`` profile passes the training split). Returns an empty (0, n_pairs)
    array when ``group_region`` is missing or empty (e.g. generic imports without trial kinds).
    """
    x = np.asarray(data.x)
    region, group = getattr(data, "group_region", None), getattr(data, "group", None)
    region = np.zeros(0, np.int64) if region is None else np.asarray(region, np.int64).ravel()
    group = np.zeros(0, np.int64) if group is None else np.asarray(group, np.int64).ravel()
    if region.size == 0 or group.shape != (x.shape[0],):
        return np.zeros((0, x.shape[1]), np.float32)
    present = [g for g in np.unique(group) if 0 <= g < region.size and region[g] == 0]
    means = [x[group == g].mean(axis=0, dtype=np.float64) for g in present]
    return np.asarray(means, dtype=np.float32).reshape(len(means), x.shape[1])


def augment_touch_batch(
    x: torch.Tensor,
    y: torch.Tensor,
    rng: np.random.Generator,
    *,
    state_means: torch.Tensor | None = None,
    mixup_alpha: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """The ``robust`` recipe's augmentation of one touch batch.

    1. Inflation shift (when ``state_means`` (S, P) is given, S >= 2): frame i gets
       ``state_means[a_i] - state_means[b_i]`` added, a_i and b_i drawn uniformly and
       independently from the S states (a_i = b_i adds 0): the same touch seen at another
       inflation. The model normalises its input per pair with a fixed affine map, so adding
       the raw difference equals adding the difference of the normalised means.
    2. Mixup (when ``mixup_alpha`` > 0) on the shifted batch: λ_i ~ Beta(α, α) per sample and a
       random partner j = perm(i) within the batch; x_i ← λ_i x_i + (1 − λ_i) x_j.

    Every draw comes from ``rng`` (numpy; the caller seeds it from (seed, epoch, rank)), in the
    order a, b (each (B,)), λ (B,), perm (B,). Returns ``(x, y_a, y_b, lam)``: y_a = y and
    y_b = y[perm], lam (B,) float32, both None without mixup. Shapes: x (B, P), y (B,).
    """
    n = int(x.shape[0])
    if state_means is not None and len(state_means) >= 2:
        ab = torch.from_numpy(rng.integers(0, len(state_means), size=(2, n))).to(x.device)
        x = x + (state_means[ab[0]] - state_means[ab[1]])  # (B, P)
    if mixup_alpha <= 0:
        return x, y, None, None
    lam = torch.from_numpy(rng.beta(mixup_alpha, mixup_alpha, size=n).astype(np.float32))
    perm = torch.from_numpy(rng.permutation(n)).to(x.device)
    lam = lam.to(x.device)
    x = lam[:, None] * x + (1 - lam[:, None]) * x[perm]  # (B, P)
    return x, y, y[perm], lam


def mixup_cross_entropy(
    logits: torch.Tensor,
    y_a: torch.Tensor,
    y_b: torch.Tensor | None = None,
    lam: torch.Tensor | None = None,
    label_smoothing: float = 0.0,
) -> torch.Tensor:
    """Mean over the batch of λ_i CE(logits_i, y_a_i) + (1 − λ_i) CE(logits_i, y_b_i), each a
    cross-entropy with ``label_smoothing``; plain (smoothed) cross-entropy when ``y_b`` is None."""
    if y_b is None:
        return F.cross_entropy(logits, y_a, label_smoothing=label_smoothing)
    ce_a = F.cross_entropy(logits, y_a, reduction="none", label_smoothing=label_smoothing)
    ce_b = F.cross_entropy(logits, y_b, reduction="none", label_smoothing=label_smoothing)
    return (lam * ce_a + (1 - lam) * ce_b).mean()


def _improved(
    select: str,
    task_obj: Any,
    val_loss: float,
    val_metric: float,
    best_loss: float,
    best_metric: float,
    best_epoch: int,
) -> bool:
    """Whether this epoch's weights replace the kept ones: lower validation loss (``select`` =
    "val_loss", the paper's rule), or a better validation metric with ties broken by the lower
    validation loss ("val_metric")."""
    if select == "val_loss":
        return val_loss < best_loss
    if best_epoch == 0:
        return True
    sign = 1.0 if task_obj.lower_is_better_metric else -1.0
    new, old = sign * val_metric, sign * best_metric
    return new < old or (new == old and val_loss < best_loss)


# ============================================================================ epoch loops
def _mix(*values: int) -> int:
    """A 63-bit seed from integers (seed, epoch, rank) — deterministic, well spread."""
    h = hashlib.blake2b(",".join(str(int(v)) for v in values).encode(), digest_size=8)
    return int.from_bytes(h.digest(), "little") & ((1 << 63) - 1)


def epoch_indices(
    n: int,
    epoch: int,
    seed: int,
    *,
    rank: int = 0,
    world_size: int = 1,
    samples: int | None = None,
) -> torch.Tensor:
    """Training indices of one rank for one epoch (int64 CPU tensor).

    A permutation of ``range(n)`` seeded by ``(seed, epoch)`` — the same on every rank —
    optionally cut to its first ``samples`` entries, padded with its own head to a multiple of
    ``world_size`` and dealt round-robin: rank r gets entries r, r + N, r + 2N, ...
    """
    g = torch.Generator().manual_seed(_mix(seed, epoch, 0x5EED))
    perm = torch.randperm(n, generator=g)
    if samples is not None and samples < n:
        perm = perm[:samples]
    pad = (-len(perm)) % world_size
    if pad:
        perm = torch.cat([perm, perm[:pad]])
    return perm[rank::world_size]


def _val_indices(n: int, samples: int | None, rank: int, world_size: int) -> torch.Tensor:
    """Validation indices of one rank: a fixed, evenly strided subset when ``samples`` < n."""
    if samples is not None and samples < n:
        idx = torch.from_numpy(np.linspace(0, n - 1, samples).round().astype(np.int64))
    else:
        idx = torch.arange(n)
    return idx[rank::world_size]


def train_one_epoch(
    model: nn.Module,
    task: Any,
    optimizer: torch.optim.Optimizer,
    data: _Tensors,
    indices: torch.Tensor,
    batch_size: int,
    *,
    epoch: int,
    d: _Dist,
    bar: Any = None,
    rng: np.random.Generator | None = None,
) -> float:
    """One pass over ``indices`` in batches; returns the mean training loss over all ranks.

    ``rng`` (touch recipes that augment): the generator of this epoch and rank for the
    augmentation's draws; None trains on the batches as they are.

    Raises EctskinError on a non-finite loss, naming the epoch and the batch. On one CPU process
    each batch is checked at once; on CUDA or under DDP the first bad batch is recorded without
    a per-batch device sync and reported (on every rank together) at the end of the epoch.
    """
    model.train()
    dev = d.device
    check_now = not d.enabled and dev.type == "cpu"
    total = torch.zeros((), dtype=torch.float64, device=dev)
    first_bad = torch.full((), -1, dtype=torch.int64, device=dev)
    count = 0
    indices = indices.to(dev)
    n_batches = math.ceil(len(indices) / batch_size)
    for b in range(n_batches):
        idx = indices[b * batch_size : (b + 1) * batch_size]
        batch = data.batch(idx)
        loss = task.loss(model, batch) if rng is None else task.loss(model, batch, rng)
        if check_now:
            if not torch.isfinite(loss):
                raise EctskinError(
                    f"training stopped: non-finite loss ({loss.item()}) at epoch {epoch + 1}, "
                    f"batch {b + 1} of {n_batches}; lower the learning rate or check the data"
                )
        else:
            bad = (~torch.isfinite(loss)) & (first_bad < 0)
            first_bad = torch.where(bad, torch.full_like(first_bad, b), first_bad)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        total += loss.detach().double() * len(idx)
        count += len(idx)
        if bar is not None:
            bar.update(1)
    sums = torch.stack([total, torch.tensor(float(count), dtype=torch.float64, device=dev)])
    _all_reduce(sums, d)
    if not check_now:
        flag = torch.where(first_bad < 0, torch.full_like(first_bad, 1 << 62), first_bad)
        _all_reduce(flag, d, dist.ReduceOp.MIN if d.enabled else None)
        if int(flag) != 1 << 62:
            raise EctskinError(
                f"training stopped: non-finite loss at epoch {epoch + 1}, batch {int(flag) + 1} "
                f"of {n_batches}; lower the learning rate or check the data"
            )
    total_sum, n = sums.tolist()
    return float(task.loss_to_report(torch.tensor(total_sum / max(n, 1))))


@torch.no_grad()
def evaluate(
    model: nn.Module, task: Any, data: _Tensors, indices: torch.Tensor, batch_size: int, d: _Dist
) -> tuple[float, float]:
    """(val_loss, val_metric) over ``indices`` of every rank (touch: CE, accuracy; track: mm², AD mm)."""
    model.eval()
    indices = indices.to(d.device)
    sums = torch.zeros(3, dtype=torch.float64, device=d.device)
    for b in range(0, len(indices), batch_size):
        sums += task.eval_sums(model, data.batch(indices[b : b + batch_size])).double()
    _all_reduce(sums, d)
    return task.finish(sums.cpu())


# ============================================================================ files
def _write_json(path: Path, obj: Any) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(to_plain(obj), indent=2) + "\n")
    os.replace(tmp, path)


def _write_metrics(path: Path, rows: list[dict[str, Any]]) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=METRICS_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r[k] for k in METRICS_COLUMNS})
    os.replace(tmp, path)


def read_metrics(path: str | Path) -> list[dict[str, float]]:
    """Rows of a run's ``metrics.csv`` as dicts of numbers (epoch as int)."""
    path = Path(path)
    if not path.is_file():
        raise EctskinError(f"{path}: no metrics file")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    try:
        return [
            {k: (int(r[k]) if k == "epoch" else float(r[k])) for k in METRICS_COLUMNS} for r in rows
        ]
    except (KeyError, TypeError, ValueError) as exc:
        raise EctskinError(f"{path}: malformed metrics file ({exc})") from None


def _use_bar(progress: bool, d: _Dist) -> bool:
    return bool(progress) and d.main and sys.stderr.isatty()


# ============================================================================ train
def train(
    task: str,
    train_data: Any,
    val_data: Any,
    out_dir: str | Path,
    *,
    profile: str = "paper",
    seed: int = 0,
    resume: bool = True,
    epochs: int | None = None,
    batch_size: int | None = None,
    device: str | torch.device | None = None,
    progress: bool = True,
    model_options: dict[str, Any] | None = None,
    split: dict[str, list[str]] | None = None,
    settings: dict[str, Any] | None = None,
    threads: int | None = None,
) -> dict[str, Any]:
    """Train the model of ``task`` ("touch": TouchMLP, "track": C2DT) and write ``out_dir``.

    Parameters
    ----------
    train_data, val_data : TouchData (task "touch") or TrackData (task "track").
    out_dir : run directory (created). If it holds ``last.pt`` and ``resume`` is true, training
        continues from it (same settings and data required); ``epochs`` may be raised to extend
        a finished run. With ``resume=False`` an existing run is overwritten.
    profile : "paper", "quick" or (touch only) "robust" (:data:`PROFILES`); ``epochs``,
        ``batch_size`` and ``settings`` (any :class:`TrainSettings` field) override it. The
        robust recipe's inflation shift needs at least two no-contact trials (``group_region``
        0) in ``train_data``; with fewer (e.g. generic imports without trial kinds) it is
        skipped with a logged warning and the rest of the recipe still applies. config.json
        records what was applied under ``recipe`` (``inflation_shift_states``: 0 when skipped).
    seed : seeds model initialisation, epoch permutations, dropout and augmentation.
    device : "cpu", "cuda", "cuda:1"...; default CUDA when available (per-rank under torchrun).
    model_options : model hyper-parameters (e.g. ``{"d_model": 32}``); the shape fields come
        from the data.
    split : trial names per split to record in ``split.json`` (default: the train/val names).
    threads : torch CPU threads while training (restored afterwards); default 1. Results
        depend on the thread count (float reduction order), so a fixed default keeps runs
        reproducible, and one thread is also the fast choice on a small shared CPU: on the
        2-core development machine under load, 2 threads ran 5-10x *slower* (OpenMP
        oversubscription). Pass more on a machine with idle cores. Ignored on CUDA.

    Returns a summary dict: best_epoch (1-based), best_val_loss, best_val_metric, metric
    (its name), select (the rule that chose best_epoch), recipe (as in config.json), epochs,
    epochs_run, resumed_from, seconds_total, seconds_this_run, seconds_per_epoch, world_size,
    device, out_dir.
    """
    check_option("task", task, TASKS)
    overrides = dict(settings or {})
    overrides.update(
        {k: v for k, v in (("epochs", epochs), ("batch_size", batch_size)) if v is not None}
    )
    s = profile_settings(task, profile, **overrides)
    out_dir = Path(out_dir)
    _check_data(task, train_data, "train_data")
    _check_data(task, val_data, "val_data")
    tr_shape, va_shape = train_data.x.shape[1:], val_data.x.shape[1:]
    if tr_shape != va_shape:
        raise EctskinError(
            f"train_data and val_data disagree: x samples of shape {tr_shape} vs {va_shape}"
        )

    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise EctskinError(f"threads must be a positive integer, got {threads!r}")
    d = _setup(device)
    previous = torch.get_num_threads()
    if d.device.type == "cpu":
        torch.set_num_threads(threads or 1)
    try:
        return _train(
            task,
            train_data,
            val_data,
            out_dir,
            s,
            profile,
            int(seed),
            resume,
            d,
            progress,
            model_options,
            split,
        )
    finally:
        torch.set_num_threads(previous)


def _train(
    task: str,
    train_data: Any,
    val_data: Any,
    out_dir: Path,
    s: TrainSettings,
    profile: str,
    seed: int,
    resume: bool,
    d: _Dist,
    progress: bool,
    model_options: dict[str, Any] | None,
    split: dict[str, Any] | None,
) -> dict[str, Any]:
    """The body of :func:`train` once inputs are checked and the process group is set up."""
    torch.manual_seed(seed)  # model initialisation: identical on every rank
    model = _build_model(task, train_data, model_options)
    normalizer = _fit_normalization(task, model, train_data)
    config = model.config
    fp_arrays = (train_data.x, train_data.y) + ((train_data.init,) if task == "track" else ())
    fingerprint = _fingerprint(*fp_arrays)
    pair_names = list(getattr(train_data, "pair_names", []) or [])
    extra_base = {
        "task": task,
        "pair_names": pair_names,
        "profile": profile,
        "seed": seed,
        "device": str(d.device),
        "world_size": d.world_size,
    }
    if task == "touch":
        extra_base["n_classes"] = int(train_data.n_classes)
    model.to(d.device)

    opt_kwargs = {"fused": True} if d.device.type in ("cpu", "cuda") else {}
    optimizer = torch.optim.Adam(model.parameters(), lr=s.lr, **opt_kwargs)
    scheduler = torch.optim.lr_scheduler.StepLR(optimizer, step_size=s.step_size, gamma=s.gamma)

    # ------------------------------------------------------------------ resume
    last_path, best_path = out_dir / "last.pt", out_dir / "model.pt"
    start_epoch, best_loss, best_metric, best_epoch, seconds_before = 0, math.inf, math.nan, 0, 0.0
    rows: list[dict[str, Any]] = []
    resumed_from = 0
    if resume and last_path.exists():
        payload = read_checkpoint(last_path, map_location=d.device)
        state = payload.get("resume")
        if not isinstance(state, dict):
            raise EctskinError(f"{last_path}: holds no training state to resume from")
        _check_resumable(last_path, payload, state, task, model, s, seed, fingerprint)
        model.load_state_dict(payload["state_dict"])
        optimizer.load_state_dict(state["optimizer"])
        scheduler.load_state_dict(state["scheduler"])
        start_epoch = resumed_from = int(state["epoch"])
        best_loss, best_metric = float(state["best_val_loss"]), float(state["best_val_metric"])
        best_epoch, seconds_before = int(state["best_epoch"]), float(state["seconds"])
        metrics_path = out_dir / "metrics.csv"
        if metrics_path.exists():  # drop rows written after last.pt (a crash in between)
            rows = [r for r in read_metrics(metrics_path) if r["epoch"] <= start_epoch]
        if d.main and start_epoch >= s.epochs:
            logger.info(
                "%s: already trained %d epochs (asked for %d); nothing to do",
                last_path,
                start_epoch,
                s.epochs,
            )
        elif d.main:
            logger.info(
                "%s: resuming %s training after epoch %d of %d",
                last_path,
                task,
                start_epoch,
                s.epochs,
            )
    elif last_path.exists() and d.main:
        logger.warning("%s exists; starting over (resume=False)", last_path)

    state_means = None
    if task == "touch" and s.inflation_shift:
        means = no_contact_means(train_data)
        if len(means) >= 2:
            state_means = torch.from_numpy(means).to(d.device)
        elif d.main:
            logger.warning(
                "inflation shift skipped: the training data holds %d no-contact trial(s) "
                "(group_region 0), at least 2 are needed",
                len(means),
            )
    recipe = {k: getattr(s, k) for k in RECIPE_FIELDS}
    recipe["inflation_shift_states"] = 0 if state_means is None else len(state_means)

    ws = d.world_size
    rank_batch = math.ceil(s.batch_size / ws)
    if d.main:
        out_dir.mkdir(parents=True, exist_ok=True)
        _write_json(
            out_dir / "config.json",
            {
                "task": task,
                "profile": profile,
                "seed": seed,
                "settings": asdict(s),
                "recipe": recipe,
                "model_kind": model.kind,
                "model": asdict(config),
                "world_size": ws,
                "batch_per_rank": rank_batch,
                "device": str(d.device),
                "n_train": int(train_data.x.shape[0]),
                "n_val": int(val_data.x.shape[0]),
                "pair_names": pair_names,
                "data_fingerprint": fingerprint,
                "torch": torch.__version__,
                "torch_threads": torch.get_num_threads(),
            },
        )
        if split is None:
            split = {"train": _split_names(train_data), "val": _split_names(val_data)}
        _write_json(out_dir / "split.json", split)
        if ws > 1 or d.device.type != "cpu":
            logger.info(
                "training %s on %s x %d (batch %d per rank)", task, d.device, ws, rank_batch
            )

    ddp_model: nn.Module = model
    if d.enabled:
        # the buffers are the normalisation: synced once at construction, constant after
        params = inspect.signature(nn.parallel.DistributedDataParallel).parameters
        no_sync = (
            {"forward_sync_buffers": False}
            if "forward_sync_buffers" in params
            else {"broadcast_buffers": False}
        )
        ddp_model = nn.parallel.DistributedDataParallel(
            model, device_ids=[d.device.index] if d.device.type == "cuda" else None, **no_sync
        )
    task_obj = _task_obj(task, model, s, state_means)
    train_t = _to_tensors(task, train_data, d.device)
    val_t = _to_tensors(task, val_data, d.device)
    val_idx = _val_indices(val_t.n, s.val_samples, d.rank, ws)
    n_per_epoch = min(s.samples_per_epoch or train_t.n, train_t.n)
    n_batches = math.ceil(math.ceil(n_per_epoch / ws) / rank_batch)

    use_bar = _use_bar(progress, d)
    log_epochs = bool(progress) and d.main and not use_bar
    epoch_bar = batch_bar = None
    if use_bar:
        from tqdm.auto import tqdm

        epoch_bar = tqdm(total=s.epochs, initial=start_epoch, desc=f"train {task}", unit="epoch")
        batch_bar = tqdm(total=n_batches, leave=False, unit="batch", desc="epoch")
    t_run = time.perf_counter()
    try:
        for epoch in range(start_epoch, s.epochs):
            t0 = time.perf_counter()
            torch.manual_seed(_mix(seed, epoch, d.rank))  # dropout etc. of this epoch
            aug_rng = (
                np.random.default_rng(_mix(seed, epoch, d.rank, 0xA6))  # augmentation draws
                if task == "touch" and (state_means is not None or s.mixup_alpha > 0)
                else None
            )
            idx = epoch_indices(
                train_t.n, epoch, seed, rank=d.rank, world_size=ws, samples=s.samples_per_epoch
            )
            if batch_bar is not None:
                batch_bar.reset(total=n_batches)
                batch_bar.set_description(f"epoch {epoch + 1}")
            lr = optimizer.param_groups[0]["lr"]
            train_loss = train_one_epoch(
                ddp_model,
                task_obj,
                optimizer,
                train_t,
                idx,
                rank_batch,
                epoch=epoch,
                d=d,
                bar=batch_bar,
                rng=aug_rng,
            )
            val_loss, val_metric = evaluate(model, task_obj, val_t, val_idx, s.eval_batch_size, d)
            scheduler.step()
            seconds = time.perf_counter() - t0
            rows.append(
                {
                    "epoch": epoch + 1,
                    "train_loss": train_loss,
                    "val_loss": val_loss,
                    "val_metric": val_metric,
                    "lr": lr,
                    "seconds": seconds,
                }
            )
            improved = _improved(
                s.select, task_obj, val_loss, val_metric, best_loss, best_metric, best_epoch
            )
            if improved:
                best_loss, best_metric, best_epoch = val_loss, val_metric, epoch + 1
            elapsed = seconds_before + time.perf_counter() - t_run
            if d.main:
                extra = {
                    **extra_base,
                    "epoch": epoch + 1,
                    "val_loss": val_loss,
                    "val_metric": val_metric,
                    "metric": task_obj.metric_name,
                }
                if improved:
                    save_checkpoint(best_path, model, config, normalizer=normalizer, extra=extra)
                _write_metrics(out_dir / "metrics.csv", rows)
                save_checkpoint(
                    last_path,
                    model,
                    config,
                    normalizer=normalizer,
                    extra=extra,
                    resume={
                        "epoch": epoch + 1,
                        "optimizer": optimizer.state_dict(),
                        "scheduler": scheduler.state_dict(),
                        "best_val_loss": best_loss,
                        "best_val_metric": best_metric,
                        "best_epoch": best_epoch,
                        "seconds": elapsed,
                        "settings": to_plain(asdict(s)),
                        "seed": seed,
                        "task": task,
                        "data_fingerprint": fingerprint,
                    },
                )
            msg = (
                f"epoch {epoch + 1}/{s.epochs}: train_loss {train_loss:.4g} val_loss "
                f"{val_loss:.4g} val_{task_obj.metric_name} {val_metric:.4g} lr {lr:.3g} "
                f"({seconds:.1f} s)"
            )
            if epoch_bar is not None:
                epoch_bar.set_postfix(
                    val_loss=f"{val_loss:.4g}", **{task_obj.metric_name: f"{val_metric:.4g}"}
                )
                epoch_bar.update(1)
            if log_epochs:
                logger.info(msg)
            else:
                logger.debug(msg)
    finally:
        for bar in (batch_bar, epoch_bar):
            if bar is not None:
                bar.close()
    if d.enabled:
        dist.barrier()  # rank 0 has written every file before anyone returns
    this_run = time.perf_counter() - t_run
    epochs_run = max(s.epochs - start_epoch, 0)
    total = seconds_before + this_run
    summary = {
        "task": task,
        "best_epoch": best_epoch,
        "best_val_loss": best_loss,
        "best_val_metric": best_metric,
        "metric": task_obj.metric_name,
        "select": s.select,
        "recipe": recipe,
        "epochs": s.epochs,
        "epochs_run": epochs_run,
        "resumed_from": resumed_from,
        "seconds_total": total,
        "seconds_this_run": this_run,
        "seconds_per_epoch": total / max(start_epoch, s.epochs, 1),
        "world_size": ws,
        "device": str(d.device),
        "out_dir": str(out_dir),
    }
    if d.main:
        logger.info(
            "%s training done: best epoch %d, val_loss %.4g, val_%s %.4g (%.1f s)",
            task,
            best_epoch,
            best_loss,
            task_obj.metric_name,
            best_metric,
            total,
        )
    return summary


def _check_resumable(
    path: Path,
    payload: dict,
    state: dict,
    task: str,
    model: nn.Module,
    s: TrainSettings,
    seed: int,
    fingerprint: str,
) -> None:
    """Refuse to resume a run trained with other settings, another model or other data."""
    hint = "use another output folder, or resume=False (--force) to start over"
    if state.get("task") != task or payload["kind"] != model.kind:
        raise EctskinError(
            f"{path}: holds a {state.get('task')!r} run ({payload['kind']!r} model), not a "
            f"{task!r} run; {hint}"
        )
    old_cfg = asdict(config_from_dict(payload["kind"], payload["config"], path))
    new_cfg = asdict(model.config)
    diff = [k for k in new_cfg if old_cfg.get(k) != new_cfg[k]]
    if diff:
        detail = ", ".join(f"{k} {old_cfg.get(k)!r} -> {new_cfg[k]!r}" for k in diff)
        raise EctskinError(f"{path}: the model differs from the saved one ({detail}); {hint}")
    # runs saved before a setting existed were trained with its default
    defaults = {f.name: f.default for f in fields(TrainSettings) if f.default is not MISSING}
    old = {**to_plain(defaults), **dict(state.get("settings") or {})}
    new = to_plain(asdict(s))
    diff = [k for k in new if k != "epochs" and old.get(k) != new[k]]
    if diff:
        detail = ", ".join(f"{k} {old.get(k)!r} -> {new[k]!r}" for k in diff)
        raise EctskinError(f"{path}: training settings differ ({detail}); {hint}")
    if int(state.get("seed", seed)) != seed:
        raise EctskinError(f"{path}: was trained with seed {state.get('seed')}, not {seed}; {hint}")
    if state.get("data_fingerprint") != fingerprint:
        raise EctskinError(f"{path}: was trained on different training data; {hint}")


# ============================================================================ CLI helper
def main_from_args(
    task: str,
    data_path: str | Path,
    out: str | Path,
    *,
    profile: str = "paper",
    seed: int = 0,
    epochs: int | None = None,
    batch_size: int | None = None,
    window: int = 10,
    prior: bool = True,
    resume: bool = True,
    device: str | None = None,
    progress: bool = True,
    counts: tuple[float, float, float] | None = None,
    split_seed: int | None = None,
    model_options: dict[str, Any] | None = None,
    threads: int | None = None,
) -> dict[str, Any]:
    """Everything ``ectskin train TASK DATA --out RUN`` does, from a recording file.

    Reads the recording (HDF5 via ``ectskin.io.hdf5``; ``.npz``/``.csv`` via the generic
    importer), builds the data set (``touch_dataset`` / ``track_dataset(window, prior)``), splits
    the trials with ``split_groups`` (the paper's counts 125/32/32 or 108/18/20, scaled to the
    data; touch stratified by region; seed ``split_seed``, default ``seed``), writes
    ``split.json`` (train/val/test trial names, task, data file) and calls :func:`train`. Runs
    unchanged under ``torchrun`` (every rank reads the data; only rank 0 writes). Returns train's
    summary plus ``n_train``/``n_val``/``n_test`` samples.
    """
    from ectskin.learn import datasets

    profile_settings(task, profile)  # an unknown profile fails before the data is read
    data_path = Path(data_path)
    rec = load_recording(data_path)
    if task == "touch":
        data = datasets.touch_dataset(rec)
        counts = counts or datasets.TOUCH_SPLIT
    else:
        data = datasets.track_dataset(rec, window=window, prior=prior)
        counts = counts or datasets.TRACK_SPLIT
    split_ids = datasets.split_groups(
        data.group_names,
        counts,
        seed=seed if split_seed is None else split_seed,
        stratify=data.group_region if task == "touch" and len(data.group_region) else None,
    )
    parts = {k: data.select(v) for k, v in split_ids.items()}
    split = {
        **datasets.split_names(split_ids, data.group_names),
        "task": task,
        "data": str(data_path.resolve()),
        "counts": [float(c) for c in counts],
        "split_seed": seed if split_seed is None else split_seed,
    }
    summary = train(
        task,
        parts["train"],
        parts["val"],
        out,
        profile=profile,
        seed=seed,
        resume=resume,
        epochs=epochs,
        batch_size=batch_size,
        device=device,
        progress=progress,
        model_options=model_options,
        split=split,
        threads=threads,
    )
    summary.update({f"n_{k}": int(p.n_samples) for k, p in parts.items()})
    return summary


def load_recording(path: str | Path):
    """A Recording from HDF5 (``ectskin.io.hdf5``) or a generic NPZ/CSV file."""
    path = Path(path)
    if not path.exists():
        raise EctskinError(f"{path}: no such data file")
    if path.suffix.lower() in (".npz", ".csv"):
        from ectskin.io.generic import load_generic

        return load_generic(path)
    from ectskin.io.hdf5 import read_recording

    return read_recording(path)
