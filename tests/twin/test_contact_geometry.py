"""The fingertip rests on the deformed skin (``twin/finger.py``, the contact): no skin inside a
finger in any state, a placement smooth in force (no steps in the readout), a cover that
compresses under the pad as a bonded thin layer, and fingers that differ.

The clearance is measured here independently of the placement's own samples: the skin on a dense
grid of rest points around the finger, deformed by the mechanics, against the analytic solid of
:class:`~ectskin.twin.finger.Fingertip` (a sphere cut flat by the pressed pad), which the
fingertip's panels are checked to follow.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.layout import default_layout
from ectskin.twin import SensorModel, Touch
from ectskin.twin.finger import CONTACT_SMOOTHING_MM, Finger


@pytest.fixture(scope="module")
def layout():
    return default_layout()


@pytest.fixture(scope="module")
def sensor(layout):
    return SensorModel(layout)


def _clearance(sensor, one, touch, p, forces, tip, step=0.5):
    """(F,) least gap (mm) along the fingertip's axis between the skin under it and its lower
    surface, less the cover under the pad and its height above the skin: the skin of ``one``'s
    face on a ``step`` grid of rest points within two fingertip radii of its point, deformed with
    ``touch`` (``one`` or a tuple holding it) pressing with ``forces``."""
    R = tip.finger.radius_mm
    g = np.arange(-2 * R, 2 * R + 1e-9, step)
    U, V = np.meshgrid(g, g)
    near = U**2 + V**2 <= (2 * R) ** 2
    c = sensor.manipulator.config
    grid = np.c_[U[near], V[near]] + np.asarray(one.uv_mm)
    grid[:, 0] = np.clip(grid[:, 0], -c.width_mm / 2, c.width_mm / 2)
    grid[:, 1] = np.clip(grid[:, 1], 0.0, c.length_mm)
    skin = sensor.manipulator.deform(one.surface, grid, p, touch, forces)  # (F, n, 3)
    rel = skin - tip.centre_mm[:, None]
    z = np.einsum("fni,fi->fn", rel, tip.axis)  # along the axis, from the centre
    r = np.linalg.norm(rel - z[..., None] * tip.axis[:, None], axis=2)
    # the solid's lower surface at lateral distance r: the flat pad R − δ below the centre, then
    # the sphere; beyond R the skin is beside the finger, not under it
    lower = -np.minimum((R - tip.pad_depth_mm)[:, None], np.sqrt(np.maximum(R**2 - r**2, 0.0)))
    gap = np.where(r < R, lower - z, np.inf)
    return gap.min(axis=1) - tip.cover_mm - tip.height_mm


# the hard places: beside the chambers' side walls (x = ±20 mm), near their ends along the axis
# (z = 5, 35, 45, 75, 85, 115 mm), between two chambers, and the middle of a face
POINTS = [
    Touch("front", (5.0, 40.0)),
    Touch("front", (18.0, 60.0)),
    Touch("front", (-17.0, 100.0)),
    Touch("front", (12.0, 32.0)),
    Touch("front", (-10.0, 72.0)),
    Touch("back", (18.0, 48.0)),
    Touch("back", (0.0, 60.0)),
]
STATES = [(20.0, 20.0, 20.0), (0.0, 20.0, 0.0), (10.0, 0.0, 20.0)]
FORCES = np.array([0.3, 1.0, 2.0])
#: what the placement's finite samples leave: the skin may rise this far into the cover between
#: them (2 % of the 1 mm cover). Placed along the surface normal at its point (before the
#: fingertips rested), the skin reached up to 5 mm into the cover and 4 mm into the fingertip.
TOLERANCE_MM = 0.02


@pytest.mark.parametrize("p", STATES)
def test_no_skin_inside_a_fingertip_anywhere(sensor, p):
    """Over points × inflation states × forces, and 2 mm above the skin: the least clearance
    between the skin under the fingertip and its surface, beyond the cover, is >= 0 (to the
    samples' tolerance)."""
    worst = np.inf
    for touch in POINTS:
        tip = sensor.fingertips(p, touch, FORCES)[0]
        worst = min(worst, _clearance(sensor, touch, touch, p, FORCES, tip).min())
        hover = sensor.fingertips(p, touch, [0.0], heights_mm=[2.0])[0]
        assert hover.pad_depth_mm[0] == 0 and hover.cover_mm[0] == sensor.finger.skin_cover_mm
        worst = min(worst, _clearance(sensor, touch, touch, p, [0.0], hover).min())
    assert worst >= -TOLERANCE_MM, worst


def test_fingers_that_differ_and_two_fingers_rest_too(sensor):
    """A small soft and a big stiff fingertip, and two fingers pressing at once, each resting on
    the skin as both deform it."""
    p = (20.0, 20.0, 20.0)
    for r, e in ((7.0, 0.05), (10.0, 0.2)):
        other = sensor.with_fingers(replace(sensor.finger, radius_mm=r, pulp_modulus_mpa=e))
        for touch in POINTS[:3]:
            tip = other.fingertips(p, touch, FORCES)[0]
            assert (tip.finger.radius_mm, tip.finger.pulp_modulus_mpa) == (r, e)
            assert _clearance(other, touch, touch, p, FORCES, tip).min() >= -TOLERANCE_MM
    both = (Touch("front", (5.0, 40.0)), Touch("front", (-12.0, 75.0)))
    forces = np.array([[1.0, 2.0], [2.0, 0.5]])
    two = sensor.with_fingers(sensor.finger, replace(sensor.finger, radius_mm=10.0))
    tips = two.fingertips(p, both, forces)
    assert [t.finger.radius_mm for t in tips] == [8.0, 10.0]
    for one, tip in zip(both, tips):
        assert _clearance(two, one, both, p, forces, tip).min() >= -TOLERANCE_MM


def test_the_panels_are_the_fingertip_that_rests(sensor):
    """The method of moments sees the solid the clearance is measured against: the pad's panels
    lie on the plane R − δ below the centre, every fingertip panel within R of it, and the shaft
    rises from the centre along the axis."""
    p, touch = (20.0, 20.0, 20.0), POINTS[1]
    tip = sensor.fingertips(p, touch, FORCES)[0]
    d = sensor.discretisation
    n_tip = len(sensor.finger_panels(p, touch, FORCES)[0].centres) - (
        d.finger_shaft_around * d.finger_shaft_along
    )
    for f, panels in enumerate(sensor.finger_panels(p, touch, FORCES)):
        rel = panels.centres - tip.centre_mm[f]
        z = rel @ tip.axis[f]
        assert z[:n_tip].min() == pytest.approx(-(8.0 - tip.pad_depth_mm[f]), abs=1e-9)
        assert np.linalg.norm(rel[:n_tip], axis=1).max() <= 8.0 + 1e-9
        shaft = rel[n_tip:]
        radial = np.linalg.norm(shaft - np.outer(shaft @ tip.axis[f], tip.axis[f]), axis=1)
        assert (shaft @ tip.axis[f]).min() > 0 and radial.min() > 0.9 * 8.0


def test_the_rest_height_on_a_dimple_by_hand(sensor):
    """Uninflated, a finger pressing the middle of the front face with F sits in its own dimple
    (a Gaussian of depth F / k_d, k_d = 1 N/mm, σ = 9 mm): the skin rises toward the pad's rim
    ρ = √(δ (2R − δ)) by F (1 − exp(−ρ² / 2σ²)), so the pad rests that far above the point,
    plus R − δ to the centre and the cover. The smooth law rests it at least there and at most
    τ ln(number of samples + 1) above (the body bends a little under the press too)."""
    by_hand = {0.3: 7.1646, 1.0: 6.2377, 2.0: 5.3992}  # R − δ + F (1 − exp(−ρ²/2σ²)), mm
    touch = Touch("front", (0.0, 60.0))
    tip = sensor.fingertips((0, 0, 0), touch, list(by_hand))[0]
    rest = np.einsum("fi,fi->f", tip.centre_mm - tip.point_mm, tip.axis) - tip.cover_mm
    bias = CONTACT_SMOOTHING_MM * math.log(1 + 22 * 64)  # 22 rings of 64 samples
    for k, need in enumerate(by_hand.values()):
        assert need - 2e-3 <= rest[k] <= need + bias, (rest[k], need)
    # the fingertip's axis is the face's normal carried by the body: in the dimple's middle, with
    # no bulges, it is the skin's own normal there
    normal = sensor.manipulator.surface_normal("front", [touch.uv_mm], (0, 0, 0), touch, [1.0])
    np.testing.assert_allclose(tip.axis[1], normal[0, 0], atol=1e-3)


@pytest.mark.parametrize(
    "p, uv, forces",
    [((20, 20, 20), (5.0, 40.0), (1.94, 2.06)), ((0, 0, 0), (5.0, 60.0), (0.84, 0.92))],
)
def test_the_readout_is_smooth_in_force(sensor, layout, p, uv, forces):
    """No steps as the finger presses harder. Between two chambers at 20/20/20 ml the bulges
    beside a 2-N press reached into the fingertip placed along the normal at its point: the
    method of moments nearly failed, and the E3–E4 readout dropped by 48 fF from 1.98 to 2.00 N
    and rose again at 2.02 N (second differences of 100 fF). On the uninflated face, fingertip
    panels pressed flat whole as their centres crossed the pad's plane made steps of 0.55 fF
    at 0.87 N. Resting on the skin, with panels that bend with the pad, every pair's second
    difference over 0.02-N steps stays below 0.05 fF."""
    f = np.round(np.arange(forces[0], forces[1] + 1e-9, 0.02), 4)
    c = sensor.capacitance(p, Touch("front", uv), f)
    d2 = np.abs(np.diff(c, n=2, axis=0)).max(axis=0)
    worst = layout.pair_names[int(np.argmax(d2))]
    assert d2.max() < 0.05e-3, (worst, d2.max())
    assert np.abs(np.diff(c, axis=0)).max() > 1e-4  # the readout does move with the force


def test_the_cover_compresses_as_a_bonded_thin_layer():
    """The cover under the pad: Hertz δ = (9F²/(16 R E*²))^(1/3) and a = √(R δ), the mean
    pressure F/(π a²) over E_c = E (1 + 2 S²), S = a / 2h (R 8 mm, E* 0.1 MPa, h 1 mm, E 0.07
    MPa), by hand: at 1 N δ = 1.9157 mm, a = 3.915 mm, S = 1.957, E_c = 0.6064 MPa, P = 0.02077
    MPa, ε = 0.03425. The wider pad stiffens the bonded layer faster than the pressure rises, so
    the cover compresses less at 2 N than at 0.3 N."""
    fg = Finger()
    by_hand = {0.3: 1 - 0.5 * math.tanh(0.04479 / 0.5), 1.0: 1 - 0.5 * math.tanh(0.03425 / 0.5),
               2.0: 1 - 0.5 * math.tanh(0.02856 / 0.5)}
    got = fg.cover_mm(np.array(list(by_hand)))
    np.testing.assert_allclose(got, list(by_hand.values()), rtol=2e-5)
    assert fg.cover_mm(0.0) == 1.0 and fg.indentation_mm(0.0) == 0.0
    assert fg.cover_mm(2.0) > fg.cover_mm(0.3)
    assert replace(fg, cover_modulus_mpa=math.inf).cover_mm(1.0) == 1.0  # a rigid cover
    soft = replace(fg, cover_modulus_mpa=1e-6)  # far softer than any silicone: the bound holds
    assert 0.5 <= soft.cover_mm(2.0) < 0.51
    # the pad's indentation is bounded smoothly at R / 2: Hertz below, R / 2 far above
    assert fg.indentation_mm(1.0) == pytest.approx(1.91577, rel=1e-4)
    assert fg.indentation_mm(50.0) == pytest.approx(4.0, rel=1e-3)


@pytest.mark.parametrize(
    "field, value",
    [("cover_modulus_mpa", 0.0), ("cover_modulus_mpa", float("nan")), ("cover_max_strain", 1.0),
     ("cover_max_strain", 0.0)],
)
def test_a_finger_refuses_a_cover_that_is_not_one(field, value):
    with pytest.raises(EctskinError, match=f"finger: {field} must be"):
        Finger(**{field: value})


def test_a_sensor_takes_other_fingers_cheaply(sensor):
    """``with_fingers`` shares the rest-state panels and the manipulator; touch k gets finger k;
    a bigger fingertip reads differently; the original sensor keeps its finger."""
    big = replace(sensor.finger, radius_mm=10.0)
    other = sensor.with_fingers(sensor.finger, big)
    assert other._rest is sensor._rest and other.manipulator is sensor.manipulator
    assert other.finger_of(0) is sensor.finger and other.finger_of(1) is big
    assert other.finger_of(5) is big and sensor.finger_of(1) is sensor.finger
    touch = Touch("front", (0.0, 60.0))
    c8 = sensor.capacitance((0, 0, 0), touch, [1.0])[0]
    c10 = sensor.with_fingers(big).capacitance((0, 0, 0), touch, [1.0])[0]
    assert np.abs(c10 - c8).max() > 1e-3
    with pytest.raises(EctskinError, match="with_fingers: expected one or more Finger"):
        sensor.with_fingers()


def test_only_the_samples_that_weigh_are_solved_and_nothing_changes(sensor, monkeypatch):
    """The placement solves only the skin samples whose need may come within the margin of the
    highest (the others weigh < e⁻⁵⁰ in the smooth law), and finds a hovering finger's skin once
    for all its heights: against the placement that solves every sample of every frame (the
    margin infinite), the fingertips are the same to round-off (two fingers, the face's edge,
    beside a bulge and hovering included), while far fewer samples were solved."""
    import ectskin.twin.finger as finger

    deformed = [0]
    surface_map = sensor.manipulator.surface_map  # (deform's too)

    def counting(*loads, **kw):
        mapped = surface_map(*loads, **kw)

        def deform(uv, *a, **k):
            deformed[0] += np.asarray(uv).size // 2
            return mapped(uv, *a, **k)

        return deform

    cases = [(p, t, FORCES, None) for p in STATES[:2] for t in POINTS[:5]]
    cases += [(STATES[0], Touch("front", (19.5, 3.0)), FORCES, None)]  # a corner of the face
    cases += [(STATES[0], t, np.zeros(4), np.array([0.5, 2.0, 6.0, 15.0])) for t in POINTS[:3]]
    both = (Touch("front", (5.0, 40.0)), Touch("front", (-12.0, 75.0)))
    cases += [(STATES[0], both, np.array([[1.0, 2.0], [2.0, 0.5]]), None)]
    monkeypatch.setattr(sensor.manipulator, "surface_map", counting)
    fast = [sensor.fingertips(p, t, f, heights_mm=h) for p, t, f, h in cases]
    work, deformed[0] = deformed[0], 0
    monkeypatch.setattr(finger, "_PRUNE_MARGIN_MM", math.inf)
    hover_frames = []
    placement = finger._placement

    def one_by_one(*a, **kw):
        hover_frames.append(len(a[6]))
        return placement(*a, **kw)

    monkeypatch.setattr(finger, "_placement", one_by_one)
    monkeypatch.setattr(finger, "_rest_one", _every_frame(finger))
    for (p, t, f, h), tips in zip(cases, fast):
        for got, ref in zip(tips, sensor.fingertips(p, t, f, heights_mm=h)):
            np.testing.assert_allclose(got.centre_mm, ref.centre_mm, rtol=0, atol=1e-12)
            np.testing.assert_array_equal(got.axis, ref.axis)
    assert work < 0.4 * deformed[0], (work, deformed[0])  # skin points mapped, fast / reference
    assert 4 in hover_frames  # the reference placed the hovering frames one by one


def _every_frame(finger):
    """``_rest_one`` without sharing the skin between frames (the reference)."""

    def rest_one(m, fg, one, inflation_ml, touch, forces, force_one, heights_one, handling):
        contact = heights_one <= 0
        pts, nrm, depth, cover, above = finger._placement(
            m, fg, one, inflation_ml, touch, np.asarray(forces, dtype=np.float64), force_one,
            contact, handling,
        )
        lift = np.maximum(heights_one, 0.0)
        centre = pts + nrm * (above + cover + lift)[:, None]
        return finger.Fingertip(fg, pts, nrm, centre, depth, cover, lift)

    return rest_one
