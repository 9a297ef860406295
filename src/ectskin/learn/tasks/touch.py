"""Touch classification: :class:`TouchTask`, one class per calibrated frame (TouchMLP).

Training: cross-entropy on the class logits, metric = accuracy (:class:`TouchCriterion`); the
``robust`` recipe adds the inflation shift, mixup and label smoothing
(:mod:`ectskin.learn.augment`). Evaluation: accuracy, misclassified count, confusion map
(Fig. 7) and adjacency of the confusions (:func:`ectskin.learn.metrics.touch.touch_metrics`);
baselines of :func:`ectskin.learn.baselines.touch.touch_baselines`.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ectskin._check import EctskinError
from ectskin.io import Recording
from ectskin.learn.augment import augment_touch_batch, mixup_cross_entropy, no_contact_means
from ectskin.learn.baselines.touch import touch_baselines
from ectskin.learn.data.touch import TouchData, touch_dataset
from ectskin.learn.engine import Tensors
from ectskin.learn.metrics.touch import region_adjacency, touch_metrics
from ectskin.learn.models import TouchMLP, TouchMLPConfig
from ectskin.learn.normalizer import Normalizer
from ectskin.learn.predict.base import forward_batches
from ectskin.learn.profiles import TrainSettings
from ectskin.learn.splits import TOUCH_SPLIT
from ectskin.learn.tasks.base import (
    Criterion,
    EvalCase,
    Task,
    as_tensor,
    build_config,
    sample_name,
)
from ectskin.viz.learning import plot_confusion

#: frames per batch when predicting a test split
PREDICT_BATCH = 8192


class TouchCriterion(Criterion):
    """Cross-entropy on class logits; metric = accuracy.

    With ``settings`` of a recipe (:class:`TrainSettings` ``inflation_shift``, ``mixup_alpha``,
    ``label_smoothing``) the training loss augments the batch (:func:`augment_touch_batch`) and
    uses :func:`mixup_cross_entropy`; validation stays plain cross-entropy on unchanged frames.
    ``state_means`` (n_states, P): the no-contact means of the inflation shift (None: no shift).
    """

    def __init__(
        self, settings: TrainSettings | None = None, state_means: torch.Tensor | None = None
    ) -> None:
        super().__init__()
        self.label_smoothing = float(settings.label_smoothing) if settings is not None else 0.0
        self.mixup_alpha = float(settings.mixup_alpha) if settings is not None else 0.0
        self.mixup_pairs = str(settings.mixup_pairs) if settings is not None else "any"
        self.channel_gain = float(settings.channel_gain) if settings is not None else 0.0
        self.state_means = state_means  # (n_states, P) or None: no inflation shift
        self.shift_states = 0 if state_means is None else len(state_means)

    @property
    def augments(self) -> bool:
        return self.state_means is not None or self.mixup_alpha > 0 or self.channel_gain > 0

    def loss(
        self, model: nn.Module, batch: tuple[torch.Tensor, ...], rng: np.random.Generator | None
    ) -> torch.Tensor:
        x, y = batch
        if rng is None:
            if self.label_smoothing:
                return F.cross_entropy(model(x), y, label_smoothing=self.label_smoothing)
            return F.cross_entropy(model(x), y)  # mean over the batch (the paper's loss)
        x, y_a, y_b, lam = augment_touch_batch(
            x,
            y,
            rng,
            state_means=self.state_means,
            mixup_alpha=self.mixup_alpha,
            mixup_pairs=self.mixup_pairs,
            channel_gain=self.channel_gain,
        )
        return mixup_cross_entropy(model(x), y_a, y_b, lam, self.label_smoothing)

    def eval_sums(self, model: nn.Module, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        x, y = batch
        logits = model(x)  # (B, C)
        ce = F.cross_entropy(logits, y, reduction="sum")
        correct = (logits.argmax(1) == y).sum()
        return torch.stack([ce, correct.to(ce.dtype), ce.new_tensor(len(y))])

    def finish(self, sums: torch.Tensor) -> tuple[float, float]:
        ce, correct, n = sums.tolist()
        return ce / n, correct / n


class TouchTask(Task[TouchData]):
    """Touch classification: :class:`~ectskin.learn.data.touch.TouchData` → TouchMLP."""

    name = "touch"
    model_kind = TouchMLP.kind
    data_type = "TouchData"
    arrays = ("x", "y")
    batch_fields = ("x", "y")
    metric_name = "accuracy"
    lower_is_better_metric = False
    split_counts = TOUCH_SPLIT
    windowed = False
    figure_captions: ClassVar[dict[str, str]] = {
        "fig7_confusion": "Fig. 7: confusion map of the test set"
    }

    # ------------------------------------------------------------------ data
    def check_options(self, *, window: int, prior: bool) -> None:
        if window != 10 or not prior:
            raise EctskinError(
                f"the window and prior options apply to 'track' only, got window={window!r}, "
                f"prior={prior!r} for 'touch'"
            )

    def dataset(
        self, rec: Recording, *, window: int = 10, prior: bool = True, reference: Any = "auto"
    ) -> TouchData:
        return touch_dataset(rec, reference=reference)

    def stratify(self, data: TouchData) -> np.ndarray | None:
        return data.group_region if len(data.group_region) else None

    def _check_shapes(self, data: TouchData, what: str) -> None:
        x, y = data.x, data.y
        n = x.shape[0]
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
                f"{what}: {sample_name(data, i)} has label {y[i]}, expected 0..{n_classes - 1}"
            )

    def check_trainable(self, data: TouchData, what: str) -> None:
        """A classifier needs two classes: training frames of one class (a recording without
        touch trials) are refused, the same for the TouchMLP and every classical model."""
        classes = np.unique(data.y)
        if classes.size < 2:
            found = f"class {int(classes[0])}" if classes.size else "no class"
            if classes.size and classes[0] == 0:
                found += ", no touch"
            raise EctskinError(
                f"{what}: the training frames hold one touch class ({found}); a touch model "
                "(any --model: mlp, auto or a classical one) needs at least two: record touch "
                "trials (ectskin simulate --touch-trials 1 or more)"
            )

    def tensors(self, data: TouchData, device: torch.device) -> Tensors:
        return Tensors((as_tensor(data.x, np.float32, device), as_tensor(data.y, np.int64, device)))

    # ------------------------------------------------------------------ model
    def build_model(self, data: TouchData, model_options: dict[str, Any] | None) -> TouchMLP:
        shape = {"n_pairs": int(data.x.shape[1]), "n_classes": int(data.n_classes)}
        return TouchMLP(build_config(TouchMLPConfig, shape, model_options))

    def fit_normalization(self, model: nn.Module, data: TouchData) -> dict[str, Any]:
        """Per-pair mean / std of the training frames (a :class:`Normalizer`), held in the
        model's buffers; returned as ``{"x": Normalizer.to_dict()}``."""
        norm = Normalizer.fit(data.x)
        model.set_normalization(x_mean=norm.mean, x_std=norm.std)
        return {"x": norm.to_dict()}

    def checkpoint_extra(self, data: TouchData) -> dict[str, Any]:
        """The class count and the Eq. 2 reference of the training frames
        (:func:`~ectskin.learn.data.touch.reference_doc`: evaluation and inference calibrate
        the same way)."""
        out: dict[str, Any] = {"n_classes": int(data.n_classes)}
        if getattr(data, "reference", None):
            out["reference"] = data.reference
        return out

    # ------------------------------------------------------------------ training
    def criterion(
        self, model: nn.Module, settings: TrainSettings, train_data: TouchData, device: torch.device
    ) -> TouchCriterion:
        """With ``settings.inflation_shift``, the no-contact means of the training split's
        inflation states (at least two, else the shift is skipped with a warning)."""
        state_means, notes = None, []
        if settings.inflation_shift:
            means = no_contact_means(train_data)
            if len(means) >= 2:
                state_means = torch.from_numpy(means).to(device)
            else:
                notes.append(
                    f"inflation shift skipped: the training data holds {len(means)} no-contact "
                    "trial(s) (group_region 0), at least 2 are needed"
                )
        criterion = TouchCriterion(settings, state_means)
        criterion.notes.extend(notes)
        return criterion

    # ------------------------------------------------------------------ evaluation
    def predict(self, model: nn.Module, data: TouchData) -> np.ndarray:
        """(n,) int64 predicted classes (argmax of the logits)."""
        return forward_batches(
            model, [data.x], batch_size=PREDICT_BATCH, output=lambda z: z.argmax(dim=1)
        )

    def test_metrics(self, case: EvalCase[TouchData]) -> dict[str, Any]:
        ds, test, layout = case.data, case.test, case.recording.layout
        adjacency = region_adjacency(layout) if layout.n_classes == ds.n_classes else None
        return touch_metrics(
            test.y,
            case.pred,
            ds.n_classes,
            adjacency=adjacency,
            group=test.group,
            group_names=ds.group_names,
        )

    def baseline_metrics(self, train: TouchData, test: TouchData, *, seed: int) -> dict[str, Any]:
        return {k: r.to_metrics() for k, r in touch_baselines(train, test, seed=seed).items()}

    def figures(self, case: EvalCase[TouchData], metrics: dict[str, Any]) -> dict[str, Any]:
        return {"fig7_confusion": plot_confusion(np.asarray(metrics["confusion"]))}
