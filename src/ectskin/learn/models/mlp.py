"""TouchMLP: the paper's touch classifier (§4.1, Fig. 6).

One frame of calibrated readouts (paper Eq. 2, one value per electrode pair) → one hidden layer of
128 ReLU units with dropout 0.1 → 19 class logits (class 0 = no touch, 1..18 = touch regions).

The per-channel input normalisation (mean/std fitted on the training set only) is held in
buffers of the module, so a checkpoint restores it with the weights and the model always takes
*calibrated* readouts, never pre-normalised ones.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch
from torch import nn

from ectskin._check import EctskinError


@dataclass
class TouchMLPConfig:
    """Hyper-parameters of :class:`TouchMLP` (defaults: the paper's)."""

    n_pairs: int = 28  # input channels (electrode pairs)
    hidden: int = 128  # hidden units
    n_classes: int = 19  # 0 = no touch, 1..n_regions
    dropout: float = 0.1

    def __post_init__(self) -> None:
        for name in ("n_pairs", "hidden", "n_classes"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or isinstance(v, bool) or v < 1:
                raise EctskinError(f"TouchMLPConfig.{name} must be a positive integer, got {v!r}")
            setattr(self, name, int(v))
        if self.n_classes < 2:
            raise EctskinError(f"TouchMLPConfig.n_classes must be >= 2, got {self.n_classes}")
        if not 0.0 <= float(self.dropout) < 1.0:
            raise EctskinError(f"TouchMLPConfig.dropout must be in [0, 1), got {self.dropout!r}")
        self.dropout = float(self.dropout)


class TouchMLP(nn.Module):
    """n_pairs → hidden (ReLU, dropout) → n_classes logits.

    Buffers ``x_mean`` and ``x_std`` (n_pairs,) normalise the calibrated input; they default to
    0 and 1 and are set from the training data with :meth:`set_normalization`.
    """

    kind = "touch_mlp"
    #: stacks of layers in the state dict: config field → key prefix (none here)
    layer_stacks: ClassVar[dict[str, str]] = {}

    @staticmethod
    def state_shapes(config: TouchMLPConfig) -> dict[str, tuple[str | int, ...]]:
        """The state-dict tensors whose shapes hold every size of ``config``, each dimension
        named by its config field (or a fixed int): a checkpoint is checked against them before
        the model is built (:func:`ectskin.learn.checkpoint.load_checkpoint`)."""
        return {
            "x_mean": ("n_pairs",),
            "x_std": ("n_pairs",),
            "net.0.weight": ("hidden", "n_pairs"),
            "net.3.weight": ("n_classes", "hidden"),
        }

    def __init__(self, config: TouchMLPConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or TouchMLPConfig()
        self.register_buffer("x_mean", torch.zeros(config.n_pairs))
        self.register_buffer("x_std", torch.ones(config.n_pairs))
        self.net = nn.Sequential(
            nn.Linear(config.n_pairs, config.hidden),
            nn.ReLU(),
            nn.Dropout(config.dropout),
            nn.Linear(config.hidden, config.n_classes),
        )

    def set_normalization(self, x_mean: np.ndarray, x_std: np.ndarray) -> None:
        """Set the per-channel input statistics, each (n_pairs,) in calibrated units."""
        for name, value in (("x_mean", x_mean), ("x_std", x_std)):
            buf = getattr(self, name)
            val = torch.as_tensor(np.asarray(value, dtype=np.float32))
            if val.shape != buf.shape:
                raise EctskinError(
                    f"TouchMLP.set_normalization: {name} must have shape {tuple(buf.shape)}, "
                    f"got {tuple(val.shape)}"
                )
            buf.copy_(val)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: (B, n_pairs) calibrated readouts (Eq. 2) → (B, n_classes) logits."""
        x = (x - self.x_mean) / self.x_std  # (B, n_pairs)
        return self.net(x)  # (B, n_classes)
