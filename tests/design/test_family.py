"""The layout family and the manufacturing rules, against the paper's layout file and hand cases."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.design.family import (
    FaceDesign,
    LayoutDesign,
    ManufacturingRules,
    _lengths,
    build_layout,
    check_manufacturable,
    conductor_gap_mm,
)
from ectskin.layout import Electrode, SensorLayout, default_layout


def test_the_paper_layout_is_a_member_of_the_family():
    # catches: wrong pad size/position, wire start height, length order or x spread
    built = build_layout(LayoutDesign(), "paper-again")
    paper = default_layout()
    assert built.n_electrodes == paper.n_electrodes
    for a, b in zip(built.electrodes, paper.electrodes):
        assert (a.name, a.skin, a.width_mm) == (b.name, b.skin, b.width_mm)
        np.testing.assert_allclose(a.polyline_mm, b.polyline_mm)
        assert a.pad_centre_mm == pytest.approx(b.pad_centre_mm)
        assert a.pad_size_mm == pytest.approx(b.pad_size_mm)
    assert built.regions == paper.regions and built.markers == paper.markers


@pytest.mark.parametrize(
    "order, expected",
    [
        ("ascending", [20, 45, 70, 95]),
        ("descending", [95, 70, 45, 20]),
        ("outside_in", [20, 70, 95, 45]),  # outer wires shortest (left one first), then inner
        ("inside_out", [70, 20, 45, 95]),  # inner wires shortest
    ],
)
def test_length_orders_by_hand(order, expected):
    np.testing.assert_allclose(_lengths(FaceDesign(order=order)), expected)


def _wire(name, x, width=1.0, pad=(5.0, 5.0), v=(10.0, 50.0)):
    return Electrode(name, "front", np.array([[x, v[0]], [x, v[1]]]), width, (x, 7.5), pad)


def test_conductor_gap_by_hand():
    # two 1 mm wires 3 mm apart: 2 mm between their edges; pads 3 mm apart are 5 mm wide: they
    # overlap by 2 mm
    assert conductor_gap_mm(_wire("a", 0, pad=(1, 1)), _wire("b", 3, pad=(1, 1))) == pytest.approx(
        2.0
    )
    assert conductor_gap_mm(_wire("a", 0), _wire("b", 3)) == pytest.approx(-2.0)
    # pads 7 mm apart, 5 mm wide: 2 mm; wires 7 mm apart: 6 mm
    assert conductor_gap_mm(_wire("a", 0), _wire("b", 7)) == pytest.approx(2.0)


def _paper_dict():
    return default_layout().to_dict()


def _load(d, tmp_path):
    path = tmp_path / "cand.json"
    path.write_text(json.dumps(d))
    return SensorLayout.from_json(path.read_text(), source=str(path))


def test_the_paper_layout_meets_the_default_rules():
    check_manufacturable(default_layout())


def test_the_shipped_8_electrode_proposal_loads_and_meets_the_default_rules():
    """docs/layouts/proposed-8e.json (design-0004 of the 8-electrode search, BENCHMARKS.md)
    stays a valid, manufacturable layout with the paper's electrode count and pairs."""
    from pathlib import Path

    from ectskin.layout import load_layout

    layout = load_layout(Path(__file__).parents[2] / "docs" / "layouts" / "proposed-8e.json")
    check_manufacturable(layout)
    assert layout.n_electrodes == 8 and layout.n_pairs == 28
    assert {layout.electrode_surface(k) for k in range(8)} == {"front", "back"}


def test_a_thin_wire_is_one_error_naming_file_and_field(tmp_path):
    d = _paper_dict()
    d["electrodes"][2]["width_mm"] = 0.3
    with pytest.raises(
        EctskinError, match=r"cand\.json: electrodes\[2\]\.width_mm: .*0\.3 mm.*0\.5"
    ):
        check_manufacturable(_load(d, tmp_path))


def test_wires_too_close_are_one_error_naming_file_and_field(tmp_path):
    d = _paper_dict()  # E2 moved to 1.8 mm from E1 (0.8 mm gap), its pad left where it was
    d["electrodes"][1]["polyline_mm"] = [[-13.2, 12.0], [-13.2, 55.0]]
    d["electrodes"][1]["pad"]["centre_mm"] = [-6.0, 7.5]
    layout = _load(d, tmp_path)  # the loader accepts it: they do not touch
    with pytest.raises(
        EctskinError,
        match=r"cand\.json: electrodes\[1\]\.polyline_mm: .*'E1' and 'E2' are 0\.80 mm apart",
    ):
        check_manufacturable(layout)
    check_manufacturable(layout, ManufacturingRules(min_spacing_mm=0.5))


def test_a_wire_inside_the_skin_but_within_the_margin_is_refused(tmp_path):
    layout = default_layout()  # E1's left edge at -15.5 mm: 4.5 mm inside the -20 mm side
    check_manufacturable(layout, ManufacturingRules(edge_margin_mm=4.5))
    with pytest.raises(
        EctskinError, match=r"electrodes\[0\]\.polyline_mm: .*'E1' reaches \(-15\.50"
    ):
        check_manufacturable(layout, ManufacturingRules(edge_margin_mm=4.6))


def test_many_fanned_wires_are_built_manufacturable_and_do_not_cross():
    design = LayoutDesign(
        FaceDesign(8, 36.0, 15.0, 100.0, "outside_in", "fan", 0.5),
        FaceDesign(3, 20.0, 30.0, 90.0, "inside_out", "fan", 1.0),
    )
    layout = build_layout(design, "fan")
    assert layout.n_electrodes == 11 and layout.n_pairs == 55
    front = [e for e in layout.electrodes if e.skin == "front"]
    pads = [e.pad_centre_mm[0] for e in front]
    tops = [e.polyline_mm[-1, 0] for e in front]
    assert np.all(np.diff(pads) > 0) and np.all(np.diff(tops) > 0)  # order kept: no crossing
    assert min(e.pad_size_mm[0] for e in front) < 5.0  # 8 pads shrink to fit the 40 mm face


def test_a_design_whose_pads_do_not_fit_is_refused():
    with pytest.raises(EctskinError, match="pads of"):
        build_layout(LayoutDesign(FaceDesign(8, 12.0, routing="straight")), "x")
