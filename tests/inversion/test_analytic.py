"""The inversion on a flat skin whose readouts are closed-form (``conftest.AnalyticField``).

The fitting code is tested apart from the twin: the truth is known exactly, the model is exact,
so a noise-free frame must give the point back to the optimiser's tolerance, the scatter over
noisy repeats must be the Cramér–Rao bound (the least-squares fit is efficient at this SNR) and
the standard errors must be the bound at the truth, computed here from finite differences of the
model's readouts (not from the Jacobian the inversion uses).
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import FingerGuess, Inversion, fit_frames, results_to_arrays
from ectskin.twin.bound import crb
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout

STATE = (0.0,)
NO_DRIFT = ReadoutConfig(drift_rel=0.0)


def noisy(c: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``n`` frames of the twin's readout electronics (no drift) measuring ``c`` (n_pairs,)."""
    rng = np.random.default_rng(seed)
    return readout(np.repeat(c[None], n, 0), np.arange(n) / 30.0, rng, NO_DRIFT, np.zeros(c.size))


def bound_at(field, face, u, v, force=0.0, height=0.0, n_frames=1):
    """CRB std of (u, v, force or height) at the truth, nuisances (gain, offset) estimated, from
    central differences of ``field.readout``."""
    x = np.array([u, v, height if height else force])
    cols = []
    for j, step in enumerate((1e-5, 1e-5, 1e-6)):
        e = np.zeros(3)
        e[j] = step
        a, b = x + e, x - e
        args = [(p[0], p[1], 0.0, p[2]) if height else (p[0], p[1], p[2], 0.0) for p in (a, b)]
        cols.append((field.readout(face, *args[0]) - field.readout(face, *args[1])) / (2 * step))
    J = np.stack(cols + [field.untouched, np.ones(field.n_pairs)], axis=1)
    c = field.readout(face, u, v, force, height)
    return crb(J, noise_pf(c, ReadoutConfig()) / np.sqrt(n_frames), nuisance_cols=[3, 4]).std


@pytest.fixture(scope="module")
def inv(analytic_field):
    return Inversion({STATE: analytic_field})


@pytest.mark.parametrize("u, v, force, height", [
    (0.5, 20.3, 0.8, 0.0), (-6.2, 33.1, 1.7, 0.0), (11.7, 12.9, 0.45, 0.0), (2.3, 25.7, 0.0, 2.2),
    (-12.4, 8.6, 0.0, 0.9),
])
def test_a_noise_free_frame_gives_the_point_back(inv, analytic_field, u, v, force, height):
    y = analytic_field.readout("front", u, v, force, height)
    r = inv.fit(y, STATE)
    assert r.n_fingers == 1 and r.converged
    f = r.fingers[0]
    assert f.face == "front" and f.contact == (height == 0)
    np.testing.assert_allclose([f.u_mm, f.v_mm], [u, v], atol=1e-5)
    np.testing.assert_allclose([f.force_n, f.height_mm], [force, height], atol=1e-6)


def test_drift_is_a_nuisance_it_estimates(inv, analytic_field):
    """A common gain and offset on the readout move neither the point nor the force, and come
    back as the nuisance coefficients."""
    y = analytic_field.readout("front", 4.1, 22.2, 1.3)
    gain, offset = 4e-4, 3e-4
    r = inv.fit(y + gain * analytic_field.untouched + offset, STATE)
    f = r.fingers[0]
    np.testing.assert_allclose([f.u_mm, f.v_mm, f.force_n], [4.1, 22.2, 1.3], atol=1e-5)
    np.testing.assert_allclose([r.nuisance["gain"], r.nuisance["offset"]], [gain, offset],
                               rtol=1e-5)
    # without the drift terms the same frame is fitted worse, and the point moves
    plain = Inversion({STATE: analytic_field}, drift=()).fit(y + gain * analytic_field.untouched
                                                              + offset, STATE)
    g = plain.fingers[0]
    assert np.hypot(g.u_mm - 4.1, g.v_mm - 22.2) > 0.1
    assert plain.log_likelihood < r.log_likelihood - 10


def test_push_columns_and_their_prior(analytic_field):
    """A push column (here any smooth pattern over the pairs) is a nuisance like the drift:
    without a prior its coefficient comes back and the point stays; with a prior of vanishing
    width it is held at 0, as if absent; the prior's information narrows the standard errors
    towards those of the fit without the column."""
    rng = np.random.default_rng(6)
    col = np.abs(rng.normal(size=(analytic_field.n_pairs, 1))) * 1e-3  # pF per N
    y = analytic_field.readout("front", -3.3, 27.7, 0.9)
    free = Inversion({STATE: analytic_field}, push={STATE: col})
    r = free.fit(y + 1.5 * col[:, 0], STATE)
    np.testing.assert_allclose([r.fingers[0].u_mm, r.fingers[0].v_mm], [-3.3, 27.7], atol=1e-5)
    assert r.nuisance["push_1"] == pytest.approx(1.5, rel=1e-5)
    pinned = Inversion({STATE: analytic_field}, push={STATE: col}, push_prior_sd=1e-9)
    plain = Inversion({STATE: analytic_field})
    frame = noisy(y + 0.2 * col[:, 0], 1, 1)[0]
    a, b = pinned.fit(frame, STATE), plain.fit(frame, STATE)
    assert abs(a.nuisance["push_1"]) < 1e-6
    assert a.fingers[0].u_mm == pytest.approx(b.fingers[0].u_mm, abs=1e-6)
    assert a.fingers[0].u_se_mm == pytest.approx(b.fingers[0].u_se_mm, rel=1e-3)
    assert free.fit(frame, STATE).fingers[0].u_se_mm >= b.fingers[0].u_se_mm


@pytest.mark.parametrize("gate_p", [1e-4, 0.0])
def test_the_count_is_chosen_by_bic(analytic_field, gate_p):
    """0, 1 and 2 fingers, with the gate (counts tried while the fewer do not explain the
    frame) and without it (every count fitted, BIC alone decides)."""
    inv = Inversion({STATE: analytic_field}, gate_p=gate_p)
    rng = np.random.default_rng(3)
    c_u = analytic_field.untouched
    for seed in range(6):
        zero = inv.fit(noisy(c_u, 1, seed)[0], STATE)
        assert zero.n_fingers == 0, zero.bic_by_count
        u, v, f = rng.uniform(-16, 16), rng.uniform(4, 56), rng.uniform(0.4, 1.9)
        one = inv.fit(noisy(analytic_field.readout("front", u, v, f), 1, seed)[0], STATE)
        assert one.n_fingers == 1, (u, v, f, one.bic_by_count)
        if not gate_p:
            assert np.all(np.isfinite(one.bic_by_count))
        # two fingers far enough apart to be two (≥ 15 mm), both pressing
        while True:
            a, b = rng.uniform((-16, 4), (16, 56), size=(2, 2))
            if np.hypot(*(a - b)) >= 15:
                break
        fa, fb = rng.uniform(0.4, 1.9, 2)
        y = (analytic_field.readout("front", *a, fa) + analytic_field.delta("front", *b, fb))
        frame = noisy(y, 1, seed)[0]
        two = inv.fit(frame, STATE)
        assert two.n_fingers == 2, (a, b, two.bic_by_count)
        # the fit is as likely as the truth (β fitted there): the truth lies inside the fit's 99 %
        # likelihood-ratio region for the 6 finger parameters, 2 Δℓ <= χ²₆(0.99) = 16.8 (with
        # the gate the optimiser may stop at a nearby optimum that the noise cannot tell apart)
        sigma = noise_pf(frame, ReadoutConfig())
        N = np.c_[c_u, np.ones(c_u.size)] / sigma[:, None]
        z = (frame - y) / sigma
        chi2_truth = float(np.sum((z - N @ np.linalg.lstsq(N, z, rcond=None)[0]) ** 2))
        ll_truth = -0.5 * chi2_truth - np.log(sigma).sum() - 0.5 * c_u.size * np.log(2 * np.pi)
        assert 2 * (ll_truth - two.log_likelihood) <= 16.8, (a, b, two.bic_by_count)
        # and each finger lies within 5 standard errors of its true point (either order): two
        # fingers on 15 pairs are far less determined than one, their errors reach millimetres
        got = np.array([[g.u_mm, g.v_mm] for g in two.fingers])
        se = np.array([[g.u_se_mm, g.v_se_mm] for g in two.fingers])
        true = np.stack([a, b])
        z_err = min(np.abs((got - true) / se).max(), np.abs((got[::-1] - true) / se[::-1]).max())
        assert z_err < 5, (a, b, got, se)


def test_bic_keeps_noise_from_being_a_finger(make_analytic_field):
    """A finger hovering far enough (up to 200 mm) has a signal below the noise, so one-finger
    fits always lower χ² on an untouched frame a little. BIC charges 3 ln n (8.1 here) for the
    finger: of 20 noisy untouched frames at most 2 count one (χ² gains above 8.1 with about 3
    parameters' worth of noise happen a few per cent of the time); with every count fitted."""
    far = make_analytic_field(height_range_mm=(0.5, 200.0))
    inv = Inversion({STATE: far}, gate_p=0.0)
    counts = [inv.fit(y, STATE).n_fingers for y in noisy(far.untouched, 20, 0)]
    assert sum(counts) <= 2, counts


def test_standard_errors_are_the_bound_at_the_truth(inv, analytic_field):
    for k, (u, v, f, h) in enumerate([(1.2, 18.4, 1.1, 0.0), (-7.5, 30.2, 0.0, 1.7)]):
        y = noisy(analytic_field.readout("front", u, v, f, h), 1, 10 + k)[0]
        r = inv.fit(y, STATE)
        g = r.fingers[0]
        se = [g.u_se_mm, g.v_se_mm, g.force_se_n if h == 0 else g.height_se_mm]
        np.testing.assert_allclose(se, bound_at(analytic_field, "front", u, v, f, h), rtol=0.03)


def test_the_scatter_over_noisy_repeats_is_the_bound(inv, analytic_field):
    """400 repeats: the sample standard deviation of an efficient estimator is the bound within
    its own sampling error, sd 1/sqrt(2·399) = 3.5 %, so within ±15 % (> 4 sd); the mean within
    4 bounds/√400 of the truth (no bias beyond the noise)."""
    u, v, f = 3.4, 24.6, 0.9
    frames = noisy(analytic_field.readout("front", u, v, f), 400, 5)
    res, _ = fit_frames(inv, frames, STATE)
    arr = results_to_arrays(res)
    assert np.all(arr["n_fingers"] == 1)
    est = np.c_[arr["uv_mm"][:, 0], arr["force_n"][:, 0]]
    bound = bound_at(analytic_field, "front", u, v, f)
    ratio = est.std(axis=0, ddof=1) / bound
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    assert np.all(np.abs(est.mean(axis=0) - [u, v, f]) < 4 * bound / np.sqrt(400))


def test_a_window_of_frames_is_averaged(inv, analytic_field):
    """Four frames averaged: the same point as their mean, errors halved (noise / √4)."""
    frames = noisy(analytic_field.readout("front", -2.0, 40.0, 1.5), 4, 8)
    one = inv.fit(frames.mean(axis=0), STATE)
    win = inv.fit(frames, STATE)
    assert win.fingers[0].u_mm == pytest.approx(one.fingers[0].u_mm, abs=1e-9)
    assert win.fingers[0].u_se_mm == pytest.approx(one.fingers[0].u_se_mm / 2, rel=1e-3)
    res, _ = fit_frames(inv, frames, STATE, window=4)
    assert res[-1].fingers[0].u_mm == pytest.approx(win.fingers[0].u_mm, abs=1e-9)
    assert res[0].fingers[0].u_se_mm == pytest.approx(one.fingers[0].u_se_mm, rel=0.05)


def test_frames_fitted_in_worker_processes_are_the_same(inv, analytic_field, monkeypatch):
    """fit_frames on 2 processes, 5 frames per job: the same arrays as in this process, bit for
    bit, with a window reaching over the jobs' borders, per-frame states and seeds (a job that
    lost its place, or a window cut at a job's start, changes the frames after a border)."""
    import ectskin.inversion.frames as frames_mod

    monkeypatch.setattr(frames_mod, "FRAMES_PER_JOB", 5)
    pts = [(1.2, 18.4, 1.1, 0.0), (-7.5, 30.2, 0.0, 1.7), (6.0, 15.0, 0.7, 0.0)]
    y = np.concatenate([noisy(analytic_field.readout("front", *p), 6, 20 + k)
                        for k, p in enumerate(pts)])
    states = np.zeros((y.shape[0], 1))
    guess = FingerGuess("front", 0.0, 30.0, force_n=1.0)
    seeds = [[] if f % 4 else [[guess]] for f in range(y.shape[0])]
    for kw in ({"window": 3}, {"seeds": seeds}):
        one, _ = fit_frames(inv, y, states, **kw)
        two, sec = fit_frames(inv, y, states, workers=2, **kw)
        a, b = results_to_arrays(one), results_to_arrays(two)
        assert sec.shape == (y.shape[0],) and np.all(sec > 0)
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    with pytest.raises(EctskinError, match="workers"):
        fit_frames(inv, y, states, workers=0)


def test_relative_and_difference_readouts_give_the_same_fit(inv, analytic_field):
    y = noisy(analytic_field.readout("front", 6.0, 15.0, 0.7), 1, 2)[0]
    ref = analytic_field.untouched * 1.3  # any reference: Eq. 2 is undone with it
    a = inv.fit(y, STATE)
    b = inv.fit((y - ref) / ref, STATE, kind="relative", reference=ref)
    c = inv.fit(y - analytic_field.untouched, STATE, kind="difference")
    for other in (b, c):
        assert other.fingers[0].u_mm == pytest.approx(a.fingers[0].u_mm, abs=1e-7)
        assert other.fingers[0].force_n == pytest.approx(a.fingers[0].force_n, abs=1e-8)


def test_masked_channels_are_left_out(inv, analytic_field):
    """NaN channels (masked, in any frame of the window) are left out: the point comes back
    from the others, and the standard errors grow (less information)."""
    y = analytic_field.readout("front", 5.5, 31.0, 1.4)
    full = inv.fit(y, STATE)
    masked = y.copy()
    masked[[2, 7]] = np.nan
    window = np.stack([y, masked])
    one, two = (inv.fit(frame, STATE).fingers[0] for frame in (masked, window))
    for g in (one, two):
        np.testing.assert_allclose([g.u_mm, g.v_mm, g.force_n], [5.5, 31.0, 1.4], atol=1e-5)
    assert one.u_se_mm > full.fingers[0].u_se_mm
    assert two.u_se_mm == pytest.approx(one.u_se_mm / np.sqrt(2), rel=1e-6)  # two frames
    # the masked model is the same model on fewer channels: dropping them by hand agrees
    assert inv.model(STATE).masked(np.isfinite(masked)).n_pairs == y.size - 2


def test_bad_input_is_refused_at_the_door(inv, analytic_field):
    y = analytic_field.readout("front", 0.0, 20.0, 1.0)
    cases = [
        (lambda: inv.fit(y[:-1], STATE), "readouts must have shape"),
        (lambda: inv.fit(np.r_[y[:-1], np.inf], STATE), "must be finite or NaN"),
        (lambda: inv.fit(np.where(np.arange(y.size) < 9, np.nan, y), STATE), "too few"),
        (lambda: inv.fit(y, (10.0,)), "no response field for state [10.0]"),
        (lambda: inv.fit(y, STATE, kind="ratio"), "'kind'"),
        (lambda: inv.fit(y, STATE, kind="relative"), "needs the reference"),
        (lambda: inv.fit(y, STATE, kind="relative", reference=np.zeros(y.size)), "reference must"),
        (lambda: Inversion({}), "non-empty mapping"),
        (lambda: Inversion({STATE: analytic_field}, max_fingers=3), "max_fingers"),
        (lambda: Inversion({STATE: analytic_field}, drift=("tilt",)), "'drift'"),
        (lambda: Inversion({STATE: analytic_field}, push={STATE: np.ones((3, 2))}), "push"),
        (lambda: fit_frames(inv, y[None], STATE, window=0), "window"),
        (lambda: Inversion({STATE: analytic_field}, push_prior_sd=0.0), "push_prior_sd"),
        (lambda: Inversion({STATE: analytic_field}, model_error=0.1), "model_error"),
        (lambda: fit_frames(inv, y[None], np.zeros((2, 1))), "states"),
        (lambda: fit_frames(inv, y[None]), "states (the inflation"),
    ]
    for call, words in cases:
        with pytest.raises(EctskinError, match=None) as info:
            call()
        assert words in str(info.value), (words, str(info.value))
