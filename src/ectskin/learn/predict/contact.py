"""Contact inference on a stream: :class:`ContactPredictor` (a trained contact run).

``predict(window)`` gives the raw columns of :meth:`ContactNet.decode`; ``read(window)`` one
:class:`ContactReading` per frame: finger count, probabilities of contact and hover, and per
finger its face, point (mm), uncertainty (mm, the model's own, one standard deviation per axis;
NaN where the model gives none), force (N) and the force's standard deviation (N; None where
the model gives none: a run trained before the force had its σ).

A contact run whose ``candidates.json`` selects a classical model
(:mod:`ectskin.learn.contact_choice`) answers with its ``model.skops`` instead
(:class:`~ectskin.learn.contact_classical.ContactClassical`: the same columns, through
scikit-learn, from the window's last frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ectskin._check import EctskinError
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.learn.predict.base import Predictor, as_input

__all__ = ["ContactPredictor", "ContactReading", "FingerEstimate"]


@dataclass(frozen=True)
class FingerEstimate:
    """One finger of a :class:`ContactReading`: what the model says about it."""

    face: str
    u_mm: float
    v_mm: float
    sigma_mm: float
    force_n: float
    force_sigma_n: float | None = None


@dataclass(frozen=True)
class ContactReading:
    """What the contact model says about one frame."""

    count: int
    p_contact: float
    p_hover: float
    fingers: tuple[FingerEstimate, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "count": self.count,
            "p_contact": self.p_contact,
            "p_hover": self.p_hover,
            "fingers": [vars(f) for f in self.fingers],
        }


class ContactPredictor(Predictor):
    """Contact count, points, forces and hover from a window of calibrated frames."""

    kind = "contact_net"
    _output = "decode"  # ContactNet.decode, the model's own

    def __init__(
        self,
        model: torch.nn.Module | None,
        config: Any,
        payload: dict,
        source: str,
        classical: Any = None,
    ) -> None:
        self.classical = classical
        if classical is None:
            super().__init__(model, config, payload, source)
            return
        self.model = None
        self.config = classical.config
        self.payload = {
            "kind": f"contact_{classical.name}",
            "extra": {"faces": classical.faces, "face_extent": classical.face_extent},
        }
        self.source = source
        self.device = torch.device("cpu")
        self.pair_names = list(classical.pair_names)

    @classmethod
    def from_run(
        cls, run_dir: str | Path, *, device: str | torch.device = "cpu", layout: Any = None
    ):
        """Load the model a contact run answers with: ``model.skops`` when its
        ``candidates.json`` selects a classical model, else ``model.pt`` (on ``device``); or the
        model file itself. With ``layout`` a model of another skin is refused."""
        from ectskin.learn.candidates import read_candidates
        from ectskin.learn.contact_classical import load_contact_classical

        path = Path(run_dir)
        if path.is_dir():
            doc = read_candidates(path)
            if doc is not None and doc.get("task") == "contact" and doc["selected"] != "contactnet":
                path = path / "model.skops"
        if path.suffix == ".skops":
            model = load_contact_classical(path, layout=layout)
            return cls(None, None, {}, str(path), classical=model)
        return super().from_run(run_dir, device=device, layout=layout)

    @property
    def model_name(self) -> str:
        """ "contactnet" or the classical candidate answering."""
        return "contactnet" if self.classical is None else self.classical.name

    @property
    def runtime(self) -> str:
        return "skops" if self.classical is not None else super().runtime

    def use_runtime(self, runtime: str):
        """As :meth:`Predictor.use_runtime`; a classical model answers through scikit-learn
        whatever is asked."""
        if self.classical is not None:
            return self
        return super().use_runtime(runtime)

    @property
    def window(self) -> int:
        return int(self.config.window)

    def _single_shapes(self) -> list[tuple[int, ...]]:
        return [(1, self.window, self.n_pairs)]

    @property
    def faces(self) -> list[str]:
        names = self.payload.get("extra", {}).get("faces") or []
        return [str(f) for f in names] or [f"face{k}" for k in range(self.config.n_faces)]

    @property
    def face_extent(self) -> dict[str, Any]:
        """{face: [[u_lo, u_hi], [v_lo, v_hi]]} mm of the skins the model was trained on."""
        return dict(self.payload.get("extra", {}).get("face_extent") or {})

    def predict(self, window_calibrated: Any) -> np.ndarray:
        """(k, n_pairs) window, oldest frame first → (3 + S · 6,) columns (``PRED_COLUMNS``,
        then ``SLOT_COLUMNS`` per slot); batched (B, k, n_pairs) → (B, columns)."""
        x, batched = as_input(
            "window",
            window_calibrated,
            (self.window, self.n_pairs),
            f"ContactPredictor({self.source})",
            self.pair_names,
        )
        if self.classical is not None:
            out = self.classical.predict(x.numpy()).astype(np.float32)
        else:
            out = self._forward([x], batched)
        return out if batched else out[0]

    def read(self, window_calibrated: Any) -> ContactReading:
        """One window → its :class:`ContactReading` (the first ``count`` slots are fingers)."""
        row = np.asarray(self.predict(window_calibrated), dtype=np.float64)
        if row.ndim != 1:
            raise EctskinError(
                f"ContactPredictor({self.source}).read takes one window ({self.window}, "
                f"{self.n_pairs}); use predict for a batch"
            )
        count = int(row[PRED_COLUMNS.index("count")])
        fingers = []
        faces = self.faces
        for s in range(count):
            a = len(PRED_COLUMNS) + s * len(SLOT_COLUMNS)
            face, u, v, sigma, force, force_sd = row[a : a + len(SLOT_COLUMNS)]
            fingers.append(
                FingerEstimate(
                    faces[int(face)],
                    float(u),
                    float(v),
                    float(sigma),
                    float(force),
                    float(force_sd) if np.isfinite(force_sd) and force_sd > 0 else None,
                )
            )
        return ContactReading(
            count=count,
            p_contact=float(row[PRED_COLUMNS.index("p_contact")]),
            p_hover=float(row[PRED_COLUMNS.index("p_hover")]),
            fingers=tuple(fingers),
        )
