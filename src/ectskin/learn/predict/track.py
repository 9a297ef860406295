"""Deformation tracking on a stream: :class:`TrackPredictor` (a trained C2DT run).

``predict(window, init)`` gives the marker coordinates (mm) at the window's last frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.learn.predict.base import Predictor, as_input

__all__ = ["TrackPredictor"]


class TrackPredictor(Predictor):
    """Marker coordinates (mm) from a window of calibrated frames (C2DT)."""

    kind = "c2dt"

    @property
    def window(self) -> int:
        return int(self.config.window)

    @property
    def n_markers(self) -> int:
        return int(self.config.n_markers)

    @property
    def prior(self) -> bool:
        return bool(self.config.prior)

    def _single_shapes(self) -> list[tuple[int, ...]]:
        shapes = [(1, self.window, self.n_pairs)]
        return shapes + [(1, self.n_markers, 3)] if self.prior else shapes

    def predict(self, window_calibrated: Any, init: Any = None) -> np.ndarray:
        """(k, n_pairs) window (oldest first) and (n_markers, 3) initial coordinates (mm) →
        (n_markers, 3) coordinates, mm. Batched: (B, k, n_pairs), (B, n_markers, 3) →
        (B, n_markers, 3). ``init`` is required with prior knowledge, ignored without.

        With prior knowledge the window must be calibrated against the trajectory's first
        frame (its readouts are c_0 of Eq. 2) and ``init`` holds that frame's markers.
        """
        owner = f"TrackPredictor({self.source})"
        x, batched = as_input(
            "window", window_calibrated, (self.window, self.n_pairs), owner, self.pair_names
        )
        i = None
        if self.prior:
            if init is None:
                raise EctskinError(
                    f"{owner}: this model uses prior knowledge; pass init, the markers' "
                    f"coordinates in the trajectory's first frame ({self.n_markers}, 3) mm"
                )
            i, batched_i = as_input("init", init, (self.n_markers, 3), owner, [])
            if batched_i != batched or i.shape[0] != x.shape[0]:
                raise EctskinError(
                    f"{owner}: window and init disagree in batch size "
                    f"({tuple(x.shape)} vs {tuple(i.shape)})"
                )
        out = self._forward([x, i], batched)
        return out if batched else out[0]
