"""What the live engine emits per processed frame, and its JSON message (the dashboard protocol)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._files import to_jsonable


def json_list(a: np.ndarray | None) -> list | None:
    """Array → nested lists of floats, non-finite → None (``ectskin._files``'s JSON policy)."""
    if a is None:
        return None
    a = np.asarray(a, dtype=np.float64)
    return a.tolist() if np.isfinite(a).all() else to_jsonable(a)


@dataclass
class Output:
    """What the engine emits per processed frame.

    ``raw`` (n_pairs,) pF; ``calibrated`` (n_pairs,) Eq. 2 against the touch reference (None until
    a reference exists); ``touch_probs`` (n_classes,) and ``touch_cls``; ``markers_pred``,
    ``markers_reference``, ``markers_true`` (n_markers, 3) mm; ``label``, ``trial`` and
    ``inflation`` (ml) as the frame carried them (None when the source does not know);
    ``latency_ms`` from the frame's arrival to this output; ``stats`` a snapshot of
    :attr:`LiveEngine.stats`.
    """

    seq: int
    t: float
    raw: np.ndarray
    calibrated: np.ndarray | None = None
    touch_probs: np.ndarray | None = None
    touch_cls: int | None = None
    markers_pred: np.ndarray | None = None
    markers_reference: np.ndarray | None = None
    markers_true: np.ndarray | None = None
    label: int | None = None
    trial: str | None = None
    inflation: tuple[float, ...] | None = None
    latency_ms: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)

    def to_json_dict(self) -> dict[str, Any]:
        """The ``{"type": "frame", ...}`` message the dashboard streams (non-finite → None)."""
        touch = None
        if self.touch_probs is not None:
            touch = {"cls": self.touch_cls, "probs": json_list(self.touch_probs)}
        markers = None
        if self.markers_pred is not None or self.markers_true is not None:
            markers = {
                "pred": json_list(self.markers_pred),
                "reference": json_list(self.markers_reference),
                "true": json_list(self.markers_true),
            }
        return {
            "type": "frame",
            "seq": int(self.seq),
            "t": float(self.t),
            "raw": json_list(self.raw),
            "calibrated": json_list(self.calibrated),
            "touch": touch,
            "markers": markers,
            "label": None if self.label is None else int(self.label),
            "trial": self.trial,
            "inflation": None if self.inflation is None else [float(v) for v in self.inflation],
            "latency_ms": float(self.latency_ms),
            "stats": dict(self.stats),
        }
