"""The two-finger examples figure (``viz.inversion.plot_two_finger_examples``): what each panel
holds against the given frames, counted by hand, and bad input named."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.viz.inversion import plot_two_finger_examples

FACES = ["front", "back"]
EXTENT = {f: ((-20.0, 20.0), (0.0, 120.0)) for f in FACES}


def _frames():
    """Two frames: (1) both fingers on the front, fitted one pressing on the front and one
    hovering 6 mm over the back; (2) one finger on each face, fitted both pressing on the back."""
    true_face = np.array([[0, 0], [0, 1]])
    true_uv = np.array([[[0, 20], [10, 80]], [[-5, 50], [5, 90]]], float)
    fit_face = np.array([["front", "back"], ["back", "back"]])
    fit_uv = np.array([[[1, 21], [-10, 40]], [[6, 88], [-6, 30]]], float)
    fit_contact = np.array([[True, False], [True, True]])
    fit_height = np.array([[0.0, 6.0], [0.0, 0.0]])
    return true_face, true_uv, fit_face, fit_uv, fit_contact, fit_height


def _markers(ax, marker):
    return sorted(tuple(np.round(np.c_[ln.get_xdata(), ln.get_ydata()][0], 6))
                  for ln in ax.lines if ln.get_marker() == marker)


def test_each_panel_holds_its_faces_true_and_fitted_fingers():
    fig = plot_two_finger_examples(*_frames(), FACES, EXTENT,
                                   wires={"front": [[(0, 10), (0, 100)]]}, titles=["a", "b"])
    ax = fig.axes
    assert len(ax) == 4  # two frames × two faces, in order: frame 1 front, back, frame 2 ...
    assert _markers(ax[0], "o") == [(0, 20), (10, 80)] and _markers(ax[1], "o") == []
    assert _markers(ax[2], "o") == [(-5, 50)] and _markers(ax[3], "o") == [(5, 90)]
    assert _markers(ax[0], "x") == [(1, 21)] and _markers(ax[1], "x") == []
    assert _markers(ax[1], "+") == [(-10, 40)]  # the hovering finger, with its height
    assert [t.get_text() for t in ax[1].texts] == ["6 mm"]
    assert _markers(ax[2], "x") == [] and _markers(ax[3], "x") == [(-6, 30), (6, 88)]
    # the wire on the front faces only; the title names the frame on its first panel
    grey = [ln for a in ax for ln in a.lines if ln.get_color() == "0.55"]
    assert len(grey) == 2 and all(ln.axes in (ax[0], ax[2]) for ln in grey)
    assert ax[0].get_title().startswith("a") and ax[2].get_title().startswith("b")


def test_bad_input_names_the_field():
    tf, tuv, ff, fuv, fc, fh = _frames()
    with pytest.raises(EctskinError, match="true_face must be"):
        plot_two_finger_examples(tf[:, :1], tuv, ff, fuv, fc, fh, FACES, EXTENT)
    with pytest.raises(EctskinError, match="fit_uv"):
        plot_two_finger_examples(tf, tuv, ff, fuv[:, :1], fc, fh, FACES, EXTENT)
    with pytest.raises(EctskinError, match="extent"):
        plot_two_finger_examples(tf, tuv, ff, fuv, fc, fh, FACES, {"front": EXTENT["front"]})
    with pytest.raises(EctskinError, match="2 frames"):
        plot_two_finger_examples(tf, tuv, ff, fuv, fc, fh, FACES, EXTENT, titles=["a"])
    with pytest.raises(EctskinError, match="no frame"):
        plot_two_finger_examples(tf[:0], tuv[:0], ff[:0], fuv[:0], fc[:0], fh[:0], FACES, EXTENT)
