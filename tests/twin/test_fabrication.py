"""Fabricated skins: each perturbation against a hand-computed or independently solved reference.

What each test catches (each was broken once and seen to fail):

* a wire shift that misses the pad, or moves the wrong electrode, or a bonding offset that
  leaves the skin rectangle behind (test_wire_and_pad_move_by_exactly_delta,
  test_bonding_offset_moves_a_skin_and_nothing_else);
* a width that does not reach the solver (test_wider_wire_raises_its_standing_capacitance);
* a dead electrode whose pairs keep their signal, or that touches other pairs
  (test_dead_electrode_reads_only_the_electronics_noise);
* a short modelled as anything but one conductor: the sum C_ik + C_jk is compared with a
  method-of-moments solve where the two electrodes' panels are literally one conductor
  (test_short_is_one_conductor_in_the_method_of_moments);
* zero spreads that still change a bit of the skin or of the recording
  (test_zero_variation_is_the_nominal_skin_bit_for_bit).
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.electrostatics import Panels, maxwell_capacitance
from ectskin.io.recording import Recording, Trial
from ectskin.twin.fabrication import (
    FabricationVariation,
    Fault,
    apply_fault,
    apply_fault_true,
    neighbour_pairs,
    perturb_layout,
    sample_skin,
    simulate_skin,
)
from ectskin.twin.mechanics import Manipulator, ManipulatorConfig
from ectskin.twin.protocol import Protocol
from ectskin.twin.readout import ReadoutConfig
from ectskin.twin.sensor import SensorModel
from ectskin.twin.simulate import simulate_experiment


def _zeros(layout):
    return np.zeros(layout.n_electrodes), np.ones(layout.n_electrodes)


def test_wire_and_pad_move_by_exactly_delta(layout):
    shift, scale = _zeros(layout)
    shift[2] = 0.37
    out = perturb_layout(layout, shift, scale, {})
    for k, (a, b) in enumerate(zip(layout.electrodes, out.electrodes)):
        d = 0.37 if k == 2 else 0.0
        np.testing.assert_array_equal(b.polyline_mm[:, 0], a.polyline_mm[:, 0] + d)
        np.testing.assert_array_equal(b.polyline_mm[:, 1], a.polyline_mm[:, 1])
        assert b.pad_centre_mm == (a.pad_centre_mm[0] + d, a.pad_centre_mm[1])
        assert b.width_mm == a.width_mm and b.pad_size_mm == a.pad_size_mm


def test_bonding_offset_moves_a_skin_and_nothing_else(layout):
    shift, scale = _zeros(layout)
    out = perturb_layout(layout, shift, scale, {"back": (0.5, -0.75)})
    for a, b in zip(layout.skins, out.skins):
        d = (0.5, -0.75) if a.name == "back" else (0.0, 0.0)
        assert b.u_mm == (a.u_mm[0] + d[0], a.u_mm[1] + d[0])
        assert b.v_mm == (a.v_mm[0] + d[1], a.v_mm[1] + d[1])
    for a, b in zip(layout.electrodes, out.electrodes):
        d = np.array((0.5, -0.75) if a.skin == "back" else (0.0, 0.0))
        np.testing.assert_array_equal(b.polyline_mm, a.polyline_mm + d)
    assert out.regions == layout.regions and out.markers == layout.markers  # on the body


def test_sampled_skin_is_its_draws_within_the_spreads(layout):
    v = FabricationVariation()
    skin = sample_skin(layout, v, seed=3)
    assert np.all(np.abs(skin.wire_shift_mm) <= 2 * v.wire_position_sigma_mm)
    assert np.all(np.abs(skin.width_scale - 1) <= v.width_rel)
    assert abs(skin.eps_r / 2.0 - 1) <= v.eps_rel
    assert abs(skin.manipulator.thickness_mm / 20.0 - 1) <= v.thickness_rel
    assert all(max(map(abs, o)) <= v.bonding_offset_mm for o in skin.offsets_mm.values())
    # the layout is exactly those draws applied
    again = perturb_layout(layout, skin.wire_shift_mm, skin.width_scale, skin.offsets_mm)
    assert again.to_dict() == skin.layout.to_dict()
    assert sample_skin(layout, v, seed=3).to_dict() == skin.to_dict()  # seeded
    assert sample_skin(layout, v, seed=4).to_dict() != skin.to_dict()


def test_wider_wire_raises_its_standing_capacitance(layout):
    # E1 and E2 are neighbours on the front skin (pair 0); widen E1 only
    assert layout.pair_names[0] == "E1-E2"
    values = []
    for w in (0.6, 1.0, 1.4):
        shift, scale = _zeros(layout)
        scale[0] = w
        sensor = SensorModel(perturb_layout(layout, shift, scale, {}), chamber_eps_r=None)
        values.append(sensor.capacitance([0.0, 0.0, 0.0])[0, 0])
    assert values[0] < values[1] < values[2]


def _tiny_recording(layout, n=50, seed=0):
    rng = np.random.default_rng(seed)
    c = rng.uniform(0.05, 1.0, layout.n_pairs) * (
        1 + 0.01 * rng.standard_normal((n, layout.n_pairs))
    )
    t = np.arange(n) / 30
    return Recording(layout, [Trial("a", c, t, np.zeros(n))], 30.0)


def test_dead_electrode_reads_only_the_electronics_noise(layout):
    rec = _tiny_recording(layout)
    cfg = ReadoutConfig()
    out = apply_fault(rec, Fault("dead", (3,)), cfg, seed=0)
    c0, c1 = rec.trials[0].capacitance, out.trials[0].capacitance
    with_3 = np.array([3 in p for p in layout.pairs])
    assert with_3.sum() == layout.n_electrodes - 1
    sigma = cfg.resolution_pf / np.sqrt(12 * cfg.samples_per_frame)  # quantisation only
    assert np.all(np.abs(c1[:, with_3]) < 6 * sigma)
    assert np.std(c1[:, with_3]) > 0.3 * sigma  # noise, not a constant
    np.testing.assert_array_equal(c1[:, ~with_3], c0[:, ~with_3])
    assert out.meta["fault"] == {"kind": "dead", "electrodes": [3]}


def test_short_is_one_conductor_in_the_method_of_moments(layout):
    """C_Mk of the merged conductor from a direct solve equals C_ik + C_jk for every k."""
    sensor = SensorModel(layout, chamber_eps_r=None)
    i, j = 0, 1
    panels = sensor.electrode_panels([0.0, 0.0, 0.0], None, [0.0])[0]
    n = layout.n_electrodes
    separate = Panels(panels.centres, panels.u, panels.v, panels.conductor, n)
    K = maxwell_capacitance(separate, sensor.eps_r)
    c = -K[layout.pairs[:, 0], layout.pairs[:, 1]]
    # the merged system: j's panels become i's; conductors renumbered 0..n-2
    cond = np.where(panels.conductor == j, i, panels.conductor)
    cond = np.where(cond > j, cond - 1, cond)
    Km = maxwell_capacitance(Panels(panels.centres, panels.u, panels.v, cond, n - 1), sensor.eps_r)
    shorted = apply_fault_true(c[None], layout, Fault("short", (i, j)))[0]
    index = {(int(a), int(b)): p for p, (a, b) in enumerate(layout.pairs)}
    for k in range(n):
        if k in (i, j):
            continue
        km = k - 1 if k > j else k
        want = -Km[i, km]
        for e in (i, j):
            got = shorted[index[(min(e, k), max(e, k))]]
            assert got == pytest.approx(want, rel=1e-6)
    assert shorted[index[(i, j)]] == 0.0
    # pairs without i or j are untouched
    free = [p for p, (a, b) in enumerate(layout.pairs) if {a, b}.isdisjoint({i, j})]
    np.testing.assert_array_equal(shorted[free], c[free])


def test_shorts_are_drawn_between_neighbours_on_one_skin(layout):
    pairs = neighbour_pairs(layout)
    assert set(pairs) == {(0, 1), (1, 2), (2, 3), (4, 5), (5, 6), (6, 7)}
    for seed in range(10):
        skin = sample_skin(layout, FabricationVariation(fault="short"), seed)
        assert skin.fault.electrodes in pairs


def test_zero_variation_is_the_nominal_skin_bit_for_bit(layout):
    skin = sample_skin(layout, FabricationVariation.none(), seed=5)
    assert skin.layout.to_dict() == layout.to_dict()
    assert skin.eps_r == 2.0 and skin.fault is None
    assert skin.manipulator == ManipulatorConfig()
    p = Protocol(levels_ml=(0.0,), touch_trials=0, duration_s=0.2, seed=1)
    a = simulate_experiment(p, layout=layout, workers=1, progress=False)
    b = simulate_skin(p, skin, workers=1, progress=False)
    assert len(a.trials) == len(b.trials) == 1
    for ta, tb in zip(a.trials, b.trials):
        np.testing.assert_array_equal(ta.capacitance, tb.capacitance)
        np.testing.assert_array_equal(ta.markers, tb.markers)
    assert b.layout == layout and b.meta["fabrication"]["eps_r"] == 2.0


def test_a_thicker_body_is_what_the_twin_simulates(layout):
    skin = sample_skin(layout, FabricationVariation(thickness_rel=0.1), seed=2)
    thick = skin.manipulator.thickness_mm
    assert thick != 20.0
    front = Manipulator(skin.manipulator).deform("front", np.array([[0.0, 60.0]]), [0, 0, 0])
    assert front[0, 0, 1] == pytest.approx(thick / 2)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"width_rel": -0.1}, "width_rel"),
        ({"eps_rel": 1.0}, "eps_rel"),
        ({"wire_position_sigma_mm": float("nan")}, "wire_position_sigma_mm"),
        ({"fault": "melted"}, "fault"),
    ],
)
def test_bad_variation_is_one_clear_error(kwargs, field):
    with pytest.raises(EctskinError, match=field):
        FabricationVariation(**kwargs)


def test_a_skin_pushed_off_its_layout_is_refused(layout):
    with pytest.raises(EctskinError, match="seed 0.*not a valid layout"):
        sample_skin(layout, FabricationVariation(wire_position_sigma_mm=10.0), seed=0)
