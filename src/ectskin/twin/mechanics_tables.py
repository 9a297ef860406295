"""Numerical helpers of :mod:`ectskin.twin.mechanics`: the section's torsion constants, a
row-wise ``np.interp`` (the face's pull-in), and the bounded caches of the per-state tables and
the rod's poses (one state is deformed many times: a fingertip's placement maps its skin
samples a dozen times per frame, a response field's grid row asks for each touch's pose from
its cavity cells, electrodes and fingertip)."""

from __future__ import annotations

import numpy as np

#: per-state tables kept (bulge heights, arc lengths): the last this many states
STATES_KEPT = 8
#: rod poses kept (:meth:`~ectskin.twin.mechanics.Manipulator.pose`): at most this many, and
#: beyond the last 8 only while they hold at most this many frames in all (a frame's pose is
#: 61 × 12 numbers)
POSES_KEPT = 64
#: point sets whose state part :meth:`~ectskin.twin.mechanics.Manipulator.deform` keeps
#: (``keep_rest``): a sensor's electrode corners and cavity cells per surface, a few states
RESTS_KEPT = 24
POSE_FRAMES_KEPT = 4096


def rect_torsion(a: float, b: float) -> float:
    """Torsion constant J of a solid a × b rectangle (a ≥ b), Saint-Venant's series (mm⁴)."""
    a, b = max(a, b), min(a, b)
    n = np.arange(1, 40, 2)
    beta = (1 - 192 * b / (np.pi**5 * a) * np.sum(np.tanh(n * np.pi * a / (2 * b)) / n**5)) / 3
    return float(beta * a * b**3)


def bredt_torsion(w: float, t: float, wall_side: float, wall_face: float) -> float:
    """Torsion constant of a thin-walled rectangular tube (Bredt): 4 A_m² / ∮ds/t (mm⁴)."""
    bm, hm = w - wall_side, t - wall_face  # median line
    return float(4 * (bm * hm) ** 2 / (2 * bm / wall_face + 2 * hm / wall_side))


def interp_rows(x: np.ndarray, xp: np.ndarray, fp: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``np.interp(x[k], xp[rows[k]], fp)`` for every k at once, by the same arithmetic: ``x``
    (k,), ``xp`` (n_rows, n) each row increasing, ``fp`` (n,), ``rows`` (k,) int.

    Below a row's first node fp[0], from its last on fp[-1]; between, on the node j with
    xp[j] ≤ x < xp[j + 1], fp[j] where x == xp[j], else slope · (x − xp[j]) + fp[j] with
    slope = (fp[j + 1] − fp[j]) / (xp[j + 1] − xp[j]) (numpy's own formula)."""
    n_rows, n = xp.shape
    rows = np.asarray(rows, dtype=np.intp)
    # #{nodes <= x} of each point's row: one search of all the rows laid end to end (row r
    # shifted by r · span, so the rows' ranges are apart by at least one), then made exact by
    # the row's own nodes (the shift rounds; it can move a point at most past one node)
    lo, span = xp[:, 0].min(), xp[:, -1].max() - xp[:, 0].min() + 1.0
    shift = span * np.arange(n_rows)
    ends = ((xp - lo) + shift[:, None]).ravel()
    q = np.clip(x - lo, -0.5, span - 0.5) + shift.take(rows)
    base = rows * n
    count = np.searchsorted(ends, q, side="right") - base
    flat = xp.ravel()
    count = count - ((count > 0) & (flat.take(base + np.maximum(count - 1, 0)) > x))
    count = count + ((count < n) & (flat.take(base + np.minimum(count, n - 1)) <= x))
    j = np.clip(count - 1, 0, n - 2)
    x0, x1 = flat.take(base + j), flat.take(base + j + 1)
    f0 = fp.take(j)
    slope = (fp.take(j + 1) - f0) / (x1 - x0)
    out = np.where(x == x0, f0, slope * (x - x0) + f0)
    out = np.where(count == 0, fp[0], out)
    return np.where(count >= n, fp[n - 1], out)


def pull_in_table(slope: np.ndarray, zg: np.ndarray, kappa: float, n_phis: int) -> np.ndarray:
    """(n_phis, n_z) κ S(ζ) + (1 − κ) ζ on the axial grid ``zg`` for φ = 0 … 1, S the face's arc
    length along z where its slope is φ · ``slope`` (trapezoids): the rows that
    :func:`invert_pull_in` inverts (:meth:`~ectskin.twin.mechanics.Manipulator._face_pull_in`);
    read-only."""
    phis = np.linspace(0.0, 1.0, n_phis)
    integrand = np.sqrt(1.0 + (phis[:, None] * slope[None, :]) ** 2)
    steps = 0.5 * (integrand[:, 1:] + integrand[:, :-1]) * np.diff(zg)
    arc = np.concatenate([np.zeros((phis.size, 1)), np.cumsum(steps, axis=1)], axis=1)
    mixed = kappa * arc + (1.0 - kappa) * zg[None, :]  # increasing in ζ for every φ
    mixed.setflags(write=False)
    return mixed


def invert_pull_in(z: np.ndarray, phi: np.ndarray, mixed: np.ndarray, zg: np.ndarray) -> np.ndarray:
    """(k,) ζ with κ S(ζ) + (1 − κ) ζ = z at φ: the two rows of :func:`pull_in_table` that
    bracket each φ inverted, blended linearly in φ."""
    n_phi = mixed.shape[0]
    fi = np.clip(phi * (n_phi - 1), 0, n_phi - 1 - 1e-9)
    i0 = fi.astype(int)
    wi = fi - i0
    k = z.shape[0]
    both = interp_rows(np.concatenate([z, z]), mixed, zg, np.concatenate([i0, i0 + 1]))
    return (1 - wi) * both[:k] + wi * both[k:]


def kept_arrays(cache: dict, key, make) -> tuple[np.ndarray, ...]:
    """``cache[key]``, or ``make()``'s arrays copied, read-only, kept under ``key`` (at most
    :data:`RESTS_KEPT` entries)."""
    value = cache.get(key)
    if value is None:
        value = tuple(np.array(a) for a in make())  # own copies: the caller's may change
        for a in value:
            a.setflags(write=False)
        remember(cache, key, value, kept=RESTS_KEPT)
    return value


def remember(cache: dict, key, value, kept: int = STATES_KEPT) -> None:
    """``cache[key] = value``, dropping the oldest entry beyond ``kept``."""
    if len(cache) >= kept:
        cache.pop(next(iter(cache)))
    cache[key] = value


def pose_key(force, touch, inflation, handling) -> tuple:
    """A hashable digest of a pose's inputs (arrays by their bytes)."""
    def arr(a):
        return None if a is None else np.ascontiguousarray(a, dtype=np.float64).tobytes()

    h = None
    if handling is not None:
        h = (arr(handling.shear_n), handling.push, arr(handling.push_force_n))
    return (arr(force), touch, arr(inflation), h)
