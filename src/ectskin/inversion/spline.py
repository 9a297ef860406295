"""The response field's tensor-product spline, evaluated at one point with its three slopes.

A field interpolates each pair's signal over (u, v, s) with cubic not-a-knot B-splines in u and
v and one polynomial piece in s (the force, or ln height, between clamped knots). The inversion
evaluates it some 10⁴–10⁵ times a second of stream, each time at one point, so the cost of one
call is the live engine's budget. The B-splines alive on a knot span are polynomials there: each
span's are turned once (:func:`span_polynomials`) into monomials of the span's own coordinate
τ = (x − t_i) / (t_{i+1} − t_i), and a call evaluates k + 1 powers of τ and one small product per
axis instead of Cox–de Boor's recursion (:func:`basis_in_span`, The NURBS Book A2.2/A2.3, which
cost more than the contraction with the coefficients itself). Both give the same numbers to
rounding (``tests/inversion/test_spline.py``).
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence
from operator import mul

import numpy as np
from scipy.interpolate import make_interp_spline

from ectskin._check import EctskinError

#: Δ and ∂Δ/∂(u, v, s) of one face and mode at one point x = (u, v, s): ((n_pairs,), (n_pairs, 3))
Signal = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
#: one axis: x → (the span i, the live B-splines B_{i-k} … B_i at x, their slopes)
AxisBasis = Callable[[float], tuple[int, list[float], list[float]]]


def clamped_knots(lo: float, hi: float, k: int) -> np.ndarray:
    """The knots of one polynomial piece of degree k on [lo, hi] (its B-splines: Bernstein's)."""
    return np.r_[[lo] * (k + 1), [hi] * (k + 1)]


def basis_in_span(t: Sequence[float], k: int, i: int, x: float) -> tuple[list[float], list[float]]:
    """The values and first derivatives at x of the k+1 B-splines of degree k alive on span i
    (t[i] <= x < t[i+1]; x may lie outside, the span's polynomials then extended),
    B_{i-k} … B_i: Cox–de Boor's recursion."""
    left = [x - t[i + 1 - j] for j in range(1, k + 1)]
    right = [t[i + j] - x for j in range(1, k + 1)]
    n = [1.0]
    low = n
    for d in range(1, k + 1):
        low = n
        saved = 0.0
        n = []
        for r in range(d):
            tmp = low[r] / (right[r] + left[d - r - 1])
            n.append(saved + right[r] * tmp)
            saved = left[d - r - 1] * tmp
        n.append(saved)
    # slopes from the degree k-1 functions (zero beyond the live ones)
    lk = [0.0] + list(low) + [0.0] if k else [0.0, 0.0]
    der = []
    for r in range(k + 1):
        j = i - k + r
        a = lk[r] / (t[j + k] - t[j]) if k and t[j + k] > t[j] else 0.0
        b = lk[r + 1] / (t[j + k + 1] - t[j + 1]) if k and t[j + k + 1] > t[j + 1] else 0.0
        der.append(k * (a - b))
    return n, der


def span_polynomials(t: Sequence[float], k: int) -> list[tuple[float, float, np.ndarray]]:
    """Per span i = k … len(t) − k − 2: (t_i, 1 / h_i, A (k+1, k+1)) with the live B-splines
    there B_{i-k+a}(x) = Σ_j τ^j A[j, a], τ = (x − t_i) / h_i, h_i = t_{i+1} − t_i (a span of no
    length gets A = 0: no x falls in it). A is solved from the B-splines at k + 1 points inside
    the span (a Vandermonde system in τ ∈ (0, 1), well conditioned for the cubic)."""
    out = []
    tau = (np.arange(k + 1) + 0.5) / (k + 1)
    vander = np.vander(tau, k + 1, increasing=True)
    for i in range(k, len(t) - k - 1):
        h = t[i + 1] - t[i]
        if h <= 0:
            out.append((float(t[i]), 0.0, np.zeros((k + 1, k + 1))))
            continue
        values = np.array([basis_in_span(t, k, i, t[i] + a * h)[0] for a in tau])
        out.append((float(t[i]), 1.0 / h, np.linalg.solve(vander, values)))
    return out


def axis_basis(t: Sequence[float], k: int) -> AxisBasis:
    """One axis of a spline with knots ``t`` and degree ``k``: x → (span i, the live B-splines
    at x clamped into [t[k], t[-k-1]], their slopes), the two as lists (plain floats: a call's
    few products cost less than one array's making)."""
    knots = [float(a) for a in t]
    # per span, A's columns: B_a = Σ_j τ^j A[j, a]
    cols = [(t0, inv_h, [tuple(float(c) for c in col) for col in A.T])
            for t0, inv_h, A in span_polynomials(knots, k)]
    lo, hi, last = knots[k], knots[-k - 1], len(knots) - k - 2
    powers = range(1, k + 1)

    def at(x: float) -> tuple[int, list[float], list[float]]:
        x = min(max(x, lo), hi)
        i = min(max(bisect.bisect_right(knots, x) - 1, k), last)
        t0, inv_h, A = cols[i - k]
        tau = (x - t0) * inv_h
        m = [1.0]
        dm = [0.0]
        for j in powers:
            dm.append(j * inv_h * m[-1])
            m.append(m[-1] * tau)
        return i, [sum(map(mul, m, c)) for c in A], [sum(map(mul, dm, c)) for c in A]

    return at


def tensor_spline(u: np.ndarray, v: np.ndarray, x: np.ndarray, lo: float, hi: float,
                  values: np.ndarray) -> Signal:
    """The interpolant of ``values`` (n_u, n_v, n_s, q) over the nodes (u, v, s) as the field
    builds it (cubic not-a-knot in u and v, the polynomial through the s nodes on [lo, hi]), and
    its three slopes: p = (u, v, s) → ((q,), (q, 3)); beyond the nodes' ranges the value and
    slopes of the nearest point inside."""
    c = values
    bases: list[AxisBasis] = []
    ks = []
    for ax, (nodes, k, t) in enumerate(
        [(u, min(3, u.size - 1), None), (v, min(3, v.size - 1), None),
         (x, x.size - 1, clamped_knots(lo, hi, x.size - 1))]
    ):
        s = make_interp_spline(nodes, c, k=k, t=t, axis=ax)
        c = np.moveaxis(s.c, 0, ax)
        bases.append(axis_basis(s.t, k))
        ks.append(k)
    coef = np.ascontiguousarray(c)
    n_pairs = coef.shape[-1]
    (ku, kv, k_s), (bu_at, bv_at, bs_at) = ks, bases
    if coef.shape[2] != k_s + 1:  # s is one polynomial piece: every coefficient along s is live
        raise EctskinError(f"tensor_spline: {coef.shape[2]} coefficients along s for one piece "
                           f"of degree {k_s}")

    def signal(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # the k+1 live basis functions of each axis and their slopes, contracted with the live
        # block of coefficients: rows u·v, u'·v, u·v', then along s the function and its slope
        iu, bu, du = bu_at(float(p[0]))
        iv, bv, dv = bv_at(float(p[1]))
        _, bs, ds = bs_at(float(p[2]))
        w = (np.array((bu, du, bu))[:, :, None] * np.array((bv, bv, dv))[:, None, :]).reshape(3, -1)
        block = coef[iu - ku: iu + 1, iv - kv: iv + 1].reshape(w.shape[1], -1)
        z = (np.array((bs, ds)) @ (w @ block).reshape(3, k_s + 1, n_pairs)).reshape(6, n_pairs)
        # z's rows: (u·v, u'·v, u·v') × (s, s'); ∂/∂u, ∂/∂v, ∂/∂s as the columns
        return z[0], z[[2, 4, 1]].T

    return signal
