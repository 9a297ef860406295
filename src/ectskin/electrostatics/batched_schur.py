"""The Schur path (:mod:`~.schur`) for many added panel sets at once on a PyTorch device.

:meth:`FixedConductors.capacitance <ectskin.electrostatics.schur.FixedConductors.capacitance>`
adds each set to the fixed panels' factor one at a time (one BLAS-3 triangular solve for the
batch, then a small Cholesky factor per set). :func:`schur_batch` does the same block solve for
k sets of one size as batched torch calls: the fixed–added coefficients of all sets (the exact
panel integral for near pairs, :func:`~.batched._integral`), ``W = L⁻¹ C`` for all their columns,
the Schur complements ``S = D − Wᵀ W``, one batched Cholesky (``torch.linalg.cholesky_ex``) and
the Maxwell matrices ``K = K₀ + Zᵀ Z``, with the cavity cells' first-order term as the NumPy path
has it. The fixed panels' factor, charges and cell field operator move to the device once per
:class:`~.schur.FixedConductors` and device. Same numbers as the NumPy path to round-off
(``tests/electrostatics/test_batched.py``). A set whose Schur complement does not factor is
flagged in the returned mask (its rows NaN), not raised.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ectskin._check import EctskinError
from ectskin.electrostatics.batched import _distances, _frames, _integral
from ectskin.electrostatics.mom import EPS0_PF_PER_MM
from ectskin.electrostatics.panels import Panels
from ectskin.electrostatics.schur import FixedConductors


def _on_device(fixed: FixedConductors, device: str) -> dict:
    """The fixed panels' factor, charges, geometry and cell operator as torch tensors on
    ``device``, computed once per instance and device."""
    import torch

    store = fixed.__dict__.setdefault("_torch", {})
    if device not in store:
        dev = torch.device(device)

        def t(a):
            return torch.tensor(np.asarray(a, dtype=np.float64), device=dev)  # (a copy)

        p = fixed.panels
        store[device] = {
            "L": t(fixed._L), "y": t(fixed._y), "K0": t(fixed.K0), "c": t(p.centres),
            "frames": _frames(t(p.u), t(p.v)), "areas": t(p.areas), "sizes": t(p.sizes),
            "G": None if fixed._G is None else t(fixed._G.reshape(-1, p.n_panels)),
        }
    return store[device]


def schur_batch(
    fixed: FixedConductors,
    added: Sequence[Panels],
    blocks: Sequence[np.ndarray],
    *,
    device: str,
    sensitivity_columns: int | None = None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """(K (k, n_c, n_c) pF, S (k, n, n) or None, ok (k,) bool) of ``fixed`` with each added set.

    As ``fixed.capacitance(added, sensitivity_columns=..., blocks=blocks)``; every added set must
    have the same number of panels (a fingertip at many points and heights), ``blocks`` its own
    potential matrix (:func:`~.mom.potential_matrix` of its shape).
    """
    import torch

    added = list(added)
    if not added or len(blocks) != len(added):
        raise EctskinError(
            f"schur_batch: need one own block per added set, got {len(added)} sets and "
            f"{len(blocks)} blocks"
        )
    n_f = added[0].n_panels
    nc = fixed.n_conductors
    for k, p in enumerate(added):
        if not isinstance(p, Panels) or p.n_panels != n_f or p.n_conductors != nc:
            raise EctskinError(
                f"schur_batch: added[{k}] must be Panels of {n_f} panels and {nc} conductors"
            )
    n_s = sensitivity_columns
    if n_s is not None and (fixed._cells is None or not 1 <= n_s <= nc):
        raise EctskinError(
            f"schur_batch: sensitivity_columns needs FixedConductors(cells=...) and must be in "
            f"1..{nc}, got {n_s}"
        )
    d = _on_device(fixed, device)
    dev = d["L"].device

    def stack(arrays):
        return torch.as_tensor(np.stack(arrays), dtype=torch.float64, device=dev)

    k = len(added)
    cb = stack([p.centres for p in added]).reshape(-1, 3)  # (k n_f, 3)
    ub, vb = stack([p.u for p in added]).reshape(-1, 3), stack([p.v for p in added]).reshape(-1, 3)
    areas_b = stack([p.areas for p in added]).reshape(-1)
    sizes_b = stack([p.sizes for p in added]).reshape(-1)
    # the fixed–added coefficients of all sets: (N_E, k n_f), as schur._block
    ca = d["c"]
    dist = _distances(ca[None], cb[None])[0]
    near = dist < fixed.near_factor * torch.maximum(d["sizes"][:, None], sizes_b[None, :])
    ii, jj = near.nonzero(as_tuple=True)
    C = 2.0 / dist
    if ii.numel():
        C[ii, jj] = (_integral(cb[jj] - ca[ii], _frames(ub[jj], vb[jj])) / areas_b[jj]
                     + _integral(ca[ii] - cb[jj], d["frames"][ii]) / d["areas"][ii])
    C *= 0.5 / (4.0 * math.pi * EPS0_PF_PER_MM * fixed.eps_r)
    W = torch.linalg.solve_triangular(d["L"], C, upper=False)  # (N_E, k n_f)
    W = W.reshape(-1, k, n_f).permute(1, 0, 2)  # (k, N_E, n_f)
    Wt = W.transpose(1, 2)
    schur = stack(list(blocks)) - Wt @ W
    M, info = torch.linalg.cholesky_ex(schur)
    good = (info == 0) & torch.isfinite(schur).all(dim=(1, 2))
    conductor = torch.as_tensor(np.stack([p.conductor for p in added]), device=dev)
    B_f = torch.nn.functional.one_hot(conductor, nc).to(torch.float64)  # (k, n_f, n_c)
    H = B_f - Wt @ d["y"]
    Z = torch.linalg.solve_triangular(M, H, upper=False)
    K = d["K0"] + Z.transpose(1, 2) @ Z
    K = 0.5 * (K + K.transpose(1, 2))
    ok = good.cpu().numpy()
    K_out = np.full((k, nc, nc), np.nan)
    K_out[ok] = K[good].cpu().numpy()
    if n_s is None:
        return K_out, None, ok
    q_f = torch.linalg.solve_triangular(M.transpose(1, 2), Z[:, :, :n_s], upper=True)
    rhs_e = d["y"][None, :, :n_s] - W @ q_f  # (k, N_E, n)
    q_e = torch.linalg.solve_triangular(d["L"].T, rhs_e, upper=True)
    pts, vol = (torch.as_tensor(np.asarray(a, dtype=np.float64), device=dev)
                for a in fixed._cells)  # type: ignore[union-attr]
    m = pts.shape[0]
    E = d["G"] @ q_e  # (k, 3 M, n): the fixed panels' field at the cells
    cf = cb.reshape(k, n_f, 3)
    w = _distances(pts[None].expand(k, -1, -1), cf) ** -3 / (4.0 * math.pi * EPS0_PF_PER_MM
                                                             * fixed.eps_r)  # (k, M, n_f)
    E = E.reshape(k, 3, m, n_s) + torch.stack(
        [(pts[None, :, x, None] - cf[:, None, :, x]) * w for x in range(3)], dim=1
    ) @ q_f[:, None]  # (k, 3, M, n)
    S = torch.einsum("kxma,m,kxmb->kab", E, vol, E)
    S_out = np.full((k, n_s, n_s), np.nan)
    S_out[ok] = S[good].cpu().numpy()
    return K_out, S_out, ok
