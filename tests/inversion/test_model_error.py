"""The field's model error from the fits' residuals (``ectskin.inversion.model_error``).

The estimator is checked on residuals drawn from its own variance model with known (a, r), and
on pure noise; the chain (fit, residuals, estimate, standard errors with it) on the flat skin
of ``conftest.AnalyticField`` whose frames carry a model error the inversion does not know: a
random share of each channel's signal, drawn per frame. There the readout noise's standard
errors cover few of the force's errors, and those with the estimated model error about as
many as a Gaussian's 1σ and 2σ do. The estimate reads readouts only; the labels are used only
to score the coverage.
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import Inversion, estimate_model_error, fit_frames
from ectskin.inversion.model_error import RunningModelError, ml_model_error, residuals
from ectskin.inversion.result import sandwich
from ectskin.twin.bound import crb
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout

STATE = (0.0,)
NO_DRIFT = ReadoutConfig(drift_rel=0.0)


def draws(a: float, r: float, n: int = 600, channels: int = 15, seed: int = 0):
    rng = np.random.default_rng(seed)
    sigma = rng.uniform(0.5e-4, 2e-4, (n, channels))
    signal = rng.uniform(-0.05, 0.05, (n, channels))
    e = rng.normal(0.0, np.sqrt(sigma**2 + a**2 + (r * signal) ** 2))
    return e, sigma, signal


@pytest.mark.parametrize("a, r", [(3e-4, 0.02), (0.0, 0.03), (5e-4, 0.0)])
def test_the_estimate_recovers_a_known_floor(a, r):
    e, s, d = draws(a, r)
    est = ml_model_error(e, s, d)
    # 9 000 channels: the variance parts come back within a few per cent; a part that is not
    # there holds a few per cent of the variance at most (the signal's rms is 0.05 / √3 pF)
    rms = 0.05 / np.sqrt(3)
    floor, share = est.a_pf**2, (est.r * rms) ** 2
    if a:
        assert est.a_pf == pytest.approx(a, rel=0.08)
    else:
        assert floor < 0.03 * share
    if r:
        assert est.r == pytest.approx(r, rel=0.08)
    else:
        assert share < 0.03 * floor
    assert est.chi2_per_channel_with == pytest.approx(1.0, abs=0.06)
    assert est.chi2_per_channel > 2.0
    assert (est.n_frames, est.n_channels) == (600, 9000)


def test_pure_noise_has_no_model_error():
    e, s, d = draws(0.0, 0.0)
    est = ml_model_error(e, s, d)
    assert est.a_pf < 0.2 * 0.5e-4 and est.r < 1e-3
    assert est.chi2_per_channel == pytest.approx(1.0, abs=0.05)


def test_channels_left_out_do_not_count():
    e, s, d = draws(3e-4, 0.02)
    e2 = e.copy()
    e2[:, 0] = np.nan  # a masked channel
    e2[5] = np.nan  # a frame with none
    est = ml_model_error(e2, s, d)
    assert (est.n_frames, est.n_channels) == (599, 599 * 14)
    assert est.r == pytest.approx(0.02, rel=0.1)


def test_bad_input_is_named():
    e, s, d = draws(0.0, 0.01, n=5)
    with pytest.raises(EctskinError, match="leverage must lie"):
        ml_model_error(e, s, d, np.full_like(e, 1.5))
    with pytest.raises(EctskinError, match="one shape"):
        ml_model_error(e, s[:, :3], d)
    with pytest.raises(EctskinError, match="residual must be"):
        ml_model_error(e[0], s, d)
    with pytest.raises(EctskinError, match="sigma must be > 0"):
        ml_model_error(e, -s, d)
    with pytest.raises(EctskinError, match="no finite channel"):
        ml_model_error(np.full_like(e, np.nan), s, d)
    with pytest.raises(EctskinError, match="bound_error"):
        Inversion({STATE: _Dummy()}, bound_error=(-1.0, 0.0))


class _Dummy:  # never reached: the option is checked first
    n_pairs = 3


#: the share of each channel's signal that the field does not model, drawn per frame
MODEL_SHARE = 0.03


def frames(field, n: int, seed: int):
    """``n`` pressed frames of ``field``'s front face with the model error, the twin's readout
    noise on top; their points and forces."""
    rng = np.random.default_rng(seed)
    (u0, u1), (v0, v1) = field.spec.window
    truth = np.column_stack([rng.uniform(u0 + 3, u1 - 3, n), rng.uniform(v0 + 3, v1 - 3, n),
                             rng.uniform(0.5, 1.8, n)])
    clean = np.array([field.readout("front", u, v, f) for u, v, f in truth])
    signal = clean - field.untouched
    c = clean + MODEL_SHARE * signal * rng.standard_normal(signal.shape)
    y = readout(c, np.arange(n) / 30.0, rng, NO_DRIFT, np.zeros(field.n_pairs))
    return y, truth


def test_the_force_error_bars_cover_with_the_estimated_model_error(analytic_field):
    inv = Inversion({STATE: analytic_field}, max_fingers=1)
    # estimated on frames of their own (readouts only), scored on others
    y_est, _ = frames(analytic_field, 200, seed=1)
    est = estimate_model_error(inv, y_est, STATE)
    assert est.r == pytest.approx(MODEL_SHARE, rel=0.2)
    assert est.chi2_per_channel > 20 and est.chi2_per_channel_with == pytest.approx(1, abs=0.2)
    y, truth = frames(analytic_field, 300, seed=2)
    plain, _ = fit_frames(inv, y, STATE)
    widened, _ = fit_frames(inv.with_bound_error(est.floor), y, STATE)
    cover = {}
    for name, res in (("plain", plain), ("widened", widened)):
        assert all(r.n_fingers == 1 for r in res)
        press = np.array([r.fingers[0].contact for r in res])
        assert press.mean() > 0.9  # the rest fitted hovering: no force to score
        f = np.array([[r.fingers[0].force_n, r.fingers[0].force_se_n] for r in res])[press]
        z = np.abs(f[:, 0] - truth[press, 2]) / f[:, 1]
        cover[name] = (np.mean(z < 1), np.mean(z < 2))
    # the fits themselves are the same; only their standard errors differ
    np.testing.assert_array_equal([r.fingers[0].u_mm for r in plain],
                                  [r.fingers[0].u_mm for r in widened])
    # the readout noise's point standard error stays, and is the plain one's
    noise_se = [r.fingers[0].point_se_noise_mm for r in widened]
    np.testing.assert_array_equal(noise_se, [r.fingers[0].point_se_noise_mm for r in plain])
    np.testing.assert_allclose(noise_se, [np.hypot(r.fingers[0].u_se_mm, r.fingers[0].v_se_mm)
                                          for r in plain], rtol=1e-12)
    assert all(np.hypot(w.fingers[0].u_se_mm, w.fingers[0].v_se_mm) > n
               for w, n in zip(widened, noise_se))
    assert cover["plain"][1] < 0.5
    assert 0.55 < cover["widened"][0] < 0.85 and cover["widened"][1] > 0.88


def test_residuals_are_the_frame_less_the_fit(analytic_field):
    """By hand: a noise-free frame of the model itself leaves residuals at the optimiser's
    tolerance; the signal is the frame less the untouched readout; σ the readout's noise."""
    inv = Inversion({STATE: analytic_field}, max_fingers=1)
    y = analytic_field.readout("front", 2.0, 30.0, 1.1)[None]
    res, _ = fit_frames(inv, y, STATE)
    e, s, d, h = residuals(inv, y, STATE, res)
    assert np.max(np.abs(e)) < 1e-6 * np.max(np.abs(d))
    np.testing.assert_allclose(d[0], y[0] - analytic_field.untouched)
    np.testing.assert_allclose(s[0], noise_pf(y[0], ReadoutConfig()))
    with pytest.raises(EctskinError, match="one of each per frame"):
        residuals(inv, y, STATE, res + res)
    # a bare number is the one-chamber state; a state array of the wrong rank is named
    np.testing.assert_array_equal(residuals(inv, y, 0.0, res)[0], e)
    with pytest.raises(EctskinError, match="states must be"):
        residuals(inv, y, np.zeros((1, 1, 1)), res)


def test_the_running_estimate_is_the_batch_estimate_of_its_window():
    """By the batch estimator: the running estimate appears after ``first`` frames, is renewed
    after every ``every`` more, and is each time :func:`ml_model_error` of exactly the last
    ``window`` frames (an off-by-one in the window or the schedule changes the numbers)."""
    e, s, d = draws(3e-4, 0.02, n=260, seed=3)
    h = np.random.default_rng(4).uniform(0.0, 0.6, e.shape)
    run = RunningModelError(first=100, every=70, window=150)
    made = [run.add(e[i], s[i], d[i], h[i]) for i in range(260)]
    assert [i for i, m in enumerate(made) if m] == [99, 169, 239]
    want = ml_model_error(e[240 - 150:240], s[240 - 150:240], d[240 - 150:240],
                          h[240 - 150:240])
    assert run.estimate == want and run.n_added == 260
    assert run.estimate.r == pytest.approx(0.02, rel=0.2)
    first = RunningModelError(first=100, every=70, window=150)
    for i in range(100):
        first.add(e[i], s[i], d[i], h[i])
    assert first.estimate == ml_model_error(e[:100], s[:100], d[:100], h[:100])
    first.reset()
    assert first.estimate is None and first.n_added == 0


def test_the_running_estimate_waits_for_a_channel_and_names_bad_frames():
    run = RunningModelError(first=2, every=1, window=5)
    nan = np.full(4, np.nan)
    assert not run.add(nan, nan, nan, nan) and not run.add(nan, nan, nan, nan)
    assert run.estimate is None  # every channel masked so far
    with pytest.raises(EctskinError, match=r"channels \(4,\), got shapes"):
        run.add(np.zeros(3), np.ones(3), np.zeros(3), np.zeros(3))
    with pytest.raises(EctskinError, match="window"):
        RunningModelError(first=10, window=5)
    with pytest.raises(EctskinError, match="every must be"):
        RunningModelError(every=0)


def test_the_sandwich_is_the_weighted_fits_own_scatter():
    """By simulation: a linear fit weighted by σ of readouts that scatter by a wider, uneven
    spread, with a Gaussian prior on one column. The sandwich's standard errors are the scatter
    of the fitted parameters over many draws (within the Monte Carlo error), exceed the bound
    of the spread alone (which only weights by the spread reach), and equal the plain bound
    where the spread is σ."""
    rng = np.random.default_rng(5)
    J = rng.normal(size=(28, 5))
    sigma = rng.uniform(0.5, 1.5, 28)
    spread = sigma * rng.uniform(1.0, 4.0, 28)
    prior = {4: 0.3**2}
    cols = [0, 1, 2]
    ok = np.ones(3, bool)
    got = sandwich(J, sigma, spread, prior, cols, ok)
    # the fit: weighted least squares with the prior as one more row, over 20 000 draws
    theta = rng.normal(size=5)
    A = np.vstack([J / sigma[:, None], np.eye(5)[4] / 0.3])
    draws = 20000
    y = J @ theta + rng.normal(size=(draws, 28)) * spread
    z = np.hstack([y / sigma, np.full((draws, 1), theta[4] / 0.3)
                   + rng.normal(size=(draws, 1))])  # the prior's centre scatters by its sd
    fits = np.linalg.lstsq(A, z.T, rcond=None)[0].T
    np.testing.assert_allclose(fits[:, cols].std(axis=0), got, rtol=0.03)
    gls = crb(J, spread, prior_var=prior, nuisance_cols=[3, 4]).std
    assert np.all(got > gls)
    np.testing.assert_allclose(sandwich(J, sigma, sigma, prior, cols, ok),
                               crb(J, sigma, prior_var=prior, nuisance_cols=[3, 4]).std,
                               rtol=1e-9)
    assert np.isinf(sandwich(J, sigma, spread, prior, cols, np.array([True, False, True]))[1])
    with pytest.raises(EctskinError, match="prior variances must be > 0"):
        sandwich(J, sigma, spread, {4: 0.0}, cols, ok)
