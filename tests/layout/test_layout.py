"""Sensor layouts: the paper's default, any electrode count, and refusal of invalid layouts."""

import copy
import json

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.layout import SensorLayout, default_layout, load_layout
from ectskin.layout.geometry import sample_polyline


def test_default_layout_matches_the_paper():
    lay = default_layout()
    assert (lay.n_electrodes, lay.n_pairs, lay.n_regions, lay.n_markers) == (8, 28, 18, 5)
    assert lay.n_classes == 19
    # fixed ECT order (1,2),(1,3)…(7,8)
    assert lay.pairs[:3].tolist() == [[0, 1], [0, 2], [0, 3]]
    assert lay.pairs[-1].tolist() == [6, 7]
    assert lay.pair_names[0] == "E1-E2" and lay.pair_names[-1] == "E7-E8"
    # 4 wires per face, 1 mm wide, 20/45/70/95 mm long; 6+6 same-face pairs
    lengths = sorted(round(e.length_mm) for e in lay.electrodes)
    assert lengths == [20, 20, 45, 45, 70, 70, 95, 95]
    assert int(lay.same_surface.sum()) == 12
    desc = lay.electrode_descriptors()
    assert desc.shape == (8, 6) and np.all(np.isfinite(desc))


def test_round_trip_json(tmp_path):
    lay = default_layout()
    path = tmp_path / "l.json"
    path.write_text(lay.to_json())
    again = load_layout(path)
    assert again.to_dict() == lay.to_dict()


def _three_electrodes():
    d = default_layout().to_dict()
    d["electrodes"] = d["electrodes"][:3]
    return d


def test_any_electrode_count_gives_n_choose_2_pairs():
    lay = SensorLayout.from_dict(_three_electrodes())
    assert lay.n_pairs == 3
    assert lay.pairs.tolist() == [[0, 1], [0, 2], [1, 2]]


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d["electrodes"][1].update(name="E1"), "duplicate electrode 'E1'"),
        (lambda d: d["electrodes"][1]["polyline_mm"].__setitem__(1, [-15.0, 25.0]), "overlap"),
        (lambda d: d["electrodes"][0]["polyline_mm"].__setitem__(1, [-15.0, 140.0]), "off its skin"),
        (lambda d: d["electrodes"][0].update(skin="top"), "names skin 'top'"),
        (lambda d: d["electrodes"][0].update(width_mm=-1), "width"),
        (lambda d: d["regions"][3].update(id=1), "duplicate region id 1"),
        (lambda d: d["markers"][0].update(surface="inside"), "expected one of front"),
        (lambda d: d.update(version=9), "layout version 1"),
        (lambda d: d.pop("electrodes"), "missing field 'electrodes'"),
    ],
)
def test_invalid_layouts_are_refused_with_a_clear_message(mutate, message):
    d = copy.deepcopy(default_layout().to_dict())
    mutate(d)
    with pytest.raises(EctskinError, match=message):
        SensorLayout.from_dict(d, source="bad.json")


def test_corrupt_layout_file(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text('{"schema": "ectskin.layout", ')
    with pytest.raises(EctskinError, match=r"broken.json: not valid JSON \(line 1"):
        load_layout(p)
    p.write_bytes(b"\x89HDF\r\n\x1a\n\x00\xff")
    with pytest.raises(EctskinError, match="broken.json"):
        load_layout(p)
    with pytest.raises(EctskinError, match="cannot read layout file"):
        load_layout(tmp_path / "missing.json")


def test_unknown_region_is_a_clear_error():
    with pytest.raises(EctskinError, match="unknown region 19"):
        default_layout().region(19)


def test_layout_json_names_pairs_in_file_order():
    d = json.loads(default_layout().to_json())
    d["electrodes"] = list(reversed(d["electrodes"]))
    lay = SensorLayout.from_dict(d)
    assert lay.pair_names[0] == "E8-E7"


@pytest.mark.parametrize("field, value", [("electrodes", ""), ("electrodes", "E\x001"), ("markers", "M\x00")])
def test_names_a_file_cannot_store_are_refused(field, value):
    d = json.loads(default_layout().to_json())
    d[field][0]["name"] = value
    with pytest.raises(EctskinError, match="non-empty text without NUL"):
        SensorLayout.from_dict(d, source="bad.json")


def test_sample_polyline_needs_a_step_or_a_count():
    poly = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert sample_polyline(poly, n=3).tolist() == [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]]
    with pytest.raises(TypeError, match="step_mm or n"):
        sample_polyline(poly)
