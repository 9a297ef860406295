"""Numerical helpers of :mod:`ectskin.twin.mechanics`: the section's torsion constants, a
row-wise ``np.interp`` (the face's pull-in) and the axial grid's search, both started from a
binned lookup of the nodes, the pose's interpolation along the axis, and the bounded caches of
the per-state tables and the rod's poses (one state is deformed many times: a fingertip's
placement maps its skin samples a dozen times per frame, a response field's grid row asks for
each touch's pose from its cavity cells, electrodes and fingertip)."""

from __future__ import annotations

from dataclasses import dataclass

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


@dataclass(frozen=True)
class RowLookup:
    """Where to start :func:`interp_rows`' search in each row of a table ``xp`` (n_rows, n)
    (:func:`row_lookup`): bins of ``width`` from ``lo``, a quarter of the rows' least node
    spacing, and ``below`` (n_rows · n_bins,) the count of a row's nodes ≤ each bin's left edge."""

    lo: float
    width: float
    n_bins: int
    below: np.ndarray


def row_lookup(xp: np.ndarray) -> RowLookup | None:
    """The :class:`RowLookup` of the rows ``xp`` (n_rows, n), each increasing; None where the
    rows have no spacing to bin by (a node repeated, or not finite).

    A point in bin b lies at most one node beyond the bin's count, and a point that rounding
    puts in the next or the previous bin at most one node off it (two bins are narrower than
    any spacing): the guess that :func:`interp_rows` corrects by one node either way."""
    xp = np.asarray(xp, dtype=np.float64)
    if xp.ndim != 2 or xp.shape[1] < 2 or not np.all(np.isfinite(xp)):
        return None
    gap = float(np.diff(xp, axis=1).min())
    lo, hi = float(xp[:, 0].min()), float(xp[:, -1].max())
    if not gap > 0 or (hi - lo) / gap > 1e5:
        return None
    width = gap / 4.0
    n_bins = int(np.ceil((hi - lo) / width)) + 2  # the last bin's edge beyond every node
    edges = lo + width * np.arange(n_bins)
    below = np.stack([np.searchsorted(row, edges, side="right") for row in xp])
    if np.any(np.diff(below, axis=1) > 1) or np.any(below[:, -1] != xp.shape[1]):
        return None
    flat = below.ravel().astype(np.intp)
    flat.setflags(write=False)
    return RowLookup(lo, width, n_bins, flat)


def interp_rows(
    x: np.ndarray, xp: np.ndarray, fp: np.ndarray, rows: np.ndarray,
    lookup: RowLookup | None = None,
) -> np.ndarray:
    """``np.interp(x[k], xp[rows[k]], fp)`` for every k at once, by the same arithmetic: ``x``
    (k,), ``xp`` (n_rows, n) each row increasing, ``fp`` (n,), ``rows`` (k,) int; ``lookup``:
    :func:`row_lookup` of ``xp`` (the same numbers, found faster), or None.

    Below a row's first node fp[0], from its last on fp[-1]; between, on the node j with
    xp[j] ≤ x < xp[j + 1], fp[j] where x == xp[j], else slope · (x − xp[j]) + fp[j] with
    slope = (fp[j + 1] − fp[j]) / (xp[j + 1] − xp[j]) (numpy's own formula)."""
    n = xp.shape[1]
    rows = np.asarray(rows, dtype=np.intp)
    base = rows * n
    flat = xp.ravel()
    count = _count_le(x, xp, rows, lookup)
    j = np.minimum(np.maximum(count - 1, 0), n - 2)  # (np.clip's integers, without its overhead)
    x0, x1 = flat.take(base + j), flat.take(base + j + 1)
    f0 = fp.take(j)
    slope = (fp.take(j + 1) - f0) / (x1 - x0)
    out = np.where(x == x0, f0, slope * (x - x0) + f0)
    out = np.where(count == 0, fp[0], out)
    return np.where(count >= n, fp[n - 1], out)


def _count_le(x: np.ndarray, xp: np.ndarray, rows: np.ndarray, lookup: RowLookup | None):
    """(k,) #{nodes ≤ x[k]} of row ``rows[k]`` of ``xp`` (n_rows, n), exactly (a NaN counts
    every node, as ``np.searchsorted`` counts it)."""
    n_rows, n = xp.shape
    base = rows * n
    if lookup is not None:
        # to within one node: the count of the point's bin (a NaN or a point beyond the last
        # node in the last bin, where every node is counted)
        b = np.fmax(np.fmin(np.floor((x - lookup.lo) / lookup.width), lookup.n_bins - 1), 0.0)
        count = lookup.below.take(rows * lookup.n_bins + b.astype(np.intp))
    else:
        # one search of all the rows laid end to end (row r shifted by r · span, so the rows'
        # ranges are apart by at least one), to within one node (the shift rounds; it can move
        # a point at most past one node)
        lo, span = xp[:, 0].min(), xp[:, -1].max() - xp[:, 0].min() + 1.0
        shift = span * np.arange(n_rows)
        ends = ((xp - lo) + shift[:, None]).ravel()
        q = np.clip(x - lo, -0.5, span - 0.5) + shift.take(rows)
        count = np.searchsorted(ends, q, side="right") - base
    # made exact by the row's own nodes
    flat = xp.ravel()
    count = count - ((count > 0) & (flat.take(base + np.maximum(count - 1, 0)) > x))
    return count + ((count < n) & (flat.take(base + np.minimum(count, n - 1)) <= x))


#: :func:`row_lookup` of the last few axial grids (:func:`on_axis`), by their bytes
_GRIDS: dict[bytes, RowLookup | None] = {}


def grid_segment(grid: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``np.clip(np.searchsorted(grid, x) - 1, 0, grid.size - 2)``, the same integers, found
    with the grid's :func:`row_lookup` (kept for the last few grids): the segment of the
    increasing ``grid`` (n,) that holds each of ``x``, the first or last beyond the ends."""
    key = grid.tobytes()
    try:
        lookup = _GRIDS[key]
    except KeyError:
        lookup = row_lookup(grid[None])
        if len(_GRIDS) >= STATES_KEPT:
            _GRIDS.clear()
        _GRIDS[key] = lookup
    xf = np.ravel(x)
    if lookup is None or xf.size < 256:  # (a few points: the search is the quicker)
        below = np.searchsorted(grid, xf)
    else:  # #{nodes < x}: #{nodes <= x} less a node equal to x
        le = _count_le(xf, grid[None], np.zeros(xf.size, dtype=np.intp), lookup)
        below = le - ((le > 0) & (grid.take(np.maximum(le - 1, 0)) == xf))
    return np.minimum(np.maximum(below - 1, 0), grid.size - 2).reshape(np.shape(x))


def axis_table(r: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(F n_z, 18) what :func:`on_axis` interpolates: row f n_z + i holds the axis ``r`` (F, n_z,
    3) and the section frame's first two columns (``rot`` (F, n_z, 3, 3); the third meets a zero)
    of frame f at grid point i, then the same at grid point i + 1 (the last point twice), so one
    gather reads both ends of a point's grid segment."""
    nodes = np.concatenate([r, rot[..., 0], rot[..., 1]], axis=-1)  # (F, n_z, 9)
    after = np.concatenate([nodes[:, 1:], nodes[:, -1:]], axis=1)
    return np.concatenate([nodes, after], axis=-1).reshape(-1, 18)


def on_axis(zs, axis, zq, xs, yprime) -> np.ndarray:
    """(F, n, 3) the points at section offsets (``xs``, ``yprime``) (F, n) of the deformed
    body at stretched axial positions ``zq`` ((n,) or (F, n)): the pose's :func:`axis_table`
    ``axis`` interpolated linearly on the axial grid ``zs`` (n_z,)
    (:meth:`~ectskin.twin.mechanics.Manipulator.deform`)."""
    n_f = axis.shape[0] // zs.size
    j = grid_segment(zs, zq)
    w = np.broadcast_to((zq - zs[j]) / (zs[j + 1] - zs[j]), xs.shape)[..., None]
    at = np.broadcast_to(j + (np.arange(n_f) * zs.size)[:, None], xs.shape)  # (F, n)
    ends = axis.take(at, axis=0)  # (F, n, 18): the segment's two ends
    a = ends[..., :9] * (1 - w) + w * ends[..., 9:]  # (F, n, 9)
    return a[..., :3] + (a[..., 3:6] * xs[..., None] + a[..., 6:9] * yprime[..., None])

def pull_in_table(
    slope: np.ndarray, zg: np.ndarray, kappa: float, n_phis: int
) -> tuple[np.ndarray, RowLookup | None]:
    """(n_phis, n_z) κ S(ζ) + (1 − κ) ζ on the axial grid ``zg`` for φ = 0 … 1, S the face's arc
    length along z where its slope is φ · ``slope`` (trapezoids): the rows that
    :func:`invert_pull_in` inverts (:meth:`~ectskin.twin.mechanics.Manipulator._face_pull_in`),
    read-only, and their :func:`row_lookup`."""
    phis = np.linspace(0.0, 1.0, n_phis)
    integrand = np.sqrt(1.0 + (phis[:, None] * slope[None, :]) ** 2)
    steps = 0.5 * (integrand[:, 1:] + integrand[:, :-1]) * np.diff(zg)
    arc = np.concatenate([np.zeros((phis.size, 1)), np.cumsum(steps, axis=1)], axis=1)
    mixed = kappa * arc + (1.0 - kappa) * zg[None, :]  # increasing in ζ for every φ
    mixed.setflags(write=False)
    return mixed, row_lookup(mixed)


def invert_pull_in(
    z: np.ndarray, phi: np.ndarray, table: tuple[np.ndarray, RowLookup | None], zg: np.ndarray
) -> np.ndarray:
    """(k,) ζ with κ S(ζ) + (1 − κ) ζ = z at φ: the two rows of :func:`pull_in_table`'s
    ``table`` that bracket each φ inverted, blended linearly in φ."""
    mixed, lookup = table
    n_phi = mixed.shape[0]
    fi = np.minimum(np.maximum(phi * (n_phi - 1), 0), n_phi - 1 - 1e-9)  # (np.clip's numbers)
    i0 = fi.astype(int)
    wi = fi - i0
    k = z.shape[0]
    rows = np.concatenate([i0, i0 + 1])
    both = interp_rows(np.concatenate([z, z]), mixed, zg, rows, lookup)
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
