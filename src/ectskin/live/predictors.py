"""How the live engine binds trained models to the sensor layout: channels, classes, markers.

A predictor follows the ``TouchPredictor`` / ``TrackPredictor`` protocol of
:mod:`ectskin.learn.predict` (``n_pairs``, optional ``pair_names``; ``n_classes`` for touch;
``window`` and ``n_markers`` for tracking). :func:`bind_predictors` checks them against the layout
once, when the engine is built, and says which layout channels each model consumes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout


@dataclass(frozen=True)
class Binding:
    """The result of :func:`bind_predictors`.

    ``touch_channels`` / ``track_channels``: (n_model_pairs,) layout indices each model consumes,
    in the model's order, or None for all pairs in layout order. ``n_classes``: the touch model's
    (the layout's without one). ``window``: the tracking model's window (1 without one).
    """

    touch_channels: np.ndarray | None
    track_channels: np.ndarray | None
    n_classes: int
    window: int


def bind_predictors(layout: SensorLayout, touch: Any = None, track: Any = None) -> Binding:
    """Check ``touch`` and ``track`` (either may be None) against ``layout``."""
    touch_sel = model_channels(touch, layout, "touch model") if touch is not None else None
    track_sel = model_channels(track, layout, "tracking model") if track is not None else None
    n_classes = int(getattr(touch, "n_classes", layout.n_classes))
    if touch is not None and n_classes != layout.n_classes:
        raise EctskinError(
            f"touch model has {n_classes} classes, layout {layout.name!r} has "
            f"{layout.n_classes} (no touch + {layout.n_regions} regions)"
        )
    window = 1
    if track is not None:
        window = int(track.window)
        if int(track.n_markers) != layout.n_markers:
            raise EctskinError(
                f"tracking model predicts {track.n_markers} markers, layout {layout.name!r} "
                f"has {layout.n_markers}"
            )
    return Binding(touch_sel, track_sel, n_classes, window)


def model_channels(predictor: Any, layout: SensorLayout, what: str) -> np.ndarray | None:
    """Channel indices the predictor consumes (None = all, in layout order).

    A model that names its channels (``pair_names``, all of them the layout's) is mapped by name
    (a subset or another order); unnamed channels must match the layout's count.
    """
    n = int(predictor.n_pairs)
    names = [str(p) for p in getattr(predictor, "pair_names", None) or []]
    index = {p: j for j, p in enumerate(layout.pair_names)}
    known = len(names) == n and all(p in index for p in names)
    if known:  # the model names its channels (a subset or another order): map by name
        sel = np.array([index[p] for p in names], dtype=np.int64)
        return None if np.array_equal(sel, np.arange(layout.n_pairs)) else sel
    if n == layout.n_pairs:  # unnamed (or generically named) channels: layout order
        return None
    raise EctskinError(
        f"{what} expects {n} channels, layout {layout.name!r} has {layout.n_pairs} pairs"
        + (f" (model channels {names[:4]}… are not the layout's pair names)" if names else "")
    )
