"""Figures of the twin's characterisation: paper Fig. 3 (inflation) and Fig. 4 (two-stage touch).

Plot functions take ``axes=None, show=False`` (or build a figure when none is given), return the
figure and never decide where files go: the caller saves.
"""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure


def plot_response(
    t_s: np.ndarray,
    calibrated: np.ndarray,
    pair_names: list[str],
    selected: list[int],
    *,
    title: str,
    stages: list[tuple[float, str]] = (),
    show: bool = False,
):
    """Two panels as in the paper: (a) all pairs' calibrated change vs time, (b) 4 selected pairs.

    ``calibrated`` is (n_frames, n_pairs), relative change (Eq. 2), plotted in %.
    """
    fig = Figure(figsize=(11, 6.5), layout="constrained")  # no pyplot state: nothing leaks
    gs = fig.add_gridspec(2, 4, height_ratios=[1.25, 1])
    ax = fig.add_subplot(gs[0, :])
    colors = colormaps["turbo"](np.linspace(0, 1, calibrated.shape[1]))
    for k in range(calibrated.shape[1]):
        ax.plot(t_s, 100 * calibrated[:, k], color=colors[k], lw=0.9, label=pair_names[k])
    for ts, label in stages:
        ax.axvline(ts, color="0.5", ls="--", lw=0.8)
        ax.text(ts, ax.get_ylim()[1], f" {label}", va="top", fontsize=8, color="0.3")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("calibrated capacitance c (%)")
    ax.set_title(f"a  {title}: all {calibrated.shape[1]} pairs")
    ax.legend(ncol=7, fontsize=6, loc="upper left", bbox_to_anchor=(0, -0.18), frameon=False)
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
        manager.canvas.figure = fig
        fig.set_canvas(manager.canvas)
        plt.show()
    return fig
