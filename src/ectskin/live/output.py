"""What the live engine emits per processed frame, and its JSON message (the dashboard protocol).

The message carries every number of an :class:`Output` as it is (non-finite → ``null``), except
the ECT image, which is quantised (:meth:`EctFrame.to_json_dict`): it is a picture for the page,
and at full precision it would be most of every message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._files import to_jsonable

#: Quantisation levels of the ECT image in a JSON message: values are sent as integers in
#: [-ECT_LEVELS, ECT_LEVELS] times ``scale / ECT_LEVELS`` (0.1 % of the largest magnitude).
ECT_LEVELS = 1000


def json_list(a: np.ndarray | None) -> list | None:
    """Array → nested lists of floats, non-finite → None (``ectskin._files``'s JSON policy)."""
    if a is None:
        return None
    a = np.asarray(a, dtype=np.float64)
    return a.tolist() if np.isfinite(a).all() else to_jsonable(a)


def quantise(images: dict[str, np.ndarray]) -> dict[str, Any]:
    """Per-face images → ``{"scale": s, "levels": L, "faces": {face: nested int lists}}`` with
    value ≈ q · s / L, s the largest finite magnitude over all faces (1.0 when all are zero);
    a non-finite pixel is ``null``. The error per pixel is at most s / (2 L)."""
    finite = [np.abs(a[np.isfinite(a)]) for a in images.values()]
    top = max((float(a.max()) for a in finite if a.size), default=0.0)
    scale = top if top > 0 else 1.0
    faces: dict[str, Any] = {}
    for face, a in images.items():
        q = np.rint(np.asarray(a, dtype=np.float64) * (ECT_LEVELS / scale))
        ok = np.isfinite(q)
        if ok.all():
            faces[face] = q.astype(np.int64).tolist()
        else:
            obj = q.astype(object)
            obj[ok] = q[ok].astype(np.int64)
            obj[~ok] = None
            faces[face] = obj.tolist()
    return {"scale": scale, "levels": ECT_LEVELS, "faces": faces}


@dataclass
class EctFrame:
    """The ECT head's result for one frame: ``images`` per face (n_v, n_u), row 0 at the lowest
    v, column 0 at the lowest u, over the imager's ``grid_extent``; the located touch ``face``,
    ``u_mm``, ``v_mm`` and the image value there, ``peak``."""

    images: dict[str, np.ndarray]
    face: str
    u_mm: float
    v_mm: float
    peak: float

    def to_json_dict(self) -> dict[str, Any]:
        """``{"face", "u_mm", "v_mm", "peak", "image": quantise(images)}`` (non-finite → None)."""
        return {
            "face": self.face,
            "u_mm": _number(self.u_mm),
            "v_mm": _number(self.v_mm),
            "peak": _number(self.peak),
            "image": quantise(self.images),
        }


def _number(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass
class Output:
    """What the engine emits per processed frame.

    ``raw`` (n_pairs,) pF; ``calibrated`` (n_pairs,) Eq. 2 against the touch reference (None until
    a reference exists); ``touch_probs`` (n_classes,) and ``touch_cls``; ``markers_pred``,
    ``markers_reference``, ``markers_true`` (n_markers, 3) mm; ``label``, ``trial`` and
    ``inflation`` (ml) as the frame carried them (None when the source does not know);
    ``contact`` the contact head's ``ContactReading`` (:mod:`ectskin.learn.predict.contact`) and
    ``ect`` the ECT head's :class:`EctFrame` (None without the head, before a reference exists,
    and for the ECT head on frames between its images); ``latency_ms`` from the frame's arrival
    to this output; ``stats`` a snapshot of :attr:`LiveEngine.stats`.
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
    contact: Any = None
    ect: EctFrame | None = None
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
            "contact": None if self.contact is None else to_jsonable(self.contact.to_dict()),
            "ect": None if self.ect is None else self.ect.to_json_dict(),
            "label": None if self.label is None else int(self.label),
            "trial": self.trial,
            "inflation": None if self.inflation is None else [float(v) for v in self.inflation],
            "latency_ms": float(self.latency_ms),
            "stats": dict(self.stats),
        }
