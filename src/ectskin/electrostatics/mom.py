"""Capacitance of conductors in a homogeneous dielectric by the method of moments (paper Eq. 1).

Each conductor surface is cut into flat parallelogram panels (:class:`~.panels.Panels`) that carry
a uniform charge each. With collocation at the panel centres, the potentials ``phi`` (V) and the
panel charges ``q`` (pC) are related by the potential-coefficient matrix ``P`` (1/pF)::

    phi_i = sum_j P_ij q_j,    P_ij = 1 / (4π ε0 εr A_j) ∫_panel_j dA' / |r_i − r'|      (1)

Setting conductor c to 1 V and all others to 0 V and solving ``P q = B[:, c]`` gives the charges
induced on every conductor; summed per conductor they form column c of the Maxwell (short-circuit)
capacitance matrix ``K`` (pF), ``Q_a = sum_c K_ac V_c``. The ECT readout of electrode pair (i, j)
with electrode i excited and every other conductor held at 0 V is the charge induced on j,
``C_ij = −K_ij`` (paper Eq. 1, ``C = Q / V``).

Units: mm, pF, V, pC; ``ε0 = 8.8541878128e-3 pF/mm``.

Accuracy and speed
------------------
* Near pairs (centre distance below ``near_factor`` × the larger panel diagonal, self terms
  included) use the exact closed-form integral of ``1/R`` over a planar polygon (Wilton et al.,
  IEEE Trans. Antennas Propag. 32(3), 1984, Eq. 5 with the in-plane edge form), evaluated for the
  parallelogram itself; on the panel plane it reduces to the classic rectangle self term
  ``2[a ln((b+d)/a) + b ln((a+d)/b)]``, d = √(a²+b²), at the centre of an a × b rectangle.
* Far pairs use the point-charge approximation ``A_j / |r_i − r_j|``; with the default
  ``near_factor = 3`` its relative error is below ``1 / (12 · 3²) ≈ 0.9 %`` for the worst
  (elongated) panel and falls as 1 / distance²; the resulting capacitances agree with an
  all-exact matrix to 0.1–0.2 % (see the tests).
* Everything is vectorised: one N × N expression for the far field, an index list for near
  pairs, then a Cholesky factorisation (``P`` is symmetrised, ``P ← (P + Pᵀ)/2``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Literal, overload

import numpy as np
import scipy.linalg
from scipy.spatial.distance import cdist

from ectskin._check import EctskinError, check_array
from ectskin.electrostatics.panels import Panels, cross3

logger = logging.getLogger(__name__)

#: Vacuum permittivity, pF/mm.
EPS0_PF_PER_MM = 8.8541878128e-3

#: Pairs closer than this many (larger) panel diagonals use the exact panel integral.
NEAR_FACTOR = 3.0


# ====================================================================== exact panel integral
def potential_integral(points, centres, u, v) -> np.ndarray:
    """Exact ``∫_panel dA' / |p − r'|`` (mm) for M (point, parallelogram panel) pairs.

    Parameters
    ----------
    points : (M, 3) mm
        Observation points ``p``.
    centres, u, v : (M, 3) mm
        Panels ``centre ± u/2 ± v/2`` (one per point; broadcast them with indexing).

    Returns
    -------
    (M,) mm
        The integral; divide by ``4π ε0 εr A`` for the potential (V) of 1 pC spread uniformly.

    The polygon formula (Wilton et al. 1984): with ``h`` the height of p above the panel plane
    and, for each edge k, ``t_k`` the in-plane distance from the projection of p to the edge line
    (positive on the inner side), ``l±`` the signed distances along the edge from the foot of that
    perpendicular to the edge's end points and ``R±`` the distances from p to them,
    ``R0² = t_k² + h²``::

        ∫ dA/R = Σ_k t_k ln((R+ + l+)/(R− + l−))
                 − |h| Σ_k [atan(t_k l+ / (R0² + |h| R+)) − atan(t_k l− / (R0² + |h| R−))]

    Points on the panel plane, on an edge line or at a corner are handled: an edge whose line
    passes through the projected point contributes zero (t_k = 0).
    """
    p = check_array("points", points, (None, 3))
    m = p.shape[0]
    c = check_array("centres", centres, (m, 3))
    frames = _panel_frames(check_array("u", u, (m, 3)), check_array("v", v, (m, 3)))
    return _integral(c - p, frames)


def _panel_frames(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per-panel constants of the polygon formula for parallelograms ``± u/2 ± v/2``, (N, 23).

    Columns 0–14: the frame rows (û, v̂, m_u, m_v, n̂), with n̂ = u × v / |u × v|,
    m_u = û × n̂ and m_v = v̂ × n̂ the in-plane outward normals of the edges c0→c1 and c1→c2.
    The edges k = 0..3 run c_k → c_k+1 with c0 = −u/2 − v/2, c1 = u/2 − v/2, c2 = u/2 + v/2,
    c3 = −u/2 + v/2 (relative to the centre), directions s_k = (û, v̂, −û, −v̂) and outward
    normals m_k = (m_u, m_v, −m_u, −m_v). Columns 15–16: ``c_k·m_k`` for k even / odd; 17–18:
    ``c_k·s_k`` for k even / odd; 19–20: (|u|/2, |v|/2); 21–22: ``|c_k|²`` for k even / odd.
    """
    lu = np.linalg.norm(u, axis=1)
    lv = np.linalg.norm(v, axis=1)
    eu = u / lu[:, None]
    ev = v / lv[:, None]
    n = cross3(u, v)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    mu = cross3(eu, n)
    mv = cross3(ev, n)
    hu = 0.5 * u
    hv = 0.5 * v
    huv = np.einsum("nj,nj->n", hu, hv)
    hh = np.einsum("nj,nj->n", hu, hu) + np.einsum("nj,nj->n", hv, hv)
    out = np.empty((u.shape[0], 23))
    out[:, 0:15] = np.stack([eu, ev, mu, mv, n], axis=1).reshape(-1, 15)
    out[:, 15] = -np.einsum("nj,nj->n", hv, mu)  # c0·m_u = c2·(−m_u)   (hu ⊥ m_u)
    out[:, 16] = np.einsum("nj,nj->n", hu, mv)  # c1·m_v = c3·(−m_v)   (hv ⊥ m_v)
    out[:, 17] = -0.5 * lu - np.einsum("nj,nj->n", hv, eu)  # c0·û = c2·(−û)
    out[:, 18] = np.einsum("nj,nj->n", hu, ev) - 0.5 * lv  # c1·v̂ = c3·(−v̂)
    out[:, 19] = 0.5 * lu
    out[:, 20] = 0.5 * lv
    out[:, 21] = hh + 2.0 * huv  # |c0|² = |c2|²
    out[:, 22] = hh - 2.0 * huv  # |c1|² = |c3|²
    return out


#: :func:`_integral` evaluates this many pairs at a time (its temporaries stay in the cache)
_CHUNK = 8192


def _integral(rel0: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """The polygon formula for M pairs: ``rel0`` (M, 3) = panel centre − point, ``frames``
    (M, 23) the rows of :func:`_panel_frames` for each pair's panel (:func:`_integral_columns`
    of their columns, :data:`_CHUNK` pairs at a time: each pair's arithmetic is its own, so
    the numbers are the same)."""
    m = rel0.shape[0]
    if m <= _CHUNK:
        return _integral_columns(rel0.T, frames.T)
    out = np.empty(m)
    for s in range(0, m, _CHUNK):
        out[s : s + _CHUNK] = _integral_columns(rel0[s : s + _CHUNK].T, frames[s : s + _CHUNK].T)
    return out


def pair_integrals(
    points: np.ndarray, ip: np.ndarray, centres: np.ndarray, frames_t: np.ndarray, jp: np.ndarray
) -> np.ndarray:
    """(M,) ``∫_panel dA' / |p − r'|`` of point ``points[ip[k]]`` over panel ``jp[k]`` (centres
    (N, 3), ``frames_t`` (23, N): :func:`_panel_frames` of the panels, transposed and
    contiguous): :func:`_integral` of the pairs, gathered :data:`_CHUNK` pairs at a time into
    contiguous columns (the same numbers as gathering all the pairs' rows first)."""
    pts, cen = np.ascontiguousarray(points.T), np.ascontiguousarray(centres.T)  # (3, ·)
    m = ip.size
    out = np.empty(m)
    for s in range(0, m, _CHUNK):
        i, j = ip[s : s + _CHUNK], jp[s : s + _CHUNK]
        rel = cen.take(j, axis=1) - pts.take(i, axis=1)
        out[s : s + _CHUNK] = _integral_columns(rel, frames_t.take(j, axis=1))
    return out


def _integral_columns(rel: np.ndarray, f: np.ndarray) -> np.ndarray:
    """:func:`_integral` of the columns: ``rel`` (3, M) and ``f`` (23, M) (contiguous rows are
    the fastest: each is read several times).

    See :func:`potential_integral`. Everything is (M,) arithmetic on the projections of ``rel``
    onto the panel frame, one edge at a time; ``ln((R+ + l+)/(R− + l−))`` is evaluated as
    ``asinh(l+/R0) − asinh(l−/R0)`` (since R = √(R0² + l²)), which has no cancellation for
    either sign of l.
    """
    rx, ry, rz = rel[0], rel[1], rel[2]
    # rel0·(û, v̂, m_u, m_v, n̂)
    du = rx * f[0] + ry * f[1] + rz * f[2]
    dv = rx * f[3] + ry * f[4] + rz * f[5]
    dmu = rx * f[6] + ry * f[7] + rz * f[8]
    dmv = rx * f[9] + ry * f[10] + rz * f[11]
    h = np.abs(rx * f[12] + ry * f[13] + rz * f[14])  # height of the point above the panel plane
    hh = h * h
    # R at corner k: |rel0 + c_k|² = |rel0|² + 2 rel0·c_k + |c_k|², rel0·c_k = ±|u|/2 du ± |v|/2 dv
    rel_sq = rx * rx + ry * ry + rz * rz
    half_u, half_v = f[19], f[20]
    ab = half_u * du + half_v * dv
    a_b = half_u * du - half_v * dv
    e0 = rel_sq + f[21]
    e1 = rel_sq + f[22]
    r = (
        np.sqrt(np.maximum(e0 - 2.0 * ab, 0.0)),
        np.sqrt(np.maximum(e1 + 2.0 * a_b, 0.0)),
        np.sqrt(np.maximum(e0 + 2.0 * ab, 0.0)),
        np.sqrt(np.maximum(e1 - 2.0 * a_b, 0.0)),
    )
    # edge k: t_k = (rel0 + c_k)·m_k, l−_k = (rel0 + c_k)·s_k, l+_k = l−_k + edge length
    t_all = (dmu + f[15], dmv + f[16], f[15] - dmu, f[16] - dmv)
    lm_all = (du + f[17], dv + f[18], f[17] - du, f[18] - dv)
    edge = (2.0 * half_u, 2.0 * half_v)
    total = np.zeros(rx.shape[0])
    for k in range(4):
        t = t_all[k]
        lm = lm_all[k]
        lp = lm + edge[k % 2]
        rm = r[k]
        rp = r[(k + 1) % 4]
        r0sq = t * t + hh
        r0 = np.sqrt(r0sq)
        # R0 = 0 only when t = 0 (and h = 0): that edge contributes t · (…) = 0
        r0 = np.where(r0 > 0.0, r0, 1.0)
        log_term = np.arcsinh(lp / r0) - np.arcsinh(lm / r0)
        # atan(y1/x1) − atan(y2/x2) with x ≥ 0 as one atan2 (the difference lies in (−π, π))
        x1 = r0sq + h * rp
        x2 = r0sq + h * rm
        y1 = t * lp
        y2 = t * lm
        atan_term = np.arctan2(y1 * x2 - y2 * x1, x1 * x2 + y1 * y2)
        total += t * log_term - h * atan_term
    return total


# ====================================================================== potential matrix
def potential_matrix(
    panels: Panels,
    eps_r: float = 1.0,
    *,
    near_factor: float = NEAR_FACTOR,
    blocks: Sequence[tuple[int, np.ndarray]] = (),
) -> np.ndarray:
    """(N, N) potential coefficients P (1/pF = V/pC), Eq. (1), symmetrised.

    ``P[i, j]`` is the potential at the centre of panel i due to 1 pC spread uniformly over
    panel j in a dielectric of relative permittivity ``eps_r``. Pairs whose centre distance is
    below ``near_factor`` times the larger of the two panel diagonals (:attr:`Panels.sizes`),
    including each panel with itself, use the exact integral :func:`potential_integral`; all
    others use the point-charge approximation ``1 / (4π ε0 εr |r_i − r_j|)``. Finally
    ``P ← (P + Pᵀ) / 2``.

    ``blocks``: (start, D) pairs, D an (m, m) matrix: the panels ``start .. start + m − 1`` are a
    rigid motion of panels whose own potential matrix (the same ``eps_r`` and ``near_factor``)
    is D, so their mutual entries are taken from D instead of computed (a fingertip pressed
    anywhere on the sensor: its own block depends only on its shape). P depends only on the
    panels' relative geometry, so this is the same matrix to round-off; every other entry is
    computed as without ``blocks``, bit for bit.
    """
    if not isinstance(panels, Panels):
        raise EctskinError(f"panels must be Panels, got {type(panels).__name__}")
    eps_r = _positive("eps_r", eps_r)
    near_factor = _positive("near_factor", near_factor)
    n = panels.n_panels
    if n == 0:
        raise EctskinError("potential_matrix: panels is empty (0 panels)")
    known = _block_ids(n, blocks)
    c = panels.centres
    areas = panels.areas
    reach = near_factor * panels.sizes
    dist = cdist(c, c)  # (N, N) mm, symmetric
    # near pairs i <= j, as index lists: |r_i − r_j| < near_factor · max(size_i, size_j)
    ii, jj = np.nonzero(dist < np.maximum(reach[:, None], reach[None, :]))
    upper = ii <= jj
    if known is not None:  # pairs inside a given block are not computed
        upper &= (known[ii] < 0) | (known[ii] != known[jj])
    ii, jj = ii[upper], jj[upper]
    scale = 0.5 / (4.0 * np.pi * EPS0_PF_PER_MM * eps_r)
    # far field: P_ij ≈ 1 / |r_i − r_j|, symmetric: (P¹ + P¹ᵀ) / 2 is P¹ (×2 × ½ applied as one)
    with np.errstate(divide="ignore"):
        P = np.divide(1.0, dist, out=dist)
    P *= 2.0 * scale
    # near field: exact (1/A_j) ∫ dA'/|r_i − r'| both ways, then symmetrised
    frames = np.ascontiguousarray(_panel_frames(panels.u, panels.v).T)  # (23, N)
    both_i, both_j = np.concatenate([ii, jj]), np.concatenate([jj, ii])
    one_way = pair_integrals(c, both_i, c, frames, both_j) / areas.take(both_j)
    m = ii.size
    sym = (one_way[:m] + one_way[m:]) * scale
    P[ii, jj] = sym
    P[jj, ii] = sym
    for start, D in blocks:
        P[start : start + D.shape[0], start : start + D.shape[0]] = D
    if logger.isEnabledFor(logging.DEBUG):
        logger.debug("potential_matrix: %d panels, %d near pairs", n, 2 * m - np.sum(ii == jj))
    return P


def _block_ids(n: int, blocks: Sequence[tuple[int, np.ndarray]]) -> np.ndarray | None:
    """(n,) the index of the given block (:func:`potential_matrix`'s ``blocks``) each panel
    lies in, −1 for none; None without blocks. Blocks must be square, finite, inside the n
    panels and must not overlap."""
    if not blocks:
        return None
    ids = np.full(n, -1)
    for k, item in enumerate(blocks):
        try:
            start, D = item
        except (TypeError, ValueError):
            raise EctskinError(
                f"potential_matrix: blocks[{k}] must be a (start, D) pair, got {item!r:.60}"
            ) from None
        D = np.asarray(D)
        if isinstance(start, bool) or not isinstance(start, int | np.integer):
            raise EctskinError(f"potential_matrix: blocks[{k}] start must be an int, got {start!r}")
        m = D.shape[0] if D.ndim == 2 else -1
        if D.ndim != 2 or D.shape[1] != m or m < 1 or not 0 <= start <= n - m:
            raise EctskinError(
                f"potential_matrix: blocks[{k}] must be a square (m, m) matrix of panels "
                f"start .. start + m − 1 within the {n} panels, got start {start} and shape "
                f"{D.shape}"
            )
        if np.any(ids[start : start + m] >= 0):
            raise EctskinError(f"potential_matrix: blocks[{k}] overlaps another block")
        if not np.all(np.isfinite(D)):
            raise EctskinError(f"potential_matrix: blocks[{k}] has non-finite entries")
        ids[start : start + m] = k
    return ids


# ====================================================================== capacitance
@overload
def maxwell_capacitance(
    panels: Panels,
    eps_r: float = ...,
    *,
    near_factor: float = ...,
    return_charges: Literal[False] = ...,
    blocks: Sequence[tuple[int, np.ndarray]] = ...,
) -> np.ndarray: ...


@overload
def maxwell_capacitance(
    panels: Panels,
    eps_r: float = ...,
    *,
    near_factor: float = ...,
    return_charges: Literal[True],
    blocks: Sequence[tuple[int, np.ndarray]] = ...,
) -> tuple[np.ndarray, np.ndarray]: ...


def maxwell_capacitance(
    panels: Panels,
    eps_r: float = 1.0,
    *,
    near_factor: float = NEAR_FACTOR,
    return_charges: bool = False,
    blocks: Sequence[tuple[int, np.ndarray]] = (),
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """(n_conductors, n_conductors) Maxwell (short-circuit) capacitance matrix K, pF.

    ``K[a, c]`` is the charge (pC) on conductor a when conductor c is at 1 V and all the others
    are at 0 V: solve ``P q = B`` with ``B[i, c] = 1`` for panels i of conductor c (Cholesky of the
    symmetric positive-definite P of :func:`potential_matrix`) and sum q over each conductor's
    panels. K is symmetric (symmetrised here against round-off), ``K[a, a] > 0``,
    ``K[a, b] < 0`` for a ≠ b and every row sums to ≥ 0 (the charge induced at infinity).

    With ``return_charges=True`` also returns the panel charges q, (N, n_conductors) pC.
    ``blocks``: known diagonal blocks of P (:func:`potential_matrix`).
    """
    if not isinstance(panels, Panels):
        raise EctskinError(f"panels must be Panels, got {type(panels).__name__}")
    counts = np.bincount(panels.conductor, minlength=panels.n_conductors)
    if np.any(counts == 0):
        empty = np.flatnonzero(counts == 0).tolist()
        raise EctskinError(
            f"maxwell_capacitance: conductor(s) {empty} have no panels "
            f"(n_conductors={panels.n_conductors}); every conductor needs at least one panel"
        )
    P = potential_matrix(panels, eps_r, near_factor=near_factor, blocks=blocks)
    if not np.all(np.isfinite(P)):
        i, j = np.argwhere(~np.isfinite(P))[0]
        raise EctskinError(
            f"maxwell_capacitance: potential coefficient P[{i}, {j}] is not finite; panels {i} "
            f"and {j} (centres {panels.centres[i].tolist()}, {panels.centres[j].tolist()} mm) "
            "coincide"
        )
    try:
        factor = scipy.linalg.cho_factor(P, lower=False, overwrite_a=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise EctskinError(
            "maxwell_capacitance: the potential matrix is not positive definite; panels of "
            "different conductors probably overlap or touch (two conductors in contact are one "
            "conductor); keep a gap of at least about one panel size between conductors"
        ) from None
    n = panels.n_panels
    B = np.zeros((n, panels.n_conductors))
    B[np.arange(n), panels.conductor] = 1.0
    q = scipy.linalg.cho_solve(factor, B, check_finite=False)  # (N, n_conductors) pC per V
    K = B.T @ q  # K[a, c] = Σ_{i ∈ a} q[i, c]
    K = 0.5 * (K + K.T)
    return (K, q) if return_charges else K


def field_at(panels: Panels, charges, points, eps_r: float = 1.0) -> np.ndarray:
    """(M, 3, n_columns) electric field (V/mm) at ``points`` of the panel charges.

    ``charges`` is (N, n_columns) pC, e.g. the per-excitation charges of
    :func:`maxwell_capacitance` (``return_charges=True``); each panel's charge is taken as a point
    charge at its centre, so the points should lie at least a panel size or two from every panel.
    """
    if not isinstance(panels, Panels):
        raise EctskinError(f"panels must be Panels, got {type(panels).__name__}")
    eps_r = _positive("eps_r", eps_r)
    q = np.asarray(charges, dtype=np.float64)
    if q.ndim != 2 or q.shape[0] != panels.n_panels:
        raise EctskinError(
            f"charges must have shape ({panels.n_panels}, n_columns), got {q.shape}"
        )
    r = check_array("points", points, (None, 3), finite=True)
    c = panels.centres
    # |r − c|² = |r|² + |c|² − 2 r·c, and Σ_i q_i (r − c_i) w_i = r Σ_i q_i w_i − Σ_i c_i q_i w_i
    # with w = 1 / |r − c|³: one (M, N) matrix and one BLAS product instead of three of each
    # (3x faster; the points lie a panel size or more from every panel, so the cancellations cost
    # about 1e-15 of the field)
    d2 = r @ (-2.0 * c.T)
    d2 += np.einsum("ij,ij->i", r, r)[:, None]
    d2 += np.einsum("ij,ij->i", c, c)[None, :]
    w = np.sqrt(d2)
    w *= d2
    np.divide(1.0, w, out=w)  # 1 / |r − c|³, (M, N)
    n = q.shape[1]
    sums = w @ np.concatenate([q, c[:, 0, None] * q, c[:, 1, None] * q, c[:, 2, None] * q], axis=1)
    E = np.stack([r[:, k, None] * sums[:, :n] - sums[:, (k + 1) * n : (k + 2) * n]
                  for k in range(3)], axis=1)  # (M, 3, n_columns)
    E /= 4.0 * np.pi * EPS0_PF_PER_MM * eps_r
    return E


def dielectric_sensitivity(panels: Panels, charges, points, volumes, eps_r: float = 1.0) -> np.ndarray:
    """(n_columns, n_columns) ECT sensitivity ``S_ac = ∫ E_a · E_c dV`` over sample volumes, mm·(V/mm)².

    First-order (linearised, "sensitivity map") change of the Maxwell capacitance matrix when the
    relative permittivity inside the sampled volume changes by δε (uniformly):
    ``δK = ε0 δε S`` (pF), because ``K_ac = ∫ ε ∇φ_a · ∇φ_c dV`` is stationary in the potentials
    φ_c (conductor c at 1 V, the others at 0 V; ``E_c = −∇φ_c`` from the charges of column c).
    An ECT pair's readout ``C_ij = −K_ij`` thus falls where δε < 0 lies between electrodes i and j
    (E_i · E_j < 0 there). ``points`` (M, 3) mm are the centres of sample cells of ``volumes``
    (M,) mm³.
    """
    vol = np.asarray(volumes, dtype=np.float64).reshape(-1)
    E = field_at(panels, charges, points, eps_r)
    if vol.shape[0] != E.shape[0] or np.any(~np.isfinite(vol)) or np.any(vol < 0):
        raise EctskinError(
            f"volumes must be {E.shape[0]} finite non-negative cell volumes (mm^3), got shape "
            f"{vol.shape}"
        )
    Ew = E * vol[:, None, None]
    return Ew.reshape(-1, E.shape[2]).T @ E.reshape(-1, E.shape[2])


def ect_readout(K, electrodes, pairs) -> np.ndarray:
    """(n_pairs,) ECT pair capacitances ``C = −K[e_i, e_j]``, pF (paper Eq. 1).

    Parameters
    ----------
    K : (n_conductors, n_conductors) pF
        Maxwell capacitance matrix from :func:`maxwell_capacitance`.
    electrodes : (n_electrodes,) int
        Conductor index (row of K) of each electrode, in layout order.
    pairs : (n_pairs, 2) int
        Electrode indices (0-based, into ``electrodes``) of each pair, e.g.
        :attr:`SensorLayout.pairs`.

    The readout excites electrode i with V and holds every other conductor at 0 V: the other
    electrodes through the virtual-ground charge amplifier, and any extra conductor in K (a
    grounded finger) too. The charge measured on electrode j is then ``Q_j = K_ji V``, so
    ``C_ij = Q / V`` with the sign of a capacitance is ``−K_ij``.
    """
    K = check_array("K", K, (None, None), finite=True)
    if K.shape[0] != K.shape[1]:
        raise EctskinError(f"K must be a square (n_conductors, n_conductors) array, got {K.shape}")
    e = _index_array("electrodes", electrodes, K.shape[0], "conductor", ndim=1)
    p = _index_array("pairs", pairs, e.shape[0], "electrode", ndim=2)
    if p.shape[1] != 2:
        raise EctskinError(f"pairs must have shape (n_pairs, 2), got {p.shape}")
    if np.any(p[:, 0] == p[:, 1]):
        k = int(np.flatnonzero(p[:, 0] == p[:, 1])[0])
        raise EctskinError(f"pairs[{k}] pairs electrode {int(p[k, 0])} with itself")
    return -K[e[p[:, 0]], e[p[:, 1]]]


def two_terminal_capacitance(K, a: int, b: int) -> float:
    """Capacitance (pF) between conductors a and b, floating with charges +Q and −Q.

    Every other conductor in K stays at 0 V (when K holds only a and b this is the classic
    two-conductor capacitance). From the 2 × 2 block ``[[K_aa, K_ab], [K_ab, K_bb]]``, with
    ``Q = K_aa V_a + K_ab V_b = −(K_ab V_a + K_bb V_b)`` and ``C = Q / (V_a − V_b)``::

        C = (K_aa K_bb − K_ab²) / (K_aa + K_bb + 2 K_ab)

    For two long parallel wires this is the textbook ``π ε L / arccosh(d / 2a)``.
    """
    K = check_array("K", K, (None, None), finite=True)
    if K.shape[0] != K.shape[1]:
        raise EctskinError(f"K must be a square (n_conductors, n_conductors) array, got {K.shape}")
    for name, idx in (("a", a), ("b", b)):
        if isinstance(idx, (bool, np.bool_)) or not isinstance(idx, (int, np.integer)):
            raise EctskinError(f"{name} must be a conductor index (int), got {idx!r:.60}")
        if not 0 <= int(idx) < K.shape[0]:
            raise EctskinError(f"{name} must be in 0..{K.shape[0] - 1}, got {int(idx)}")
    if a == b:
        raise EctskinError(f"two_terminal_capacitance needs two different conductors, got {a}, {b}")
    kaa, kbb, kab = K[a, a], K[b, b], 0.5 * (K[a, b] + K[b, a])
    den = kaa + kbb + 2.0 * kab
    if not den > 0:
        raise EctskinError(
            f"two_terminal_capacitance: K_aa + K_bb + 2 K_ab = {den:.4g} pF must be > 0 "
            "(is K a Maxwell capacitance matrix?)"
        )
    return float((kaa * kbb - kab * kab) / den)


# ====================================================================== small checks
def _positive(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise EctskinError(f"{name} must be a positive number, got {value!r:.60}") from None
    if not (np.isfinite(x) and x > 0):
        raise EctskinError(f"{name} must be a positive finite number, got {x}")
    return x


def _index_array(name: str, value, bound: int, what: str, ndim: int) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise EctskinError(f"{name} must hold integer {what} indices, got dtype {arr.dtype}")
    if arr.ndim != ndim:
        raise EctskinError(f"{name} must be a {ndim}-d array of {what} indices, got {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() >= bound):
        bad = tuple(int(i) for i in np.argwhere((arr < 0) | (arr >= bound))[0])
        raise EctskinError(
            f"{name}{list(bad)} = {int(arr[bad])} is not a valid {what} index (0..{bound - 1})"
        )
    return arr.astype(np.int64)
