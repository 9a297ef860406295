"""The fast paths of the twin's geometry against slow, independent references: the mechanics'
per-state tables and rod poses kept between calls, the pull-in's row-wise interpolation, the
Newton steps that put the skin samples under a fingertip, and a response field's hover row
placed at once (``twin/finger.py``: :func:`~ectskin.twin.finger.hover_fingertips`) against
each touch placed alone, the path the simulation takes.
"""

from __future__ import annotations

import numpy as np
import pytest

import ectskin.twin.finger as finger
import ectskin.twin.mechanics as mechanics
import ectskin.twin.mechanics_tables as mechanics_tables
from ectskin.layout import default_layout
from ectskin.twin import Manipulator, SensorModel, Touch
from ectskin.twin.mechanics_tables import interp_rows

STATES = [(20.0, 20.0, 20.0), (0.0, 20.0, 0.0)]
HEIGHTS = np.array([0.5, 2.0, 6.0, 15.0])
#: hovering over the middle, beside a chamber's side wall, over a gap between chambers, at the
#: face's corner, on the back
HOVER = [
    Touch("front", (0.0, 60.0)),
    Touch("front", (18.0, 32.0)),
    Touch("front", (-17.0, 40.0)),
    Touch("back", (5.0, 80.0)),
    Touch("front", (24.5, 2.0)),
    Touch("back", (-20.0, 100.0)),
]


@pytest.fixture(scope="module")
def sensor():
    return SensorModel(default_layout())


def test_interp_rows_is_numpy_interp_row_by_row():
    """Every point against ``np.interp`` on its own row, bit for bit: inside, on the nodes,
    below the first and beyond the last (a bisection off by one reads the wrong interval)."""
    rng = np.random.default_rng(0)
    for n in (2, 3, 41, 61, 64, 65):
        xp = np.sort(rng.normal(size=(5, n)) * 10.0, axis=1)
        fp = np.sort(rng.normal(size=n))
        x = np.concatenate([rng.uniform(xp.min() - 3, xp.max() + 3, 300), xp.ravel()])
        rows = np.concatenate([rng.integers(0, 5, 300), np.repeat(np.arange(5), n)])
        ref = np.array([np.interp(xi, xp[r], fp) for xi, r in zip(x, rows)])
        np.testing.assert_array_equal(interp_rows(x, xp, fp, rows), ref)


def test_the_state_tables_follow_the_state():
    """One manipulator deforming several states in turn (more than it keeps) maps each as a
    fresh one does, bit for bit; the heights it hands out are the caller's to change."""
    rng = np.random.default_rng(1)
    uv = np.c_[rng.uniform(-25, 25, 50), rng.uniform(0, 120, 50)]
    touch = Touch("front", (3.0, 50.0))
    states = [(0, 0, 0), (20, 20, 20), (0, 20, 0)] + [(k, 2 * k, 0) for k in range(1, 10)]
    m = Manipulator()
    for p in states + states[:3]:
        for surface in ("front", "back"):
            got = m.deform(surface, uv, p, touch, [0.0, 1.5])
            ref = Manipulator().deform(surface, uv, p, touch, [0.0, 1.5])
            np.testing.assert_array_equal(got, ref)
    h = m.bulge_height_mm((20, 20, 20))
    h[:] = 0.0
    assert np.all(m.bulge_height_mm((20, 20, 20)) > 1.0)


def test_a_rows_poses_are_kept(monkeypatch):
    """The touches of a grid row are each solved once: deformed again after the whole row (the
    cavity cells, the electrodes and the placement of each node), no rod is solved again;
    poses of many frames are let go beyond the last 8."""
    m = Manipulator()
    p = m.check_inflation((20, 20, 20))
    forces = np.array([0.4, 0.8, 1.5, 1.9])
    row = [Touch("front", (0.0, float(v))) for v in np.arange(0.0, 120.0, 4.0)]  # 30 touches
    solved = []
    solve = mechanics.solve_rod
    monkeypatch.setattr(mechanics, "solve_rod", lambda *a, **k: solved.append(1) or solve(*a, **k))
    for t in row + row:
        m.deform("front", np.zeros((1, 2)), p, t, forces)
    assert len(solved) == len(row)
    big = np.linspace(0.0, 2.0, 900)
    for t in row[:12]:
        m.pose(big, t, p)
    assert sum(v[1].shape[0] for v in m._poses.values()) <= mechanics_tables.POSE_FRAMES_KEPT + 8 * 900


@pytest.mark.parametrize("p", STATES)
def test_the_skin_samples_land_on_their_targets(sensor, p):
    """The Newton steps (their 2 × 2 inverses and projections written out) converge: every
    sample under a pressed fingertip, beside a bulge included, lies at its wanted lateral offset
    from the finger's point to < 1e-4 mm (a wrong inverse or projection does not converge).
    The points keep their samples on the face (the face's edge stops a sample beyond it)."""
    m = sensor.manipulator
    forces = np.array([0.3, 2.0])
    for one in (Touch("front", (13.0, 32.0)), Touch("back", (0.0, 60.0))):
        uv = np.asarray([one.uv_mm])
        pts = m.deform(one.surface, uv, p, one, forces)[:, 0]
        frame = m.face_frame(one.surface, uv, p, one, forces)[:, 0]
        _, _, target = finger._pad(sensor.finger, forces, np.ones(2, dtype=bool))

        def deform(rest, one=one):
            return m.deform(one.surface, rest, p, one, forces)

        skin, valid = finger._skin_at(
            m, one.surface, deform, np.asarray(one.uv_mm), target, pts, frame
        )
        assert valid.all() and skin.shape == target.shape[:2] + (3,)
        lateral = np.einsum("fki,fmi->fmk", frame[..., :2].transpose(0, 2, 1), skin - pts[:, None])
        np.testing.assert_allclose(lateral, target, rtol=0, atol=1e-4)


def test_the_projections_are_einsum_and_norm():
    """:func:`finger._along` is einsum's projection to round-off (a swapped index is not);
    :func:`finger._length` is the norm, bit for bit."""
    rng = np.random.default_rng(2)
    d = rng.normal(size=(4, 50, 3)) * 7.0
    axes = rng.normal(size=(4, 2, 3))
    np.testing.assert_allclose(
        finger._along(d, axes[:, None]), np.einsum("fki,fmi->fmk", axes, d), rtol=0, atol=1e-13
    )
    t = rng.normal(size=(4, 50, 2))
    np.testing.assert_array_equal(finger._length(t), np.linalg.norm(t, axis=2))


@pytest.mark.parametrize("p", STATES)
def test_a_hover_row_placed_at_once_is_each_touch_placed_alone(sensor, p):
    """The reference is the twin's own placement of each touch on its own (force 0 at each
    height, :meth:`SensorModel.fingertips`); the row's is the same to round-off, on both faces,
    beside a bulge, over a gap and at the face's corner (a touch paired with another's frames,
    or the faces mixed up, moves a fingertip by millimetres)."""
    tips = finger.hover_fingertips(sensor.manipulator, sensor.finger, p, HOVER, HEIGHTS)
    zeros = np.zeros(HEIGHTS.size)
    for t, tip in zip(HOVER, tips):
        ref = sensor.fingertips(p, t, zeros, heights_mm=HEIGHTS)[0]
        np.testing.assert_allclose(tip.centre_mm, ref.centre_mm, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tip.point_mm, ref.point_mm, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tip.axis, ref.axis, rtol=0, atol=1e-15)
        for name in ("pad_depth_mm", "cover_mm", "height_mm"):
            np.testing.assert_array_equal(getattr(tip, name), getattr(ref, name))


def test_the_hover_row_answers_only_its_own_placements(sensor):
    """Inside :func:`finger.hovering` the twin's placement of a row's touch is the row's; another
    height, inflation, force or touch, and anything after the block, is placed anew."""
    p = STATES[0]
    m, fg = sensor.manipulator, sensor.finger
    zeros = np.zeros(HEIGHTS.size)
    with finger.hovering(m, fg, p, HOVER[:3], HEIGHTS) as tips:
        assert sensor.fingertips(p, HOVER[1], zeros, heights_mm=HEIGHTS)[0] is tips[1]
        others = [
            sensor.fingertips(p, HOVER[1], zeros, heights_mm=HEIGHTS + 1.0)[0],
            sensor.fingertips(STATES[1], HOVER[1], zeros, heights_mm=HEIGHTS)[0],
            sensor.fingertips(p, HOVER[3], zeros, heights_mm=HEIGHTS)[0],
            sensor.fingertips(p, HOVER[1], zeros + 0.5, heights_mm=HEIGHTS)[0],
        ]
        assert all(o is not tips[1] for o in others)
        assert not np.allclose(others[0].centre_mm, tips[1].centre_mm)
    after = sensor.fingertips(p, HOVER[1], zeros, heights_mm=HEIGHTS)[0]
    assert after is not tips[1]
    np.testing.assert_allclose(after.centre_mm, tips[1].centre_mm, rtol=0, atol=1e-12)
