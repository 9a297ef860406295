"""The digital twin: electrostatics on the deformed sensor, the paper's §2.2 characterisation,
the protocol, and the simulation driver."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.layout import default_layout
from ectskin.twin import Finger, Protocol, SensorModel, Touch, plan_trials, simulate_experiment
from ectskin.twin.characterize import characterize
from ectskin.twin.human import finger_path, hand_push
from ectskin.twin.live import LiveTwin
from ectskin.twin.mechanics import Handling
from ectskin.twin.protocol import region_bounds
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout
from ectskin.twin.response import TouchResponse


@pytest.fixture(scope="module")
def layout():
    return default_layout()


@pytest.fixture(scope="module")
def sensor(layout):
    return SensorModel(layout)


@pytest.fixture(scope="module")
def char(sensor):
    return characterize(None, sensor=sensor)


def test_readout_is_symmetric_and_positive(sensor, layout):
    c = sensor.capacitance([0, 0, 0])[0]
    assert np.all(c > 0)  # C_ij = -K_ij > 0
    # the layout is mirror-symmetric front/back: E1-E2 equals E5-E6, E1-E6 equals E2-E5
    name = {n: k for k, n in enumerate(layout.pair_names)}
    assert c[name["E1-E2"]] == pytest.approx(c[name["E5-E6"]], rel=1e-6)
    assert c[name["E1-E6"]] == pytest.approx(c[name["E2-E5"]], rel=1e-6)
    # neighbours couple more than distant wires on the same face
    assert c[name["E1-E2"]] > c[name["E1-E4"]]


def _refinement_change(layout):
    base = SensorModel(layout)
    fine = SensorModel(layout, discretisation=base.discretisation.refined(2))
    worst = 0.0
    for p, touch in (([0, 0, 0], None), ([0, 20, 20], Touch("front", (0.0, 60.0)))):
        c1 = base.capacitance(p, touch, [1.0])[0]
        c2 = fine.capacitance(p, touch, [1.0])[0]
        worst = max(worst, float(np.max(np.abs(c1 - c2) / c2)))
    return worst


@pytest.mark.slow
def test_readout_converges_under_refinement(layout):
    """Doubling the panel density changes every pair by < 1 % at the default resolution."""
    assert _refinement_change(layout) < 0.01


def test_inflation_response_matches_the_paper(char, layout):
    """§2.2: (20,20,20) ml changes readouts by up to about 40 %; same-face pairs rise, cross-face
    pairs fall; (0,20,20) looks like (20,20,20)."""
    change = np.array([p["inflation_change"] for p in char["pairs"]])
    same = np.array([p["same_face"] for p in char["pairs"]])
    assert 0.25 <= np.abs(change).max() <= 0.60
    assert np.all(change[same] > 0)
    assert np.all(change[~same] < 0)  # the air chambers between the faces grow
    assert change[~same].mean() < -0.05
    facing = [layout.pair_names.index(f"E{k}-E{k + 4}") for k in range(1, 5)]
    assert np.all(change[facing] < 0)  # wires facing each other across the body move apart
    partial = np.array(char["partial_inflation_change"])
    assert char["partial_vs_full_correlation"] > 0.7
    big = np.abs(change) > 0.02
    assert np.mean(np.sign(partial[big]) == np.sign(change[big])) >= 0.8


def test_air_chambers_lower_the_pairs_they_lie_between(sensor, layout):
    """The cavities (air, first order) lower every cross-face pair, whose field crosses them,
    by more than any same-face pair; None gives back the homogeneous medium."""
    from ectskin.twin.mechanics import Manipulator, ManipulatorConfig

    homogeneous = SensorModel(layout, chamber_eps_r=None)
    with_air = sensor.capacitance([0, 0, 0])[0]
    without = homogeneous.capacitance([0, 0, 0])[0]
    rel = (with_air - without) / without
    same = layout.same_surface
    assert np.all(rel[~same] < -0.02)
    assert rel[~same].max() < rel[same].min()
    # the same dielectric as the body: no correction at all
    np.testing.assert_allclose(
        SensorModel(layout, chamber_eps_r=2.0).capacitance([0, 0, 0]),
        homogeneous.capacitance([0, 0, 0]),
    )
    with pytest.raises(EctskinError, match="chamber_eps_r"):
        SensorModel(layout, chamber_eps_r=0.5)
    with pytest.raises(EctskinError, match="chamber_wall_mm"):
        SensorModel(layout, Manipulator(ManipulatorConfig(chamber_wall_mm=10.0)))


def test_touch_moves_mainly_the_pairs_near_it(char, layout):
    """A touch moves the pairs whose field covers the touch point; bending adds much less."""
    infl = np.abs([p["inflation_change"] for p in char["pairs"]]).max()
    near_wins = 0
    for t in char["touches"]:
        touch_only = np.abs(t["touch_only_change"])
        bending = np.abs(t["bending_only_change"])
        assert bending.max() < 0.25 * touch_only.max()
        assert bending.max() < 0.25 * infl
        # distance of each pair to the touch point: the nearer of its two wires
        u, v = t["uv_mm"]
        dist = []
        for e in layout.electrodes:
            poly = e.polyline_mm
            same_face = layout.skin(e.skin).surface == t["surface"]
            zc = np.clip(v, poly[:, 1].min(), poly[:, 1].max())
            d = np.hypot(poly[0, 0] - u, zc - v) if same_face else 1e3
            dist.append(d)
        dist = np.array(dist)
        pair_d = np.minimum(dist[layout.pairs[:, 0]], dist[layout.pairs[:, 1]])
        top = np.argsort(-touch_only)[:5]
        near_wins += np.median(pair_d[top]) < np.median(pair_d)
    assert near_wins >= 0.8 * len(char["touches"])


def _trial_model(sensor, layout, region, p, seed, **protocol):
    proto = Protocol(**protocol)
    rng = np.random.default_rng(seed)
    reg = layout.region(region)
    lo, hi = region_bounds(reg, proto.touch_margin)
    path = finger_path(300, 30.0, np.asarray([reg.centre_mm]), lo, hi, proto, rng)
    hand = hand_push(300, 30.0, proto, rng, sensor.manipulator.config)
    push_dir = None
    if hand.push_force_n is not None:
        push_dir = hand.push_force_n[np.argmax(np.linalg.norm(hand.push_force_n, axis=1))]
        push_dir = push_dir / np.linalg.norm(push_dir)
    model = TouchResponse(sensor, p, reg.surface, path, hand, push_dir, proto)
    return reg, path, hand, model(path, hand)


@pytest.mark.parametrize(
    "region, p, seed, options",
    [(5, [10, 0, 20], 5, {}), (14, [0, 20, 0], 6, {"hover": True, "approach": True})],
)
def test_the_trial_model_stays_close_to_direct_solves(sensor, layout, region, p, seed, options):
    """A trial's readout model (force, height, point, hand) against direct MoM solves of the
    same frames: within 0.5 fF and 5 % of the finger's signal at every pair."""
    reg, path, hand, c = _trial_model(sensor, layout, region, p, seed, **options)
    rest = sensor.capacitance(p)[0]
    frames = np.random.default_rng(seed).choice(path.force_n.size, 5, replace=False)
    if not path.contact.all():  # include frames above the skin
        frames = np.r_[frames[:3], np.flatnonzero(~path.contact)[[0, -5]]]
    for i in frames:
        handling = Handling(path.shear_n[i : i + 1], hand.push, hand.push_force_n[i : i + 1])
        direct = sensor.capacitance(
            p,
            Touch(reg.surface, tuple(path.uv_mm[i])),
            path.force_n[i : i + 1],
            handling,
            heights_mm=path.height_mm[i : i + 1],
        )[0]
        err = np.abs(c[i] - direct)
        assert err.max() < 0.5e-3, (i, err.max())
        assert err.max() < 0.05 * np.abs(direct - rest).max()


def test_readout_has_no_staircase_and_the_papers_snr(sensor):
    """1 fF per conversion, averaged: the output grid is finer than the noise, the noise is the
    model's σ, and every pair's SNR is over 60 dB (paper §3)."""
    cfg = ReadoutConfig()
    c = sensor.capacitance([0, 0, 0])[0]
    rng = np.random.default_rng(0)
    meas = readout(np.repeat(c[None], 4000, axis=0), np.zeros(4000), rng, cfg, np.zeros(c.size))
    sigma = noise_pf(c, cfg)
    np.testing.assert_allclose(meas.std(axis=0), sigma, rtol=0.1)
    assert cfg.output_step_pf < 0.5 * sigma.min()
    assert len(np.unique(meas[:, np.argmin(c)])) > 10  # many levels, not a 1-fF staircase
    assert np.all(20 * np.log10(c / sigma) > 60.0)
    with pytest.raises(EctskinError, match="samples_per_frame"):
        ReadoutConfig(samples_per_frame=0)


def test_readout_is_smooth_in_the_force(sensor):
    """No steps from the discretisation as the finger presses harder: the fingertip keeps its
    panels while the surface normal tilts (they once flipped in and out: a 0.2-0.4 fF step)."""
    p, touch = [10, 0, 20], Touch("back", (5.0, 90.0))
    c = sensor.capacitance(p, touch, np.linspace(0.9, 1.1, 9))
    d1 = np.diff(c, axis=0)
    d2 = np.diff(c, n=2, axis=0)
    moving = np.abs(d1).min(axis=0) > 1e-6  # pairs that change by > 1e-3 fF per step
    assert moving.sum() >= 10
    assert np.all(np.sign(d1[:, moving]) == np.sign(d1[0, moving]))  # monotone over the range
    assert np.all(np.abs(d2[:, moving]) < 0.1 * np.abs(d1[:, moving]).mean(axis=0))


def test_protocol_plan_matches_the_paper(layout):
    plans = plan_trials(Protocol(), layout)
    assert len(plans) == 189
    touch = [p for p in plans if p.kind == "touch"]
    assert len(touch) == 162
    assert {p.region for p in touch} == set(range(1, 19))
    assert sum(p.occluded for p in touch) == 16  # 146 clean tracking trials
    for p in touch:
        reg = layout.region(p.region)
        assert reg.surface == p.surface
        for u, v in p.touch_uv_mm:
            assert reg.u_mm[0] < u < reg.u_mm[1]
            assert reg.v_mm[0] < v < reg.v_mm[1]
    assert plan_trials(Protocol(), layout) == plans  # deterministic for a seed
    assert plan_trials(Protocol(seed=1), layout) != plans


def test_protocol_rejects_bad_parameters():
    with pytest.raises(EctskinError, match="force_range_n"):
        Protocol(force_range_n=(2.0, 1.0))
    with pytest.raises(EctskinError, match="impossible inflation"):
        simulate_experiment(
            Protocol(levels_ml=(-5.0,), touch_trials=0, duration_s=0.2), progress=False
        )


def test_simulation_is_deterministic_and_independent_of_workers(layout):
    # (two points per trial, sliding from one to the other: the default reading's solves, cheaper)
    proto = Protocol(levels_ml=(0.0, 20.0), n_chambers=3, touch_trials=1, duration_s=2.0, seed=3,
                     touch_dwells=2)
    a = simulate_experiment(proto, workers=1, progress=False)
    b = simulate_experiment(proto, workers=2, progress=False)
    assert a.n_trials == 16 and a.trials[0].n_frames == 60
    for ta, tb in zip(a.trials, b.trials):
        np.testing.assert_array_equal(ta.capacitance, tb.capacitance)
        np.testing.assert_array_equal(ta.markers, tb.markers)
    t = next(t for t in a.trials if t.meta["kind"] == "touch")
    assert np.all(t.labels == t.region) and t.region > 0
    assert np.all((t.force >= 0.25) & (t.force <= 2.1))  # the range, plus the tremor
    # the output grid: 1 fF per conversion over 256 conversions
    step = ReadoutConfig().output_step_pf
    np.testing.assert_allclose(t.capacitance / step, np.round(t.capacitance / step), atol=1e-6)
    nc = a.trials[0]
    assert nc.meta["kind"] == "no_contact" and np.all(nc.labels == 0)


def test_a_subset_of_trials_and_the_hand_off_are_the_same_trials():
    """``trials=`` gives the named trials exactly as the whole experiment has them (plan order);
    without the hand (push_max_n = 0) a trial keeps its finger and its readout noise, so the
    difference to the trial with the hand is the hand's smooth effect alone. (With the hand's
    random numbers skipped when it is off, the noise was drawn anew: the difference's
    second derivative was 0.32-0.39 fF against 0.005-0.04 fF now.)"""
    proto = Protocol(levels_ml=(0.0, 20.0), n_chambers=3, touch_trials=1, duration_s=2.0, seed=3,
                     touch_dwells=1)
    full = simulate_experiment(proto, workers=1, progress=False)
    by_name = {t.name: t for t in full.trials}
    touch = [t.name for t in full.trials if t.meta["kind"] == "touch"][:3]
    sub = simulate_experiment(proto, workers=1, progress=False, trials=touch[::-1])
    assert [t.name for t in sub.trials] == touch and sub.meta["only_trials"] == touch
    # a whole experiment is not a subset: its metadata names no trials (the ``trials`` argument
    # was once rebound to the result list, so every run wrote ``only_trials``)
    assert "only_trials" not in full.meta
    for t in sub.trials:
        np.testing.assert_array_equal(t.capacitance, by_name[t.name].capacitance)
        np.testing.assert_array_equal(t.markers, by_name[t.name].markers)
    with pytest.raises(EctskinError, match=r"trial\(s\) \['nope'\] are not in the protocol's plan"):
        simulate_experiment(proto, workers=1, progress=False, trials=["nope"])
    off = simulate_experiment(
        replace(proto, push_max_n=0.0), workers=1, progress=False, trials=touch
    )
    for t in off.trials:
        on = by_name[t.name]
        np.testing.assert_array_equal(t.force, on.force)
        np.testing.assert_array_equal(t.finger_uv_mm, on.finger_uv_mm)
        np.testing.assert_array_equal(t.labels, on.labels)
        d = on.capacitance - t.capacitance
        assert np.abs(d).max() > 2e-3  # the hand moves the readouts (5-26 fF here) ...
        rough = np.std(np.diff(d, 2, axis=0))  # ... smoothly: the noise is the same draw
        assert rough < 0.25 * np.std(np.diff(on.capacitance, 2, axis=0)), rough


def test_lifts_give_per_frame_contact_labels():
    proto = Protocol(
        levels_ml=(0.0,), touch_trials=1, no_contact_trial=False, duration_s=20.0, lifts=True
    )
    t = simulate_experiment(proto, workers=1, progress=False).trials[0]
    assert set(np.unique(t.labels)) == {0, t.region}
    assert np.all(t.force[t.labels == 0] == 0)


def test_the_finger_is_human(layout):
    """Force wanders and trembles at 8-12 Hz; the point rolls and slides a little, inside the
    region; with approach and hover the finger is above the skin at recorded heights."""
    proto = Protocol(push_max_n=0.0)
    reg = layout.region(5)
    lo, hi = region_bounds(reg, proto.touch_margin)
    path = finger_path(
        900, 30.0, np.asarray([reg.centre_mm]), lo, hi, proto, np.random.default_rng(1)
    )
    assert path.contact.all() and np.all(path.height_mm == 0)
    f = path.force_n
    spectrum = np.abs(np.fft.rfft(f - f.mean())) ** 2
    hz = np.fft.rfftfreq(f.size, 1 / 30.0)
    band = (hz >= 8) & (hz <= 12)
    assert spectrum[band].sum() > 10 * spectrum[(hz > 4) & (hz < 7.5)].sum()  # a tremor peak
    assert 0.01 < np.std(np.diff(f)) / f.mean() < 0.1
    spread = path.uv_mm.std(axis=0)
    assert np.all((spread > 0.1) & (spread < 1.5))
    assert np.all((path.uv_mm >= lo) & (path.uv_mm <= hi))
    assert np.allclose(
        np.linalg.norm(path.shear_n, axis=1) / f, np.linalg.norm(path.shear_n[0]) / f[0]
    )
    hov = finger_path(
        900,
        30.0,
        np.asarray([reg.centre_mm]),
        lo,
        hi,
        Protocol(approach=True, hover=True),
        np.random.default_rng(2),
    )
    assert not hov.contact[0] and not hov.contact[-1] and hov.contact.any()
    assert hov.height_mm[0] == pytest.approx(Protocol().approach_height_mm)
    assert np.all(hov.force_n[~hov.contact] == 0) and np.all(hov.height_mm[~hov.contact] > 0)
    with pytest.raises(EctskinError, match="tremor_hz"):
        Protocol(tremor_hz=(8.0, 20.0))
    with pytest.raises(EctskinError, match="force_range_n"):
        Protocol(force_range_n=(0.3, 500.0))
    with pytest.raises(EctskinError, match="push_max_n must be at most"):
        Protocol(push_max_n=50.0)
    with pytest.raises(EctskinError, match="finger: pulp_modulus_mpa"):
        Finger(pulp_modulus_mpa=-1.0)


def test_deformation_signals_are_much_smaller_than_inflation_and_touch(sensor, char):
    """§4.2: the hand's push moves the readout far less than inflation and touch do."""
    rest = sensor.capacitance([0, 20, 20])[0]
    push = Handling(push=Touch("right", (0.0, 100.0)), push_force_n=np.array([[-1.0, 0.5, 0.0]]))
    pushed = sensor.capacitance([0, 20, 20], None, [0.0], push)[0]
    moved = np.abs(pushed / rest - 1).max()
    infl = np.abs([p["inflation_change"] for p in char["pairs"]]).max()
    touch = np.median([np.abs(t["touch_only_change"]).max() for t in char["touches"]])
    assert 1e-4 < moved < 0.1 * infl and moved < 0.1 * touch


def test_live_twin_streams_touch_and_inflation():
    twin = LiveTwin(seed=1)
    c0, m0, lab0 = twin.next_frame()
    assert c0.shape == (28,) and m0.shape == (5, 3) and lab0 == 0
    twin.set_touch(5, force_n=2.0)
    for _ in range(30):
        c1, m1, lab1 = twin.next_frame()
    assert lab1 == 5
    assert np.max(np.abs(c1 - c0) / c0) > 0.05  # the finger changes the readout
    assert np.linalg.norm(m1[-1] - m0[-1]) > 3.0  # and bends the manipulator
    with pytest.raises(EctskinError, match="unknown region 42"):
        twin.set_touch(42)
    with pytest.raises(EctskinError, match="impossible inflation"):
        twin.set_inflation([0, 50, 0])


def test_touch_dwells_move_the_finger_within_its_region(layout):
    proto = Protocol(
        levels_ml=(0.0,),
        touch_trials=1,
        no_contact_trial=False,
        duration_s=3.0,
        touch_dwells=3,
        dwell_slide_s=0.0,
        seed=2,
    )
    t = simulate_experiment(proto, workers=1, progress=False).trials[0]
    points = t.meta["touch_uv_mm"]
    assert len(points) == 3 and len({tuple(p) for p in points}) == 3
    reg = layout.region(t.region)
    assert all(reg.u_mm[0] < u < reg.u_mm[1] and reg.v_mm[0] < v < reg.v_mm[1] for u, v in points)
    segments = np.array_split(np.arange(t.n_frames), 3)
    means = [t.capacitance[s].mean(axis=0) for s in segments]
    assert np.abs(means[0] - means[1]).max() > 2e-3  # a different placement reads differently
    assert np.all(t.labels == t.region)


def test_trials_carry_the_fingers_ground_truth(layout):
    proto = Protocol(
        levels_ml=(0.0,), touch_trials=1, duration_s=4.0, hover=True, approach=True, seed=4
    )
    rec = simulate_experiment(proto, workers=1, progress=False)
    rest, touch = rec.trials
    assert (
        rest.has_ground_truth and not rest.contact.any() and np.isnan(rest.finger_height_mm).all()
    )
    assert touch.has_ground_truth and touch.finger_surface == (layout.region(touch.region).surface,)
    on = touch.contact[:, 0]  # (one finger: finger 0 of the fingers axis)
    assert on.any() and (~on).any()
    assert np.all(touch.finger_height_mm[on] == 0) and np.all(touch.finger_height_mm[~on] > 0)
    assert np.all(touch.force[~on] == 0) and np.all(touch.force[on] > 0)
    np.testing.assert_array_equal(touch.labels != 0, on)
    reg = layout.region(touch.region)
    assert np.all(
        (touch.finger_uv_mm[:, 0, 0] > reg.u_mm[0]) & (touch.finger_uv_mm[:, 0, 0] < reg.u_mm[1])
    )


def test_each_dwell_has_its_own_readout_model(sensor, layout):
    """A finger that moves to new points within a trial (touch_dwells): the readout of a frame
    of the last dwell against a direct MoM solve there stays within 0.5 fF; one model around the
    trial's mean point (before dwells had their own) was far off."""
    from ectskin.twin.simulate import _rows, _touch_segment

    proto = Protocol(touch_dwells=2, dwell_slide_s=0.0, push_max_n=0.0)
    reg = layout.region(5)
    lo, hi = region_bounds(reg, proto.touch_margin)
    aims = np.array([lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)])  # the region's far corners
    rng = np.random.default_rng(3)
    n, p = 120, [10, 0, 20]
    path = finger_path(n, 30.0, aims, lo, hi, proto, rng)
    hand = hand_push(n, 30.0, proto, rng, sensor.manipulator.config)
    plan = SimpleNamespace(surface=reg.surface, touch_uv_mm=tuple(map(tuple, aims)))
    rows = np.array_split(np.arange(n), 2)[1]
    c, _, _ = _touch_segment(
        sensor, p, plan, proto, _rows(path, rows), _rows(hand, rows), None, None
    )
    one = TouchResponse(sensor, p, reg.surface, path, hand, None, proto)(path, hand)
    i = rows[len(rows) // 2]
    handling = Handling(path.shear_n[i : i + 1], hand.push, hand.push_force_n)
    direct = sensor.capacitance(
        p, Touch(reg.surface, tuple(path.uv_mm[i])), path.force_n[i : i + 1], handling
    )[0]
    err_dwell = np.abs(c[len(rows) // 2] - direct).max()
    err_one = np.abs(one[i] - direct).max()
    print(f"dwell model {err_dwell * 1e3:.3f} fF, one model {err_one * 1e3:.3f} fF")
    assert err_dwell < 0.5e-3, err_dwell
    assert err_one > 5 * err_dwell, (err_one, err_dwell)
