"""The quick paths of the surface map (``twin/surface_map.py``, ``twin/mechanics_tables.py``)
against slow, independent references: the binned start of the row-wise interpolation and of
the axial grid's search against numpy's own search, the pose's interpolation against
``np.interp`` per column, and the values the manipulator keeps between calls (the dimple's
stiffness per state and point, the axial grids' lookups) against a fresh manipulator's, so a
value kept for one state, point or grid and reused for another is caught."""

from __future__ import annotations

import numpy as np
import pytest

import ectskin.twin.mechanics_tables as tables
from ectskin.twin import Manipulator, Touch
from ectskin.twin.finger import Finger, rest_fingertips
from ectskin.twin.mechanics import ManipulatorConfig
from ectskin.twin.mechanics_tables import (
    axis_table,
    grid_segment,
    interp_rows,
    on_axis,
    row_lookup,
)


def _probes(xp: np.ndarray, rng) -> np.ndarray:
    """Points that a search gets wrong first: on the nodes, one ulp either side of them, on
    and beside the lookup's bin edges, far beyond both ends, inf and NaN, and random ones."""
    nodes = np.unique(xp)
    lookup = row_lookup(np.atleast_2d(xp))
    edges = np.zeros(0)
    if lookup is not None:
        edges = lookup.lo + lookup.width * np.arange(lookup.n_bins)
    near = np.concatenate([nodes, edges])
    return np.concatenate([
        near, np.nextafter(near, np.inf), np.nextafter(near, -np.inf),
        rng.uniform(nodes[0] - 5.0, nodes[-1] + 5.0, 400),
        [nodes[0] - 1e6, nodes[-1] + 1e6, np.inf, -np.inf, np.nan],
    ])


def test_interp_rows_with_a_lookup_is_numpy_interp():
    """With the rows' lookup, every point against ``np.interp`` on its own row, bit for bit
    (a guess more than one node off, or a correction left out, reads the wrong interval at the
    nodes and the bin edges); inf as numpy has it, NaN as the search without the lookup. Rows
    without a spacing to bin by get no lookup."""
    rng = np.random.default_rng(0)
    for n in (2, 3, 41, 61):
        xp = np.cumsum(rng.uniform(0.2, 3.0, (5, n)), axis=1) - rng.uniform(0, 20, (5, 1))
        xp[2] = np.linspace(-3.0, 40.0, n)  # evenly spaced (nodes on the bin edges)
        fp = np.sort(rng.normal(size=n))
        lookup = row_lookup(xp)
        assert lookup is not None
        x = _probes(xp, rng)
        for r in range(5):
            rows = np.full(x.size, r)
            ref = np.array([np.interp(xi, xp[r], fp) for xi in x])
            ref[np.isnan(x)] = fp[-1]  # (a NaN counts every node, lookup or not)
            np.testing.assert_array_equal(interp_rows(x, xp, fp, rows, lookup), ref)
            np.testing.assert_array_equal(interp_rows(x, xp, fp, rows), ref)
    assert row_lookup(np.array([[0.0, 1.0, 1.0, 2.0]])) is None  # a node repeated
    assert row_lookup(np.array([[0.0, np.inf]])) is None
    assert row_lookup(np.array([[0.0, 1e-9, 1.0]])) is None  # too many bins


@pytest.mark.parametrize("n_points", [5, 3000])
def test_grid_segment_is_the_clipped_search(n_points):
    """:func:`grid_segment` (by numpy's search for a few points, by the lookup for many) is
    ``clip(searchsorted(grid, x) − 1, 0, n − 2)``, the same integers: a point on a node
    belongs to the segment below it."""
    rng = np.random.default_rng(1)
    for grid in (np.linspace(0.0, 120.0, 61), np.cumsum(rng.uniform(0.5, 3.0, 40))):
        x = _probes(grid, rng)
        x = np.resize(x, max(n_points, 1)) if n_points < x.size else np.resize(x, n_points)
        ref = np.clip(np.searchsorted(grid, x) - 1, 0, grid.size - 2)
        np.testing.assert_array_equal(grid_segment(grid, x), ref)
        np.testing.assert_array_equal(grid_segment(grid, x.reshape(-1, 1)), ref[:, None])


def test_on_axis_is_the_pose_interpolated_per_column():
    """The points on the deformed axis against ``np.interp`` of each column of the pose (axis
    and section frame) per frame, then offset in the section (beyond the ends, the end
    segment's line): a gather from the wrong segment or frame moves a point by up to a grid
    step's bending."""
    m = Manipulator()
    p = m.check_inflation((20, 0, 20))
    touch = Touch("front", (8.0, 70.0))
    forces = np.array([0.5, 1.5, 2.5])
    zs, r, rot = m.pose(forces, touch, p)
    rng = np.random.default_rng(2)
    zq = np.concatenate([zs, rng.uniform(zs[0], zs[-1], 300), [-3.0, 123.0]])
    xs = rng.uniform(-25, 25, (3, zq.size))
    yp = rng.uniform(-10, 10, (3, zq.size))
    got = on_axis(zs, axis_table(r, rot), zq, xs, yp)
    for f in range(3):
        def at(a, f=f):
            out = np.stack([np.interp(zq, zs, a[f, :, k]) for k in range(3)], axis=-1)
            # beyond the ends: the end segment's line (np.interp would hold the end's value)
            for z, i in ((zq[-2], 0), (zq[-1], zs.size - 2)):
                t = (z - zs[i]) / (zs[i + 1] - zs[i])
                out[zq == z] = (1 - t) * a[f, i] + t * a[f, i + 1]
            return out
        ref = at(r) + at(rot[..., 0]) * xs[f, :, None] + at(rot[..., 1]) * yp[f, :, None]
        np.testing.assert_allclose(got[f], ref, rtol=0, atol=1e-12)


def test_the_dimple_stiffness_follows_the_state_and_the_point():
    """One manipulator's dimple depths over states and points, more than it keeps, in turn and
    again, are a fresh manipulator's (a stiffness kept without its state or point is not)."""
    m = Manipulator()
    states = [(0, 0, 0), (20, 20, 20), (0, 25, 0)]
    points = [Touch("front", (0.0, float(v))) for v in np.arange(5.0, 120.0, 5.0)]
    for _ in range(2):
        for p in states:
            for t in points:
                got = m.dimple_depth_mm([0.5, 2.0], t, p)
                np.testing.assert_array_equal(got, Manipulator().dimple_depth_mm([0.5, 2.0], t, p))


def test_a_stretched_grid_gets_its_own_lookup(monkeypatch):
    """With the chambers' axial strain on, each state's axial grid differs: one manipulator
    deforming states in turn (and again), with the grids' lookups kept between them, maps each
    as a fresh manipulator with no lookups kept does, bit for bit (a grid's lookup reused for
    another grid puts points in the wrong segment)."""
    config = ManipulatorConfig(axial_strain_per_ml=0.02)  # spans up to 60 % longer
    m = Manipulator(config)
    rng = np.random.default_rng(3)
    uv = np.c_[rng.uniform(-25, 25, 400), rng.uniform(0, 120, 400)]
    touch = Touch("back", (4.0, 90.0))
    kept: dict = {}
    for p in [(0, 0, 0), (25, 0, 10), (5, 30, 5), (0, 0, 0), (25, 0, 10)]:
        monkeypatch.setattr(tables, "_GRIDS", kept)
        got = m.deform("back", uv, p, touch, [0.3, 1.8])
        monkeypatch.setattr(tables, "_GRIDS", {})
        np.testing.assert_array_equal(
            got, Manipulator(config).deform("back", uv, p, touch, [0.3, 1.8])
        )
    assert 1 < len(kept) <= tables.STATES_KEPT


@pytest.mark.parametrize("p", [(20.0, 20.0, 20.0), (0.0, 0.0, 0.0)])
def test_a_rows_fingertips_are_each_touch_placed_on_a_fresh_body(p):
    """A contact row's touches placed one after the other on one manipulator (its poses,
    dimple stiffnesses, grids and tables kept between them) rest exactly where each placed on
    a fresh manipulator rests: nothing kept for one touch or force is used for another."""
    m, fg = Manipulator(), Finger()
    forces = np.array([0.36, 0.82, 1.48, 1.94])
    per, heights = forces[:, None], np.zeros((4, 1))
    row = [Touch("front", (12.0, float(v))) for v in (2.0, 33.0, 60.0, 118.0)]
    for t in row + row[:1]:
        got = rest_fingertips(m, [fg], p, t, forces, per, heights)[0]
        ref = rest_fingertips(Manipulator(), [fg], p, t, forces, per, heights)[0]
        np.testing.assert_array_equal(got.centre_mm, ref.centre_mm)
        np.testing.assert_array_equal(got.axis, ref.axis)
