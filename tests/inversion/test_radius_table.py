"""The finger nuisances' tables from coarse response fields (their nodes against direct solves),
and the radius's table (:func:`ectskin.inversion.finger_nuisance.radius_table`) on the twin's small
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
from ectskin.inversion import Inversion
from ectskin.inversion.finger_nuisance import MODULUS_PRIOR_SD, RADIUS_PRIOR_SD, radius_table
from ectskin.twin import Touch
from ectskin.twin.field_finger import finger_field_specs, finger_tables


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


def test_finger_tables_from_fields_are_the_direct_solves_differences(small_spec, small_field,
                                                                     tmp_path):
    """:func:`~ectskin.twin.field_finger.finger_tables`: the columns of both nuisances from coarse
    fields (5 mm here, 4 forces, no hover part) at a node against central differences of direct
    solves with the same fingers (E0 e^(±0.1), R0 e^(±0.05)), to 1e-4 of the column (2.6e-5
    seen); the inversion takes them as its finger nuisances' tables."""
    with threadpool_limits(limits=1):
        tabs = finger_tables([small_spec], tmp_path, workers=0, progress=False,
                             spacing_mm=(5.0, 5.0))
    st = small_spec.inflation_ml
    assert set(tabs) == {"modulus", "radius"} and set(tabs["modulus"]) == {st}
    sensor = small_spec.sensor()
    f0 = sensor.finger
    for name, field, h in (("modulus", "pulp_modulus_mpa", 0.1), ("radius", "radius_mm", 0.05)):
        tab = tabs[name][st]
        u, v = tab.nodes["front"]
        assert (u.size, v.size) == (5, 5) and tab.forces_n.size == 4 and tab.step == h
        assert tab.values["front"].shape == (5, 5, 4, sensor.layout.n_pairs)
        i, j, q = 1, 3, 2
        touch = Touch("front", (float(u[i]), float(v[j])))
        c = [sensor.with_fingers(replace(f0, **{field: getattr(f0, field) * math.exp(s)}))
             .capacitance(st, touch, tab.forces_n[q: q + 1])[0] for s in (h, -h)]
        direct = (c[0] - c[1]) / (2 * h)
        np.testing.assert_allclose(tab.values["front"][i, j, q], direct, rtol=0,
                                   atol=1e-4 * np.abs(direct).max())
    inv = Inversion({st: small_field}, modulus=tabs["modulus"], radius=tabs["radius"])
    assert inv.finger_prior_sd == {"modulus": MODULUS_PRIOR_SD, "radius": RADIUS_PRIOR_SD}
    with pytest.raises(EctskinError, match="finger nuisance"):
        finger_field_specs(small_spec, "pulp")
    # never finer than the state's own field; no hover part, no graded bands
    small, big = finger_field_specs(replace(small_spec, spacing_mm=(12.0, 3.0)), "radius")
    assert small.spacing_mm == big.spacing_mm == (12.0, 8.0) and small.height_nodes == 0
    assert big.finger.radius_mm == pytest.approx(small_spec.finger.radius_mm * math.exp(0.05))
