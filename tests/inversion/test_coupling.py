"""Two fingers as coupled conductors (``ectskin.inversion.coupling``).

The closed form is checked against the matrix it abbreviates, −(G S⁻¹ Gᵀ − G Gᵀ), and its
derivatives against finite differences; the rank-one factor against an exact rank-one signal;
the model against a direct two-finger solve of the twin, where it must explain far more of what
superposition misses.
"""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.inversion import Inversion
from ectskin.inversion.coupling import correction, electrode_pairs, rank_one
from ectskin.twin import Touch
from ectskin.twin.readout import ReadoutConfig, readout

PAIRS = electrode_pairs(28)


def test_electrode_pairs_follow_the_layout_order():
    i, j = PAIRS
    assert list(zip(i[:8], j[:8])) == [(0, 1), (0, 2), (0, 3), (0, 4), (0, 5), (0, 6), (0, 7),
                                        (1, 2)]
    assert len(i) == 28 and electrode_pairs(15)[0].size == 15
    with pytest.raises(EctskinError, match="not the pairs"):
        electrode_pairs(27)


def test_rank_one_recovers_an_exact_factor():
    rng = np.random.default_rng(0)
    g = rng.uniform(0.01, 0.2, size=(5, 8))
    delta = -g[:, PAIRS[0]] * g[:, PAIRS[1]]
    np.testing.assert_allclose(rank_one(delta, PAIRS), g, rtol=1e-8)


def test_the_correction_is_the_coupled_conductors_schur_complement():
    rng = np.random.default_rng(1)
    ga, gb = rng.uniform(0.01, 0.2, size=(2, 8))
    dga, dgb = rng.normal(size=(2, 8, 3)) * 0.01
    i, j = PAIRS
    for rho in (0.0, 0.3, 0.8):
        c, da, db, drho = correction(ga, dga, gb, dgb, rho, PAIRS)
        G = np.stack([ga, gb], axis=1)
        full = G @ np.linalg.inv(np.array([[1.0, rho], [rho, 1.0]])) @ G.T - G @ G.T
        np.testing.assert_allclose(c, -full[i, j], rtol=1e-12, atol=1e-15)
        eps = 1e-6
        cp = correction(ga, dga, gb, dgb, rho + eps, PAIRS)[0]
        cm = correction(ga, dga, gb, dgb, rho - eps, PAIRS)[0] if rho else c
        step = 2 * eps if rho else eps
        np.testing.assert_allclose(drho, (cp - cm) / step, rtol=1e-4, atol=1e-9)
        for col in range(3):
            up = correction(ga + eps * dga[:, col], dga, gb + eps * dgb[:, col], dgb, rho, PAIRS)[0]
            dn = correction(ga - eps * dga[:, col], dga, gb - eps * dgb[:, col], dgb, rho, PAIRS)[0]
            np.testing.assert_allclose(da[:, col] + db[:, col], (up - dn) / (2 * eps),
                                       rtol=1e-5, atol=1e-12)
    assert np.all(correction(ga, dga, gb, dgb, 0.0, PAIRS)[0] == 0)


def test_the_coupled_model_explains_a_direct_two_finger_solve(small_spec, small_field):
    """Two fingers pressing 15 mm apart (a direct solve, one grounded conductor): their readout
    is well short of the sum of their signals (superposition misses about 40 %); the coupled
    model, with the field's own signals and ρ chosen best, misses under a quarter of that."""
    st = small_spec.inflation_ml
    a, b, fa, fb = (-4.0, 44.0), (5.0, 56.0), 1.0, 1.2
    with threadpool_limits(limits=1):
        c2 = small_spec.sensor().capacitance(
            st, (Touch("front", a), Touch("front", b)), np.array([[fa, fb]]))[0]
    m = Inversion({st: small_field}).model(st)
    xa, xb = np.array([*a, fa]), np.array([*b, fb])
    two = c2 - m.untouched
    summed = m.signal("front", "contact", xa)[0] + m.signal("front", "contact", xb)[0]
    keys = [("front", "contact")] * 2
    rhos = np.linspace(0.0, 0.9, 91)
    miss = [np.linalg.norm(two - summed - m.coupling(keys, [xa, xb], r)[0]) for r in rhos]
    best = int(np.argmin(miss))
    assert np.linalg.norm(two - summed) > 0.2 * np.linalg.norm(two)  # superposition misses
    assert miss[best] < 0.25 * np.linalg.norm(two - summed)
    assert 0.1 < rhos[best] < 0.7


def test_coupled_fit_of_superposed_fingers_finds_no_coupling(analytic_field):
    """Fingers that do superpose (the analytic skin's): the coupled fit finds ρ ≈ 0 and the
    same fingers as the superposition fit."""
    st = (0.0,)
    y = analytic_field.readout("front", -8.0, 20.0, 1.0) + analytic_field.delta("front", 7.0,
                                                                                40.0, 1.5)
    frame = readout(y[None], np.zeros(1), np.random.default_rng(3), ReadoutConfig(drift_rel=0.0),
                    np.zeros(y.size))[0]
    coupled = Inversion({st: analytic_field}, two_fingers="coupled").fit(frame, st)
    plain = Inversion({st: analytic_field}).fit(frame, st)
    assert coupled.n_fingers == plain.n_fingers == 2
    assert coupled.coupling < 0.05
    got = sorted((g.u_mm, g.v_mm) for g in coupled.fingers)
    np.testing.assert_allclose(got, sorted((g.u_mm, g.v_mm) for g in plain.fingers), atol=0.5)
    with pytest.raises(EctskinError, match="'two_fingers'"):
        Inversion({st: analytic_field}, two_fingers="sum")
