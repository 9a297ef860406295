"""Many method-of-moments solves at once on a PyTorch device (a GPU where one is present).

A response field's contact row (:mod:`ectskin.twin.field_solve`) is dozens of independent solves
of panel sets of one size: the electrodes deformed by the finger at each point and force, and the
fingertip. :func:`maxwell_batch` solves k such sets as one batch: the potential coefficients of
Eq. (1) (:func:`~.mom.potential_matrix`: the exact panel integral for near pairs, a point charge
otherwise, symmetrised), a batched Cholesky factor (``torch.linalg.cholesky_ex``) and solve, the
Maxwell matrices, and the chamber cavities' first-order term
(:func:`~.mom.dielectric_sensitivity`); :func:`readout_batch` turns them into the ECT readout
C_ij = −K_ij with the cavities' term as :class:`~ectskin.twin.sensor.SensorModel` adds it. The
same numbers as the one-at-a-time NumPy/SciPy path to round-off (``tests/electrostatics/
test_batched.py`` compares them).

Where the solve runs: ``device`` "cpu", "cuda", "cuda:1", … (a PyTorch device), or from the
environment variable :data:`SOLVE_DEVICE_ENV` through :func:`solve_device`; "auto" means
"cuda" when PyTorch sees a GPU and the NumPy path otherwise. Float64 throughout. A set whose
potential matrix is not positive definite (a fingertip panel too close to a wire end) is flagged
in the returned mask, not raised: the caller solves it the twin's own way (it refines the
fingertip).

Units: mm, pF, V, pC.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from ectskin._check import EctskinError
from ectskin.electrostatics.mom import EPS0_PF_PER_MM, NEAR_FACTOR
from ectskin.electrostatics.panels import Panels

#: environment variable naming the device of the batched solves ("cpu", "cuda", "auto"; unset or
#: empty: the NumPy path)
SOLVE_DEVICE_ENV = "ECTSKIN_SOLVE_DEVICE"
#: sets per batch at most (memory: a batch holds k × N² potential coefficients and, with cavity
#: cells, k × M × N field weights, in float64)
MAX_BATCH = 128


def solve_device(device: str | None = None) -> str | None:
    """The torch device of batched solves: ``device``, else ``$ECTSKIN_SOLVE_DEVICE``; None (or
    "" / "numpy") means the NumPy path; "auto" means "cuda" if PyTorch sees a GPU, else None."""
    value = os.environ.get(SOLVE_DEVICE_ENV, "") if device is None else device
    value = value.strip().lower()
    if value in ("", "numpy", "none"):
        return None
    import torch  # deferred: the NumPy path does not need it

    if value == "auto":
        return "cuda" if torch.cuda.is_available() else None
    try:
        dev = torch.device(value)
    except (RuntimeError, ValueError):
        raise EctskinError(
            f"solve device: expected 'cpu', 'cuda', 'cuda:N', 'auto' or 'numpy' (option or "
            f"${SOLVE_DEVICE_ENV}), got {value!r}"
        ) from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise EctskinError(f"solve device {value!r}: PyTorch sees no CUDA GPU on this machine")
    return str(dev)


# ---------------------------------------------------------------------- the panel integral
def _frames(u, v):
    """:func:`~.mom._panel_frames` in torch, (..., 23) from (..., 3) edge vectors."""
    import torch

    lu = torch.linalg.vector_norm(u, dim=-1)
    lv = torch.linalg.vector_norm(v, dim=-1)
    eu = u / lu[..., None]
    ev = v / lv[..., None]
    n = torch.linalg.cross(u, v, dim=-1)
    n = n / torch.linalg.vector_norm(n, dim=-1, keepdim=True)
    mu = torch.linalg.cross(eu, n, dim=-1)
    mv = torch.linalg.cross(ev, n, dim=-1)
    hu, hv = 0.5 * u, 0.5 * v
    huv = (hu * hv).sum(-1)
    hh = (hu * hu).sum(-1) + (hv * hv).sum(-1)
    cols = [
        -(hv * mu).sum(-1), (hu * mv).sum(-1), -0.5 * lu - (hv * eu).sum(-1),
        (hu * ev).sum(-1) - 0.5 * lv, 0.5 * lu, 0.5 * lv, hh + 2.0 * huv, hh - 2.0 * huv,
    ]
    return torch.cat([eu, ev, mu, mv, n, torch.stack(cols, dim=-1)], dim=-1)


def _integral(rel0, f):
    """:func:`~.mom._integral` in torch: ``∫ dA'/|p − r'|`` for M pairs, rel0 (M, 3) = panel
    centre − point, f (M, 23) the panel's frame rows."""
    import torch

    proj = torch.einsum("mj,mkj->mk", rel0, f[:, :15].reshape(-1, 5, 3))
    du, dv, dmu, dmv = proj[:, 0], proj[:, 1], proj[:, 2], proj[:, 3]
    h = proj[:, 4].abs()
    hh = h * h
    rel_sq = (rel0 * rel0).sum(-1)
    ab = f[:, 19] * du + f[:, 20] * dv
    a_b = f[:, 19] * du - f[:, 20] * dv
    e0 = rel_sq + f[:, 21]
    e1 = rel_sq + f[:, 22]
    r = (
        (e0 - 2.0 * ab).clamp_min(0.0).sqrt(), (e1 + 2.0 * a_b).clamp_min(0.0).sqrt(),
        (e0 + 2.0 * ab).clamp_min(0.0).sqrt(), (e1 - 2.0 * a_b).clamp_min(0.0).sqrt(),
    )
    t_all = (dmu + f[:, 15], dmv + f[:, 16], f[:, 15] - dmu, f[:, 16] - dmv)
    lm_all = (du + f[:, 17], dv + f[:, 18], f[:, 17] - du, f[:, 18] - dv)
    edge = (2.0 * f[:, 19], 2.0 * f[:, 20])
    total = torch.zeros_like(du)
    for k in range(4):
        t, lm = t_all[k], lm_all[k]
        lp = lm + edge[k % 2]
        rm, rp = r[k], r[(k + 1) % 4]
        r0sq = t * t + hh
        r0 = r0sq.sqrt()
        r0 = torch.where(r0 > 0.0, r0, torch.ones_like(r0))  # t = 0: the edge adds t·(…) = 0
        log_term = torch.asinh(lp / r0) - torch.asinh(lm / r0)
        x1, x2 = r0sq + h * rp, r0sq + h * rm
        y1, y2 = t * lp, t * lm
        total = total + t * log_term - h * torch.atan2(y1 * x2 - y2 * x1, x1 * x2 + y1 * y2)
    return total


def _distances(a, b):
    """(k, n, m) exact pairwise distances (no |a|² + |b|² − 2ab cancellation)."""
    import torch

    return torch.cdist(a, b, compute_mode="donot_use_mm_for_euclid_dist")


def _potential(c, u, v, areas, sizes, eps_r: float, near_factor: float):
    """(k, N, N) :func:`~.mom.potential_matrix` of k panel sets of one size."""
    import torch

    dist = _distances(c, c)
    reach = near_factor * sizes
    near = dist < torch.maximum(reach[:, :, None], reach[:, None, :])
    near &= torch.ones_like(near[0]).triu()[None]
    b, i, j = near.nonzero(as_tuple=True)
    scale = 0.5 / (4.0 * math.pi * EPS0_PF_PER_MM * eps_r)
    P = (2.0 * scale) / dist
    frames = _frames(u, v)
    one_ij = _integral(c[b, j] - c[b, i], frames[b, j]) / areas[b, j]
    one_ji = _integral(c[b, i] - c[b, j], frames[b, i]) / areas[b, i]
    sym = (one_ij + one_ji) * scale
    P[b, i, j] = sym
    P[b, j, i] = sym
    return P


# ---------------------------------------------------------------------- the batched solve
def maxwell_batch(
    sets: Sequence[Panels],
    eps_r: float = 1.0,
    *,
    device: str = "cpu",
    near_factor: float = NEAR_FACTOR,
    blocks: Sequence[Sequence[tuple[int, np.ndarray]]] | None = None,
    cells: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
    sensitivity_columns: int | None = None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Maxwell matrices of k panel sets at once: (K (k, n_c, n_c) pF, S or None, ok (k,) bool).

    As :func:`~.mom.maxwell_capacitance` of each set (``blocks[s]``: its known diagonal blocks,
    the fingertips' own potential matrices); with ``cells[s]`` = (points (M, 3) mm, volumes (M,)
    mm³) and ``sensitivity_columns`` = n also S (k, n, n), :func:`~.mom.dielectric_sensitivity`
    of the first n conductors' charges over the cells. Sets of equal panel and cell counts are
    solved together, at most :data:`MAX_BATCH` at a time. ``ok[s]`` is False where set s's
    potential matrix is not positive definite (its K and S rows are then NaN).
    """
    sets = list(sets)
    if not sets:
        raise EctskinError("maxwell_batch: no panel sets given")
    nc = sets[0].n_conductors
    for k, p in enumerate(sets):
        if not isinstance(p, Panels):
            raise EctskinError(f"maxwell_batch: sets[{k}] must be Panels, got {type(p).__name__}")
        if p.n_conductors != nc:
            raise EctskinError(
                f"maxwell_batch: sets[{k}] has n_conductors={p.n_conductors}, sets[0] {nc}"
            )
        if np.any(np.bincount(p.conductor, minlength=nc) == 0):
            raise EctskinError(f"maxwell_batch: sets[{k}] leaves a conductor without panels")
    for name, given in (("blocks", blocks), ("cells", cells)):
        if given is not None and len(given) != len(sets):
            raise EctskinError(
                f"maxwell_batch: {name} must have one entry per set ({len(sets)}), got {len(given)}"
            )
    n_s = sensitivity_columns
    if n_s is not None and (cells is None or not 1 <= n_s <= nc):
        raise EctskinError(
            f"maxwell_batch: sensitivity_columns needs cells and must be in 1..{nc}, got {n_s}"
        )
    K = np.full((len(sets), nc, nc), np.nan)
    S = None if n_s is None else np.full((len(sets), n_s, n_s), np.nan)
    ok = np.zeros(len(sets), dtype=bool)
    groups: dict[tuple[int, int], list[int]] = {}
    for k, p in enumerate(sets):
        m = -1 if cells is None else int(np.shape(cells[k][0])[0])
        groups.setdefault((p.n_panels, m), []).append(k)
    for idx in groups.values():
        for start in range(0, len(idx), MAX_BATCH):
            part = idx[start : start + MAX_BATCH]
            _solve_group(
                [sets[k] for k in part], eps_r, device, near_factor,
                None if blocks is None else [blocks[k] for k in part],
                None if cells is None else [cells[k] for k in part], n_s, part, K, S, ok,
            )
    return K, S, ok


def _solve_group(sets, eps_r, device, near_factor, blocks, cells, n_s, part, K_out, S_out, ok_out):
    """One batch of sets of equal sizes, written into the outputs' rows ``part``."""
    import torch

    dev = torch.device(device)

    def stack(arrays):
        return torch.as_tensor(np.stack(arrays), dtype=torch.float64, device=dev)

    c = stack([p.centres for p in sets])
    P = _potential(
        c, stack([p.u for p in sets]), stack([p.v for p in sets]),
        stack([p.areas for p in sets]), stack([p.sizes for p in sets]), float(eps_r),
        float(near_factor),
    )
    for s, known in enumerate(blocks or ()):
        for first, D in known:
            m = D.shape[0]
            P[s, first : first + m, first : first + m] = torch.tensor(np.asarray(D), device=dev)
    L, info = torch.linalg.cholesky_ex(P)
    good = (info == 0) & torch.isfinite(P).all(dim=(1, 2))
    nc = sets[0].n_conductors
    conductor = torch.as_tensor(np.stack([p.conductor for p in sets]), device=dev)
    B = torch.nn.functional.one_hot(conductor, nc).to(torch.float64)  # (k, N, n_c)
    q = torch.cholesky_solve(B, L)
    Kb = B.transpose(1, 2) @ q
    Kb = 0.5 * (Kb + Kb.transpose(1, 2))
    rows = np.asarray(part)
    good_np = good.cpu().numpy()
    K_out[rows[good_np]] = Kb[good].cpu().numpy()
    ok_out[rows] = good_np
    if n_s is None or S_out is None:
        return
    pts = stack([np.asarray(x[0], dtype=np.float64) for x in cells])  # (k, M, 3)
    vol = stack([np.asarray(x[1], dtype=np.float64).reshape(-1) for x in cells])  # (k, M)
    w = _distances(pts, c) ** -3  # (k, M, N) 1 / |r − c|³
    qn = q[:, :, :n_s]
    sums = w @ qn  # (k, M, n)
    E = torch.stack([pts[:, :, x, None] * sums - w @ (c[:, :, x, None] * qn) for x in range(3)],
                    dim=2) / (4.0 * math.pi * EPS0_PF_PER_MM * eps_r)  # (k, M, 3, n)
    Sb = torch.einsum("kmxa,km,kmxb->kab", E, vol, E)
    S_out[rows[good_np]] = Sb[good].cpu().numpy()


def readout_batch(
    sets: Sequence[Panels],
    *,
    eps_r: float,
    n_electrodes: int,
    pairs: np.ndarray,
    device: str,
    chamber_eps_r: float | None = None,
    blocks: Sequence[Sequence[tuple[int, np.ndarray]]] | None = None,
    cells: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(k, n_pairs) ECT readouts C_ij = −K_ij (pF) of k panel sets, and ok (k,) bool.

    The readout of :class:`~ectskin.twin.sensor.SensorModel` for each set: the Maxwell matrix of
    the electrodes (and the finger conductor), plus, where ``chamber_eps_r`` differs from
    ``eps_r``, ``ε0 (ε_chamber − ε_r) S`` from the cavity ``cells``.
    """
    cavities = chamber_eps_r is not None and chamber_eps_r != eps_r
    if cavities and cells is None:
        raise EctskinError("readout_batch: a chamber permittivity needs the cavity cells")
    K, S, ok = maxwell_batch(
        sets, eps_r, device=device, blocks=blocks, cells=cells if cavities else None,
        sensitivity_columns=n_electrodes if cavities else None,
    )
    n = n_electrodes
    Kn = K[:, :n, :n]
    if S is not None:
        assert chamber_eps_r is not None  # (cavities says so)
        Kn = Kn + EPS0_PF_PER_MM * (chamber_eps_r - eps_r) * S
    pairs = np.asarray(pairs)
    return -Kn[:, pairs[:, 0], pairs[:, 1]], ok
