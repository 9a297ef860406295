"""Readable figures (ectskin.viz): Fig. 7's cell numbers sized to the cells, the 28-line legend
of the characterisation figures outside the axes with entries one can tell apart, and the one
policy for figure formats and resolutions."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.viz import DEFAULT_DPI, check_figure_options, figure_file, plot_confusion
from ectskin.viz.twin import plot_response


def _paper_like_confusion(n: int = 19) -> np.ndarray:
    conf = np.diag(np.full(n, 1500))
    conf[0, 0] = 4900  # the no-touch class: the largest count, four digits
    conf[3, 4], conf[10, 2] = 7, 123
    return conf


def test_fig7_cell_numbers_fit_their_cells_and_are_readable():
    """The counts of a 19-class map were drawn at 5.5 pt (6 px at 110 dpi) whatever the cell
    size. Catches a fixed small font (``fontsize=5.5``): every number is now at least 8 pt and
    still fits inside its cell; empty cells hold no "0"."""
    conf = _paper_like_confusion()
    fig = plot_confusion(conf)
    ax = fig.axes[0]
    texts = ax.texts
    assert sorted(t.get_text() for t in texts) == sorted(str(v) for v in conf[conf > 0])
    renderer = fig.canvas.get_renderer()
    box = ax.get_window_extent(renderer)
    cell_w, cell_h = box.width / 19, box.height / 19
    for t in texts:
        assert t.get_fontsize() >= 8, t.get_text()
        ext = t.get_window_extent(renderer)
        assert ext.width < cell_w and ext.height < cell_h, (t.get_text(), ext.width, cell_w)
    # a small map gets larger numbers, capped
    small = plot_confusion(np.diag([5, 6, 7]))
    assert all(8 <= t.get_fontsize() <= 10 for t in small.axes[0].texts)


def test_the_28_line_legend_is_outside_the_axes_and_its_entries_differ():
    """Fig. 3/4's legend lists 28 pairs. Catches a legend inside the axes (it hid data), a font
    below 7 pt, and entries told apart by a continuous colour map only (28 shades)."""
    t = np.arange(90) / 30
    calibrated = np.random.default_rng(0).normal(0, 0.01, (90, 28)).cumsum(axis=0)
    names = [f"E{i + 1}-E{j + 1}" for i, j in itertools.combinations(range(8), 2)]
    fig = plot_response(t, calibrated, names, [0, 1, 2, 3], title="inflation")
    top = fig.axes[0]
    legend = top.get_legend()
    assert legend is not None and len(legend.get_texts()) == 28
    assert legend._ncols >= 4
    assert all(text.get_fontsize() >= 7 for text in legend.get_texts())
    renderer = fig.canvas.get_renderer()
    fig.draw(renderer)
    leg_box = legend.get_window_extent(renderer)
    for ax in fig.axes:  # outside every panel: it covers no curve
        assert not leg_box.overlaps(ax.get_window_extent(renderer)), ax.get_title()
    styles = {(tuple(h.get_color()), h.get_linestyle()) for h in legend.legend_handles}
    assert len(styles) == 28


def test_figure_options_are_checked_once():
    assert check_figure_options() == ("png", DEFAULT_DPI)
    assert check_figure_options("svg", 300) == ("svg", 300)
    assert figure_file("fig7_confusion", "pdf") == "fig7_confusion.pdf"
    with pytest.raises(EctskinError, match="allowed values are 'png', 'pdf', 'svg'; got 'jpg'"):
        check_figure_options("jpg")
    for dpi in (0, 29, 1201, 150.0, True):
        with pytest.raises(EctskinError, match="dpi must be an integer from 30 to 1200"):
            check_figure_options("png", dpi)
