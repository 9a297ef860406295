"""Field-backed Cramér–Rao bounds (ectskin.twin.bound_field) against independent references:
``crb`` point by point, an analytic field whose Jacobian is known, and ``TwinResponse``'s direct
bound (finite differences of method-of-moments solves) on a small built field."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.twin.bound import TwinResponse, crb, finite_difference_jacobian, point_bounds
from ectskin.twin.bound_field import (
    StateNuisances,
    crb_many,
    field_bound_maps,
    field_bounds,
    field_nuisances,
    reduce,
)
from ectskin.twin.bound_modulus import ModulusTable, modulus_column, modulus_table
from ectskin.twin.field import ResponseField
from ectskin.twin.field_build import build_field
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec
from ectskin.twin.readout import ReadoutConfig, noise_pf


@pytest.fixture(autouse=True, scope="module")
def _blas_one_thread():
    with threadpool_limits(limits=1):
        yield


def test_crb_many_is_crb_row_by_row():
    """Random Jacobians with a collinear nuisance (unresolved), a dead column, a prior, a known
    column: every row as ``crb`` gives it, inf where it says unresolved."""
    rng = np.random.default_rng(0)
    J = rng.normal(size=(40, 12, 7)) * rng.uniform(0.01, 100, size=(1, 1, 7))
    J[:4, :, 6] = -3 * J[:4, :, 0]  # a nuisance that moves the readouts as u does
    J[4:7, :, 2] = 0.0  # no information on the third parameter
    s = rng.uniform(0.5, 2.0, (40, 12))
    var = [np.inf, np.inf, np.inf, 0.5, np.inf, 0.0, np.inf]
    std, ok = crb_many(J, s, n_nuisance=4, prior_var=var)
    for i in range(40):
        ref = crb(J[i], s[i], nuisance_cols=[3, 4, 5, 6], prior_var={3: 0.5, 5: 0.0})
        assert ok[i].tolist() == ref.resolved.tolist()
        np.testing.assert_allclose(std[i], ref.std, rtol=1e-10)
    assert not ok[:4, 0].any() and not ok[4:7, 2].any() and ok[7:].all()


def test_crb_many_refuses_bad_input():
    with pytest.raises(EctskinError, match="sigma"):
        crb_many(np.ones((2, 3, 2)), np.zeros((2, 3)))
    with pytest.raises(EctskinError, match="prior_var"):
        crb_many(np.ones((2, 3, 2)), np.ones((2, 3)), prior_var=[1.0])


# ------------------------------------------------------------------ an analytic field
WINDOW = ((-4.0, 4.0), (40.0, 52.0))


def _linear_field(layout, seed=1):
    """A field whose readouts are C = a + b u + c v + d F (per pair): the splines reproduce a
    linear function exactly, so its Jacobian is (b, c, d) everywhere."""
    spec = FieldSpec(layout, (0.0, 20.0, 0.0), discretisation=COARSE_FIELD_MESH,
                     spacing_mm=(2.0, 3.0), faces=("front",), window_mm=WINDOW, force_nodes=4,
                     height_nodes=0)
    rng = np.random.default_rng(seed)
    p = layout.n_pairs
    a = rng.uniform(0.5, 2.0, p)
    b, c, d = rng.normal(0, 1e-3, (3, p))
    u, v = spec.grid("front")
    F = spec.forces()
    vals = (a + b * u[:, None, None, None] + c * v[None, :, None, None]
            + d * F[None, None, :, None])
    return ResponseField(spec, a, {"front": vals}, {}), (a, b, c, d)


def test_the_field_bound_is_crb_of_the_analytic_jacobian(layout):
    field, (a, b, c, d) = _linear_field(layout)
    rng = np.random.default_rng(2)
    uv = np.c_[rng.uniform(-4, 4, 6), rng.uniform(40, 52, 6)]
    force = rng.uniform(0.4, 1.8, 6)
    P = rng.normal(0, 1e-3, (layout.n_pairs, 2))
    K = rng.normal(0, 1e-3, (layout.n_pairs, 3))
    cols = StateNuisances((0.0, 20.0, 0.0), P, K, 0.07, 0.0)
    got = field_bounds(field, "front", uv, force, columns=cols,
                       prior_sd={"inflation": 1.0, "finger": 2.0})
    J = np.c_[b, c, d]
    for i, (uu, vv) in enumerate(uv):
        C = a + b * uu + c * vv + d * force[i]
        sigma = noise_pf(C, ReadoutConfig())
        fin = (0.07 * (C - a))[:, None]
        full = np.c_[J, P, K, fin]
        refs = {
            "none": crb(J, sigma),
            "push": crb(np.c_[J, P], sigma, nuisance_cols=[3, 4]),
            "inflation": crb(np.c_[J, K], sigma, nuisance_cols=[3, 4, 5],
                             prior_var={3: 1.0, 4: 1.0, 5: 1.0}),
            "finger": crb(np.c_[J, fin], sigma, nuisance_cols=[3], prior_var={3: 4.0}),
            "all": crb(full, sigma, nuisance_cols=range(3, 9),
                       prior_var={5: 1.0, 6: 1.0, 7: 1.0, 8: 4.0}),
        }
        for case, ref in refs.items():
            np.testing.assert_allclose(got[case]["position_mm"][i], np.hypot(*ref.std[:2]),
                                       rtol=1e-6)
            np.testing.assert_allclose(got[case]["force_n"][i], ref.std[2], rtol=1e-6)


def test_maps_and_reductions(layout):
    field, _ = _linear_field(layout)
    maps = field_bound_maps({(0.0, 20.0, 0.0): field}, None, layout, spacing_mm=2.0,
                            nuisances=())
    face = maps["states"][0]["faces"]["front"]
    assert face["u_mm"].tolist() == [-3.0, -1.0, 1.0, 3.0] and len(face["v_mm"]) == 6
    pos = face["contact"]["none"]["position_mm"]
    ref = field_bounds(field, "front", [[-1.0, face["v_mm"][2]]], 1.0, nuisances=())["none"]
    np.testing.assert_allclose(pos[2, 1], ref["position_mm"][0])
    r = reduce(np.array([1.0, 2.0, np.inf, 3.0]), np.array([0.05, 0.2, np.inf, 0.01]))
    assert r["loc_mm_mean"] == 2.0 and r["force_n_mean"] == pytest.approx(0.26 / 3)
    assert r["force_observable_share"] == 0.5 and r["position_resolved_share"] == 0.75
    with pytest.raises(EctskinError, match="force range"):
        field_bound_maps({(0.0, 20.0, 0.0): field}, None, layout, force_n=3.0, nuisances=())
    with pytest.raises(EctskinError, match="nuisance columns"):
        field_bound_maps({(0.0, 20.0, 0.0): field}, None, layout)


# ------------------------------------------------------------------ against the direct bound
#: the field-backed bound against TwinResponse's, relative, per case (module docstring of
#: twin/bound_field.py): u, v, F from the field's splines within a few %; the push and
#: inflation columns of the untouched state and the finger column κ ΔC each within 35 % here
#: (between the wires over the inflated chamber; docs/bound.md gives the errors elsewhere)
TOLERANCE = {"none": 0.03, "push": 0.35, "inflation": 0.35, "finger": 0.35, "all": 0.35}


@pytest.fixture(scope="module")
def built(layout, tmp_path_factory):
    spec = FieldSpec(layout, (0.0, 20.0, 0.0), discretisation=COARSE_FIELD_MESH,
                     spacing_mm=(1.0, 1.0), faces=("front",), window_mm=((-1.0, 3.0), (52.0, 56.0)),
                     force_nodes=6, height_nodes=0)
    return build_field(spec, tmp_path_factory.mktemp("fields"), workers=0, progress=False)


def test_the_field_bound_meets_the_direct_bound(built):
    cols = field_nuisances(built)
    direct = TwinResponse(built.spec.sensor(), built.spec.inflation_ml)
    for uv in [(0.7, 54.3), (2.2, 52.6)]:
        ref = point_bounds(direct, "front", uv, force_n=1.0)
        got = field_bounds(built, "front", [uv], 1.0, columns=cols)
        for case, (pos, force) in ref.items():
            assert got[case]["position_mm"][0] == pytest.approx(pos, rel=TOLERANCE[case]), case
            assert got[case]["force_n"][0] == pytest.approx(force, rel=TOLERANCE[case]), case
        # the nuisances cost information: without them the bound would be far too low
        assert got["push"]["position_mm"][0] > 1.5 * got["none"]["position_mm"][0]


# ------------------------------------------------------------------ the pulp's modulus
def test_a_modulus_column_along_the_force_column_has_a_known_bound(layout):
    """A modulus column exactly k × ∂C/∂F: the force is unresolved with the modulus unknown,
    and with a prior of standard deviation s its variance grows by exactly k² s² (the estimate
    absorbs F + k x; Woodbury), the position's not at all."""
    field, (a, b, c, d) = _linear_field(layout)
    k, s = 0.3, 0.4
    u, v = np.linspace(-4, 4, 4), np.linspace(40, 52, 5)
    forces = np.exp(np.linspace(np.log(0.3), np.log(2.0), 4))
    table = ModulusTable({"front": (u, v)}, forces,
                         {"front": np.broadcast_to(k * d, (4, 5, 4, d.size)).copy()}, 0.1)
    cols = StateNuisances((0.0, 20.0, 0.0), np.zeros((layout.n_pairs, 1)),
                          np.zeros((layout.n_pairs, 3)), 0.0, 0.0, table)
    uv, force = [[0.5, 44.0], [-2.7, 50.5]], [0.6, 1.7]
    got = field_bounds(field, "front", uv, force, columns=cols, nuisances=("modulus",),
                       prior_sd={"modulus": s})
    np.testing.assert_allclose(got["modulus"]["force_n"] ** 2,
                               got["none"]["force_n"] ** 2 + (k * s) ** 2, rtol=1e-6)
    np.testing.assert_allclose(got["modulus"]["position_mm"], got["none"]["position_mm"],
                               rtol=1e-6)
    unknown = field_bounds(field, "front", uv, force, columns=cols, nuisances=("modulus",),
                           prior_sd={})
    assert np.all(np.isinf(unknown["modulus"]["force_n"]))
    assert np.all(np.isfinite(unknown["modulus"]["position_mm"]))
    with pytest.raises(EctskinError, match="modulus table"):
        field_bounds(field, "front", uv, force, nuisances=("modulus",),
                     columns=StateNuisances((0.0, 20.0, 0.0), np.zeros((layout.n_pairs, 1)),
                                            np.zeros((layout.n_pairs, 3)), 0.0, 0.0))


def test_a_nuisance_never_lowers_the_bound():
    """The Fisher-information argument: one more column (with or without a prior) can only
    raise every parameter's bound (or leave it), never lower it."""
    rng = np.random.default_rng(5)
    J = rng.normal(size=(200, 28, 6))
    J[:50, :, 5] = 0.9 * J[:50, :, 2] + 0.05 * rng.normal(size=(50, 28))  # nearly collinear
    s = rng.uniform(0.5, 2.0, (200, 28))
    for var in (np.inf, 0.16):
        without, _ = crb_many(J[:, :, :5], s, n_nuisance=2, prior_var=[np.inf] * 4 + [1.0])
        with_, _ = crb_many(J, s, n_nuisance=3, prior_var=[np.inf] * 4 + [1.0, var])
        assert np.all(with_ >= without * (1 - 1e-12))
        assert np.any(with_[:50, 2] > 1.5 * without[:50, 2])  # and the collinear one costs


def test_the_modulus_table_meets_direct_solves_off_its_nodes(built):
    """The table (direct differences at nodes, cubic in u, v, ln F) against
    ``modulus_column`` at points and forces between its nodes (the column changes quickly with
    the force: with 4 force nodes instead of 6 it misses by 25-50 % here), and that against
    ``TwinResponse``'s own modulus column (a sensor built anew with the modulus E0 e^x)."""
    sensor = built.spec.sensor()
    table = modulus_table(sensor, built.spec.inflation_ml, {"front": ((-1.0, 3.0), (52.0, 56.0))},
                          (0.5, 2.0), spacing_mm=1.0)
    assert table.n_solves == 2 * 25 * 6 and table.forces_n.size == 6
    uv, force = np.array([[0.7, 54.3], [2.2, 52.6]]), np.array([1.1, 0.7])
    direct = modulus_column(sensor, built.spec.inflation_ml, "front", uv, force)
    got = table.column("front", uv, force)
    err = np.linalg.norm(got - direct, axis=1) / np.linalg.norm(direct, axis=1)
    assert np.all(err < 0.1), err
    twin = TwinResponse(sensor, built.spec.inflation_ml)
    _, J, names = finite_difference_jacobian(twin, "front", uv[0], force_n=1.1,
                                             nuisances=("modulus",))
    assert names[-1] == "modulus"
    np.testing.assert_allclose(J[:, -1], direct[0], rtol=1e-9, atol=1e-12)
    with pytest.raises(EctskinError, match="force_nodes"):
        modulus_table(sensor, (0.0, 20.0, 0.0), {"front": ((-1.0, 3.0), (52.0, 56.0))},
                      (0.5, 2.0), force_nodes=3)


def test_the_field_bound_with_the_modulus_meets_the_direct_bound(built):
    """The field's bound with the modulus table against ``TwinResponse``'s direct bound with
    the modulus column of finite differences, and never below the bound without it."""
    cols = field_nuisances(built, finger=False, modulus=True, spacing_mm=1.0)
    direct = TwinResponse(built.spec.sensor(), built.spec.inflation_ml)
    for uv in [(0.7, 54.3), (2.2, 52.6)]:
        ref = point_bounds(direct, "front", uv, force_n=1.0, nuisances=("modulus",))
        got = field_bounds(built, "front", [uv], 1.0, columns=cols, nuisances=("modulus",))
        assert got["modulus"]["force_n"][0] == pytest.approx(ref["modulus"][1], rel=0.1)
        assert got["modulus"]["position_mm"][0] == pytest.approx(ref["modulus"][0], rel=0.1)
        assert got["modulus"]["force_n"][0] >= got["none"]["force_n"][0]
