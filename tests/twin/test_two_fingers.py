"""Two simultaneous fingers in the twin: the protocol option, the mechanics and electrostatics of a
tuple of touches, the second finger's readout model and the simulated trials' ground truth.

``tests/data/twin_single_finger_baseline.npz`` holds the capacitance and markers of a small
simulation (see :func:`_small`) on the default path (no second finger, the hand on): with the
option at 0 the twin must give the same numbers. It was written by the code before the second
finger existed, and written again when the fingertips began to rest on the skin, with a cover
that compresses, and each trial began to draw its person's finger: those change every touch
frame on purpose. The trial without contact (no finger) and every trial's markers (the finger's
placement moves no marker) stayed bit for bit what they were.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.electrostatics import Panels, maxwell_capacitance
from ectskin.layout import default_layout
from ectskin.twin import Protocol, SensorModel, Touch, plan_trials, simulate_experiment
from ectskin.twin.human import finger_path, hand_push, second_finger_path
from ectskin.twin.mechanics import Handling, Manipulator, touch_loads
from ectskin.twin.protocol import finger_separation_mm, region_bounds
from ectskin.twin.response import SecondFingerResponse, TouchResponse
from ectskin.twin.rod import PointLoad
from ectskin.twin.rod import solve as solve_rod

BASELINE = Path(__file__).resolve().parents[1] / "data" / "twin_single_finger_baseline.npz"


@pytest.fixture(scope="module")
def layout():
    return default_layout()


@pytest.fixture(scope="module")
def sensor(layout):
    return SensorModel(layout)


def _small(**kw) -> Protocol:
    """The baseline's protocol: one state (10 ml each), a trial without and two with touch, 1 s."""
    return Protocol(levels_ml=(10.0,), touch_trials=2, duration_s=1.0, seed=3,
                    **{"touch_dwells": 1, **kw})


@pytest.fixture(scope="module")
def one_finger_rec():
    return simulate_experiment(_small(), workers=1, progress=False)


@pytest.fixture(scope="module")
def two_finger_rec():
    return simulate_experiment(_small(second_finger=1.0), workers=1, progress=False)


# ------------------------------------------------------------------------------ protocol
def test_second_finger_at_zero_gives_the_earlier_numbers(one_finger_rec):
    """The option at 0 (default) reproduces the stored simulation (the module docstring says
    when it was written and what changed it)."""
    rec = one_finger_rec
    base = np.load(BASELINE)
    cap = np.stack([t.capacitance for t in rec.trials])
    markers = np.stack([t.markers for t in rec.trials])
    # bit for bit on the machine that wrote the baseline; a hair of BLAS rounding elsewhere
    np.testing.assert_allclose(cap, base["capacitance"], rtol=1e-12, atol=0)
    np.testing.assert_allclose(markers, base["markers"], rtol=1e-12, atol=1e-12)
    assert all(t.n_fingers == 1 and t.contact.shape == (t.n_frames, 1) for t in rec.trials)


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan"), True, "0.3", None])
def test_protocol_refuses_a_second_finger_that_is_not_a_fraction(bad):
    with pytest.raises(EctskinError, match=r"protocol: second_finger must be a fraction .* 0 to 1"):
        Protocol(second_finger=bad)


def test_second_fingers_follow_the_placement_rule(layout):
    """A fraction of the touch trials, another region, a finger's width away on the same face;
    every other draw of the plan is what it is without the option."""
    base = Protocol(seed=4)
    plans0 = plan_trials(base, layout)
    plans = plan_trials(dataclasses.replace(base, second_finger=0.3), layout)
    touch = [p for p in plans if p.kind == "touch"]
    two = [p for p in touch if p.second_surface is not None]
    assert 0.2 < len(two) / len(touch) < 0.4
    assert all(p.second_surface is None for p in plans if p.kind != "touch")
    faces = set()
    for p in two:
        reg2 = layout.region(p.second_region)
        assert p.second_region != p.region and reg2.surface == p.second_surface
        lo, hi = region_bounds(reg2, base.touch_margin)
        assert np.all(lo <= p.second_uv_mm) and np.all(np.asarray(p.second_uv_mm) <= hi)
        same = p.second_surface == p.surface
        faces.add(same)
        if same:
            gap = np.linalg.norm(np.asarray(p.touch_uv_mm) - p.second_uv_mm, axis=1).min()
            # the widest finger drawn (people differ: radii up to 10 mm) never overlaps
            hi = base.finger_radius_range_mm[1]
            assert gap >= finger_separation_mm(base) == 2 * hi + 4 * base.slide_mm
    assert faces == {True, False}  # both the same and the other face occur
    strip = {"second_surface": None, "second_region": 0, "second_uv_mm": None}
    assert [dataclasses.replace(p, **strip) for p in plans] == plans0


def test_the_second_finger_lands_late_and_leaves_early():
    proto = Protocol()
    n = 900
    path = second_finger_path(
        n, 30.0, np.array([0.0, 60.0]), (-5.0, 50.0), (5.0, 70.0), proto, np.random.default_rng(1)
    )
    on = np.flatnonzero(path.contact)
    assert on.size and np.all(np.diff(on) == 1)  # one press
    assert 0.1 * n - 1 <= on[0] <= 0.4 * n and 0.6 * n - 1 <= on[-1] < 0.9 * n
    lo, hi = proto.force_range_n
    f = path.force_n[on]
    assert np.all(f > 0.5 * lo) and np.all(f < hi * (1 + 4 * proto.tremor_rel))
    off = ~path.contact
    assert np.all(path.force_n[off] == 0) and np.isnan(path.uv_mm[off]).all()
    assert np.all(np.abs(path.uv_mm[on] - [0.0, 60.0]) <= [5.0, 10.0])
    assert np.all(path.height_mm[on] == 0) and np.isnan(path.height_mm[off]).all()


def test_the_placement_rule_keeps_the_protocols_own_finger_apart_without_variability():
    same = Protocol(finger_variability=False, finger_radius_mm=9.0)
    assert finger_separation_mm(same) == 2 * 9.0 + 4 * same.slide_mm


# ----------------------------------------------------------------------------- mechanics
def test_touch_loads_shapes():
    t1, t2 = Touch("front", (0.0, 60.0)), Touch("back", (5.0, 30.0))
    assert touch_loads([1.0, 2.0], t1)[1].shape == (2, 1)
    assert touch_loads([1.0, 2.0], (t1, t2))[1].shape == (1, 2)  # one frame
    assert touch_loads(np.ones((4, 2)), (t1, t2))[1].shape == (4, 2)
    assert touch_loads([0.0, 0.0, 0.0], None)[1].shape == (3, 0)
    with pytest.raises(EctskinError, match=r"2 touches take forces of shape \(F, 2\).*\(4, 3\)"):
        touch_loads(np.ones((4, 3)), (t1, t2))
    with pytest.raises(EctskinError, match="non-empty tuple of Touch"):
        touch_loads([1.0], ())


def test_two_loads_bend_the_rod_as_the_rod_gives_for_them():
    """Two equal presses: the pose is the rod's solution for the two point loads built by hand
    (arc position = v, offset (u, ±thickness/2), force along the inward normal)."""
    m = Manipulator()
    c = m.config
    p = [0.0, 0.0, 0.0]  # no inflation: no axial stretch, z = s
    t1, t2 = Touch("front", (10.0, 100.0)), Touch("back", (-15.0, 70.0))
    forces = np.array([[0.5, 0.5], [1.5, 1.5]])
    _, r, rot = m.pose(forces, (t1, t2), p)
    loads = [
        PointLoad(
            100.0,
            (10.0, c.thickness_mm / 2),
            np.c_[0 * forces[:, 0], -forces[:, 0], 0 * forces[:, 0]],
        ),
        PointLoad(
            70.0,
            (-15.0, -c.thickness_mm / 2),
            np.c_[0 * forces[:, 1], forces[:, 1], 0 * forces[:, 1]],
        ),
    ]
    zs = np.linspace(0.0, c.length_mm, c.beam_points)
    r_ref, rot_ref = solve_rod(zs, m.section_stiffness(zs, p), loads, 2, tol_mm=c.rod_tol_mm)
    np.testing.assert_allclose(r, r_ref, atol=1e-9)
    np.testing.assert_allclose(rot, rot_ref, atol=1e-9)
    # the two presses bend the body: front press towards -y near the tip wins over the back one
    assert r[1, -1, 1] < r[0, -1, 1] < 0


def test_a_pinch_dents_both_faces_and_leaves_the_axis_straight():
    """Equal presses at the same point of both faces: no net force or moment (axis straight),
    and each face is dented by F / k_d at its finger (no inflation: k_d = k_d0)."""
    m = Manipulator()
    c = m.config
    uv = (5.0, 60.0)
    f = 1.2
    touches = (Touch("front", uv), Touch("back", uv))
    _, r, _ = m.pose([[f, f]], touches, [0, 0, 0])
    assert np.abs(r[0, :, :2]).max() < 1e-9
    for surface, side in (("front", 1.0), ("back", -1.0)):
        y = m.deform(surface, [uv], [0, 0, 0], touches, [[f, f]])[0, 0, 1]
        assert y == pytest.approx(side * (c.thickness_mm / 2 - f / c.dimple_stiffness_n_per_mm))


def test_a_single_touch_and_a_tuple_of_one_agree_exactly():
    m = Manipulator()
    t = Touch("front", (3.0, 80.0))
    forces = np.array([0.4, 1.7])
    shear = np.array([[0.1, -0.05], [0.2, 0.1]])
    uv = np.array([[0.0, 60.0], [10.0, 110.0]])
    one = m.deform("back", uv, [10, 0, 20], t, forces, Handling(shear_n=shear))
    tup = m.deform("back", uv, [10, 0, 20], (t,), forces[:, None], Handling(shear_n=shear[:, None]))
    assert one.tobytes() == tup.tobytes()


# ------------------------------------------------------------------------ electrostatics
def test_far_fingers_on_opposite_faces_add_up(sensor, layout):
    """Front bottom-left and back top-right: the change of both is the sum of each alone within
    8 % of the total (not exact: the two grounded fingertips screen part of each other's field
    for the pairs whose field reaches both, and the readout is not linear in the conductors)."""
    p = [10.0, 0.0, 20.0]
    a = Touch("front", layout.region(1).centre_mm)
    b = Touch("back", layout.region(18).centre_mm)
    rest = sensor.capacitance(p)[0]
    da = sensor.capacitance(p, a, [1.0])[0] - rest
    db = sensor.capacitance(p, b, [1.0])[0] - rest
    dab = sensor.capacitance(p, (a, b), [[1.0, 1.0]])[0] - rest
    resid = np.abs(dab - da - db).max()
    assert resid < 0.08 * np.abs(dab).max()
    assert np.abs(da).max() > 10 * resid and np.abs(db).max() > 10 * resid  # both matter


def test_a_weightless_finger_far_above_changes_almost_nothing(sensor, layout):
    """A second finger at zero force hovering over the back face: its effect falls with height
    and is a few per cent of the pressing finger's at 100 mm; it loads nothing."""
    p = [0.0, 0.0, 0.0]
    a = Touch("front", layout.region(1).centre_mm)
    far = Touch("back", layout.region(17).centre_mm)
    rest = sensor.capacitance(p)[0]
    ca = sensor.capacitance(p, a, [1.0])[0]
    change = [
        np.abs(sensor.capacitance(p, (a, far), [[1.0, 0.0]], heights_mm=[[0.0, h]])[0] - ca).max()
        for h in (30.0, 100.0)
    ]
    assert change[1] < change[0] and change[1] < 0.05 * np.abs(ca - rest).max()
    m1 = sensor.marker_positions(p, a, [1.0])
    m2 = sensor.marker_positions(p, (a, far), [[1.0, 0.0]])
    np.testing.assert_allclose(m2, m1, atol=1e-9)


# ------------------------------------------------------------------- the readout model
def _two_finger_model(sensor, layout, region, region2, p, seed):
    proto = Protocol()
    rng = np.random.default_rng(seed)
    reg, reg2 = layout.region(region), layout.region(region2)
    lo, hi = region_bounds(reg, proto.touch_margin)
    path = finger_path(300, 30.0, np.asarray([reg.centre_mm]), lo, hi, proto, rng)
    hand = hand_push(300, 30.0, proto, rng, sensor.manipulator.config)
    push_dir = hand.push_force_n[np.argmax(np.linalg.norm(hand.push_force_n, axis=1))]
    push_dir = push_dir / np.linalg.norm(push_dir)
    lo2, hi2 = region_bounds(reg2, proto.touch_margin)
    path2 = second_finger_path(300, 30.0, np.asarray(reg2.centre_mm), lo2, hi2, proto, rng)
    model = TouchResponse(sensor, p, reg.surface, path, hand, push_dir, proto)
    one = model(path, hand)
    n_one = model.n_solves
    second = SecondFingerResponse(model, path, reg2.surface, path2)
    assert second.n_solves == model.n_solves - n_one == proto.force_nodes + 4
    return reg, reg2, path, path2, hand, one, one + second(path, path2)


@pytest.mark.parametrize(
    "region, region2, p, seed",
    [(5, 14, [0, 20, 0], 6), pytest.param(2, 8, [20, 20, 20], 7, marks=pytest.mark.slow)],
)
def test_the_two_finger_model_stays_close_to_direct_solves(
    sensor, layout, region, region2, p, seed
):
    """Frames with both fingers, model against direct MoM solves: within 1 fF and 1 % of the
    fingers' signal at every pair, and far closer than leaving the second finger out."""
    reg, reg2, path, path2, hand, one, c = _two_finger_model(
        sensor, layout, region, region2, p, seed
    )
    rest = sensor.capacitance(p)[0]
    assert np.array_equal(c[~path2.contact], one[~path2.contact])  # without it: the 1-finger model
    frames = np.random.default_rng(seed).choice(np.flatnonzero(path2.contact), 4, replace=False)
    for i in frames:
        handling = Handling(
            np.stack([path.shear_n[i : i + 1], path2.shear_n[i : i + 1]], axis=1),
            hand.push,
            hand.push_force_n[i : i + 1],
        )
        touches = (
            Touch(reg.surface, tuple(path.uv_mm[i])),
            Touch(reg2.surface, tuple(path2.uv_mm[i])),
        )
        forces = np.array([[path.force_n[i], path2.force_n[i]]])
        direct = sensor.capacitance(p, touches, forces, handling)[0]
        err = np.abs(c[i] - direct).max()
        assert err < 1e-3, (i, err)
        assert err < 0.01 * np.abs(direct - rest).max()
        assert err < 0.05 * np.abs(one[i] - direct).max()


# ------------------------------------------------------------------- simulated trials
def test_two_finger_trials_carry_both_fingers(two_finger_rec, layout):
    proto = _small(second_finger=1.0)
    touch = [t for t in two_finger_rec.trials if t.meta["kind"] == "touch"]
    assert len(touch) == 2
    for t in touch:  # the second finger is finger 1 of the fingers axis
        assert t.n_fingers == 2 and t.finger_surface[1] == t.meta["second_finger"]["surface"]
        assert t.finger_surface[0] == t.meta["surface"]
        assert t.meta["mom_solves"] == 11 + proto.force_nodes + 4
        counts = np.bincount(t.n_contacts, minlength=3)
        assert counts[0] == 0 and counts[1] > 0 and counts[2] > 0  # 1- and 2-contact frames
        second = t.finger(1)
        on = second.contact
        assert not on[0] and not on[-1]
        reg2 = layout.region(t.meta["second_finger"]["region"])
        lo, hi = region_bounds(reg2, proto.touch_margin)
        assert np.all((lo <= second.uv_mm[on]) & (second.uv_mm[on] <= hi))
        assert np.isnan(second.uv_mm[~on]).all()
        assert np.all(second.height_mm[on] == 0) and np.isnan(second.height_mm[~on]).all()
        assert np.all(second.force[on] > 0) and np.all(second.force[~on] == 0)
    none = two_finger_rec.trials[0]
    assert none.meta["kind"] == "no_contact" and none.n_fingers == 1


def test_the_option_leaves_the_first_finger_alone(one_finger_rec, two_finger_rec):
    """The second finger draws from its own stream: the first finger's truth, and the readout
    of the frames without the second finger, are those of the one-finger simulation."""
    for a, b in zip(one_finger_rec.trials, two_finger_rec.trials):
        if b.n_fingers == 2:  # the readout moves by tens of fF where both press, only there
            both = b.contact[:, 1]
            assert np.abs(b.capacitance[both] - a.capacitance[both]).max() > 5e-3
            assert np.array_equal(b.capacitance[~both], a.capacitance[~both])
        else:
            assert np.array_equal(b.capacitance, a.capacitance)
        assert np.array_equal(a.labels, b.labels)
        for field in ("contact", "finger_uv_mm", "force", "finger_height_mm"):  # finger 0
            first = getattr(b, field)[:, :1]
            assert np.array_equal(getattr(a, field), first, equal_nan=True), field


# ------------------------------------------------------------------------------ resting on skin
def test_a_fingertip_the_skin_reaches_into_rests_on_it(sensor):
    """A frame of a simulated two-finger trial at 20/20/20 ml (seed 0's contact experiment with
    the hand off) where a chamber's bulge under the back finger's pad came within 0.07 mm of a
    wire while the fingertips were placed along the normal at their points: the method of
    moments failed, with the fingertip refined too. Resting on the skin (every frame now), it
    solves with the default fingertip, the skin keeps the cover under both pads, and the readout
    stays near the same fingers 10 % lighter."""
    infl = (20.0, 20.0, 20.0)
    touch = (
        Touch("back", (15.243184552839152, 49.63840443854273)),
        Touch("front", (-17.254362765218175, 63.89830961971546)),
    )
    forces = np.array([[0.6278329852902538, 1.1450248567485297]])
    shear = np.array(
        [[[0.1700579133327279, 0.05518682274776538], [-0.18296100368546128, -0.00739357909729519]]]
    )
    handling = Handling(shear_n=shear)
    pe = sensor.electrode_panels(infl, touch, forces, handling)[0]
    placed = sensor.finger_panels(infl, touch, forces, handling)[0]
    # the default fingertip and the wires: the collocation matrix is positive definite
    maxwell_capacitance(Panels.concatenate([pe, placed]), sensor.eps_r)
    # every wire panel keeps most of the cover to the fingers' panels (0.07 mm before)
    gap = np.min(np.linalg.norm(pe.centres[:, None] - placed.centres[None], axis=2))
    assert gap > 0.5 * sensor.finger.skin_cover_mm, gap
    c = sensor.capacitance(infl, touch, forces, handling)[0]
    assert np.isfinite(c).all() and (c > 0).all()
    near = sensor.capacitance(infl, touch, 0.9 * forces, handling)[0]
    assert np.abs(c - near).max() < 0.1 * np.abs(near).max()


# ------------------------------------------------------------------------------ people differ
def test_each_trial_is_touched_by_its_own_finger(one_finger_rec, two_finger_rec, sensor):
    """Per touch trial a fingertip radius and pulp modulus drawn in the protocol's ranges, on the
    fingers axis; none for a trial without contact; the second finger draws its own and leaves
    the first finger's alone."""
    proto = _small()
    lo_r, hi_r = proto.finger_radius_range_mm
    lo_e, hi_e = proto.finger_modulus_range_mpa
    touch = [t for t in one_finger_rec.trials if t.meta["kind"] == "touch"]
    for t in touch:
        assert t.finger_radius_mm.shape == t.finger_modulus_mpa.shape == (1,)
        assert lo_r <= t.finger(0).radius_mm <= hi_r and lo_e <= t.finger(0).modulus_mpa <= hi_e
    assert touch[0].finger_radius_mm[0] != touch[1].finger_radius_mm[0]  # people differ
    rest = one_finger_rec.trials[0]
    assert rest.meta["kind"] == "no_contact" and rest.finger_radius_mm is None
    for a, b in zip(one_finger_rec.trials, two_finger_rec.trials):
        if b.n_fingers == 2:
            assert np.array_equal(b.finger_radius_mm[:1], a.finger_radius_mm)
            assert np.array_equal(b.finger_modulus_mpa[:1], a.finger_modulus_mpa)
            assert lo_r <= b.finger(1).radius_mm <= hi_r and lo_e <= b.finger(1).modulus_mpa <= hi_e
            assert b.finger_radius_mm[1] != b.finger_radius_mm[0]


def test_a_trial_solves_with_its_drawn_finger_and_nothing_else_changes(one_finger_rec, sensor):
    """The trial simulated with the option off on a sensor whose finger is the one the trial drew
    is the same trial bit for bit: the draw goes into the solves, and it comes from a stream of
    its own (every other draw of the trial stays)."""
    from ectskin.twin.finger import Finger
    from ectskin.twin.simulate import simulate_trial

    proto = _small()
    plan = next(p for p in plan_trials(proto, sensor.layout) if p.kind == "touch")
    on = next(t for t in one_finger_rec.trials if t.name == plan.name)
    drawn = Finger(radius_mm=on.finger(0).radius_mm, pulp_modulus_mpa=on.finger(0).modulus_mpa)
    off = dataclasses.replace(proto, finger_variability=False, finger_radius_mm=drawn.radius_mm)
    drift = np.random.default_rng([proto.seed, 2]).uniform(0, 2 * np.pi, sensor.layout.n_pairs)
    again = simulate_trial(plan, off, sensor.with_fingers(drawn), drift)
    assert np.array_equal(again.capacitance, on.capacitance)
    assert np.array_equal(again.markers, on.markers, equal_nan=True)
    assert np.array_equal(again.force, on.force)


@pytest.mark.parametrize(
    "field, value",
    [
        ("finger_radius_range_mm", (10.0, 7.0)),
        ("finger_radius_range_mm", (1.0, 7.0)),
        ("finger_radius_range_mm", (7.0,)),
        ("finger_modulus_range_mpa", (0.0, 0.2)),
        ("finger_modulus_range_mpa", (0.05, float("nan"))),
        ("finger_variability", "yes"),
    ],
)
def test_protocol_refuses_finger_ranges_that_are_not_ranges(field, value):
    with pytest.raises(EctskinError, match=f"protocol: {field} must be"):
        Protocol(**{field: value})
