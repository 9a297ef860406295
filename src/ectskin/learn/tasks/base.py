"""What a learning task is: :class:`Task` (data, model, evaluation) and :class:`Criterion` (loss).

A task owns everything that differs between, say, touch classification and marker tracking, so
that training (:mod:`ectskin.learn.train`) and evaluation (:mod:`ectskin.learn.evaluate`) hold no
task branches (DETR's criterion and postprocessors are the pattern):

* data: build its data set from a recording, check a split at the door, its trial split counts
  and stratification, and the split's tensors in the order the model takes them;
* model: build it from the data and options, fit its normalisation on the training split;
* training: a :class:`Criterion` (training loss, validation sums, validation loss and metric)
  and whether a lower metric is better (the selection rule);
* evaluation: batched prediction of a test split, the test metrics (from
  :mod:`ectskin.learn.metrics`), its baselines and its figures (through :mod:`ectskin.viz`).

A task is generic in its data set class (``Task[TouchData]``, see :mod:`ectskin.learn.data`). A
new task is a new subclass registered in :data:`ectskin.learn.tasks.TASKS`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np
import torch
from torch import nn

from ectskin._check import EctskinError
from ectskin.io import Recording
from ectskin.learn.data.base import SampleData
from ectskin.learn.engine import Tensors
from ectskin.learn.profiles import TrainSettings

#: the data set class of a task
DataT = TypeVar("DataT", bound=SampleData)


class Criterion(ABC):
    """The training loss and the validation sums of one task, for one model and recipe."""

    #: no-contact states the inflation shift uses (0: no shift), recorded in config.json's recipe
    shift_states: int = 0
    #: warnings about the recipe (e.g. a part skipped for lack of data), logged once by training
    notes: list[str]

    def __init__(self) -> None:
        self.notes = []

    @property
    def augments(self) -> bool:
        """Whether :meth:`loss` draws random numbers (augmentation): then the training loop
        passes it a generator seeded per epoch and rank."""
        return False

    @abstractmethod
    def loss(
        self, model: nn.Module, batch: tuple[torch.Tensor, ...], rng: np.random.Generator | None
    ) -> torch.Tensor:
        """The mean training loss of ``batch`` (a 0-d tensor to backpropagate)."""

    def loss_to_report(self, loss_mean: torch.Tensor) -> torch.Tensor:
        """The training loss in the units metrics.csv reports (default: as is)."""
        return loss_mean

    @abstractmethod
    def eval_sums(self, model: nn.Module, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """Sums over ``batch`` that :meth:`finish` turns into (val_loss, val_metric): a vector of
        fixed length per task (touch and track: loss sum, metric sum, sample count)."""

    @abstractmethod
    def finish(self, sums: torch.Tensor) -> tuple[float, float]:
        """(val_loss, val_metric) from the sums of every batch and rank."""


@dataclass
class EvalCase(Generic[DataT]):
    """A trained model's predictions on the test split, with what the metrics and figures need.

    ``data`` is the whole data set (for group names), ``test`` its test split, ``pred`` the
    model's predictions for ``test`` (touch: (n,) classes; track: (n, M, 3) mm), ``recording``
    the recording and ``config`` the model's config dataclass.
    """

    data: DataT
    test: DataT
    pred: np.ndarray
    recording: Recording
    config: Any


class Task(ABC, Generic[DataT]):
    """One learning task (see the module docstring) on data sets of class ``DataT``. Subclasses
    set the class attributes."""

    name: ClassVar[str]  # "touch", the name on the command line and in config.json
    model_kind: ClassVar[str]  # the checkpoint kind of its model ("touch_mlp")
    data_type: ClassVar[str]  # the data set class, for messages ("TouchData")
    #: array fields of the data set, checked at the door and hashed to recognise the data
    arrays: ClassVar[tuple[str, ...]]
    #: the same arrays in the order the model's forward takes them, the target last
    batch_fields: ClassVar[tuple[str, ...]]
    #: the name of the validation metric (metrics.csv's val_metric), and its direction
    metric_name: ClassVar[str]
    lower_is_better_metric: ClassVar[bool]
    #: the paper's trial split (train, val, test), scaled to the data by split_groups
    split_counts: ClassVar[tuple[int, int, int]]
    #: figure file stem → caption, of the figures :meth:`figures` draws (the caller saves them
    #: as ``<stem>.<format>``)
    figure_captions: ClassVar[dict[str, str]]
    #: whether a sample is a window of frames (``window`` frames per frame of the recording)
    windowed: ClassVar[bool] = True

    # ------------------------------------------------------------------ data
    def check_options(self, *, window: int, prior: bool) -> None:  # noqa: B027 - optional hook
        """Refuse data-set options that do not apply to this task (default: all apply)."""

    @abstractmethod
    def dataset(
        self, rec: Recording, *, window: int = 10, prior: bool = True, reference: Any = "auto"
    ) -> DataT:
        """The task's data set of ``rec`` (see :mod:`ectskin.learn.data`)."""

    def dataset_options(self, config: Any) -> dict[str, Any]:
        """The :meth:`dataset` options a trained model (its config) was trained with."""
        return {}

    def uses_rest_reference(self, config: Any) -> bool:
        """Whether a model (its config) reads frames calibrated against the recording's rest
        state (:func:`ectskin.io.calibration.touch_reference`; default yes)."""
        return True

    def stratify(self, data: DataT) -> np.ndarray | None:
        """Per-trial labels to stratify the trial split by, or None."""
        return None

    def check_data(self, data: Any, what: str) -> None:
        """Validate a split at the door (anything: a wrong class is an error naming the class
        expected), naming the split, trial and sample."""
        for name in self.arrays:
            if not isinstance(getattr(data, name, None), np.ndarray):
                raise EctskinError(
                    f"{what}: expected a {self.data_type} with array field {name!r}, got "
                    f"{type(data).__name__}"
                )
        n = data.x.shape[0]
        if n == 0:
            raise EctskinError(f"{what}: the split holds no samples")
        self._check_shapes(data, what)
        for name in self.arrays:
            arr = getattr(data, name)
            if np.issubdtype(arr.dtype, np.floating):
                finite = np.isfinite(arr.reshape(n, -1)).all(axis=1)
                if not finite.all():
                    i = int(np.argmin(finite))
                    raise EctskinError(
                        f"{what}: {name} of {sample_name(data, i)} is not finite (NaN/inf); "
                        f"check calibration and occluded markers"
                    )

    def check_trainable(self, data: DataT, what: str) -> None:  # noqa: B027 - optional hook
        """Refuse training data no model of the task can learn from (default: any goes); one
        check for every model of the task, before any is built."""

    @abstractmethod
    def _check_shapes(self, data: DataT, what: str) -> None:
        """Task-specific shape and value checks of a non-empty split."""

    @abstractmethod
    def tensors(self, data: DataT, device: torch.device) -> Tensors:
        """The split's :attr:`batch_fields` as tensors on ``device``."""

    # ------------------------------------------------------------------ model
    @abstractmethod
    def build_model(self, data: DataT, model_options: dict[str, Any] | None) -> nn.Module:
        """The task's model with its shape fields taken from the (training) data."""

    @abstractmethod
    def fit_normalization(self, model: nn.Module, data: DataT) -> dict[str, Any]:
        """Fit the model's scaling buffers on the training split; return the statistics (stored
        in the checkpoint's ``normalizer`` for reference)."""

    def checkpoint_extra(self, data: DataT) -> dict[str, Any]:
        """Task metadata stored in the checkpoints' ``extra`` (default: none)."""
        return {}

    # ------------------------------------------------------------------ training
    @abstractmethod
    def criterion(
        self, model: nn.Module, settings: TrainSettings, train_data: DataT, device: torch.device
    ) -> Criterion:
        """The training criterion of ``model`` under ``settings`` (with its recipe)."""

    # ------------------------------------------------------------------ evaluation
    @abstractmethod
    def predict(self, model: nn.Module, data: DataT) -> np.ndarray:
        """Predictions for every sample of ``data`` (batched inference)."""

    @abstractmethod
    def test_metrics(self, case: EvalCase[DataT]) -> dict[str, Any]:
        """The test-set metrics of ``case`` (as metrics.json stores them under the task)."""

    @abstractmethod
    def baseline_metrics(self, train: DataT, test: DataT, *, seed: int) -> dict[str, Any]:
        """The task's baselines fit on ``train`` and scored on ``test``: {name: metrics}."""

    def baselines_left_out(self, train: DataT) -> dict[str, str]:
        """{baseline: why} of the baselines :meth:`baseline_metrics` leaves out on ``train``
        (no meaningful number there); none by default."""
        return {}

    @abstractmethod
    def figures(self, case: EvalCase[DataT], metrics: dict[str, Any]) -> dict[str, Any]:
        """The figures of :attr:`figure_captions`: {file stem: matplotlib Figure}. May add what
        a figure shows to ``metrics`` (e.g. the trajectory of Fig. 10)."""


def sample_name(data: Any, i: int) -> str:
    """Where sample i comes from, for error messages: "trial 'name' (sample i, frame f)"."""
    try:
        where = f"trial {data.group_names[int(data.group[i])]!r} (sample {i}"
    except (AttributeError, IndexError, TypeError, ValueError):
        return f"sample {i}"
    frame = getattr(data, "frame", None)
    return where + (f", frame {int(frame[i])})" if frame is not None else ")")


def build_config(config_cls: type, shape: dict[str, Any], options: dict[str, Any] | None) -> Any:
    """``config_cls(**options, **shape)``: the shape fields come from the data, and an option
    that contradicts them or that the config does not have is an error."""
    opts = dict(options or {})
    clash = {k: (opts[k], v) for k, v in shape.items() if k in opts and opts[k] != v}
    if clash:
        detail = ", ".join(f"{k}={a!r} but the data gives {b!r}" for k, (a, b) in clash.items())
        raise EctskinError(f"model options disagree with the training data: {detail}")
    names = {f.name for f in fields(config_cls)}
    unknown = sorted(set(opts) - names)
    if unknown:
        raise EctskinError(f"unknown {config_cls.__name__} option(s): {', '.join(unknown)}")
    return config_cls(**{**opts, **shape})


def as_tensor(array: np.ndarray, dtype: Any, device: torch.device) -> torch.Tensor:
    """``array`` as a contiguous tensor of numpy ``dtype`` on ``device``."""
    return torch.from_numpy(np.ascontiguousarray(array, dtype=dtype)).to(device)
