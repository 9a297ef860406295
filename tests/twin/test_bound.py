"""Cramér–Rao bounds (ectskin.twin.bound): closed forms, nuisances, priors, Monte Carlo, the
finite-difference Jacobian against an analytic one, and the twin near and beyond the wires."""

from __future__ import annotations

import json

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin._files import json_text
from ectskin.layout import default_layout
from ectskin.twin.bound import (
    COARSE,
    TwinResponse,
    bound_maps,
    crb,
    finite_difference_jacobian,
    fisher_information,
    point_bounds,
    skin_grid,
)
from ectskin.twin.bound_fit import FitModel, fit_error
from ectskin.twin.sensor import SensorModel

# a 2 x 2 model by hand: J = [[2, 1], [0, 3]], sigma = (0.5, 2), so Σ⁻¹ = diag(4, 1/4) and
# FIM = [[16, 8], [8, 6.25]], det 36, FIM⁻¹ = [[6.25, -8], [-8, 16]] / 36
J2 = np.array([[2.0, 1.0], [0.0, 3.0]])
S2 = np.array([0.5, 2.0])


def test_fisher_information_and_bound_of_a_hand_computed_model():
    np.testing.assert_allclose(fisher_information(J2, S2), [[16.0, 8.0], [8.0, 6.25]])
    b = crb(J2, S2)
    np.testing.assert_allclose(b.std, [2.5 / 6, 4.0 / 6])
    np.testing.assert_allclose(b.cov, np.array([[6.25, -8.0], [-8.0, 16.0]]) / 36)
    assert b.resolved.all()
    # the second column a nuisance: the first's bound is the (0, 0) entry of the full inverse,
    # not 1/sqrt(FIM_00) = 0.25 (what ignoring the Schur complement would give)
    nb = crb(J2, S2, nuisance_cols=[1])
    np.testing.assert_allclose(nb.std, [2.5 / 6])
    np.testing.assert_allclose(nb.retained, [36 / (16 * 6.25)])  # 1 / (FIM_00 var_0)
    # a prior of variance 1 on the nuisance: FIM_11 = 7.25, var_0 = 7.25 / (16 * 7.25 - 64)
    np.testing.assert_allclose(
        crb(J2, S2, nuisance_cols=[1], prior_var={1: 1.0}).std, [np.sqrt(7.25 / 52)]
    )
    # known exactly (variance 0): as if the column were absent
    np.testing.assert_allclose(crb(J2, S2, nuisance_cols=[1], prior_var={1: 0.0}).std, [0.25])


def test_a_nuisance_collinear_with_a_parameter_makes_it_unresolved():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 6))
    sigma = rng.uniform(0.5, 2.0, 6)
    J = np.c_[a, b, -2.0 * a]  # the nuisance moves the readouts exactly as the first parameter
    res = crb(J, sigma, nuisance_cols=[2])
    assert not res.resolved[0] and np.isinf(res.std[0]) and res.retained[0] == 0
    assert np.isnan(res.cov[0]).all() and np.isinf(res.condition)
    # the second parameter stays estimable: its bound is that of the model without the nuisance
    assert res.resolved[1]
    np.testing.assert_allclose(res.std[1], crb(np.c_[a, b], sigma).std[1], rtol=1e-8)
    # a parameter with no information at all
    zero = crb(np.c_[a, np.zeros(6)], sigma)
    assert zero.resolved.tolist() == [True, False] and np.isinf(zero.std[1])
    np.testing.assert_allclose(zero.std[0], 1 / np.linalg.norm(a / sigma))


def test_a_nearly_collinear_nuisance_gives_a_large_finite_bound():
    """Below the clamp the bound is inf; above it a large, correct, finite number."""
    rng = np.random.default_rng(1)
    a, b, e = rng.normal(size=(3, 8))
    sigma = np.ones(8)
    for eps in (1e-2, 1e-3):
        res = crb(np.c_[a, b, a + eps * e], sigma, nuisance_cols=[2])
        full = np.linalg.inv(fisher_information(np.c_[a, b, a + eps * e], sigma))
        assert res.resolved.all()
        np.testing.assert_allclose(res.std, np.sqrt(np.diag(full))[:2], rtol=1e-6)
        assert res.std[0] > 10 * crb(np.c_[a, b], sigma).std[0]


def test_an_orthogonal_nuisance_leaves_the_bound_unchanged():
    rng = np.random.default_rng(2)
    sigma = rng.uniform(0.5, 2.0, 7)
    J = rng.normal(size=(7, 2))
    # a nuisance orthogonal to both columns in the noise's metric (whitened readouts)
    w = J / sigma[:, None]
    r = rng.normal(size=7)
    r -= w @ np.linalg.lstsq(w, r, rcond=None)[0]
    with_n = crb(np.c_[J, r * sigma], sigma, nuisance_cols=[2])
    np.testing.assert_allclose(with_n.std, crb(J, sigma).std, rtol=1e-10)
    np.testing.assert_allclose(with_n.cov, crb(J, sigma).cov, rtol=1e-10, atol=1e-14)


def test_a_prior_narrows_the_bound_toward_the_no_nuisance_value():
    rng = np.random.default_rng(3)
    sigma = rng.uniform(0.5, 2.0, 6)
    J = rng.normal(size=(6, 3))
    free = crb(J, sigma, nuisance_cols=[2]).std
    known = crb(J[:, :2], sigma).std
    assert np.all(free > known * 1.001)  # the nuisance costs something here
    seq = [crb(J, sigma, nuisance_cols=[2], prior_var={2: v}).std for v in (1e2, 1, 1e-2, 1e-4, 1e-8)]
    for wider, narrower in zip([free, *seq], seq):
        assert np.all(narrower <= wider * (1 + 1e-12))
    np.testing.assert_allclose(seq[-1], known, rtol=1e-6)
    np.testing.assert_allclose(crb(J, sigma, nuisance_cols=[2], prior_var={2: np.inf}).std, free)


def test_the_weighted_least_squares_estimator_reaches_the_bound():
    """Monte Carlo on a linear Gaussian model: the efficient estimator's covariance is the CRB."""
    rng = np.random.default_rng(4)
    n_obs, n = 10, 4
    J = rng.normal(size=(n_obs, n))
    sigma = rng.uniform(0.2, 1.0, n_obs)
    theta = rng.normal(size=n)
    draws = 40_000
    y = J @ theta + sigma * rng.standard_normal((draws, n_obs))
    w = J / sigma[:, None]
    est = np.linalg.lstsq(w, (y / sigma).T, rcond=None)[0].T  # (draws, n)
    emp = np.cov(est[:, :2].T)
    bound = crb(J, sigma, nuisance_cols=[2, 3])  # the last two columns estimated as nuisances
    # a variance's sampling error is sqrt(2 / draws) = 0.7 % relative: allow 5 of them
    np.testing.assert_allclose(np.diag(emp), bound.std**2, rtol=5 * np.sqrt(2 / draws))
    corr = bound.cov[0, 1] / np.prod(bound.std)
    assert abs(emp[0, 1] / np.sqrt(emp[0, 0] * emp[1, 1]) - corr) < 5 / np.sqrt(draws)
    np.testing.assert_allclose(est.mean(axis=0), theta, atol=5 * np.sqrt(np.diag(
        np.linalg.inv(fisher_information(J, sigma)))).max() / np.sqrt(draws))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(J=np.ones((3, 2)), sigma=np.ones(2)), "expected J (n_obs, n_params)"),
        (dict(J=np.ones((2, 2)), sigma=np.array([1.0, 0.0])), "sigma finite and > 0"),
        (dict(J=np.ones((2, 2)), sigma=np.ones(2), nuisance_cols=[5]), "nuisance_cols"),
        (dict(J=np.ones((2, 2)), sigma=np.ones(2), prior_var={1: -1.0}), "variances >= 0"),
    ],
)
def test_bad_input_is_one_clear_error(kwargs, message):
    with pytest.raises(EctskinError, match=message.replace("(", r"\(").replace(")", r"\)")):
        crb(**kwargs)


# ---------------------------------------------------------------------------- providers
class PointCharges:
    """A smooth stand-in for the twin: pair p reads a / sqrt(|x − x_p|² + (d + h − b F)²) plus a
    push term (exp of a weighted push) and an inflation term q + 0.5 q², with q >= 0 allowed
    only (the offset's lower limit forces a one-sided stencil there). Counts its calls."""

    nuisance_sizes = {"push": 2, "inflation": 1}

    def __init__(self, n_pairs: int = 5, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.xy = rng.uniform(-20, 20, (n_pairs, 2))
        self.a = rng.uniform(1, 3, n_pairs)
        self.g = rng.normal(size=(n_pairs, 2))
        self.k = rng.normal(size=n_pairs)
        self.d, self.b = 6.0, 0.8
        self.calls = 0

    def nuisance_limits(self, name):
        return (np.zeros(1), np.full(1, np.inf)) if name == "inflation" else (
            np.full(2, -np.inf), np.full(2, np.inf))

    def _parts(self, uv, force, height):
        dx = uv[:, None, :] - self.xy[None]
        z = self.d + height - self.b * force
        r2 = (dx**2).sum(axis=2) + z[:, None] ** 2
        return dx, z, r2

    def readout(self, face, uv, force, height, nuisances=None):
        self.calls += 1
        nu = nuisances or {}
        uv = np.asarray(uv, float).reshape(-1, 2)
        push = np.asarray(nu.get("push", np.zeros((len(uv), 2))))
        q = np.asarray(nu.get("inflation", np.zeros((len(uv), 1))))[:, 0]
        if np.any(q < 0):
            raise AssertionError("asked below the inflation's lower limit")
        _, _, r2 = self._parts(uv, np.asarray(force, float), np.asarray(height, float))
        return (self.a / np.sqrt(r2) + np.exp(push @ self.g.T * 0.3)
                + self.k * (q + 0.5 * q**2)[:, None])

    def analytic(self, uv, force, height):
        """(n_pairs, 3 + 3): ∂C/∂(u, v, force or height, push_1, push_2, inflation)."""
        dx, z, r2 = self._parts(np.asarray([uv], float), np.array([force]), np.array([height]))
        base = -self.a / r2[0] ** 1.5
        third = base * z[0] * (1.0 if height > 0 else -self.b)
        return np.c_[base * dx[0, :, 0], base * dx[0, :, 1], third, 0.3 * self.g, self.k]


@pytest.mark.parametrize("force, height", [(1.0, 0.0), (0.0, 2.0)])
def test_finite_difference_jacobian_matches_the_analytic_one(force, height):
    prov = PointCharges()
    c, J, names = finite_difference_jacobian(
        prov, "front", (1.0, 2.0), force_n=force, height_mm=height,
        nuisances=("push", "inflation"), steps={"inflation": 0.01},
    )
    assert names == ["u", "v", "height" if height else "force", "push_1", "push_2", "inflation"]
    assert prov.calls == 1  # every stencil row in one call
    ref = prov.analytic((1.0, 2.0), force, height)
    np.testing.assert_allclose(c, prov.readout("front", [[1.0, 2.0]], [force], [height])[0])
    # central differences: error (h²/6) f''' (a few 1e-4 here); forward (inflation at its limit,
    # step 0.01): error h f''/2 = 0.5 %, so 1e-2 holds and a central step below 0 would have
    # raised in the provider
    np.testing.assert_allclose(J[:, :5], ref[:, :5], rtol=3e-3, atol=1e-6)
    np.testing.assert_allclose(J[:, 5], ref[:, 5], rtol=1e-2)


def test_point_bounds_is_the_crb_of_the_analytic_jacobian():
    """Position = sqrt(var_u + var_v); each case estimates its nuisances with their priors."""
    from ectskin.twin.readout import ReadoutConfig, noise_pf

    prov = PointCharges()
    steps = dict.fromkeys(("u", "v", "force", "push"), 0.01) | {"inflation": 1e-5}  # tiny errors
    got = point_bounds(prov, "front", (1.0, 2.0), nuisances=("push", "inflation"),
                       prior_sd={"inflation": 0.5}, steps=steps)
    J = prov.analytic((1.0, 2.0), 1.0, 0.0)
    sigma = noise_pf(prov.readout("front", [[1.0, 2.0]], [1.0], [0.0])[0], ReadoutConfig())
    want = {
        "none": crb(J[:, :3], sigma),
        "push": crb(J[:, :5], sigma, nuisance_cols=[3, 4]),
        "inflation": crb(J[:, [0, 1, 2, 5]], sigma, nuisance_cols=[3], prior_var={3: 0.25}),
        "all": crb(J, sigma, nuisance_cols=[3, 4, 5], prior_var={5: 0.25}),
    }
    assert list(got) == list(want)
    for case, b in want.items():
        np.testing.assert_allclose(
            got[case], [np.sqrt(b.std[0] ** 2 + b.std[1] ** 2), b.std[2]], rtol=1e-3
        )


def test_bound_maps_on_a_synthetic_provider_has_the_documented_shape():
    lay = default_layout()
    prov = PointCharges(n_pairs=lay.n_pairs)
    maps = bound_maps({(0.0, 0.0, 0.0): prov}, lay, spacing_mm=20.0, faces=["front"],
                      nuisances=("push", "inflation"), hover_mm=3.0, points_per_task=5)
    u, v = skin_grid(lay, "front", 20.0)
    np.testing.assert_allclose(u, [-10.0, 10.0])
    np.testing.assert_allclose(v, 5.0 + 110.0 / 6 * (np.arange(6) + 0.5))
    assert maps["cases"] == ["none", "push", "inflation", "all"]
    assert maps["modes"] == ["contact", "hover"]
    face = maps["states"][0]["faces"]["front"]
    assert np.shape(face["contact"]["all"]["force_n"]) == (6, 2)
    assert np.shape(face["hover"]["none"]["height_mm"]) == (6, 2)
    # one point of the map is point_bounds at that point
    ref = point_bounds(prov, "front", (u[1], v[3]), nuisances=("push", "inflation"))
    assert face["contact"]["push"]["position_mm"][3, 1] == pytest.approx(ref["push"][0])
    assert face["contact"]["push"]["force_n"][3, 1] == pytest.approx(ref["push"][1])
    s = maps["summary"]["contact"]["all"]
    allf = face["contact"]["all"]["force_n"]
    assert s["force_n"]["median"] == pytest.approx(np.median(allf))
    assert s["force_observable_share"] == pytest.approx(np.mean(allf < 0.1))
    assert len(maps["wires"]["front"]) == 4


class PushLikeForce(PointCharges):
    """The hand's first load moves the readouts exactly as the finger's force does."""

    def readout(self, face, uv, force, height, nuisances=None):
        nu = dict(nuisances or {})
        push = np.asarray(nu.pop("push", np.zeros((len(uv), 2))), float)
        return super().readout(face, uv, np.asarray(force) + push[:, 0], height, nu)


def test_an_unobservable_force_is_null_in_the_maps_never_a_number():
    lay = default_layout()
    maps = bound_maps({(0.0, 0.0, 0.0): PushLikeForce(n_pairs=lay.n_pairs)}, lay,
                      spacing_mm=20.0, faces=["front"], nuisances=("push",),
                      steps={"push": 0.05})  # the force's step: the two columns are equal
    doc = json.loads(json_text(maps))
    pushed = doc["states"][0]["faces"]["front"]["contact"]["push"]
    assert all(x is None for row in pushed["force_n"] for x in row)
    s = doc["summary"]["contact"]
    assert s["push"]["force_n"] == {"mean": None, "median": None, "p95": None}
    assert s["push"]["resolved_share"] == 0 and s["push"]["force_observable_share"] == 0
    assert s["none"]["resolved_share"] == 1 and s["none"]["force_n"]["p95"] > 0


# ---------------------------------------------------------------------------- the twin
NEAR = (-5.0, 40.0)  # over wire E2 (x = -5 mm, v = 10 ... 55 mm)
BEYOND = (-15.0, 110.0)  # beyond every wire's end (the longest ends at v = 105 mm, x = +15)


@pytest.fixture(scope="module")
def twin():
    with threadpool_limits(1):  # small solves: a second BLAS thread only contends
        yield TwinResponse(SensorModel(default_layout(), discretisation=COARSE), (0.0, 10.0, 20.0))


def test_the_twin_provider_is_the_sensor_model(twin):
    from ectskin.twin.mechanics import Touch

    rows = twin.readout(
        "front", [NEAR, NEAR], [1.0, 0.0], [0.0, 2.0], {"inflation": [[0, 0, 0], [1.0, 0, 0]]}
    )
    s = twin.sensor
    np.testing.assert_allclose(rows[0], s.capacitance((0, 10, 20), Touch("front", NEAR), [1.0])[0])
    np.testing.assert_allclose(
        rows[1], s.capacitance((1, 10, 20), Touch("front", NEAR), [0.0], heights_mm=[2.0])[0]
    )
    with pytest.raises(EctskinError, match="hovering row"):
        twin.readout("front", [NEAR], [1.0], [2.0])


@pytest.fixture(scope="module")
def twin_bounds(twin):
    return {uv: point_bounds(twin, "front", uv) for uv in (NEAR, BEYOND)}


def test_near_a_wire_the_bound_is_smaller_than_beyond_the_wire_ends(twin_bounds):
    near, beyond = twin_bounds[NEAR], twin_bounds[BEYOND]
    for case in near:
        assert near[case][0] < beyond[case][0] / 3, case  # position, mm
    for case in ("push", "all"):  # force, once the hand's push is unknown
        assert near[case][1] < beyond[case][1], case


def test_a_nuisance_never_lowers_the_bound(twin_bounds):
    for point in twin_bounds.values():
        for k in range(2):
            for case in ("push", "inflation", "finger"):
                assert point[case][k] >= point["none"][k] * (1 - 1e-9), case
                assert point["all"][k] >= point[case][k] * (1 - 1e-9), case
            assert point["push"][k] > point["none"][k]


def test_a_quantile_that_reaches_an_unresolved_point_is_unresolved():
    """20 points, 1 unresolved: the 95th percentile interpolates between the largest finite
    bound (the 19th) and the unresolved one, so it is unresolved (inf), not a number near 1e300;
    the median of the finite ones is a plain number."""
    from ectskin.twin.bound import _stats

    x = np.r_[np.arange(1.0, 20.0), np.inf]
    s = _stats(x)
    assert s["p95"] == np.inf and s["mean"] == np.inf
    assert s["median"] == pytest.approx(10.5)
    clean = _stats(np.arange(1.0, 21.0))  # all resolved: plain percentiles
    assert clean["p95"] == pytest.approx(np.percentile(np.arange(1.0, 21.0), 95))


# ---------------------------------------------------------------------------- a fit that leaves columns out
def test_a_fit_that_leaves_columns_out_has_the_monte_carlo_error():
    """Linear Gaussian model, penalised least squares of u, v, F, a free nuisance and one with a
    prior, while two more columns move the data unmodelled: the empirical mean square error of
    each parameter of interest is fit_error's rms² (and no longer the CRB)."""
    rng = np.random.default_rng(7)
    n_obs = 28
    J = rng.normal(size=(n_obs, 7))  # u, v, F, free nuisance, prior nuisance, 2 left out
    sigma = rng.uniform(0.2, 1.0, n_obs)
    prior_sd, left_sd = 0.7, np.array([0.5, 1.5])
    draws = 40_000
    theta = rng.normal(size=3)
    free = rng.normal(size=(draws, 1)) * 3.0
    with_prior = rng.normal(size=(draws, 1)) * prior_sd
    left = rng.normal(size=(draws, 2)) * left_sd
    x = np.c_[np.tile(theta, (draws, 1)), free, with_prior, left]
    y = x @ J.T + sigma * rng.standard_normal((draws, n_obs))
    w = J[:, :5] / sigma[:, None]
    A = w.T @ w + np.diag([0, 0, 0, 0, prior_sd**-2])
    est = np.linalg.solve(A, w.T @ (y / sigma).T).T  # the MAP of the fitted columns
    mse = np.mean((est[:, :3] - theta) ** 2, axis=0)
    e = fit_error(J, sigma, left_out={5: left_sd[0], 6: left_sd[1]}, nuisance_cols=[3, 4],
                  prior_var={4: prior_sd**2})
    # a mean square's sampling error is about sqrt(2 / draws) = 0.7 % relative: allow 5 of them
    np.testing.assert_allclose(mse, e.rms**2, rtol=5 * np.sqrt(2 / draws))
    assert np.all(e.rms[:2] > e.std[:2] * 1.5)  # the left-out columns matter in this model
    np.testing.assert_allclose(
        e.std, crb(J[:, :5], sigma, nuisance_cols=[3, 4], prior_var={4: prior_sd**2}).std)
    np.testing.assert_allclose(e.rms**2, e.std**2 + (e.bias**2).sum(axis=1))


def test_a_left_out_column_that_a_free_nuisance_spans_costs_nothing_one_along_u_its_sd():
    rng = np.random.default_rng(8)
    J = rng.normal(size=(12, 4))
    sigma = rng.uniform(0.5, 1.0, 12)
    absorbed = fit_error(np.c_[J, 2.0 * J[:, 3]], sigma, left_out={4: 0.8}, nuisance_cols=[3])
    np.testing.assert_allclose(absorbed.bias, 0.0, atol=1e-10)
    np.testing.assert_allclose(absorbed.rms, absorbed.std)
    # the data shifted along u by 0.8 (sd): read as u, all of it, and nothing else
    along_u = fit_error(np.c_[J, J[:, 0]], sigma, left_out={4: 0.8}, nuisance_cols=[3])
    np.testing.assert_allclose(along_u.bias[:, 0], [0.8, 0.0, 0.0], atol=1e-10)
    # unresolved stays unresolved: u and v collinear
    J2 = np.c_[J[:, 0], J[:, 0], J[:, 2], J[:, 3]]
    assert np.all(np.isinf(fit_error(J2, sigma, left_out={3: 1.0}).rms[:2]))


def test_the_fit_case_of_point_bounds_is_fit_error_of_the_analytic_jacobian():
    from ectskin.twin.readout import ReadoutConfig, noise_pf

    prov = PointCharges()
    steps = dict.fromkeys(("u", "v", "force", "push"), 0.01) | {"inflation": 1e-5}
    fit = FitModel(nuisances=("push",), left_out=("inflation",))
    got = point_bounds(prov, "front", (1.0, 2.0), nuisances=("push",), prior_sd={"inflation": 0.5},
                       steps=steps, fit=fit)
    assert list(got) == ["none", "push", "fit"]
    J = prov.analytic((1.0, 2.0), 1.0, 0.0)
    sigma = noise_pf(prov.readout("front", [[1.0, 2.0]], [1.0], [0.0])[0], ReadoutConfig())
    e = fit_error(J, sigma, left_out={5: 0.5}, nuisance_cols=[3, 4])
    np.testing.assert_allclose(got["fit"], [np.hypot(*e.rms[:2]), e.rms[2]], rtol=1e-3)
    assert got["fit"][0] > got["push"][0] * 1.01  # leaving the inflation out costs here
    with pytest.raises(EctskinError, match="untouched"):  # a scale needs the untouched readout
        point_bounds(prov, "front", (1.0, 2.0), nuisances=(), prior_sd={"inflation": 0.5},
                     fit=FitModel(nuisances=(), left_out=("inflation",), scale_sd=0.1))
    with pytest.raises(EctskinError, match="needs a prior SD"):
        point_bounds(prov, "front", (1.0, 2.0), nuisances=(), prior_sd={}, fit=fit)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: fit_error(np.ones((3, 3)), np.ones(3), left_out={2: 0.0}), "standard deviations > 0"),
        (lambda: fit_error(np.ones((3, 3)), np.ones(3), left_out={5: 1.0}), "columns 0..2"),
        (lambda: fit_error(np.ones((3, 3)), np.ones(3), left_out={2: 1.0}, nuisance_cols=[2]),
         "cannot be fitted too"),
        (lambda: FitModel(nuisances=("push",), left_out=("push",)), "fitted or left out"),
        (lambda: FitModel(left_out=("hand",)), "nuisance"),
        (lambda: FitModel(scale_sd=0.0), "scale_sd"),
    ],
)
def test_a_bad_fit_is_one_clear_error(call, message):
    with pytest.raises(EctskinError, match=message):
        call()
