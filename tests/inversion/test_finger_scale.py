"""The finger-size nuisance (``Inversion(finger_scale_sd=...)``): each finger's signal fitted as
(1 + a) Δ with a Gaussian prior on a.

References: frames made with a known scale from the closed-form field (``conftest``), the
Cramér–Rao bound of that model computed here from central differences of the field's readouts
with the scale's column Δ (not from the Jacobian the inversion uses), and direct solves of the
twin (``SensorModel.capacitance``) with a fingertip of another radius than the field's.
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import Inversion, results_to_arrays
from ectskin.inversion.fit import FINGER_SCALE_SD
from ectskin.twin import Touch
from ectskin.twin.bound import crb
from ectskin.twin.finger import Finger
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout

STATE = (0.0,)
NO_DRIFT = ReadoutConfig(drift_rel=0.0)


def scaled(field, face, u, v, f, g):
    return field.untouched + g * field.delta(face, u, v, f)


def bound_with_scale(field, face, u, v, f, g, prior_sd):
    """CRB std of (u, v, F, a) at the truth of the frame c_u + g Δ, gain and offset unknown,
    a's prior sd ``prior_sd``, from central differences of ``field.readout``."""
    x = np.array([u, v, f])
    cols = []
    for j, step in enumerate((1e-5, 1e-5, 1e-6)):
        e = np.zeros(3)
        e[j] = step
        cols.append(g * (field.delta(face, *(x + e)) - field.delta(face, *(x - e))) / (2 * step))
    J = np.stack(cols + [field.delta(face, u, v, f), field.untouched, np.ones(field.n_pairs)], 1)
    sigma = noise_pf(scaled(field, face, u, v, f, g), ReadoutConfig())
    return crb(J, sigma, nuisance_cols=[4, 5], prior_var={3: prior_sd**2}).std


def test_a_known_scale_comes_back_with_the_point(analytic_field):
    """Noise-free frames with the finger's signal scaled by 0.85 and 1.2 (a weak prior; every
    start tried, ``gate_p=0``: with a free scale a hovering finger explains a noise-free frame
    within the noise): the point, the force and the scale come back to the optimiser's
    tolerance; without the scale the same frames are fitted worse and their point or force
    moves."""
    inv = Inversion({STATE: analytic_field}, finger_scale_sd=10.0, gate_p=0.0)
    plain = Inversion({STATE: analytic_field})
    for u, v, f, g in [(3.3, 21.7, 1.1, 1.2), (-8.1, 40.2, 0.7, 0.85)]:
        y = scaled(analytic_field, "front", u, v, f, g)
        r = inv.fit(y, STATE)
        assert r.n_fingers == 1 and r.converged
        e = r.fingers[0]
        np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n, e.scale], [u, v, f, g], atol=1e-4)
        p = plain.fit(y, STATE).fingers[0]
        assert max(abs(p.force_n - f), np.hypot(p.u_mm - u, p.v_mm - v)) > 1e-2


def test_standard_errors_are_the_bound_with_the_scale_and_match_the_scatter(analytic_field):
    """With the scale's prior of the module (FINGER_SCALE_SD): the standard errors are the CRB
    of the model with the scale column and its prior (to 2 %: the fit's point differs from the
    truth by noise), wider in force than without the scale (force and size both grow the
    signal), and the scatter of 300 noisy frames' estimates matches them within 0.8-1.25 (the
    sample sd of 300 has a sampling error of 4 %)."""
    u, v, f, g = 1.4, 30.6, 0.9, 1.08
    inv = Inversion({STATE: analytic_field}, finger_scale_sd=FINGER_SCALE_SD)
    bound = bound_with_scale(analytic_field, "front", u, v, f, g, FINGER_SCALE_SD)
    c = scaled(analytic_field, "front", u, v, f, g)
    frames = readout(np.repeat(c[None], 300, 0), np.arange(300) / 30.0,
                     np.random.default_rng(5), NO_DRIFT, np.zeros(c.size))
    res = [inv.fit(y, STATE) for y in frames]
    assert all(r.n_fingers == 1 for r in res)
    a = results_to_arrays(res)
    se = np.c_[a["uv_se_mm"][:, 0], a["force_se_n"][:, 0], a["scale_se"][:, 0]]
    np.testing.assert_allclose(np.median(se, axis=0), bound, rtol=0.02)
    est = np.c_[a["uv_mm"][:, 0], a["force_n"][:, 0]]
    ratio = est.std(axis=0, ddof=1) / bound[:3]
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    plain = Inversion({STATE: analytic_field}).fit(frames[0], STATE).fingers[0]
    assert res[0].fingers[0].force_se_n > 1.05 * plain.force_se_n


def test_the_scale_option_is_checked(analytic_field):
    for bad in (0.0, -0.1, float("nan"), float("inf"), "0.1"):
        with pytest.raises(EctskinError, match="finger_scale_sd"):
            Inversion({STATE: analytic_field}, finger_scale_sd=bad)  # type: ignore[arg-type]
    r = Inversion({STATE: analytic_field}).fit(analytic_field.readout("front", 0.0, 20.0, 1.0),
                                                STATE)
    assert r.fingers[0].scale == 1.0 and r.fingers[0].scale_se == 0.0


def test_a_bigger_fingertip_is_located_better_with_the_scale(small_spec, small_field):
    """Direct solves with a 10 mm fingertip (the field's is 8 mm) at points between the nodes,
    noise-free: with the scale nuisance the points are closer to the truth than without, and
    the fitted scale is above 1 (a bigger fingertip couples more)."""
    st = small_spec.inflation_ml
    sensor = small_spec.sensor().with_fingers(Finger(radius_mm=10.0))
    # one finger at most: noise-free frames of another fingertip are not explained within the
    # noise by either model, and a second finger would soak up the mismatch
    with_scale = Inversion({st: small_field}, finger_scale_sd=FINGER_SCALE_SD, max_fingers=1)
    plain = Inversion({st: small_field}, max_fingers=1)
    rng = np.random.default_rng(2)
    err = {"scale": [], "plain": []}
    for _ in range(6):
        u, v, f = rng.uniform(-6.5, 6.5), rng.uniform(42.0, 58.0), rng.uniform(0.5, 1.8)
        c = sensor.capacitance(st, Touch("front", (u, v)), [f])[0]
        for name, inv in (("scale", with_scale), ("plain", plain)):
            r = inv.fit(c, st)
            assert r.n_fingers == 1
            e = r.fingers[0]
            err[name].append(np.hypot(e.u_mm - u, e.v_mm - v))
            if name == "scale":
                assert e.scale > 1.0, e
    assert np.mean(err["scale"]) < 0.7 * np.mean(err["plain"]), err
