"""A solved trial whose finger slides in contact from dwell to dwell (``dwell_slide_s``): its
readout models cover stretches of at most ``SLIDE_SEGMENT_MM`` of the way
(:func:`ectskin.twin.simulate.readout_segments`), so every frame stays close to a direct
method-of-moments solve; trials that do not slide keep one model per dwell, as before."""

from types import SimpleNamespace

import numpy as np
import pytest

from ectskin.layout import default_layout
from ectskin.twin import Protocol, SensorModel, Touch
from ectskin.twin.human import dwell_points, finger_path, hand_push
from ectskin.twin.mechanics import Handling
from ectskin.twin.protocol import region_bounds
from ectskin.twin.simulate import SLIDE_SEGMENT_MM, _rows, _touch_segment, readout_segments


@pytest.fixture(scope="module")
def layout():
    return default_layout()


def test_segments_are_the_dwells_unless_a_solved_finger_slides():
    aims = np.array([[0.0, 20.0], [10.0, 40.0], [-5.0, 30.0]])
    n = 90
    shares = np.array_split(np.arange(n), 3)
    for proto in (Protocol(touch_dwells=3, dwell_slide_s=0.0), Protocol(touch_dwells=3, dwell_slide_s=10.0,
                                                     response="field")):
        got = readout_segments(n, 30.0, aims, proto)
        assert len(got) == 3 and all(np.array_equal(a, b) for a, b in zip(got, shares))
    slide = Protocol(touch_dwells=3, dwell_slide_s=10.0)
    got = readout_segments(n, 30.0, aims, slide)
    assert np.array_equal(np.concatenate(got), np.arange(n))  # every frame once, in order
    way = dwell_points(n, 30.0, aims, 10.0)
    for rows in got:  # each stretch of the way is at most SLIDE_SEGMENT_MM long
        length = np.linalg.norm(np.diff(way[rows], axis=0), axis=1).sum()
        assert length <= SLIDE_SEGMENT_MM + 1e-9
    # the first two dwells slide 22.4 and 18.0 mm: 6 and 5 stretches; the last one stays
    assert len(got) == 6 + 5 + 1


def test_a_sliding_finger_stays_close_to_direct_solves(layout):
    """Two dwells at the region's far corners (21 mm apart), the finger sliding between them
    over the whole first dwell: the frames at the ends of each stretch, farthest from its
    model's centre, within 0.5 fF of direct solves; one model for the whole dwell (what a
    sliding trial had before) is off by far more there."""
    sensor = SensorModel(layout)
    proto = Protocol(touch_dwells=2, dwell_slide_s=4.0, push_max_n=0.0)
    reg = layout.region(5)
    lo, hi = region_bounds(reg, proto.touch_margin)
    aims = np.array([lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)])
    n, p = 240, [10, 0, 20]
    rng = np.random.default_rng(3)
    path = finger_path(n, 30.0, aims, lo, hi, proto, rng)
    hand = hand_push(n, 30.0, proto, rng, sensor.manipulator.config)
    plan = SimpleNamespace(surface=reg.surface, touch_uv_mm=tuple(map(tuple, aims)))
    segments = readout_segments(n, 30.0, aims, proto)
    first = np.array_split(np.arange(n), 2)[0]
    old, _, _ = _touch_segment(
        sensor, p, plan, proto, _rows(path, first), _rows(hand, first), None, None
    )
    worst_new = worst_old = 0.0
    for rows in segments[:-1]:  # the stretches of the sliding dwell
        c, _, _ = _touch_segment(
            sensor, p, plan, proto, _rows(path, rows), _rows(hand, rows), None, None
        )
        for j in (0, rows.size - 1):
            i = rows[j]
            handling = Handling(path.shear_n[i : i + 1], hand.push, hand.push_force_n)
            direct = sensor.capacitance(
                p, Touch(reg.surface, tuple(path.uv_mm[i])), path.force_n[i : i + 1], handling
            )[0]
            worst_new = max(worst_new, np.abs(c[j] - direct).max())
            worst_old = max(worst_old, np.abs(old[i] - direct).max())
    print(f"sliding: per stretch {worst_new * 1e3:.3f} fF, one model {worst_old * 1e3:.3f} fF")
    assert worst_new < 0.5e-3, worst_new
    assert worst_old > 5 * worst_new
