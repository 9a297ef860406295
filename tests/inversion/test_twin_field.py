"""The inversion through a small response field of the twin, against direct solves.

Frames are made by ``SensorModel.capacitance`` (the twin's ground truth) at points, forces and
heights between the field's nodes, so the inversion sees the field's interpolation error as well
as the readout noise. ``small_field`` (conftest): 16 × 20 mm of the front face on a 2 mm grid,
5 forces, 4 heights, the coarse mesh.
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import Inversion, fit_frames, invert_recording, push_basis
from ectskin.inversion.model import spline_signal
from ectskin.io.recording import Recording, Trial
from ectskin.twin import Touch
from ectskin.twin.bound import DEFAULT_PUSH_LOADS, crb
from ectskin.twin.mechanics import Handling
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout

NO_DRIFT = ReadoutConfig(drift_rel=0.0)


@pytest.fixture(scope="module")
def sensor(small_spec):
    return small_spec.sensor()


@pytest.fixture(scope="module")
def inv(small_spec, small_field):
    return Inversion({small_spec.inflation_ml: small_field})


def test_the_fast_evaluation_is_the_fields_interpolant(small_field):
    """The inversion evaluates the field's splines itself (rebuilt from the node values): the
    same values and slopes as ``ResponseField.delta`` / ``jacobian``, at random points, in
    both modes (hovering, the slope in ln h is h · ∂/∂h)."""
    rng = np.random.default_rng(0)
    for mode in ("contact", "hover"):
        signal = spline_signal(small_field, "front", mode)
        for _ in range(20):
            u, v = rng.uniform(-8, 8), rng.uniform(40, 60)
            if mode == "contact":
                f = rng.uniform(0.3, 2.0)
                ref, J = small_field.delta("front", u, v, f), small_field.jacobian("front", u, v, f)
                s = f
                J = J[:, :3]
            else:
                h = float(np.exp(rng.uniform(0.0, np.log(8.0))))
                ref = small_field.delta("front", u, v, 0.0, h)
                J4 = small_field.jacobian("front", u, v, 0.0, h)
                J, s = np.c_[J4[:, :2], J4[:, 3] * h], np.log(h)
            d, dj = signal(np.array([u, v, s]))
            np.testing.assert_allclose(d, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
            np.testing.assert_allclose(dj, J, rtol=0, atol=1e-10 * np.abs(J).max())


def test_points_between_the_nodes_are_recovered_from_direct_solves(small_spec, sensor, inv):
    """Noise-free direct solves at random points, forces and heights off the nodes. Tolerance:
    0.15 mm, 0.03 N, 0.15 mm of height: a wrong node or mode would be off by a grid step (2 mm)
    or more, and the field's interpolation error between nodes (its acceptance bound) moves the
    fit by about the noise's own effect, one to three bounds of one frame (0.02-0.1 mm here)."""
    rng = np.random.default_rng(11)
    st = small_spec.inflation_ml
    for k in range(12):
        u, v = rng.uniform(-7.5, 7.5), rng.uniform(40.5, 59.5)
        if k % 4 == 3:
            h = float(np.exp(rng.uniform(np.log(1.2), np.log(7.0))))
            f = 0.0
            c = sensor.capacitance(st, Touch("front", (u, v)), [0.0], heights_mm=[h])[0]
        else:
            f, h = rng.uniform(0.35, 1.95), 0.0
            c = sensor.capacitance(st, Touch("front", (u, v)), [f])[0]
        r = inv.fit(c, st)
        assert r.n_fingers == 1, (u, v, f, h, r.bic_by_count)
        g = r.fingers[0]
        assert g.contact == (h == 0)
        assert np.hypot(g.u_mm - u, g.v_mm - v) < 0.15, (u, v, g)
        assert abs(g.force_n - f) < 0.03 and abs(g.height_mm - h) < 0.15, (f, h, g)


def test_scatter_over_noisy_direct_solves_is_near_the_bound(small_spec, small_field, sensor, inv):
    """200 noisy frames (the twin's readout electronics) of one direct solve: the scatter of the
    estimates is the bound of the field's model at the point, within 0.75-1.33: the sample
    standard deviation of 200 has a sampling error of 5 % (±15 % at 3 sd), and the bound here
    uses the field's slopes at the truth while the fit moves on the interpolant around the
    biased point (off by about one bound), whose slopes differ by some per cent more."""
    st = small_spec.inflation_ml
    u, v, f = 2.7, 47.3, 1.1
    c = sensor.capacitance(st, Touch("front", (u, v)), [f])[0]
    frames = readout(np.repeat(c[None], 200, 0), np.arange(200) / 30, np.random.default_rng(4),
                     NO_DRIFT, np.zeros(c.size))
    est = np.array([[g.u_mm, g.v_mm, g.force_n] for g in
                    (inv.fit(y, st).fingers[0] for y in frames)])
    J = np.c_[small_field.jacobian("front", u, v, f)[:, :3], small_field.untouched,
              np.ones(small_field.n_pairs)]
    bound = crb(J, noise_pf(c, ReadoutConfig()), nuisance_cols=[3, 4]).std
    ratio = est.std(axis=0, ddof=1) / bound
    assert np.all((ratio > 0.75) & (ratio < 1.33)), ratio


def test_counts_on_twin_frames(small_spec, small_field, sensor, inv):
    """No finger on the untouched state, one on a direct solve, two on the superposition of two
    direct solves' signals (the model's two fingers, their fingertips 18.6 mm apart: closer than
    two radii they would overlap, and the fit does not answer so), all with the readout's
    noise."""
    st = small_spec.inflation_ml
    rng = np.random.default_rng(2)
    c_u = small_field.untouched
    a = sensor.capacitance(st, Touch("front", (-5.5, 42.5)), [1.0])[0]
    b = sensor.capacitance(st, Touch("front", (5.5, 57.5)), [1.4])[0]

    def noisy(c):
        return readout(c[None], np.zeros(1), rng, NO_DRIFT, np.zeros(c.size))[0]

    assert inv.fit(noisy(c_u), st).n_fingers == 0
    assert inv.fit(noisy(a), st).n_fingers == 1
    two = inv.fit(noisy(a + b - c_u), st)
    assert two.n_fingers == 2, two.bic_by_count
    got = sorted((g.u_mm, g.v_mm) for g in two.fingers)
    np.testing.assert_allclose(got, [(-5.5, 42.5), (5.5, 57.5)], atol=0.5)


def test_the_push_basis_spans_a_push_it_was_not_built_from(small_spec, small_field, sensor):
    """A push between the basis' loads (z = 75 mm, a direction between x and y, 0.4 N: a direct
    solve) moves the readouts almost wholly within the basis' span (3 of the 9 loads'
    directions): what it misses is under 10 % of the change and below one frame's noise (its
    whitened squared norm under n_pairs, the noise's expected χ²)."""
    P = push_basis(small_field)
    assert P.shape == (small_field.n_pairs, 3)
    direction = np.array([0.6, 0.8, 0.0])
    h = Handling(push=Touch("right", (0.0, 75.0)), push_force_n=(0.4 * direction)[None])
    change = sensor.capacitance(small_spec.inflation_ml, None, np.zeros(1), h)[0] - small_field.untouched
    sigma = noise_pf(small_field.untouched, ReadoutConfig())
    Pw, cw = P / sigma[:, None], change / sigma
    rest = cw - Pw @ np.linalg.lstsq(Pw, cw, rcond=None)[0]
    assert np.linalg.norm(rest) < 0.1 * np.linalg.norm(cw)
    assert rest @ rest < small_field.n_pairs
    assert np.linalg.norm(cw) > 10  # the push is seen: tens of noise units
    assert len(DEFAULT_PUSH_LOADS) == 9


def test_a_pushed_frame_is_inverted_with_the_push_nuisance(small_spec, small_field, sensor):
    """A press while the hand pushes (a direct solve with both): with the push columns the
    point comes back within 0.3 mm and 0.05 N; the fit without them is worse."""
    st = small_spec.inflation_ml
    u, v, f = -2.4, 46.1, 1.2
    h = Handling(push=Touch("right", (0.0, 90.0)), push_force_n=np.array([[0.3, 0.2, 0.0]]))
    c = sensor.capacitance(st, Touch("front", (u, v)), [f], h)[0]
    with_push = Inversion({st: small_field}, push={st: push_basis(small_field)}).fit(c, st)
    without = Inversion({st: small_field}).fit(c, st)
    g = with_push.fingers[0]
    assert np.hypot(g.u_mm - u, g.v_mm - v) < 0.3 and abs(g.force_n - f) < 0.05, g
    assert with_push.log_likelihood > without.log_likelihood


def test_invert_recording(small_spec, small_field, sensor, layout):
    """Trials at the field's state, arrays in trial order; a trial at a state without a field
    is refused naming the state."""
    st = small_spec.inflation_ml
    rng = np.random.default_rng(9)
    c_u = small_field.untouched[None]
    press = sensor.capacitance(st, Touch("front", (1.3, 52.6)), [0.5, 1.5])
    caps = {"rest": np.repeat(c_u, 3, 0), "press": press}
    trials = [Trial(name, readout(c, np.arange(len(c)) / 30, rng, NO_DRIFT, np.zeros(c.shape[1])),
                    np.arange(len(c)) / 30.0, np.zeros(len(c), np.int16), inflation=st)
              for name, c in caps.items()]
    rec = Recording(layout, trials, 30.0)
    out = invert_recording({st: small_field}, rec)
    assert out["n_fingers"].tolist() == [0, 0, 0, 1, 1]
    assert out["trial"].tolist() == [0, 0, 0, 1, 1] and out["frame"].tolist() == [0, 1, 2, 0, 1]
    np.testing.assert_allclose(out["uv_mm"][3:, 0], [[1.3, 52.6]] * 2, atol=0.15)
    np.testing.assert_allclose(out["force_n"][3:, 0], [0.5, 1.5], atol=0.03)
    assert np.all(np.isnan(out["force_n"][:3])) and np.all(out["face"][3:, 0] == "front")
    assert out["seconds"].shape == (5,) and np.all(out["converged"])
    res, sec = fit_frames(Inversion({st: small_field}), rec)
    assert [r.n_fingers for r in res] == out["n_fingers"].tolist() and sec.shape == (5,)
    only = invert_recording({st: small_field}, rec, trials=["press"])
    assert only["trial"].tolist() == [1, 1]
    other = Recording(layout, [Trial("t", c_u, [0.0], [0], inflation=(0.0, 0.0, 0.0))], 30.0)
    with pytest.raises(EctskinError, match=r"no response field for state \[0.0, 0.0, 0.0\]"):
        invert_recording({st: small_field}, other)
    with pytest.raises(EctskinError, match="no trial 'nope'"):
        invert_recording({st: small_field}, rec, trials=["nope"])
