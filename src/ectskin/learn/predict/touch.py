"""Touch recognition on a stream: :class:`TouchPredictor` (a trained touch run).

``predict(frame)`` gives the class probabilities of a calibrated frame (or a batch), ``classify``
the most probable class. A touch run that selected a classical model (``candidates.json``, see
:mod:`ectskin.learn.candidates`) answers with its ``model.skops`` instead (its standardisation is
part of the model), through ``predict_proba``, with the same output.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from ectskin.learn.candidates import (
    CLASSICAL_FILE,
    ClassicalModel,
    load_classical,
    read_candidates,
)
from ectskin.learn.predict.base import Predictor, as_input

__all__ = ["TouchPredictor"]


def _softmax(logits: torch.Tensor) -> torch.Tensor:
    return torch.softmax(logits, dim=-1)


class TouchPredictor(Predictor):
    """Touch class probabilities from calibrated frames: the run's TouchMLP, or the classical
    model its ``candidates.json`` selects (``classical``; ``model`` is then None)."""

    kind = "touch_mlp"
    _output = staticmethod(_softmax)

    def __init__(
        self,
        model: torch.nn.Module | None,
        config: Any,
        payload: dict,
        source: str,
        classical: ClassicalModel | None = None,
    ) -> None:
        self.classical = classical
        if classical is None:
            super().__init__(model, config, payload, source)
            return
        self.model = None
        self.config = classical.config
        self.payload = {"kind": f"touch_{classical.name}", "extra": {}}
        self.source = source
        self.device = torch.device("cpu")
        self.pair_names = list(classical.pair_names)
        classical.single_frame()  # its single-frame export: now (seconds), not on the first frame

    @classmethod
    def from_run(
        cls, run_dir: str | Path, *, device: str | torch.device = "cpu", layout: Any = None
    ):
        """Load the model a run answers with: ``run_dir/model.skops`` when the run's
        ``candidates.json`` selects a classical model, else ``run_dir/model.pt`` (on
        ``device``); or the model file itself (``.skops`` or a checkpoint). With ``layout`` a
        model trained for another skin is refused before it is used."""
        path = Path(run_dir)
        if path.is_dir():
            doc = read_candidates(path)
            if doc is not None and doc["selected"] != "mlp":
                path = path / CLASSICAL_FILE
        if path.suffix == ".skops":
            return cls(None, None, {}, str(path), classical=load_classical(path, layout=layout))
        return super().from_run(run_dir, device=device, layout=layout)

    @property
    def reference_mode(self) -> str | None:
        """The Eq. 2 reference the run was trained with when it follows the inflation ("state",
        "inflation", ...: :data:`ectskin.learn.data.touch.FOLLOWS_INFLATION`), else None (the
        rest state, what a live stream is calibrated against)."""
        doc = (self.payload.get("extra") or {}).get("reference")
        mode = doc.get("mode") if isinstance(doc, dict) else None
        return str(mode) if mode else None

    @property
    def model_name(self) -> str:
        """ "mlp" or the classical candidate answering."""
        return "mlp" if self.classical is None else self.classical.name

    @property
    def n_classes(self) -> int:
        return int(self.config.n_classes)

    @property
    def runtime(self) -> str:
        return "skops" if self.classical is not None else super().runtime

    def _single_shapes(self) -> list[tuple[int, ...]]:
        return [(1, self.n_pairs)]

    def predict(self, c_calibrated: Any) -> np.ndarray:
        """(n_pairs,) → (n_classes,) probabilities; (B, n_pairs) → (B, n_classes). Class 0 = no
        touch, k = region k."""
        x, batched = as_input(
            "readouts",
            c_calibrated,
            (self.n_pairs,),
            f"TouchPredictor({self.source})",
            self.pair_names,
        )
        if self.classical is not None:
            probs = self.classical.predict_proba(x.numpy())
        else:
            probs = self._forward([x], batched)
        return probs if batched else probs[0]

    def classify(self, c_calibrated: Any) -> np.ndarray | int:
        """The most probable class: an int for one frame, (B,) int64 for a batch."""
        probs = self.predict(c_calibrated)
        return int(probs.argmax()) if probs.ndim == 1 else probs.argmax(axis=1)
