"""The dashboard's messages: the ``meta`` message that describes the layout, and their encoding.

Messages go to the page as compact strict JSON (:func:`encode`): NumPy arrays and scalars become
lists and numbers, and non-finite numbers (NaN for masked channels) become ``null``, the JSON
policy of :mod:`ectskin._files`. The ``frame`` message is the engine's
:meth:`~ectskin.live.output.Output.to_json_dict`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin._files import json_text, to_jsonable
from ectskin.layout import SensorLayout


def encode(message: Any) -> str:
    """A message as compact, strict JSON text (NaN/inf → ``null``, NumPy → lists)."""
    return json_text(message, compact=True)


def frame_dict(output: Any) -> dict[str, Any]:
    """An engine output as a JSON-able dict (``Output.to_json_dict()``, or a dict as is)."""
    if isinstance(output, dict):
        return output
    to_dict = getattr(output, "to_json_dict", None)
    if to_dict is None:
        raise EctskinError(
            f"dashboard: published outputs must be dicts or have to_json_dict(), "
            f"got {type(output).__name__}"
        )
    return to_dict()


def build_meta(
    layout: SensorLayout, *, reference_markers: Any = None, n_classes: int | None = None
) -> dict[str, Any]:
    """The ``meta`` message: everything the page needs to draw ``layout``.

    Built from :meth:`SensorLayout.to_dict`. Electrodes carry their ``surface``; pairs their two
    surfaces (``pair_surfaces``, (n_pairs, 2)) so the chart can colour same-face and cross-face
    pairs apart. ``reference_markers`` is (n_markers, 3) mm or ``None`` when not known yet (each
    frame carries the engine's current reference anyway).
    """
    d = layout.to_dict()
    skin_surface = {s["name"]: s["surface"] for s in d["skins"]}
    electrodes = [dict(e, surface=skin_surface[e["skin"]]) for e in d["electrodes"]]
    surf = [e["surface"] for e in electrodes]
    if reference_markers is not None:
        reference_markers = np.asarray(reference_markers, dtype=np.float64)
        if reference_markers.shape != (layout.n_markers, 3):
            raise EctskinError(
                f"dashboard: reference_markers must have shape ({layout.n_markers}, 3) for layout "
                f"{layout.name!r}, got {reference_markers.shape}"
            )
    return to_jsonable(
        {
            "type": "meta",
            "layout_name": layout.name,
            "n_pairs": layout.n_pairs,
            "pair_names": list(layout.pair_names),
            "pair_surfaces": [[surf[i], surf[j]] for i, j in layout.pairs],
            "n_classes": int(n_classes) if n_classes is not None else layout.n_classes,
            "regions": d["regions"],
            "skins": d["skins"],
            "electrodes": electrodes,
            "marker_names": [m["name"] for m in d["markers"]],
            "markers": d["markers"],
            "reference_markers": reference_markers,
        }
    )
