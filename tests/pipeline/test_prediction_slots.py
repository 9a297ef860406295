"""The inversion's answers as prediction slots (``pipeline.inversion.prediction_columns``): which
fitted finger stands for "the finger on the skin" in slot 0.

A two-finger fit of a frame with one finger on the skin can add a phantom: a second pressing
finger where the readouts hardly tell a point (beyond the wire ends), often at a force bound.
The point error of a frame with one finger on the skin is taken from slot 0
(``learn.tasks.contact.point_errors``), so the best-located press must come first, whatever its
force and whatever order the fit returned the fingers in."""

from __future__ import annotations

import numpy as np

from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.pipeline.inversion import prediction_columns

FACES = ("front", "back")
EXTENT = {"front": ((-25.0, 25.0), (0.0, 120.0)), "back": ((-25.0, 25.0), (0.0, 120.0))}


def arrays(rows):
    """results_to_arrays-like arrays of frames, each a list of up to two fingers
    (face, contact, (u, v), force, height, (se_u, se_v))."""
    n = len(rows)
    a = {"n_fingers": np.zeros(n, int), "face": np.full((n, 2), "", dtype="<U8"),
         "contact": np.zeros((n, 2), bool), "uv_mm": np.full((n, 2, 2), np.nan),
         "force_n": np.full((n, 2), np.nan), "height_mm": np.full((n, 2), np.nan),
         "uv_se_mm": np.full((n, 2, 2), np.nan), "force_se_n": np.full((n, 2), np.nan)}
    for i, fingers in enumerate(rows):
        a["n_fingers"][i] = len(fingers)
        for k, (face, contact, uv, force, height, se) in enumerate(fingers):
            a["face"][i, k], a["contact"][i, k] = face, contact
            a["uv_mm"][i, k], a["force_n"][i, k], a["height_mm"][i, k] = uv, force, height
            a["uv_se_mm"][i, k], a["force_se_n"][i, k] = se, 0.05
    return a


def slot(pred, i, s):
    base = len(PRED_COLUMNS) + s * len(SLOT_COLUMNS)
    col = {c: base + j for j, c in enumerate(SLOT_COLUMNS)}
    return FACES[int(pred[i, col["face"]])], (pred[i, col["u_mm"]], pred[i, col["v_mm"]])


def test_the_best_located_press_takes_slot_0():
    phantom = ("front", True, (-19.6, 106.4), 2.0, 0.0, (6.0, 9.0))  # beyond the wire ends
    real = ("front", True, (-16.1, 21.7), 1.0, 0.0, (0.1, 0.15))
    hover_low = ("back", False, (3.0, 50.0), 0.0, 4.0, (0.5, 0.5))
    hover_high = ("back", False, (-3.0, 70.0), 0.0, 9.0, (0.4, 0.4))
    no_se = ("back", True, (5.0, 60.0), 1.5, 0.0, (np.nan, np.nan))
    a = arrays([
        [phantom, real],  # the fit's order puts the stronger phantom first
        [real, phantom],
        [hover_high, hover_low],  # none presses: the lowest hovering finger first
        [no_se, real],  # a press without a standard error sorts last
    ])
    pred = prediction_columns(a, FACES, EXTENT)
    assert pred[0, 0] == pred[1, 0] == 2 and pred[2, 0] == 0  # counts are unchanged
    for i in (0, 1, 3):
        assert slot(pred, i, 0) == ("front", (-16.1, 21.7))
    assert slot(pred, 0, 1) == ("front", (-19.6, 106.4))
    assert slot(pred, 2, 0) == ("back", (3.0, 50.0)) and pred[2, 2] == 1.0  # p_hover


def test_the_readout_noises_standard_error_says_which_press_is_best_located():
    """With a model error in the standard errors (``Inversion(bound_error=...)``) the real
    finger's grows with its large signal and can pass a phantom's; ``point_se_noise_mm`` (the
    readout noise's alone) keeps the order, and a NaN there sorts last."""
    phantom = ("front", True, (-19.6, 106.4), 2.0, 0.0, (1.0, 1.2))
    real = ("front", True, (-16.1, 21.7), 1.0, 0.0, (1.5, 1.8))  # widened past the phantom's
    a = arrays([[phantom, real], [real, phantom], [phantom, real]])
    assert slot(prediction_columns(a, FACES, EXTENT), 0, 0)[1] == (-19.6, 106.4)  # by uv_se_mm
    a["point_se_noise_mm"] = np.array([[9.0, 0.2], [0.2, 9.0], [np.nan, 0.2]])
    pred = prediction_columns(a, FACES, EXTENT)
    for i in range(3):
        assert slot(pred, i, 0) == ("front", (-16.1, 21.7))
