"""The field's tensor-product spline as the inversion evaluates it (``inversion.spline``): its
values and slopes against SciPy's own evaluation of the same spline (``NdBSpline``), and the
span polynomials against Cox–de Boor's recursion."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import NdBSpline, make_interp_spline

from ectskin.inversion.spline import (
    axis_basis,
    basis_in_span,
    clamped_knots,
    span_polynomials,
    tensor_spline,
)


def _scipy_reference(u, v, x, lo, hi, values):
    """The same interpolant built axis by axis with make_interp_spline, evaluated by NdBSpline."""
    c, ts = values, []
    for ax, (nodes, k, t) in enumerate([(u, min(3, u.size - 1), None),
                                        (v, min(3, v.size - 1), None),
                                        (x, x.size - 1, clamped_knots(lo, hi, x.size - 1))]):
        s = make_interp_spline(nodes, c, k=k, t=t, axis=ax)
        c = np.moveaxis(s.c, 0, ax)
        ts.append(s.t)
    return NdBSpline(tuple(ts), c, (min(3, u.size - 1), min(3, v.size - 1), x.size - 1))


@pytest.mark.parametrize("shape", [(21, 28, 4), (4, 5, 2), (3, 2, 3), (2, 4, 4)])
def test_values_and_slopes_are_scipys(shape):
    rng = np.random.default_rng(sum(shape))
    nu, nv, ns = shape
    u = np.cumsum(rng.uniform(1.0, 3.0, nu)) - 20.0
    v = np.cumsum(rng.uniform(2.0, 5.0, nv))
    x = np.linspace(0.3, 2.0, ns)
    values = rng.standard_normal((nu, nv, ns, 7))
    ours = tensor_spline(u, v, x, 0.3, 2.0, values)
    ref = _scipy_reference(u, v, x, 0.3, 2.0, values)
    # inside the ranges, on the nodes and on the knots
    pts = np.c_[rng.uniform(u[0], u[-1], 300), rng.uniform(v[0], v[-1], 300),
                rng.uniform(0.3, 2.0, 300)]
    pts = np.r_[pts, np.c_[np.resize(u, 3), np.resize(v, 3), x[[0, -1, 0]]]]
    for p in pts:
        d, J = ours(p)
        np.testing.assert_allclose(d, ref(p), rtol=1e-10, atol=1e-12)
        for col, nu_ in enumerate(np.eye(3, dtype=int)):
            np.testing.assert_allclose(J[:, col], ref(p, nu=nu_), rtol=1e-9, atol=1e-10)
    # beyond the ranges: the value and slopes of the nearest point inside
    far = np.array([u[0] - 5.0, v[-1] + 9.0, 3.0])
    inside = np.array([u[0], v[-1], 2.0])
    for a, b in zip(ours(far), ours(inside)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_span_polynomials_are_cox_de_boor(k):
    rng = np.random.default_rng(k)
    nodes = np.cumsum(rng.uniform(0.5, 2.0, 9))
    t = list(make_interp_spline(nodes, nodes, k=k).t)
    at = axis_basis(t, k)
    for i, (t0, inv_h, A) in enumerate(span_polynomials(t, k), start=k):
        for x in np.linspace(t[i], t[i + 1], 7)[:-1]:
            value, slope = basis_in_span(t, k, i, x)
            tau = (x - t0) * inv_h
            np.testing.assert_allclose(tau ** np.arange(k + 1) @ A, value, atol=1e-13)
            span, b, db = at(x)
            assert span == i
            np.testing.assert_allclose(b, value, atol=1e-13)
            np.testing.assert_allclose(db, slope, atol=1e-11)
    # the B-splines alive at x sum to one (a partition of unity)
    for x in rng.uniform(t[k], t[-k - 1], 20):
        assert sum(at(x)[1]) == pytest.approx(1.0, abs=1e-13)
