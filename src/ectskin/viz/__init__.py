"""Figures. Plot functions take ``axes=None, show=False``, return the Figure and never save files.

Without ``show=True`` figures are built on matplotlib's Agg canvas (no GUI, no pyplot state), so
they work headless and in long-running processes; the caller saves them with ``fig.savefig``.

How callers save them is one policy too: a figure file is ``<stem>.<format>`` with a format of
:data:`FIGURE_FORMATS` at a resolution in dpi, checked once by :func:`check_figure_options`
(``ectskin evaluate|characterize|reproduce|demo --format png|pdf|svg --dpi N``).
"""

from __future__ import annotations

from ectskin._check import EctskinError, check_option
from ectskin.viz.bound import plot_bound_maps
from ectskin.viz.ect import plot_ect_images
from ectskin.viz.learning import (
    plot_confusion,
    plot_learning_curves,
    plot_marker_trajectory,
    plot_tracking_examples,
)

#: file formats figures are saved in: PNG (raster), PDF and SVG (vector)
FIGURE_FORMATS = ("png", "pdf", "svg")
#: dots per inch of a saved figure unless told otherwise (the raster parts of PDF/SVG too)
DEFAULT_DPI = 150
#: the resolutions accepted (a huge dpi would allocate a huge raster)
DPI_RANGE = (30, 1200)


def check_figure_options(figure_format: str = "png", dpi: int = DEFAULT_DPI) -> tuple[str, int]:
    """``(format, dpi)`` checked: a format of :data:`FIGURE_FORMATS` and an integer dpi in
    :data:`DPI_RANGE`; anything else is an EctskinError naming the option."""
    check_option("format", figure_format, FIGURE_FORMATS)
    lo, hi = DPI_RANGE
    if isinstance(dpi, bool) or not isinstance(dpi, int) or not lo <= dpi <= hi:
        raise EctskinError(f"dpi must be an integer from {lo} to {hi}, got {dpi!r}")
    return figure_format, dpi


def figure_file(stem: str, figure_format: str) -> str:
    """The file name of figure ``stem`` in ``figure_format``: ``fig7_confusion.pdf``."""
    return f"{stem}.{figure_format}"


__all__ = [
    "DEFAULT_DPI",
    "DPI_RANGE",
    "FIGURE_FORMATS",
    "check_figure_options",
    "figure_file",
    "plot_bound_maps",
    "plot_ect_images",
    "plot_confusion",
    "plot_learning_curves",
    "plot_marker_trajectory",
    "plot_tracking_examples",
]
