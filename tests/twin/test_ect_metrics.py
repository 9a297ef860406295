"""Checks of the ECT localisation's options and of the body it measures distances around."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.layout import default_layout
from ectskin.twin.ect import ect_grid, locate
from ectskin.twin.mechanics import ManipulatorConfig, recording_manipulator


def test_locate_refuses_an_unknown_localisation():
    """An unknown localisation was taken as "centroid" without a word (a silent fallback)."""
    grid = ect_grid(default_layout())
    img = np.zeros(grid.n_pixels)
    img[3] = 1.0
    with pytest.raises(EctskinError, match=r"localisation.*'peak', 'centroid'.*got 'peek'"):
        locate(img, grid, "peek")
    f, uv, peak = locate(img, grid, "peak")
    assert peak == 1.0 and f == grid.pixel_face[3]
    np.testing.assert_allclose(uv, grid.pixel_uv[3])


def test_the_body_is_the_recordings():
    """The twin writes its manipulator into the recording; a thicker body is read back as such,
    and a recording without one says that the default body was taken."""
    thick = ManipulatorConfig(thickness_mm=30.0)
    from dataclasses import asdict

    body, source = recording_manipulator({"manipulator": asdict(thick)})
    assert (body, source) == (thick, "recording")
    assert recording_manipulator({}) == (ManipulatorConfig(), "default")
    with pytest.raises(EctskinError, match=r"'manipulator': unknown field\(s\) \['girth_mm'\]"):
        recording_manipulator({"manipulator": {"girth_mm": 3.0}})
    with pytest.raises(EctskinError, match=r"'manipulator': expected a mapping"):
        recording_manipulator({"manipulator": [50.0, 20.0]})
