"""The bound maps' figure (ectskin.viz.plot_bound_maps): log colour scales over the data, the
wires of each face, unresolved cells left grey, drawing into given axes, and clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from ectskin._check import EctskinError
from ectskin._files import to_jsonable
from ectskin.viz import plot_bound_maps

WIRES = {"front": [[[-5.0, 10.0], [-5.0, 55.0]], [[5.0, 10.0], [5.0, 80.0]]],
         "back": [[[0.0, 10.0], [0.0, 105.0]]]}


def _maps(unresolved: bool = True) -> dict:
    """Two faces, one state, cases none and all, a 3 x 2 grid; bounds from 1e-3 to 2 (pos) and
    from 0.01 to 5 N (force); one unresolved cell (inf), written through the JSON policy."""
    pos = np.array([[1e-3, 0.01], [0.1, 0.5], [1.0, 2.0]])
    force = np.array([[0.01, 0.02], [0.05, 0.2], [1.0, 5.0]])
    faces = {}
    for face in ("front", "back"):
        case = {}
        for name, scale in (("none", 1.0), ("all", 1.5)):
            f = force * scale
            if unresolved and name == "all" and face == "back":
                f = f.copy()
                f[2, 1] = np.inf
            case[name] = {"position_mm": pos * scale, "force_n": f, "summary": {}}
        faces[face] = {"u_mm": [-10.0, 10.0], "v_mm": [23.3, 60.0, 96.7], "contact": case}
    return to_jsonable({
        "modes": ["contact"], "cases": ["none", "push", "all"],
        "settings": {"faces": ["front", "back"], "force_threshold_n": 0.1},
        "skins": {f: {"u_mm": [-20.0, 20.0], "v_mm": [5.0, 115.0]} for f in ("front", "back")},
        "wires": WIRES,
        "states": [{"inflation_ml": [0.0, 10.0, 20.0], "faces": faces}],
    })


def test_the_figure_has_log_scales_over_the_data_and_the_wires():
    maps = _maps()
    fig = plot_bound_maps(maps)
    assert isinstance(fig, Figure)
    panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    # rows: 1 state x (none, all); columns: position (front, back), force (front, back)
    assert len(panels) == 2 * 4
    meshes = [a.collections[0] for a in panels]
    assert all(isinstance(m.norm, LogNorm) for m in meshes)
    # one shared scale per quantity, spanning the finite data of all panels (all = 1.5 x none)
    pos_norm, force_norm = meshes[0].norm, meshes[2].norm
    assert all(m.norm is pos_norm for m in meshes[0::4] + meshes[1::4])
    assert (pos_norm.vmin, pos_norm.vmax) == pytest.approx((1e-3, 3.0))
    assert (force_norm.vmin, force_norm.vmax) == pytest.approx((0.01, 7.5))
    # the wires of each face, as drawn lines with the layout's coordinates
    front, back = panels[0], panels[1]
    assert sorted(tuple(ln.get_xdata()) for ln in front.lines) == [(-5.0, -5.0), (5.0, 5.0)]
    assert [tuple(ln.get_ydata()) for ln in back.lines] == [(10.0, 105.0)]
    # the unresolved cell (null in JSON) is masked, not drawn as a colour
    back_all_force = panels[4 + 3].collections[0].get_array()
    assert np.ma.count_masked(back_all_force) == 1
    # force panels straddling the 0.1 N threshold carry its contour
    assert any(len(a.collections) > 1 for a in panels[2::4] + panels[3::4])


def test_it_draws_into_given_axes():
    fig = Figure()
    axes = fig.subplots(2, 4)
    out = plot_bound_maps(_maps(unresolved=False), axes=axes)
    assert out is fig
    assert all(len(a.collections) >= 1 for a in axes.flat)


@pytest.mark.parametrize(
    "kwargs, message", [({"mode": "hover"}, "mode 'hover'"), ({"cases": ["wind"]}, "wind")]
)
def test_unknown_mode_or_case_is_one_clear_error(kwargs, message):
    with pytest.raises(EctskinError, match=message):
        plot_bound_maps(_maps(), **kwargs)


def test_a_one_column_grid_plots_without_a_contour():
    """A coarse grid may be one cell wide (a 40-mm spacing on a 40-mm skin)."""
    maps = _maps()
    for face in maps["states"][0]["faces"].values():
        for case in face["contact"].values():
            for q in ("position_mm", "force_n"):
                case[q] = [row[:1] for row in case[q]]
    fig = plot_bound_maps(maps)
    assert all(len(a.collections) == 1 for a in fig.axes if a.get_label() != "<colorbar>")
