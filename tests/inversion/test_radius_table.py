"""The radius's table (:func:`ectskin.inversion.finger_nuisance.radius_table`) on the twin's small
field: its nodes, its column against a central difference of another step (direct solves with
fingertips of other radii, not the table's), and the physics of a bigger fingertip (it couples
more: the column along the finger's own signal is positive, a fraction of it)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.inversion.finger_nuisance import RADIUS_PRIOR_SD, radius_table
from ectskin.twin import Touch


def test_the_radius_table_is_the_radius_derivative(small_spec, small_field):
    st = small_spec.inflation_ml
    sensor = small_spec.sensor()
    with threadpool_limits(limits=1):
        tab = radius_table(sensor, st, {"front": small_spec.extent("front")},
                           small_spec.force_range_n, spacing_mm=8.0, force_nodes=4)
    u, v = tab.nodes["front"]
    assert (u.size, v.size) == (4, 4) and tab.values["front"].shape == (4, 4, 4, small_field.n_pairs)
    np.testing.assert_allclose(tab.forces_n[[0, -1]], small_spec.force_range_n)
    np.testing.assert_allclose(np.diff(np.log(tab.forces_n)), np.diff(np.log(tab.forces_n))[0])
    # a node: the column against (C(R0 + h) − C(R0 − h)) / 2h × R0 with h = 0.1 mm
    i, j, q = 1, 2, 2
    touch = Touch("front", (float(u[i]), float(v[j])))
    r0 = sensor.finger.radius_mm
    c = [sensor.with_fingers(replace(sensor.finger, radius_mm=r0 + s)).capacitance(
        st, touch, tab.forces_n[q: q + 1])[0] for s in (0.1, -0.1)]
    direct = (c[0] - c[1]) / 0.2 * r0
    col = tab.values["front"][i, j, q]
    assert np.linalg.norm(col - direct) < 0.03 * np.linalg.norm(direct)
    # a bigger fingertip couples more: its column along the finger's own signal Δ is positive,
    # ∂C/∂R ≈ κ Δ with the twin's κ of 0.05-0.08 /mm (twin.bound_field), here within 0.02-0.2
    d = small_field.readout("front", u[i], v[j], tab.forces_n[q]) - small_field.untouched
    k = float(col @ d / (d @ d)) / r0
    assert 0.02 < k < 0.2, k


def test_the_radius_table_is_checked(small_spec):
    sensor, st, ext = small_spec.sensor(), small_spec.inflation_ml, {"front": small_spec.extent("front")}
    for kw in ({"spacing_mm": 0.0}, {"force_nodes": 3}, {"step": -0.1}):
        with pytest.raises(EctskinError, match="radius_table"):
            radius_table(sensor, st, ext, small_spec.force_range_n, **kw)
    with pytest.raises(EctskinError, match="force_range_n"):
        radius_table(sensor, st, ext, (1.0, 0.5))
    assert math.isclose(RADIUS_PRIOR_SD, math.log(10 / 7) / math.sqrt(12))
