"""Which layout channels a trained model consumes: :func:`model_channels`.

A predictor (:mod:`ectskin.learn.predict`) says how many channels it reads (``n_pairs``) and may
name them (``pair_names``). The live heads (:mod:`ectskin.live.heads`) ask once, when the engine is
built, and then feed the model those channels in its order.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout


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
