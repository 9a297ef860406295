"""The live engine's heads: one object per answer the engine gives for a frame.

A head is bound to the layout once, when the engine is built (its checks at the door: channels,
classes, markers, faces). Then, on every processed frame whose reference exists, it gets the
newest ``window`` raw frames and that reference and writes its answer into the frame's
:class:`~ectskin.live.output.Output` (:meth:`Head.step`). The engine runs its heads in order, each
the same way (:class:`~ectskin.live.engine.LiveEngine`); a head that raises is counted and logged
there, and the frame goes out without that head's answer.

* :class:`TouchHead` (``touch``): a TouchMLP on the frame → ``touch_probs``, ``touch_cls``;
  touch reference, window 1.
* :class:`TrackHead` (``track``): a C2DT on the model's window and the reference's marker
  coordinates → ``markers_pred``, ``markers_reference``; tracking reference.
* :class:`ContactHead` (``contact``): a ContactNet on the model's window → ``contact`` (a
  ``ContactReading``); touch reference.
* :class:`EctHead` (``ect``): an ECT imager on ``delta_c = c − c_0`` in pF → ``ect`` (an
  :class:`~ectskin.live.output.EctFrame`) every ``every``-th frame that has a reference; touch
  reference, window 1. The image is the costly part, and a heat map refreshed at a few hertz reads
  as well as one at the frame rate.

The model heads feed their model what its data set is built from offline
(:mod:`ectskin.learn.data`): paper Eq. 2 against the reference, oldest frame first, float32, the
model's channels in its order (:func:`~ectskin.live.predictors.model_channels`), and a channel
without a usable reference (NaN) fed as 0 (no change). The touch reference is the rest state
(untouched, uninflated); the tracking reference is the state at the start of the trajectory, with
the marker coordinates of that moment (the paper's prior knowledge, §4.2).

Heads are called from the engine's inference loop only (no locking).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.calibration import relative_change
from ectskin.layout import SensorLayout
from ectskin.live.output import EctFrame, Output
from ectskin.live.predictors import model_channels

#: the heads' keys, in the order the engine runs them (and the keys of their ``meta``)
HEAD_KEYS = ("touch", "track", "contact", "ect")


@dataclass(frozen=True)
class ReferenceInUse:
    """A reference a head is calibrated against: ``c0`` (n_pairs,) pF, NaN for an unusable
    channel; ``markers`` (n_markers, 3) mm the decoder's initial marker coordinates (the tracking
    reference's; None when not known)."""

    c0: np.ndarray
    markers: np.ndarray | None = None


class Head(Protocol):
    """What the engine needs of a head.

    ``key``: one of :data:`HEAD_KEYS`; ``what``: its name in messages ("touch model");
    ``reference``: ``"touch"`` or ``"tracking"``; ``window``: the raw frames it reads (1: the frame
    alone).
    """

    key: str
    what: str
    reference: str
    window: int

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        """Write the answer for the newest of ``frames`` ((window, n_pairs) raw pF, oldest
        first) into ``out``."""

    def meta(self) -> dict[str, Any]:
        """The head's part of the dashboard's ``meta`` message (JSON-able)."""


def _window_size(what: str, window: Any) -> int:
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
        raise EctskinError(f"{what}: window must be an integer >= 1, got {window!r}")
    return int(window)


def _model_input(raw: np.ndarray, c0: np.ndarray, channels: np.ndarray | None) -> np.ndarray:
    """Raw pF (..., n_pairs) → the model's float32 input (..., n_model_pairs): Eq. 2 against
    ``c0``, a channel without a usable reference (NaN, inf) fed as 0."""
    x = relative_change(raw, c0)
    x = np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0)
    if channels is not None:
        x = x[..., channels]
    return x.astype(np.float32)


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


class TouchHead:
    """A touch model (the ``TouchPredictor`` protocol of :mod:`ectskin.learn.predict`:
    ``n_pairs``, optional ``pair_names`` and ``n_classes``, ``predict(x) -> probs``) bound to
    ``layout``. ``channels`` as for :class:`ContactHead`."""

    key, what, reference, window = "touch", "touch model", "touch", 1

    def __init__(self, predictor: Any, layout: SensorLayout) -> None:
        self.predictor = predictor
        self.channels = model_channels(predictor, layout, self.what)
        self.n_classes = int(getattr(predictor, "n_classes", layout.n_classes))
        if self.n_classes != layout.n_classes:
            raise EctskinError(
                f"{self.what} has {self.n_classes} classes, layout {layout.name!r} has "
                f"{layout.n_classes} (no touch + {layout.n_regions} regions)"
            )

    def inputs(self, raw: np.ndarray, c0: np.ndarray) -> np.ndarray:
        """(n_pairs,) raw pF → the model's (n_model_pairs,) float32 input."""
        return _model_input(raw, c0, self.channels)

    def __call__(self, raw: np.ndarray, c0: np.ndarray) -> np.ndarray:
        """(n_classes,) float64 class probabilities of one frame."""
        return np.asarray(self.predictor.predict(self.inputs(raw, c0)), dtype=np.float64)

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        probs = self(frames[-1], ref.c0)
        out.touch_probs = probs
        out.touch_cls = int(np.argmax(probs))

    def meta(self) -> dict[str, Any]:
        return {"n_classes": self.n_classes}


class TrackHead:
    """A tracking model (the ``TrackPredictor`` protocol of :mod:`ectskin.learn.predict`:
    ``n_pairs``, optional ``pair_names``, ``window``, ``n_markers``, ``predict(window, init)``)
    bound to ``layout``. Without initial marker coordinates (``ref.markers`` None) it gives no
    answer. ``channels`` as for :class:`ContactHead`."""

    key, what, reference = "track", "tracking model", "tracking"

    def __init__(self, predictor: Any, layout: SensorLayout) -> None:
        self.predictor = predictor
        self.channels = model_channels(predictor, layout, self.what)
        self.window = _window_size(self.what, predictor.window)
        self.n_markers = int(predictor.n_markers)
        if self.n_markers != layout.n_markers:
            raise EctskinError(
                f"{self.what} predicts {self.n_markers} markers, layout {layout.name!r} "
                f"has {layout.n_markers}"
            )

    def inputs(self, raw_window: np.ndarray, c0: np.ndarray) -> np.ndarray:
        """(k, n_pairs) raw pF, oldest first → the model's (k, n_model_pairs) float32 input."""
        return _model_input(raw_window, c0, self.channels)

    def __call__(self, raw_window: np.ndarray, c0: np.ndarray, markers: np.ndarray) -> np.ndarray:
        """(n_markers, 3) mm marker coordinates at the newest frame of ``raw_window``, from
        ``markers`` (n_markers, 3) mm at the reference."""
        pred = self.predictor.predict(
            self.inputs(raw_window, c0), np.asarray(markers).astype(np.float32)
        )
        return np.asarray(pred, dtype=np.float64)

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        if ref.markers is None:  # no initial coordinates: the engine has said so
            return
        out.markers_pred = self(frames, ref.c0, ref.markers)
        out.markers_reference = ref.markers

    def meta(self) -> dict[str, Any]:
        return {"window": self.window, "n_markers": self.n_markers}


class ContactHead:
    """A contact model (the ``ContactPredictor`` protocol of
    :mod:`ectskin.learn.predict.contact`: ``n_pairs``, ``window``, ``faces``, ``face_extent``,
    optional ``pair_names``, ``read(window) -> ContactReading``) bound to ``layout``.

    ``channels``: (n_model_pairs,) layout indices the model consumes in its order, or None for
    all pairs in layout order (:func:`~ectskin.live.predictors.model_channels`).
    """

    key, what, reference = "contact", "contact model", "touch"

    def __init__(self, predictor: Any, layout: SensorLayout) -> None:
        self.predictor = predictor
        self.channels = model_channels(predictor, layout, self.what)
        self.window = _window_size(self.what, predictor.window)
        self.faces = _check_faces(self.what, predictor.faces, layout)
        extent = dict(getattr(predictor, "face_extent", None) or {})
        self.face_extent = {
            f: _extent("face_extent", self.what, f, e).tolist() for f, e in extent.items()
        }

    def inputs(self, raw_window: np.ndarray, c0: np.ndarray) -> np.ndarray:
        """(k, n_pairs) raw pF, oldest first → the model's (k, n_model_pairs) float32 input."""
        return _model_input(raw_window, c0, self.channels)

    def __call__(self, raw_window: np.ndarray, c0: np.ndarray):
        """The ``ContactReading`` of the newest frame of ``raw_window``."""
        return self.predictor.read(self.inputs(raw_window, c0))

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        out.contact = self(frames, ref.c0)

    def meta(self) -> dict[str, Any]:
        return {"faces": self.faces, "face_extent": self.face_extent, "window": self.window}


class EctHead:
    """An ECT imager bound to ``layout``, run every ``every``-th call of :meth:`due`."""

    key, what, reference, window = "ect", "ECT imager", "touch", 1

    def __init__(self, imager: Any, layout: SensorLayout, every: int = 1) -> None:
        what = self.what
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

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        if self.due():
            out.ect = self(frames[-1], ref.c0)

    def meta(self) -> dict[str, Any]:
        return {"faces": self.faces, "grid_extent": self.grid_extent, "every": self.every}


def build_heads(
    layout: SensorLayout,
    *,
    touch: Any = None,
    track: Any = None,
    contact: Any = None,
    imager: Any = None,
    ect_every: int = 1,
) -> tuple[Head, ...]:
    """The heads for the given models (each may be None), in the order of :data:`HEAD_KEYS`."""
    heads: list[Head] = []
    if touch is not None:
        heads.append(TouchHead(touch, layout))
    if track is not None:
        heads.append(TrackHead(track, layout))
    if contact is not None:
        heads.append(ContactHead(contact, layout))
    if imager is not None:
        heads.append(EctHead(imager, layout, ect_every))
    return tuple(heads)
