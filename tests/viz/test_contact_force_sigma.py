"""The force figure with each frame's σ (:func:`ectskin.viz.contact.plot_force_sigma`), read back
from the matplotlib artists: the error bars' lengths against the σ given, and the legend's
coverage against a hand count on seven frames.

What each test catches: bars of 2σ or σ² (or centred elsewhere than the prediction), a frame drawn
in the wrong part (the threshold taken as ≤, the parts swapped), a coverage that counts frames
without σ, uses < instead of ≤, or counts only the frames drawn (after ``max_points``), and a
frame without σ drawn with a bar.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.viz.contact import plot_force_sigma

# Seven frames. |pred - true| / sigma, by hand:
#   0: 0.1 / 0.2 = 0.5   observable (bound 0.05)       within 1σ and 2σ
#   1: 0.3 / 0.2 = 1.5   observable (bound 0.05)       within 2σ only
#   2: 1.0 / 0.4 = 2.5   not observable (bound 0.5)    neither
#   3: 0.0 / 0.1 = 0     not observable (bound 0.1: at the threshold, so not below it)  both
#   4: no σ              observable (bound 0.01)       not counted
#   5: 0.08 / 0.05 = 1.6 no bound                      within 2σ only
#   6: 0.5 / 0.5 = 1     no bound                      both (exactly 1σ, in binary too: ≤)
TRUE = np.array([1.0, 2.0, 3.0, 1.5, 0.5, 2.5, 1.0])
PRED = np.array([1.1, 2.3, 2.0, 1.5, 0.9, 2.42, 1.5])
SIGMA = np.array([0.2, 0.2, 0.4, 0.1, np.nan, 0.05, 0.5])
BOUND = np.array([0.05, 0.05, 0.5, 0.1, 0.01, np.nan, np.nan])
PARTS = {"observable": [0, 1, 4], "not_observable": [2, 3], "no_bound": [5, 6]}
# (frames, ±1σ %, ±2σ %, frames without σ) by the hand count above
LEGEND = {
    "observable": (3, 50.0, 100.0, 1),
    "not_observable": (2, 50.0, 50.0, 0),
    "no_bound": (2, 50.0, 100.0, 0),
}


def _bars(ax) -> dict[str, np.ndarray]:
    """Part → (k, 3) rows (x, centre, half length) of its error bars, from the artists."""
    out = {}
    for c in ax.containers:
        segments = [np.asarray(s) for s in c.lines[2][0].get_segments()]
        rows = [
            (s[0, 0], 0.5 * (s[0, 1] + s[1, 1]), 0.5 * abs(s[1, 1] - s[0, 1])) for s in segments
        ]
        assert all(s[0, 0] == s[1, 0] for s in segments)  # vertical bars
        out[c.lines[2][0].get_gid()] = np.array(rows)
    return out


def _legend(ax) -> dict[str, tuple[int, float, float, int]]:
    got = {}
    for text in ax.get_legend().get_texts():
        s = text.get_text()
        m = re.match(
            r"(.+), (\d+) frames?: ±1σ ([\d.]+) %, ±2σ ([\d.]+) %(?: \((\d+) without σ\))?$", s
        )
        if m is None:
            continue
        name = {
            "observable": "observable",
            "not observable": "not_observable",
            "no bound": "no_bound",
            "test frames": "all",
        }[m.group(1).split(" (")[0]]
        got[name] = (int(m.group(2)), float(m.group(3)), float(m.group(4)), int(m.group(5) or 0))
    return got


def test_error_bars_are_the_sigma_and_the_legend_the_hand_count():
    fig = plot_force_sigma(TRUE, PRED, SIGMA, BOUND, threshold_n=0.1)
    ax = fig.axes[0]
    bars = _bars(ax)
    assert set(bars) == set(PARTS)
    for part, idx in PARTS.items():
        with_sigma = [i for i in idx if np.isfinite(SIGMA[i])]
        np.testing.assert_allclose(bars[part][:, 0], TRUE[with_sigma])
        np.testing.assert_allclose(bars[part][:, 1], PRED[with_sigma])
        np.testing.assert_allclose(bars[part][:, 2], SIGMA[with_sigma])
    assert _legend(ax) == LEGEND
    assert sorted(t.get_text().split(",")[0] for t in ax.get_legend().get_texts()
                  if "frame" in t.get_text()) == [
        "no bound", "not observable (bound ≥ 0.1 N)", "observable (bound < 0.1 N)"]
    # frame 4 (no σ) is drawn, hollow and without a bar
    hollow = [ln for ln in ax.lines if ln.get_markerfacecolor() == "none"]
    assert len(hollow) == 1 and hollow[0].get_gid() == "observable"
    assert (hollow[0].get_xdata().tolist(), hollow[0].get_ydata().tolist()) == ([0.5], [0.9])


def test_coverage_counts_every_frame_not_only_those_drawn():
    """At most max_points frames are drawn; the legend's shares are over all of them, and agree
    with the contact metrics' force_coverage."""
    from ectskin.learn.metrics.contact import force_coverage

    rng = np.random.default_rng(3)
    n = 901
    t = rng.uniform(0.2, 3.0, n)
    s = rng.uniform(0.05, 0.4, n)
    p = t + s * rng.standard_normal(n) * 1.3
    fig = plot_force_sigma(t, p, s, max_points=50)
    ax = fig.axes[0]
    (rows,) = _bars(ax).values()
    assert len(rows) == 50
    np.testing.assert_allclose(rows[:, 2], np.interp(rows[:, 0], np.sort(t), s[np.argsort(t)]))
    (part,) = _legend(ax).values()
    cov = force_coverage(t, p, s)
    assert part == (
        n,
        round(100 * cov["force_coverage_1sigma"], 1),
        round(100 * cov["force_coverage_2sigma"], 1),
        0,
    )
    # a part without any σ says so, and draws no bar
    fig = plot_force_sigma(t[:5], p[:5], np.full(5, np.nan))
    assert not fig.axes[0].containers
    assert "5 frames: no σ" in fig.axes[0].get_legend().get_texts()[0].get_text()


def test_bad_input_names_the_field():
    with pytest.raises(
        EctskinError, match=r"one-dimensional of one shape, got \(7,\), \(7,\), \(5,\)"
    ):
        plot_force_sigma(TRUE, PRED, SIGMA[:5])
    with pytest.raises(EctskinError, match=r"threshold_n must be a number > 0, got 0"):
        plot_force_sigma(TRUE, PRED, SIGMA, BOUND, threshold_n=0)
    with pytest.raises(EctskinError, match=r"max_points must be an integer >= 1, got 0"):
        plot_force_sigma(TRUE, PRED, SIGMA, max_points=0)


def test_the_legend_names_what_the_frames_are_split_by():
    """An inversion splits its frames by its own standard error, and the legend says so."""
    ax = plot_force_sigma(TRUE, PRED, SIGMA, BOUND, threshold_n=0.1, split_by="σ").axes[0]
    assert sorted(t.get_text().split(",")[0] for t in ax.get_legend().get_texts()
                  if "frame" in t.get_text()) == [
        "no σ", "not observable (σ ≥ 0.1 N)", "observable (σ < 0.1 N)"]
