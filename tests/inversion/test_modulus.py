"""The pulp-modulus nuisance (``Inversion(modulus={state: table})``): each pressing finger's
signal fitted as Δ + x M, x = ln(E / E0), M from a :class:`ModulusTable`, prior sd 0.40.

References: a modulus table of the closed-form skin (``conftest``) whose column is known in
closed form at its nodes (a softer pulp presses deeper, as a larger force does, and spreads the
pad: a blur of the signal), interpolated for the frames by scipy's cubic
``RegularGridInterpolator`` with a direct solver (not the inversion's own spline); the
Cramér–Rao bound of that model from central differences of the field's readouts and of that
interpolant; and results of the inversion captured before the option existed (the default path
must stay bit-identical).

One person's finger pooled over frames (:func:`ectskin.inversion.person.pool_fingers`) and the
frames refitted with it (``Inversion.fit(finger=)``, ``fit_frames(person=)``), against: the
Gaussian product worked by hand; the linearised posterior mode of a fit with a prior centred off
0, (w_d x + w_p c) / (w_d + w_p); the ``modulus_prior_sd`` path (a prior centred at 0 given per
call gives the same fit bit for bit); and the truth of frames made with a known pulp, which the
frames' own fits, each pulled to 0 by the population's prior, miss.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator
from scipy.sparse.linalg import spsolve

from ectskin._check import EctskinError
from ectskin.inversion import (
    FingerEstimate,
    Inversion,
    InversionResult,
    fit_frames,
    results_to_arrays,
)
from ectskin.inversion.finger_nuisance import MODULUS_PRIOR_SD, TableColumns
from ectskin.inversion.person import FingerPool, pool_fingers
from ectskin.twin.bound import crb
from ectskin.twin.bound_modulus import ModulusTable
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout

STATE = (0.0,)
NO_DRIFT = ReadoutConfig(drift_rel=0.0)
#: the blur's step (mm) and the column's two parts' weights
BLUR_MM, PAD, SPREAD = 3.0, 0.5, 0.6


def closed_form_column(field, u, v, f):
    """∂C/∂ln E of the closed-form skin's finger (model of this test): a softer pulp (x < 0)
    presses deeper, as a larger force does (Hertz: −F ∂Δ/∂F × PAD), and spreads its pad (−the
    signal's discrete Laplacian over BLUR_MM × SPREAD)."""
    d0 = field.delta("front", u, v, f)
    lap = sum(field.delta("front", u + a, v + b, f) for a, b in
              ((BLUR_MM, 0), (-BLUR_MM, 0), (0, BLUR_MM), (0, -BLUR_MM))) - 4 * d0
    return -PAD * f[..., None] * field.jacobian("front", u, v, f)[..., 2] - SPREAD * lap


@pytest.fixture(scope="module")
def table(analytic_field):
    (ulo, uhi), (vlo, vhi) = analytic_field.spec.window
    u, v = np.linspace(ulo, uhi, 10), np.linspace(vlo, vhi, 15)
    forces = np.exp(np.linspace(*np.log(analytic_field.spec.force_range_n), 6))
    U, V, F = np.meshgrid(u, v, forces, indexing="ij")
    return ModulusTable({"front": (u, v)}, forces,
                        {"front": closed_form_column(analytic_field, U, V, F)}, 0.1)


@pytest.fixture(scope="module")
def reference(table):
    """The table's cubic interpolant in (u, v, ln F), scipy's with a direct solve: M at x."""
    u, v = table.nodes["front"]
    rgi = RegularGridInterpolator((u, v, np.log(table.forces_n)), table.values["front"],
                                  method="cubic", solver=spsolve)
    return lambda x: rgi(np.r_[x[0], x[1], np.log(x[2])][None])[0]


def frame(field, reference, u, v, f, x):
    return field.readout("front", u, v, f) + x * reference(np.array([u, v, f]))


def test_the_columns_are_the_tables_interpolant_with_its_slopes(analytic_field, table, reference):
    """TableColumns against scipy's cubic grid interpolant (direct solve) to 1e-9 of the
    column's size inside the nodes, the slopes against its central differences (to 1e-5); beyond
    the nodes the nearest node plane, flat across it."""
    cols = TableColumns(table, analytic_field.n_pairs, ("front",), "test")
    rng = np.random.default_rng(3)
    scale = np.abs(table.values["front"]).max()
    for _ in range(10):
        x = np.array([rng.uniform(-18, 18), rng.uniform(2, 58), np.exp(rng.uniform(*np.log((0.3, 2.0))))])
        M, dM = cols("front", x)
        np.testing.assert_allclose(M, reference(x), rtol=0, atol=1e-9 * scale)
        steps = (1e-4, 1e-4, 1e-6)
        fd = np.stack([(reference(x + h) - reference(x - h)) / (2 * s)
                       for h, s in zip(np.diag(steps), steps)], -1)
        np.testing.assert_allclose(dM, fd, rtol=0, atol=1e-5 * np.abs(fd).max())
    M_out, dM_out = cols("front", np.array([25.0, 30.0, 1.0]))
    np.testing.assert_allclose(M_out, reference(np.array([18.0, 30.0, 1.0])), atol=1e-9 * scale)
    assert np.all(dM_out[:, 0] == 0) and np.any(dM_out[:, 1] != 0)


def test_a_known_modulus_comes_back_where_the_plain_fit_is_biased(analytic_field, table,
                                                                  reference):
    """Noise-free frames of a softer and a stiffer pulp (x = ∓0.5): with the modulus the point,
    the force and x come back to 1e-3 (a weak prior: it pulls x towards 0 by less); without it the
    force is off by more than 0.05 N."""
    inv = Inversion({STATE: analytic_field}, modulus={STATE: table}, modulus_prior_sd=1e3,
                    gate_p=0.0)
    plain = Inversion({STATE: analytic_field}, gate_p=0.0)
    for u, v, f, x in [(3.3, 21.7, 1.1, -0.5), (-8.1, 40.2, 0.7, 0.5)]:
        y = frame(analytic_field, reference, u, v, f, x)
        r = inv.fit(y, STATE)
        assert r.n_fingers == 1 and r.converged and r.fingers[0].contact
        e = r.fingers[0]
        np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n, e.modulus_ln], [u, v, f, x],
                                   atol=1e-3)
        p = plain.fit(y, STATE).fingers[0]
        assert abs(p.force_n - f) > 0.05, p


def bound_with_modulus(field, reference, u, v, f, x, prior_sd):
    """CRB std of (u, v, F, x) at the truth, gain and offset unknown, x's prior sd
    ``prior_sd``: central differences of the field's readout and the reference interpolant."""
    p = np.array([u, v, f])
    cols = []
    for j, step in enumerate((1e-4, 1e-4, 1e-5)):
        e = np.zeros(3)
        e[j] = step
        cols.append((frame(field, reference, *(p + e), x) - frame(field, reference, *(p - e), x))
                    / (2 * step))
    J = np.stack(cols + [reference(p), field.untouched, np.ones(field.n_pairs)], 1)
    sigma = noise_pf(frame(field, reference, u, v, f, x), ReadoutConfig())
    return crb(J, sigma, nuisance_cols=[4, 5], prior_var={3: prior_sd**2}).std


def test_standard_errors_are_the_bound_and_the_force_within_them(analytic_field, table,
                                                                 reference):
    """With the twin's prior (0.40), a pulp of x = 0.4: the standard errors of (u, v, F, x) are
    the CRB of the model with the modulus column and its prior (to 3 %), the force's wider than
    without it; the noise-free frame's fit is within one standard error of the truth in force
    and x (the prior pulls x towards 0, and the force with it, by a fraction of that); 200
    noisy frames scatter as the standard errors say (0.75-1.33) around that fit (their mean
    within 3.5 standard errors of the mean); the plain fit misses the force by more than 5 of
    its own standard errors."""
    u, v, f, x = 1.4, 30.6, 0.9, 0.4
    inv = Inversion({STATE: analytic_field}, modulus={STATE: table}, max_fingers=1)
    plain = Inversion({STATE: analytic_field}, max_fingers=1)
    bound = bound_with_modulus(analytic_field, reference, u, v, f, x, MODULUS_PRIOR_SD)
    c = frame(analytic_field, reference, u, v, f, x)

    def fit(inv, y):
        e = inv.fit(y, STATE).fingers[0]
        return ([e.u_mm, e.v_mm, e.force_n, e.modulus_ln],
                [e.u_se_mm, e.v_se_mm, e.force_se_n, e.modulus_ln_se])

    centre, _ = fit(inv, c)
    assert abs(centre[2] - f) < bound[2] and abs(centre[3] - x) < bound[3], (centre, bound)
    p = plain.fit(c, STATE).fingers[0]
    assert abs(p.force_n - f) > 5 * p.force_se_n, p
    assert bound[2] > 1.05 * p.force_se_n
    frames = readout(np.repeat(c[None], 200, 0), np.arange(200) / 30.0,
                     np.random.default_rng(5), NO_DRIFT, np.zeros(c.size))
    est, se = (np.array(a) for a in zip(*(fit(inv, y) for y in frames)))
    np.testing.assert_allclose(np.median(se, axis=0), bound, rtol=0.03)
    ratio = est.std(axis=0, ddof=1) / bound
    assert np.all((ratio > 0.75) & (ratio < 1.33)), ratio
    assert np.all(np.abs(est.mean(axis=0) - centre) < 3.5 * bound / np.sqrt(200)), est.mean(0)


# ------------------------------------------------------------------ the default path
#: results of the inversion on two fixed frames of the closed-form skin (one finger pressing;
#: one pressing and one hovering), captured from the code before the modulus option existed
#: (commit 9e2f552; captured again with hovering above the field's top,
#: :mod:`ectskin.inversion.far`, which moves the fits by ~1e-6): (count, float.hex of the
#: log-likelihood, BIC, BIC per count, nuisances, then per finger u, v, F, h, their standard
#: errors, scale, scale_se)
GOLDEN = {
    "plain": [
        (1, (
            "0x1.f2b4d04a5fec0p+6", "-0x1.d7a03482bf51ep+7", "0x1.ba15c3083710bp+16",
            "-0x1.d7a03482bf51ep+7", "inf", "-0x1.45645b78c788fp-12", "0x1.c5c23ab400831p-17",
            "0x1.a6ed4add9e767p+1", "0x1.5db40be780de0p+4", "0x1.175dc5b4ac2efp+0", "0x0.0p+0",
            "0x1.cfdef493026c8p-6", "0x1.15f52e056df3cp-3", "0x1.0dd8c5865a99cp-5", "0x0.0p+0",
            "0x1.0000000000000p+0", "0x0.0p+0",
        )),
        (2, (
            "0x1.efed46103ef5cp+6", "-0x1.c499199da4658p+7", "0x1.997ae61b38487p+17",
            "0x1.9a1da075eba78p+14", "-0x1.c499199da4658p+7", "0x1.1470075bb5c69p-10",
            "-0x1.67e8dbdf9b7b9p-13", "-0x1.f72ca831a9e1fp+2", "0x1.3dec7200bc650p+5",
            "0x1.4d784585f1b96p-1", "0x0.0p+0", "0x1.081a9db82ea39p-2", "0x1.e562b9b268814p-3",
            "0x1.a073e51219d2cp-5", "0x0.0p+0", "0x1.0000000000000p+0", "0x0.0p+0",
            "0x1.22fbd328b6098p+3", "0x1.613b402565ce7p+3", "0x0.0p+0", "0x1.dbb318c996ddfp+0",
            "0x1.283ee4b49f503p-3", "0x1.8c2c4c34555ebp-1", "0x0.0p+0", "0x1.0f923d99f8d61p-3",
            "0x1.0000000000000p+0", "0x0.0p+0",
        )),
    ],
    "scale": [
        (1, (
            "0x1.f43517799c854p+6", "-0x1.d3b5f623a8991p+7", "0x1.ba15c3083710bp+16",
            "-0x1.d3b5f623a8991p+7", "inf", "-0x1.5862017717510p-12", "-0x1.237eff612326ep-15",
            "0x1.a757ed6d44364p+1", "0x1.5ece890dbb574p+4", "0x1.27c1ca1e26136p+0", "0x0.0p+0",
            "0x1.d37de7abc1306p-6", "0x1.4051d72ecac6ap-3", "0x1.4db3eb106a562p-4", "0x0.0p+0",
            "0x1.fc6746f67bb5ep-1", "0x1.081fc1c9eb8f9p-7",
        )),
        (2, (
            "0x1.f466562b9e693p+6", "-0x1.be3d1e9c5d34ep+7", "0x1.997ae61b38487p+17",
            "0x1.0c4faca53b138p+14", "-0x1.be3d1e9c5d34ep+7", "0x1.54d8dd80907eep-10",
            "-0x1.eb00290b422a8p-12", "-0x1.eeef7d5e4e3afp+2", "0x1.3d48886dfb9acp+5",
            "0x1.3ceb58aa4755ep+0", "0x0.0p+0", "0x1.22b0c9a2898a4p-2", "0x1.4fa28e042dc80p-2",
            "0x1.5615d0df6b0f7p-1", "0x0.0p+0", "0x1.dd02a3a902c0ap-1", "0x1.1cfb5b2b94d2fp-4",
            "0x1.1eba9c9940517p+3", "0x1.b3cbce15fcf0fp+3", "0x0.0p+0", "0x1.b62fcd727a3b7p+0",
            "0x1.6fd90150b434bp-3", "0x1.c42606de77787p+0", "0x0.0p+0", "0x1.d9409d63b96cfp-2",
            "0x1.e07a1943c7d34p-1", "0x1.363bc1ad280ffp-4",
        )),
    ],
    "coupled": [
        (1, (
            "0x1.f2b4d04a5fec0p+6", "-0x1.d7a03482bf51ep+7", "0x1.ba15c3083710bp+16",
            "-0x1.d7a03482bf51ep+7", "-0x1.7925c60e1d8e0p+7", "-0x1.45645b78c788fp-12",
            "0x1.c5c23ab400831p-17", "0x1.a6ed4add9e767p+1", "0x1.5db40be780de0p+4",
            "0x1.175dc5b4ac2efp+0", "0x0.0p+0", "0x1.cfdef493026c8p-6", "0x1.15f52e056df3cp-3",
            "0x1.0dd8c5865a99cp-5", "0x0.0p+0", "0x1.0000000000000p+0", "0x0.0p+0",
        )),
        (2, (
            "0x1.f3092e0ea6583p+6", "-0x1.c24a7c0db875fp+7", "0x1.997ae61b38487p+17",
            "0x1.9a1da075eba78p+14", "-0x1.c24a7c0db875fp+7", "0x1.c09b22c4357a7p-10",
            "-0x1.4d92add8854d5p-12", "-0x1.09ed4366474e9p+3", "0x1.3e5315c9fcd41p+5",
            "0x1.977adbcc06a46p-1", "0x0.0p+0", "0x1.c973f9fcf1fdap-2", "0x1.ea072c88cd9dbp-3",
            "0x1.1ed087b6a97e4p-3", "0x0.0p+0", "0x1.0000000000000p+0", "0x0.0p+0",
            "0x1.1c1e4e4375823p+3", "0x1.98404fa72b96ap+3", "0x0.0p+0", "0x1.e514e2bafde9ap+0",
            "0x1.b3921ab3c8b02p-3", "0x1.6ff9138fcc79ap+0", "0x0.0p+0", "0x1.813e401e62a76p-4",
            "0x1.0000000000000p+0", "0x0.0p+0",
        )),
    ],
}
GOLDEN_CONFIGS = {"plain": {}, "scale": {"finger_scale_sd": 0.12, "press_check": True},
                  "coupled": {"two_fingers": "coupled", "gate_p": 0.0}}


def golden_frames(field):
    """The two frames the golden results were captured on (seeded noise)."""
    rng = np.random.default_rng(7)
    y1 = field.readout("front", 3.3, 21.7, 1.1)
    y1 = y1 + rng.normal(0, noise_pf(y1, ReadoutConfig()))
    y2 = (field.readout("front", -8.1, 40.2, 0.7) + field.readout("front", 9.0, 12.0, 0.0, 2.0)
          - field.untouched)
    return y1, y2 + rng.normal(0, noise_pf(y2, ReadoutConfig()))


def digest(r):
    vals = [r.log_likelihood, r.bic, *r.bic_by_count, *r.nuisance.values()]
    for e in r.fingers:
        vals += [e.u_mm, e.v_mm, e.force_n, e.height_mm, e.u_se_mm, e.v_se_mm, e.force_se_n,
                 e.height_se_mm, e.scale, e.scale_se]
    return r.n_fingers, np.array(vals)


def test_the_default_path_is_unchanged(analytic_field, table):
    """Without ``modulus`` (and with a table for another state only) the fits of the golden
    frames are the results captured before the option (to 1e-9: the same arithmetic, so the
    same bits on the machine they were captured on; another BLAS may differ in the last
    bits), and the two are bit-identical to each other."""
    for name, kw in GOLDEN_CONFIGS.items():
        plain = Inversion({STATE: analytic_field}, **kw)
        other = Inversion({STATE: analytic_field}, modulus={(1.0,): table}, **kw)
        for y, (n, want) in zip(golden_frames(analytic_field), GOLDEN[name]):
            k, got = digest(plain.fit(y, STATE))
            assert k == n
            np.testing.assert_allclose(got, [float.fromhex(h) for h in want], rtol=1e-9, atol=0)
            k2, got2 = digest(other.fit(y, STATE))
            assert k2 == k and np.array_equal(got2, got)


def test_hovering_fingers_and_masked_channels(analytic_field, table, reference):
    """A hovering finger has no modulus (x 0, se 0; the BIC counts one fewer parameter than a
    pressing finger's); a masked channel leaves the recovery of a known x as it was (to 1e-3)."""
    inv = Inversion({STATE: analytic_field}, modulus={STATE: table}, modulus_prior_sd=1e3)
    hover = inv.fit(analytic_field.readout("front", 1.0, 30.0, 0.0, 3.0), STATE)
    assert hover.n_fingers == 1 and not hover.fingers[0].contact
    assert hover.fingers[0].modulus_ln == 0.0 and hover.fingers[0].modulus_ln_se == 0.0
    n = analytic_field.n_pairs
    # BIC = k ln n − 2ℓ: 3 finger parameters and the 2 drift terms
    assert np.isclose(hover.bic, 5 * np.log(n) - 2 * hover.log_likelihood)
    y = frame(analytic_field, reference, -8.1, 40.2, 0.7, 0.5)
    press = inv.fit(y, STATE)
    assert np.isclose(press.bic, 6 * np.log(n) - 2 * press.log_likelihood)
    y[4] = np.nan
    e = inv.fit(y, STATE).fingers[0]
    np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n, e.modulus_ln],
                               [-8.1, 40.2, 0.7, 0.5], atol=1e-3)


def test_the_modulus_option_is_checked(analytic_field, table):
    for bad in (0.0, -0.1, float("nan"), float("inf"), "0.4"):
        with pytest.raises(EctskinError, match="modulus_prior_sd"):
            Inversion({STATE: analytic_field}, modulus={STATE: table},
                      modulus_prior_sd=bad)  # type: ignore[arg-type]
    with pytest.raises(EctskinError, match="modulus must be a mapping"):
        Inversion({STATE: analytic_field}, modulus=[table])  # type: ignore[arg-type]
    with pytest.raises(EctskinError, match=r"modulus\[\[0.0\]\]: must be a ModulusTable"):
        Inversion({STATE: analytic_field}, modulus={STATE: "table"})
    u, v = table.nodes["front"]
    wrong = [ModulusTable({"back": (u, v)}, table.forces_n, {"back": table.values["front"]}, 0.1),
             ModulusTable(table.nodes, table.forces_n, {"front": table.values["front"][..., :3]},
                          0.1),
             ModulusTable(table.nodes, table.forces_n[:3], {"front": table.values["front"]}, 0.1)]
    for bad, what in zip(wrong, ("no nodes on the field's face", "values\\['front'\\] must be",
                                 "forces_n must be")):
        with pytest.raises(EctskinError, match=what):
            Inversion({STATE: analytic_field}, modulus={STATE: bad})
    r = Inversion({STATE: analytic_field}).fit(analytic_field.readout("front", 0.0, 20.0, 1.0),
                                                STATE)
    assert r.fingers[0].modulus_ln == 0.0 and r.fingers[0].modulus_ln_se == 0.0


def test_a_narrow_prior_holds_x_and_enters_the_standard_errors(analytic_field, table, reference):
    """A prior of sd 0.03 on a pulp of x = 0.4 (about a third of x's standard error without it,
    0.098): the fit's x is near the linearised posterior mode, x w_data / (w_data + w_prior) =
    0.034 (within 0.02-0.06; without the prior's term it would sit at its range's end, 3 sd =
    0.09), and its standard errors are the CRB with that prior (to 3 %), x's below the prior's
    sd."""
    u, v, f, x, sd = 1.4, 30.6, 0.9, 0.4, 0.03
    inv = Inversion({STATE: analytic_field}, modulus={STATE: table}, modulus_prior_sd=sd,
                    max_fingers=1)
    e = inv.fit(frame(analytic_field, reference, u, v, f, x), STATE).fingers[0]
    assert 0.02 < e.modulus_ln < 0.06, e
    bound = bound_with_modulus(analytic_field, reference, e.u_mm, e.v_mm, e.force_n,
                               e.modulus_ln, sd)
    np.testing.assert_allclose([e.u_se_mm, e.v_se_mm, e.force_se_n, e.modulus_ln_se], bound,
                               rtol=0.03)
    assert e.modulus_ln_se < sd


def test_modulus_and_radius_come_back_together(analytic_field, table, reference):
    """A radius table beside the modulus's (closed-form column of this test: a bigger tip
    couples more, 0.5 Δ, and spreads wider, +0.3 × the Laplacian): noise-free frames of x = 0.4,
    r = −0.3 (weak priors) give the point, force, x and r back to 2e-3, where the fit with the
    modulus alone misses the force by more than 0.02 N; the radius's standard error is reported,
    and x's is wider with r fitted than without."""
    u, v = table.nodes["front"]
    U, V, F = np.meshgrid(u, v, table.forces_n, indexing="ij")
    lap = closed_form_column(analytic_field, U, V, F) + PAD * F[..., None] * analytic_field.jacobian(
        "front", U, V, F)[..., 2]  # −SPREAD × the Laplacian
    rad = ModulusTable(table.nodes, table.forces_n, {"front": 0.5 * analytic_field.delta(
        "front", U, V, F) - 0.5 * lap}, 0.05)
    rgi = RegularGridInterpolator((u, v, np.log(table.forces_n)), rad.values["front"],
                                  method="cubic", solver=spsolve)
    both = Inversion({STATE: analytic_field}, modulus={STATE: table}, radius={STATE: rad},
                     modulus_prior_sd=1e3, radius_prior_sd=1e3, gate_p=0.0)
    one = Inversion({STATE: analytic_field}, modulus={STATE: table}, modulus_prior_sd=1e3,
                    gate_p=0.0)
    for p in ([3.3, 21.7, 1.1], [-8.1, 40.2, 0.7]):
        y = frame(analytic_field, reference, *p, 0.4) - 0.3 * rgi(np.r_[p[:2], np.log(p[2])][None])[0]
        r = both.fit(y, STATE)
        assert r.n_fingers == 1 and r.fingers[0].contact
        e = r.fingers[0]
        np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n, e.modulus_ln, e.radius_ln],
                                   [*p, 0.4, -0.3], atol=2e-3)
        assert 0 < e.radius_ln_se < np.inf
        o = one.fit(y, STATE).fingers[0]
        assert abs(o.force_n - p[2]) > 0.02 and o.radius_ln == 0.0 and o.radius_ln_se == 0.0, o
        assert e.modulus_ln_se > o.modulus_ln_se


# ------------------------------------------------------------ one person's finger, pooled
def result(mu: float, se: float, *, contact: bool = True, n: int = 1) -> InversionResult:
    """A result of n fingers, each at x = ``mu`` ± ``se`` (pressing or hovering)."""
    e = FingerEstimate("front", contact, 0.0, 0.0, 1.0 if contact else 0.0, 0.0, 0.1, 0.1, 0.1,
                       0.0, modulus_ln=mu, modulus_ln_se=se)
    return InversionResult(n, (e,) * n, 0.0, 0.0, True, (0.0,) * 3)


def same_arrays(a, b):
    """The results' arrays equal, NaN for NaN (results hold NaN, unequal to itself)."""
    x, y = results_to_arrays(a), results_to_arrays(b)
    assert x.keys() == y.keys()
    for k in x:
        np.testing.assert_array_equal(x[k], y[k], err_msg=k)


def test_the_pooled_posterior_is_the_gaussian_product_by_hand():
    """Two frames of x = 0.3 ± 0.2 and 0.5 ± 0.1 fitted with a prior sd 0.4: likelihood
    precisions 25 − 6.25 = 18.75 and 100 − 6.25 = 93.75, P = 6.25 + 18.75 + 93.75 = 118.75,
    centre (0.3/0.04 + 0.5/0.01) / P = 57.5 / 118.75; a hovering finger, a two-finger frame and
    a frame without the nuisance (se 0) add nothing; the floor holds the sd."""
    frames = [result(0.3, 0.2), result(0.5, 0.1), result(0.9, 0.05, contact=False),
              result(0.9, 0.05, n=2), result(0.0, 0.0)]
    pooled = pool_fingers(frames, {"modulus": 0.4}, sd_floor=0.0)
    assert pooled["modulus"][0] == pytest.approx(57.5 / 118.75, rel=1e-12)
    assert pooled["modulus"][1] == pytest.approx(118.75 ** -0.5, rel=1e-12)
    assert pool_fingers(frames, {"modulus": 0.4}, sd_floor=0.2)["modulus"][1] == 0.2
    assert pool_fingers([], {"modulus": 0.4}, sd_floor=0.0) == {"modulus": (0.0, 0.4)}
    sd0 = 0.10296  # a prior told nothing comes back exactly (fit_frames refits only where told)
    assert pool_fingers(frames[2:], {"modulus": sd0}) == {"modulus": (0.0, sd0)}
    for bad, what in (({"pulp": 0.4}, "prior_sd"), ({"modulus": 0.0}, "prior_sd")):
        with pytest.raises(EctskinError, match=what):
            pool_fingers(frames, bad)
    with pytest.raises(EctskinError, match="sd_floor"):
        pool_fingers(frames, {"modulus": 0.4}, sd_floor=-1.0)


def test_a_prior_centred_at_zero_is_the_population_prior_bit_for_bit(analytic_field, table,
                                                                      reference):
    """``finger={"modulus": (0, sd)}`` per call is ``modulus_prior_sd=sd`` of the inversion."""
    y = frame(analytic_field, reference, 1.4, 30.6, 0.9, 0.4)
    narrow = Inversion({STATE: analytic_field}, modulus={STATE: table}, modulus_prior_sd=0.03)
    wide = Inversion({STATE: analytic_field}, modulus={STATE: table})
    assert wide.fit(y, STATE, finger={"modulus": (0.0, 0.03)}) == narrow.fit(y, STATE)
    assert wide.finger_prior_sd == {"modulus": MODULUS_PRIOR_SD}
    assert Inversion({STATE: analytic_field}).finger_prior_sd == {}
    for bad in ({"modulus": (0.0, 0.0)}, {"pulp": (0.0, 0.1)}, {"modulus": 0.1}, [0.1]):
        with pytest.raises(EctskinError, match="finger"):
            wide.fit(y, STATE, finger=bad)


def test_a_prior_centred_off_zero_moves_the_fit_to_the_posterior_mode(analytic_field, table,
                                                                      reference):
    """A pulp of x = 0.4 (noise-free), a prior of sd 0.03 centred at c: at c = 0.4 the fit is the
    truth (point, force, x to 1e-3); at c = 0.2 x is the linearised posterior mode
    (w_d 0.4 + w_p 0.2) / (w_d + w_p), w_d = 1 / se_d², se_d x's standard error with a flat
    prior (to 0.01), and the force lies between the truth and the fit at c = 0."""
    u, v, f, x = 1.4, 30.6, 0.9, 0.4
    inv = Inversion({STATE: analytic_field}, modulus={STATE: table}, max_fingers=1)
    flat = Inversion({STATE: analytic_field}, modulus={STATE: table}, max_fingers=1,
                     modulus_prior_sd=1e3)
    y = frame(analytic_field, reference, u, v, f, x)
    e = inv.fit(y, STATE, finger={"modulus": (0.4, 0.03)}).fingers[0]
    np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n, e.modulus_ln], [u, v, f, x],
                               atol=1e-3)
    se_d = flat.fit(y, STATE).fingers[0].modulus_ln_se
    wd, wp = se_d**-2, 0.03**-2
    half = inv.fit(y, STATE, finger={"modulus": (0.2, 0.03)}).fingers[0]
    assert half.modulus_ln == pytest.approx((wd * 0.4 + wp * 0.2) / (wd + wp), abs=0.01)
    zero = inv.fit(y, STATE, finger={"modulus": (0.0, 0.03)}).fingers[0]
    assert min(f, zero.force_n) < half.force_n < max(f, zero.force_n)


def test_one_persons_frames_pooled_find_the_pulp_each_frame_misses(analytic_field, table,
                                                                     reference):
    """40 frames of one person (x = 0.5) at points over the wires, read with 6 times the
    electronics' noise (each frame then tells x about as well as the twin's prior does):
    each frame's x is pulled towards 0 (their mean below 0.45); pooled (prior taken out once)
    the centre is within 3 pooled sd (and 0.05) of 0.5; ``fit_frames(person=)`` refits every
    frame with it, and their mean |x − 0.5| and force error drop below the single fits'. A
    second person (x = −0.3) in the same call is pooled apart."""
    rng = np.random.default_rng(11)
    noisy = ReadoutConfig(noise_scale=6.0)
    inv = Inversion({STATE: analytic_field}, noisy, modulus={STATE: table}, max_fingers=1)
    truth, frames, forces = [], [], []
    for who, x in ((0, 0.5), (1, -0.3)):
        for _ in range(40):
            p = np.array([rng.uniform(-12, 12), rng.uniform(8, 40), rng.uniform(0.5, 1.8)])
            y = frame(analytic_field, reference, *p, x)
            frames.append(y + rng.normal(0, 1, y.size) * noise_pf(y, noisy))
            truth.append(who)
            forces.append(p[2])
    frames, forces = np.array(frames), np.array(forces)
    x_true = np.where(np.array(truth) == 0, 0.5, -0.3)
    single, _ = fit_frames(inv, frames, STATE)
    xs = np.array([r.fingers[0].modulus_ln for r in single])
    assert xs[:40].mean() < 0.45 and xs[40:].mean() > -0.27
    centre, sd = pool_fingers(single[:40], inv.finger_prior_sd)["modulus"]
    assert abs(centre - 0.5) < max(3 * sd, 0.05), (centre, sd)
    pooled, seconds = fit_frames(inv, frames, STATE, person=truth)
    assert seconds.shape == (80,) and np.all(seconds > 0)
    xp = np.array([r.fingers[0].modulus_ln for r in pooled])
    fs = np.array([r.fingers[0].force_n for r in single])
    fp = np.array([r.fingers[0].force_n for r in pooled])
    assert np.abs(xp - x_true).mean() < 0.5 * np.abs(xs - x_true).mean()
    assert np.abs(fp - forces).mean() < np.abs(fs - forces).mean()
    assert xp[40:].mean() < 0 < xp[:40].mean()
    # the same on two worker processes; without tables, person= changes nothing
    again, _ = fit_frames(inv, frames, STATE, person=truth, workers=2)
    same_arrays(again, pooled)
    assert [r.fingers[0].modulus_ln for r in again] == xp.tolist()
    plain = Inversion({STATE: analytic_field}, noisy, max_fingers=1)
    same_arrays(fit_frames(plain, frames[:5], STATE, person=truth[:5])[0],
                fit_frames(plain, frames[:5], STATE)[0])
    with pytest.raises(EctskinError, match="one label per frame"):
        fit_frames(inv, frames[:5], STATE, person=truth[:4])


def test_a_running_pool_is_the_batch_pool_whatever_prior_each_frame_had():
    """A stream pools as it goes (:class:`FingerPool`): each frame is fitted with the pool so
    far as its prior. Linear-Gaussian by hand: a frame whose likelihood is m ± l^−½ fitted with
    a prior (c, s) has the posterior μ = (m l + c/s²) / (l + 1/s²), se = (l + 1/s²)^−½;
    added with the prior it was fitted with, the pool is the population prior times the
    likelihoods: P = 1/s0² + Σ l, centre Σ m l / P, whatever prior each frame had."""
    s0 = 0.4
    likelihoods = [(0.7, 30.0), (0.2, 5.0), (0.55, 80.0), (0.4, 12.0), (0.9, 2.0)]
    pool = FingerPool({"modulus": s0}, sd_floor=0.0)
    assert pool.prior() is None and pool.n_frames == 0
    assert not pool.add(result(0.8, 0.1, contact=False)) and pool.prior() is None
    for m, lik in likelihoods:
        used = pool.prior()
        c, s = (used or {"modulus": (0.0, s0)})["modulus"]
        precision = lik + 1 / s**2
        assert pool.add(result((m * lik + c / s**2) / precision, precision**-0.5), used)
    P = 1 / s0**2 + sum(lik for _, lik in likelihoods)
    centre, sd = pool.prior()["modulus"]
    assert centre == pytest.approx(sum(m * lik for m, lik in likelihoods) / P, rel=1e-12)
    assert sd == pytest.approx(P**-0.5, rel=1e-12)
    assert pool.n_frames == len(likelihoods)
    # the same frames all fitted with the population prior: the batch pool of pool_fingers
    batch = [result((m * lik) / (lik + 1 / s0**2), (lik + 1 / s0**2) ** -0.5)
             for m, lik in likelihoods]
    assert pool_fingers(batch, {"modulus": s0}, sd_floor=0.0)["modulus"] == pytest.approx(
        (centre, sd), rel=1e-12)
    pool.reset()
    assert pool.prior() is None and pool.posterior() == {"modulus": (0.0, s0)}
    with pytest.raises(EctskinError, match="FingerPool: prior_sd"):
        FingerPool({"pulp": 0.4})
