"""ECT images of touch: per face heat maps with the true and the located contact point."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from ectskin.viz.learning import _finish, _new_figure


def plot_ect_images(
    examples: Sequence[dict],
    faces: Sequence[str],
    extents: Sequence[Sequence[float]],
    *,
    axes=None,
    show: bool = False,
) -> Figure:
    """One row per touch, one column per face: the image as a heat map (u across, v up).

    ``examples``: dicts with ``images`` (face → (n_v, n_u) array), ``true`` and ``pred``
    (face, u mm, v mm) and optionally ``trial`` (as in the ``examples`` of
    ``ect_image_metrics``). ``extents``: per face (u0, u1, v0, v1) mm, the skin's outline.
    The true contact is a white circle, the located one a black cross (on the face they lie on).
    ``axes``: an (n_examples, n_faces) array of Axes to draw into, or None for a new figure.
    """
    n, m = len(examples), len(faces)
    if axes is None:
        fig = _new_figure(show, figsize=(2.4 * m, 4.0 * max(n, 1)))
        axes = np.asarray(fig.subplots(max(n, 1), m, squeeze=False))
    else:
        axes = np.asarray(axes).reshape(max(n, 1), m)
        fig = axes.flat[0].figure
    for r, ex in enumerate(examples):
        vmax = max(float(np.nanmax(ex["images"][f])) for f in faces) or 1.0
        for c, face in enumerate(faces):
            ax = axes[r, c]
            u0, u1, v0, v1 = extents[c]
            im = ax.imshow(
                ex["images"][face],
                origin="lower",
                extent=(u0, u1, v0, v1),
                cmap="viridis",
                vmin=0.0,
                vmax=vmax,
                aspect="equal",
            )
            ax.add_patch(Rectangle((u0, v0), u1 - u0, v1 - v0, fill=False, color="0.3", lw=1))
            if ex["true"][0] == face:
                ax.plot(
                    ex["true"][1],
                    ex["true"][2],
                    "o",
                    mfc="none",
                    mec="w",
                    ms=9,
                    mew=2,
                    label="true",
                )
            if ex["pred"][0] == face:
                ax.plot(ex["pred"][1], ex["pred"][2], "x", color="k", ms=9, mew=2, label="located")
            ax.set_title(f"{ex.get('trial', '')} {face}".strip(), fontsize=8)
            ax.set_xlabel("u (mm)")
            if c == 0:
                ax.set_ylabel("v (mm)")
        fig.colorbar(im, ax=list(axes[r]), shrink=0.8, label="image (a.u.)")
    return _finish(fig, show)
