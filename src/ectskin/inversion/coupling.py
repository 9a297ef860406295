"""Two fingers as two coupled grounded conductors, from the fields of one finger.

A grounded finger lowers the mutual capacitances of the electrodes by a Schur complement of the
Maxwell matrix (paper Eq. 1): lumped to one node per finger, ΔC_ij ≈ −g_i g_j with g (n_e,) the
finger's couplings to the electrodes scaled by its own capacitance, so one finger's signal over
the pairs is a rank-one pattern. Two fingers are two such nodes whose own 2 × 2 block couples
them (directly, and through the electrodes they both face): with ρ their normalised coupling,

    ΔC_ij = −[G S⁻¹ Gᵀ]_ij,   G = [g_a g_b],   S = [[1, ρ], [ρ, 1]],

which is the superposition of the two signals at ρ = 0 and less than it for ρ > 0 (the fingers
shield each other). The inversion keeps each finger's exact signal from its field and adds only
the coupling's share,

    Δ_ab = Δ_a + Δ_b + c(ρ),   c_ij = −(ρ² A_ij − ρ B_ij) / (1 − ρ²),
    A = g_a g_aᵀ + g_b g_bᵀ,   B = g_a g_bᵀ + g_b g_aᵀ,

with ρ fitted (one more parameter of the two-finger fit). g is the rank-one factor of the
field's node signals (:func:`rank_one`), interpolated between the nodes like the signals.

The pairs are the electrodes' pairs in the layout's fixed order (1,2), (1,3) … (n−1,n)
(DESIGN.md), so n_e follows from n_pairs = n_e (n_e − 1) / 2.
"""

from __future__ import annotations

import math

import numpy as np

from ectskin._check import EctskinError

#: ρ stays below this (S is singular at 1)
RHO_MAX = 0.95
#: iterations of the rank-one factorisation (each refills the unknown diagonal)
RANK_ONE_ITERATIONS = 12
#: Gauss–Newton steps that polish the factor
GAUSS_NEWTON_STEPS = 4


def electrode_pairs(n_pairs: int) -> tuple[np.ndarray, np.ndarray]:
    """The electrode indices (i (n_pairs,), j (n_pairs,)) of each pair, i < j, in the layout's
    order."""
    n_e = int(round((1 + math.sqrt(1 + 8 * n_pairs)) / 2))
    if n_e * (n_e - 1) // 2 != n_pairs:
        raise EctskinError(
            f"coupling: {n_pairs} channels are not the pairs of a set of electrodes "
            "(n (n − 1) / 2); the two-finger coupling needs them"
        )
    i, j = np.triu_indices(n_e, k=1)
    return i, j


def rank_one(delta: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """g (..., n_e) >= 0 with −delta_ij ≈ g_i g_j for every pair of ``delta`` (..., n_pairs).

    The symmetric matrix −Δ has unknown diagonal; it is filled with g_i² of the current factor
    and the leading eigenvector taken, :data:`RANK_ONE_ITERATIONS` times (from the diagonal
    filled with each row's mean); then Gauss–Newton steps on Σ (g_i g_j + Δ_ij)² polish it."""
    i, j = pairs
    n_e = int(max(i.max(), j.max())) + 1
    lead = delta.shape[:-1]
    M = np.zeros(lead + (n_e, n_e))
    M[..., i, j] = -delta
    M[..., j, i] = -delta
    diag = np.arange(n_e)
    M[..., diag, diag] = M.sum(axis=-1) / (n_e - 1)
    g = np.zeros(lead + (n_e,))
    for _ in range(RANK_ONE_ITERATIONS):
        lam, V = np.linalg.eigh(M)
        top = V[..., -1] * np.sqrt(np.maximum(lam[..., -1], 0.0))[..., None]
        sign = np.where(top.sum(axis=-1, keepdims=True) < 0, -1.0, 1.0)
        g = np.maximum(top * sign, 0.0)
        M[..., diag, diag] = g**2
    rows = np.arange(i.size)
    for _ in range(GAUSS_NEWTON_STEPS):
        r = g[..., i] * g[..., j] + delta  # (..., n_pairs)
        J = np.zeros(lead + (i.size, n_e))
        J[..., rows, i] = g[..., j]
        J[..., rows, j] = g[..., i]
        JtJ = np.swapaxes(J, -1, -2) @ J + 1e-12 * np.eye(n_e)
        step = np.linalg.solve(JtJ, (np.swapaxes(J, -1, -2) @ r[..., None]))[..., 0]
        g = np.maximum(g - step, 0.0)
    return g


def correction(
    ga: np.ndarray, dga: np.ndarray, gb: np.ndarray, dgb: np.ndarray, rho: float,
    pairs: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The coupling's share c (n_pairs,) of two fingers' signal (module docstring) and its
    derivatives: along finger a's and b's parameters (n_pairs, 3) (from ``dga``/``dgb``
    (n_e, 3), the factors' slopes) and along ρ (n_pairs,)."""
    i, j = pairs
    den = 1.0 - rho * rho
    A = ga[i] * ga[j] + gb[i] * gb[j]
    B = ga[i] * gb[j] + gb[i] * ga[j]
    c = -(rho * rho * A - rho * B) / den
    dA_a = dga[i] * ga[j, None] + ga[i, None] * dga[j]
    dB_a = dga[i] * gb[j, None] + gb[i, None] * dga[j]
    dA_b = dgb[i] * gb[j, None] + gb[i, None] * dgb[j]
    dB_b = ga[i, None] * dgb[j] + dgb[i] * ga[j, None]
    da = -(rho * rho * dA_a - rho * dB_a) / den
    db = -(rho * rho * dA_b - rho * dB_b) / den
    drho = -(2 * rho * A - (1 + rho * rho) * B) / (den * den)
    return c, da, db, drho
