"""The live engine's optional heads beside touch and tracking: contact and the ECT image.

:class:`ContactHead` runs a contact model (the ``ContactPredictor`` protocol of
:mod:`ectskin.learn.predict.contact`: ``n_pairs``, ``window``, ``faces``, ``face_extent``,
optional ``pair_names``, ``read(window) -> ContactReading``) on the newest ``window`` frames,
calibrated by paper Eq. 2 against the touch reference, exactly as the contact data set is
(:func:`ectskin.learn.data.contact.contact_dataset`): the model was trained on those inputs.

:class:`EctHead` runs an ECT imager (``faces``, ``grid_extent``, ``image(delta_c)``,
``locate(delta_c)``) on ``delta_c = c − c_0`` in pF against the same touch reference (the
untouched, uninflated skin), every ``every``-th processed frame: the image is the costly part,
and a heat map refreshed at a few hertz reads as well as one at the frame rate.

Both are checked against the layout once, when the engine is built, and are called from the
engine's inference loop only (no locking).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.calibration import relative_change
from ectskin.layout import SensorLayout
from ectskin.live.output import EctFrame
from ectskin.live.predictors import model_channels


def _extent(name: str, what: str, face: str, ext: Any) -> np.ndarray:
    """One face's [[u_lo, u_hi], [v_lo, v_hi]] mm, finite and increasing."""
    a = np.asarray(ext, dtype=np.float64)
    if a.shape != (2, 2) or not np.isfinite(a).all() or not (a[:, 1] > a[:, 0]).all():
        raise EctskinError(
            f"{what}: {name}[{face!r}] must be [[u_lo, u_hi], [v_lo, v_hi]] mm with lo < hi, "
            f"got {ext!r}"
        )
    return a


def _check_faces(what: str, faces: Any, layout: SensorLayout) -> list[str]:
    faces = [str(f) for f in faces]
    surfaces = {s.surface for s in layout.skins}
    unknown = [f for f in faces if f not in surfaces]
    if not faces or unknown:
        raise EctskinError(
            f"{what}: faces must be surfaces of layout {layout.name!r} "
            f"({sorted(surfaces)}), got {faces}"
        )
    return faces


class ContactHead:
    """A contact model bound to ``layout``: the channels it reads and its window.

    ``channels``: (n_model_pairs,) layout indices the model consumes in its order, or None for
    all pairs in layout order (:func:`~ectskin.live.predictors.model_channels`).
    """

    def __init__(self, predictor: Any, layout: SensorLayout) -> None:
        what = "contact model"
        self.predictor = predictor
        self.channels = model_channels(predictor, layout, what)
        window = predictor.window
        if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
            raise EctskinError(f"{what}: window must be an integer >= 1, got {window!r}")
        self.window = int(window)
        self.faces = _check_faces(what, predictor.faces, layout)
        extent = dict(getattr(predictor, "face_extent", None) or {})
        self.face_extent = {
            f: _extent("face_extent", what, f, e).tolist() for f, e in extent.items()
        }

    def inputs(self, raw_window: np.ndarray, c0: np.ndarray) -> np.ndarray:
        """(k, n_pairs) raw pF, oldest first → the model's (k, n_model_pairs) float32 input:
        Eq. 2 against ``c0``; a channel without a usable reference (NaN) is fed as 0."""
        w = relative_change(raw_window, c0)
        w = np.nan_to_num(w, nan=0.0, posinf=0.0, neginf=0.0)
        if self.channels is not None:
            w = w[:, self.channels]
        return w.astype(np.float32)

    def __call__(self, raw_window: np.ndarray, c0: np.ndarray):
        """The ``ContactReading`` of the newest frame of ``raw_window``."""
        return self.predictor.read(self.inputs(raw_window, c0))

    def meta(self) -> dict[str, Any]:
        return {"faces": self.faces, "face_extent": self.face_extent, "window": self.window}


class EctHead:
    """An ECT imager bound to ``layout``, run every ``every``-th call of :meth:`due`."""

    def __init__(self, imager: Any, layout: SensorLayout, every: int = 1) -> None:
        what = "ECT imager"
        if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
            raise EctskinError(f"{what}: every must be an integer >= 1 (frames), got {every!r}")
        n = getattr(imager, "n_pairs", layout.n_pairs)
        if int(n) != layout.n_pairs:
            raise EctskinError(
                f"{what} reads {n} pairs, layout {layout.name!r} has {layout.n_pairs}"
            )
        self.imager = imager
        self.every = int(every)
        self.faces = _check_faces(what, imager.faces, layout)
        grid = dict(imager.grid_extent)
        missing = [f for f in self.faces if f not in grid]
        if missing:
            raise EctskinError(f"{what}: grid_extent has no entry for face(s) {missing}")
        self.grid_extent = {
            f: _extent("grid_extent", what, f, grid[f]).tolist() for f in self.faces
        }
        self._calls = 0

    def due(self) -> bool:
        """True on the 1st, (every+1)-th, … call: whether this frame gets an image."""
        due = self._calls % self.every == 0
        self._calls += 1
        return due

    @staticmethod
    def delta(raw: np.ndarray, c0: np.ndarray) -> np.ndarray:
        """(n_pairs,) c − c_0 in pF; 0 where the reference or the readout is unusable (NaN,
        infinite, or a zero reference, as Eq. 2 treats it)."""
        raw = np.asarray(raw, dtype=np.float64)
        c0 = np.asarray(c0, dtype=np.float64)
        dc = raw - c0
        dc[~(np.isfinite(dc) & (c0 != 0))] = 0.0
        return dc

    def __call__(self, raw: np.ndarray, c0: np.ndarray) -> EctFrame:
        """The image of one frame and the located peak."""
        dc = self.delta(raw, c0)
        images = self.imager.image(dc)
        face, u, v, peak = self.imager.locate(dc)
        return EctFrame(
            images={f: np.asarray(images[f], dtype=np.float64) for f in self.faces},
            face=str(face),
            u_mm=float(u),
            v_mm=float(v),
            peak=float(peak),
        )

    def meta(self) -> dict[str, Any]:
        return {"faces": self.faces, "grid_extent": self.grid_extent, "every": self.every}
