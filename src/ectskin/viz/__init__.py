"""Figures. Plot functions take ``axes=None, show=False``, return the Figure and never save files.

Without ``show=True`` figures are built on matplotlib's Agg canvas (no GUI, no pyplot state), so
they work headless and in long-running processes; the caller saves them with ``fig.savefig``.
"""

from ectskin.viz.learning import (
    plot_confusion,
    plot_learning_curves,
    plot_marker_trajectory,
    plot_tracking_examples,
)

__all__ = [
    "plot_confusion",
    "plot_learning_curves",
    "plot_marker_trajectory",
    "plot_tracking_examples",
]
