"""A finger hovering above the field's top height (a finger lifted off, or on its way).

A field's hover part ends at its top height (``spec.height_range_mm``, 15 mm by default), but
a finger above it still reaches the skin: on the twin, the other finger of a two-finger trial
hovers 15-90 mm up while one presses. Bounded at the top, the fit could only explain that
signal with something else, most often a second finger pressing at the skin's edge with the
least force, and the pressing finger's point moved to make room. Above the top the inversion
carries the field's top pattern up, shrinking at its own rate there:

    Δ(u, v, s) = Δ(u, v, s_top) e^{p (s − s_top)},   p = ⟨Δ, ∂Δ/∂s⟩ / ⟨Δ, Δ⟩ at s_top (≤ 0),

s = ln h: a power law (h / h_top)^p in height with the exponent the field's own slope along its
signal at the top, up to :data:`HOVER_REACH` times the top. The pattern's widening with height
is left out (the fit's height there is rough; what matters is that the signal is taken up).
p's slopes along (u, v), for the Jacobian, are central differences. A coupled finger's
rank-one factor g scales by e^{p (s − s_top) / 2} (Δ ≈ −g gᵀ). The coarse search gets nodes at
:data:`FAR_NODES` times the top, from the node values: the polynomial through the field's
ln-height nodes, its value and slope at the top.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

#: a hovering finger's height reaches this many times the field's top height
HOVER_REACH = 4.0
#: the coarse search's hover nodes above the top, in multiples of it
FAR_NODES = (2.0, 4.0)

Signal = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def rate(d: np.ndarray, ds: np.ndarray) -> np.ndarray:
    """p (...,) of signals d (..., q) with slopes ds (..., q) in s: ⟨d, ds⟩ / ⟨d, d⟩, at most 0
    (0 where d is 0)."""
    dd = np.einsum("...q,...q->...", d, d)
    p = np.einsum("...q,...q->...", d, ds) / np.where(dd > 0, dd, 1.0)
    return np.minimum(np.where(dd > 0, p, 0.0), 0.0)


#: the step (mm) of the central differences of p along u and v
RATE_STEP_MM = 1e-3


def _top(signal: Signal, top: float, x: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Δ and its slopes at the top below ``x``, p there and p's slopes along (u, v) (central
    differences)."""
    d, J = signal(np.array([x[0], x[1], top]))
    dp = np.zeros(2)
    for ax in range(2):
        step = np.zeros(3)
        step[ax] = RATE_STEP_MM
        hi = signal(np.array([x[0], x[1], top]) + step)
        lo = signal(np.array([x[0], x[1], top]) - step)
        dp[ax] = float(rate(hi[0], hi[1][:, 2]) - rate(lo[0], lo[1][:, 2])) / (2 * RATE_STEP_MM)
    return d, J, float(rate(d, J[:, 2])), dp


def far_signal(signal: Signal, top: float, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Δ and ∂Δ/∂(u, v, s) of a hover ``signal`` at x = (u, v, s) with s above ``top``."""
    d, J, p, dp = _top(signal, top, x)
    ds = float(x[2]) - top
    f = math.exp(p * ds)
    J = J * f
    J[:, :2] += (f * ds) * d[:, None] * dp[None, :]
    J[:, 2] = p * f * d
    return d * f, J


def far_factor(factor: Signal, signal: Signal, top: float, x: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """g and ∂g/∂(u, v, s) of a hover ``factor`` at x with s above ``top`` (p from ``signal``)."""
    g, dg = factor(np.array([x[0], x[1], top]))
    _, _, p, dp = _top(signal, top, x)
    ds = float(x[2]) - top
    f = math.exp(0.5 * p * ds)
    dg = dg * f
    dg[:, :2] += (0.5 * f * ds) * g[:, None] * dp[None, :]
    dg[:, 2] = 0.5 * p * f * g
    return g * f, dg


def far_nodes(delta: np.ndarray, s: np.ndarray, lo: float, hi: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Hover node signals ``delta`` (n_u, n_v, n_s, q) at ln heights ``s`` (the polynomial's
    nodes on [lo, hi]) with the nodes of :data:`FAR_NODES` appended: (n_u, n_v, n_s + k, q) and
    their ln heights."""
    t = (s - lo) / (hi - lo)
    V = np.vander(t, s.size, increasing=True)  # the polynomial's coefficients: V⁻¹ y
    w = np.linalg.solve(V.T, np.ones(s.size))  # its value at t = 1
    dw = np.linalg.solve(V.T, np.arange(s.size, dtype=np.float64)) / (hi - lo)  # its d/ds
    d_top = np.einsum("k,uvkq->uvq", w, delta)
    p = rate(d_top, np.einsum("k,uvkq->uvq", dw, delta))
    m = np.asarray(FAR_NODES, dtype=np.float64)
    far = d_top[:, :, None, :] * np.exp(p[:, :, None, None] * np.log(m)[None, None, :, None])
    return np.concatenate([delta, far], axis=2), np.r_[s, hi + np.log(m)]
