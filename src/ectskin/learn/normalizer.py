"""Per-channel standardisation fitted on the training split only: :class:`Normalizer`."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import numpy as np

from ectskin._check import EctskinError

log = logging.getLogger(__name__)

__all__ = ["Normalizer"]


class Normalizer:
    """Per-channel standardisation z = (x − mean) / std, fitted on training data only.

    Statistics are taken over every axis but the trailing ``channel_ndim`` ones: for touch frames
    (n, n_pairs) and windows (n, k, n_pairs) they are per pair; for displacements (n, M, 3) with
    ``channel_ndim=2`` per marker and axis. A channel whose std is below ``min_std`` (constant
    over the training data) keeps std = 1, so it is centred but not blown up.

    Saved as plain lists (:meth:`to_dict` / :meth:`from_dict`) inside checkpoints.
    """

    def __init__(self, mean: Any, std: Any, *, min_std: float = 1e-8) -> None:
        mean_a = np.asarray(mean, dtype=np.float64)
        std_a = np.asarray(std, dtype=np.float64)
        if mean_a.shape != std_a.shape or mean_a.ndim == 0:
            raise EctskinError(
                f"Normalizer: mean and std must have the same (channel) shape, got "
                f"{mean_a.shape} and {std_a.shape}"
            )
        if not (np.all(np.isfinite(mean_a)) and np.all(np.isfinite(std_a)) and np.all(std_a > 0)):
            raise EctskinError("Normalizer: mean must be finite and std finite and > 0")
        self.mean = mean_a
        self.std = std_a
        self.min_std = float(min_std)

    @classmethod
    def fit(cls, x: np.ndarray, *, channel_ndim: int = 1, min_std: float = 1e-8) -> Normalizer:
        """Fit on (training) samples ``x`` of shape (..., *channel_shape)."""
        a = np.asarray(x)
        if a.dtype.kind not in "biuf":
            raise EctskinError(f"Normalizer.fit: samples must be numeric, got dtype {a.dtype}")
        if a.ndim <= channel_ndim:
            raise EctskinError(
                f"Normalizer.fit: need samples of shape (n, ..., channels), got {a.shape}"
            )
        if a.size == 0:
            raise EctskinError("Normalizer.fit: no training samples")
        # two passes over chunks of samples with float64 accumulators: no float64 copy of a
        # ~100 000-window training set
        flat = a.reshape(-1, *a.shape[a.ndim - channel_ndim :])
        count = flat.shape[0]
        total = np.zeros(flat.shape[1:])
        for start in range(0, count, 65536):
            chunk = flat[start : start + 65536]
            if not np.all(np.isfinite(chunk)):
                k = start + int(np.argwhere(~np.isfinite(chunk))[0][0])
                idx = np.unravel_index(k * int(np.prod(flat.shape[1:])), a.shape)
                raise EctskinError(
                    f"Normalizer.fit: non-finite value in the sample at index "
                    f"{tuple(int(i) for i in idx[: a.ndim - channel_ndim])}"
                )
            total += chunk.sum(axis=0, dtype=np.float64)
        mean = total / count
        sq = np.zeros_like(mean)
        for start in range(0, count, 65536):
            dev = flat[start : start + 65536] - mean
            sq += np.einsum("n...,n...->...", dev, dev)
        std = np.sqrt(sq / count)
        const = std < min_std
        if const.any():
            log.info("Normalizer: %d constant channel(s) keep std = 1", int(const.sum()))
            std = np.where(const, 1.0, std)
        return cls(mean, std, min_std=min_std)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.mean.shape

    def _check(self, x: np.ndarray, what: str) -> np.ndarray:
        a = np.asarray(x)
        if a.shape[a.ndim - self.mean.ndim :] != self.mean.shape:
            raise EctskinError(
                f"Normalizer.{what}: data has trailing shape {a.shape[a.ndim - self.mean.ndim :]}, "
                f"the normaliser was fitted on channels of shape {self.mean.shape}"
            )
        return a

    def transform(self, x: np.ndarray) -> np.ndarray:
        """(..., *channel_shape) → standardised float32."""
        a = self._check(x, "transform")
        return ((a - self.mean) / self.std).astype(np.float32)

    def inverse_transform(self, z: np.ndarray) -> np.ndarray:
        """Undo :meth:`transform` (float32)."""
        a = self._check(z, "inverse_transform")
        return (a * self.std + self.mean).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """Plain lists, safe for JSON and ``torch.load(weights_only=True)``."""
        return {
            "kind": "standard",
            "mean": self.mean.tolist(),
            "std": self.std.tolist(),
            "min_std": self.min_std,
        }

    @classmethod
    def from_dict(cls, d: Any, *, source: str = "normalizer") -> Normalizer:
        if not isinstance(d, Mapping) or "mean" not in d or "std" not in d:
            raise EctskinError(
                f"{source}: expected a dict with 'mean' and 'std' lists, got {d!r:.80}"
            )
        if d.get("kind", "standard") != "standard":
            raise EctskinError(f"{source}: unknown normaliser kind {d.get('kind')!r}")
        try:
            return cls(d["mean"], d["std"], min_std=float(d.get("min_std", 1e-8)))
        except (TypeError, ValueError) as exc:
            raise EctskinError(f"{source}: {exc}") from None

    def __repr__(self) -> str:
        return f"Normalizer(shape={self.shape})"
