"""Figures of the twin's characterisation: paper Fig. 3 (inflation) and Fig. 4 (two-stage touch).

Plot functions take ``axes=None, show=False`` (or build a figure when none is given), return the
figure and never decide where files go: the caller saves.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

#: line styles that, with the 10 colours of ``tab10``, tell up to 30 curves apart in a legend
LINESTYLES = ("-", "--", ":")


def line_styles(n: int) -> list[dict[str, Any]]:
    """Colour and dash of ``n`` curves that a reader can match to their legend entries: the 10
    colours of ``tab10``, then again dashed, then dotted (a continuous colour map gives 28
    shades that no one tells apart). More than 30 curves repeat the cycle."""
    tab10 = colormaps["tab10"]
    colors = [tab10(k) for k in range(10)]
    return [
        {"color": colors[k % 10], "linestyle": LINESTYLES[(k // 10) % len(LINESTYLES)]}
        for k in range(n)
    ]


def plot_response(
    t_s: np.ndarray,
    calibrated: np.ndarray,
    pair_names: list[str],
    selected: list[int],
    *,
    title: str,
    stages: Sequence[tuple[float, str]] = (),
    show: bool = False,
):
    """Two panels as in the paper: (a) all pairs' calibrated change vs time, (b) 4 selected pairs.

    ``calibrated`` is (n_frames, n_pairs), relative change (Eq. 2), plotted in %. The legend of
    (a), one entry per pair, sits below its axes in 7 columns, each curve with its own colour
    and dash (:func:`line_styles`), so 28 entries stay readable and hide no data.
    """
    fig = Figure(figsize=(11, 7.0), layout="constrained")  # no pyplot state: nothing leaks
    FigureCanvasAgg(fig)  # headless, as every figure of ectskin.viz
    gs = fig.add_gridspec(2, 4, height_ratios=[1.25, 1])
    ax = fig.add_subplot(gs[0, :])
    for k, style in enumerate(line_styles(calibrated.shape[1])):
        ax.plot(t_s, 100 * calibrated[:, k], lw=1.0, label=pair_names[k], **style)
    for ts, label in stages:
        ax.axvline(ts, color="0.5", ls="--", lw=0.8)
        ax.text(ts, ax.get_ylim()[1], f" {label}", va="top", fontsize=8, color="0.3")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("calibrated capacitance c (%)")
    ax.set_title(f"a  {title}: all {calibrated.shape[1]} pairs")
    ax.legend(
        ncol=min(7, calibrated.shape[1]),
        fontsize=7.5,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.15),
        frameon=False,
        handlelength=3.0,
        columnspacing=1.5,
        title="pair",
        title_fontsize=7.5,
    )
    for j, k in enumerate(selected[:4]):
        a = fig.add_subplot(gs[1, j])
        a.plot(t_s, 100 * calibrated[:, k], color="tab:red", lw=1.0)
        a.set_title(f"b{j + 1}  pair {pair_names[k]}", fontsize=9)
        a.set_xlabel("time (s)")
        if j == 0:
            a.set_ylabel("c (%)")
    if show:
        import matplotlib.pyplot as plt

        manager = plt.figure().canvas.manager
        if manager is None:  # a non-interactive backend: nothing to show on
            return fig
        manager.canvas.figure = fig
        fig.set_canvas(manager.canvas)
        plt.show()
    return fig
