"""Build once, solve many: conductors that stay put, factored once, and panels added to them.

Many method-of-moments problems share most of their panels: the electrodes of one sensor state
stay where they are while a finger moves over them. Order the panels fixed first (E, N_E panels)
and added last (F, N_F panels); the potential-coefficient matrix of Eq. (1)
(:func:`~.mom.potential_matrix`) and the conductor incidence ``B`` (``B[i, c] = 1`` for panel i
of conductor c) split into blocks::

    P = [[A,  C],      B = [[B_E],
         [Cᵀ, D]]           [B_F]]

With the Cholesky factor ``A = L Lᵀ`` computed once, ``y = L⁻¹ B_E`` and ``K₀ = yᵀ y`` (the
Maxwell matrix of the fixed panels alone), each added panel set needs only ``W = L⁻¹ C``, the
Schur complement ``S = D − Wᵀ W`` (N_F × N_F) and its Cholesky factor ``S = M Mᵀ``::

    H = B_F − Wᵀ y,   q_F = S⁻¹ H,   q_E = L⁻ᵀ (y − W q_F)                          (block solve)
    K = Bᵀ q = K₀ + Hᵀ S⁻¹ H = K₀ + Zᵀ Z,   Z = M⁻¹ H                             (Maxwell K)

the same K (and charges q) as :func:`~.mom.maxwell_capacitance` of all panels together, to
round-off (the tests compare the two). The triangular solve for W is done for many added sets
at once (one BLAS-3 call over their stacked columns).

The first-order cavity term of the twin (:func:`~.mom.dielectric_sensitivity`) is supported the
same way: the field of the fixed panels at the cavity cells is a fixed linear map of their
charges, tabulated once; only the added panels' field is computed per set.

Units: mm, pF, V, pC.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
import scipy.linalg
from scipy.spatial.distance import cdist

from ectskin._check import EctskinError, check_array
from ectskin.electrostatics.mom import (
    EPS0_PF_PER_MM,
    NEAR_FACTOR,
    _panel_frames,
    _positive,
    pair_integrals,
    potential_matrix,
)
from ectskin.electrostatics.panels import Panels

logger = logging.getLogger(__name__)

#: added panel sets are solved in batches of at most this many columns of ``W`` (memory bound:
#: N_E × this many doubles)
BATCH_COLUMNS = 4096
#: two added panel sets whose geometry Gram matrices differ by at most this (mm²) are rigid
#: motions of each other, and share their own potential matrix (round-off of a rotation is
#: ~1e-13 mm²; a change of 1e-9 mm² changes P by ~1e-10 relative)
RIGID_TOL_MM2 = 1e-9


def potential_block(
    rows: Panels, cols: Panels, eps_r: float = 1.0, *, near_factor: float = NEAR_FACTOR
) -> np.ndarray:
    """(N_rows, N_cols) block of the symmetrised potential coefficients of Eq. (1), 1/pF.

    The entries that :func:`~.mom.potential_matrix` of ``Panels.concatenate([rows, cols])``
    has at (row panel i, column panel j): ``(P¹_ij + P¹_ji) / 2`` with ``P¹_ij`` the potential at
    the centre of i of 1 pC on j, exact for near pairs (centre distance below ``near_factor``
    times the larger panel diagonal) and a point charge otherwise.
    """
    for name, p in (("rows", rows), ("cols", cols)):
        if not isinstance(p, Panels):
            raise EctskinError(f"potential_block: {name} must be Panels, got {type(p).__name__}")
    eps_r = _positive("eps_r", eps_r)
    near_factor = _positive("near_factor", near_factor)
    return _block(rows, rows.sizes, None, cols, eps_r, near_factor)


def _block(
    rows: Panels, row_sizes: np.ndarray, row_frames: np.ndarray | None, cols: Panels,
    eps_r: float, near_factor: float,
) -> np.ndarray:
    """:func:`potential_block` with the rows' sizes (and :func:`~.mom._panel_frames`, computed
    for the near pairs' rows only when None) at hand."""
    ca, cb = rows.centres, cols.centres
    dist = cdist(ca, cb)
    near = dist < near_factor * np.maximum(row_sizes[:, None], cols.sizes[None, :])
    ii, jj = np.nonzero(near)
    with np.errstate(divide="ignore"):
        P = np.divide(2.0, dist, out=dist)  # far pairs: P¹_ij + P¹_ji = 2 / |r_i − r_j|
    # near pairs: P¹_ij (col panel j's exact potential at row centre i) + P¹_ji (row panel i's
    # at col centre j)
    if ii.size:
        # every panel's frame once, transposed: the pairs gathered into contiguous columns
        # (:func:`~.mom.pair_integrals`, as the potential matrix does)
        cft = np.ascontiguousarray(_panel_frames(cols.u, cols.v).T)
        rft = np.ascontiguousarray(
            (_panel_frames(rows.u, rows.v) if row_frames is None else row_frames).T
        )
        near_ij = pair_integrals(ca, ii, cb, cft, jj) / cols.areas[jj]
        P[ii, jj] = near_ij + pair_integrals(cb, jj, ca, rft, ii) / rows.areas[ii]
    P *= 0.5 / (4.0 * np.pi * EPS0_PF_PER_MM * eps_r)
    return P


def incidence(panels: Panels) -> np.ndarray:
    """(N, n_conductors) conductor incidence: 1 where panel i belongs to conductor c."""
    B = np.zeros((panels.n_panels, panels.n_conductors))
    B[np.arange(panels.n_panels), panels.conductor] = 1.0
    return B


def _cell_field_operator(panels: Panels, points: np.ndarray, eps_r: float) -> np.ndarray:
    """(3, M, N) V/mm per pC: the field at ``points`` of 1 pC on each panel (a point charge at its
    centre, as :func:`~.mom.field_at`)."""
    c = panels.centres
    comps = [points[:, k, None] - c[None, :, k] for k in range(3)]  # (M, N) each, mm
    d2 = comps[0] * comps[0] + comps[1] * comps[1] + comps[2] * comps[2]
    w = 1.0 / (d2 * np.sqrt(d2)) / (4.0 * np.pi * EPS0_PF_PER_MM * eps_r)
    return np.stack([dk * w for dk in comps])


class FixedConductors:
    """Panels that stay put, factored once; :meth:`capacitance` adds other panels to them.

    Parameters
    ----------
    panels : the fixed panels (N_E). ``panels.n_conductors`` counts every conductor of the
        solves, also those that only the added panels make up (a finger).
    eps_r : relative permittivity of the homogeneous medium.
    near_factor : as :func:`~.mom.potential_matrix`.
    cells : optional (points (M, 3) mm, volumes (M,) mm³) of sample cells for the first-order
        dielectric sensitivity (:func:`~.mom.dielectric_sensitivity`); the fixed panels' field
        there is tabulated once.

    Attributes
    ----------
    K0 : (n_conductors, n_conductors) pF, the Maxwell matrix of the fixed panels alone (rows of
        conductors without fixed panels are zero).
    """

    def __init__(
        self,
        panels: Panels,
        eps_r: float = 1.0,
        *,
        near_factor: float = NEAR_FACTOR,
        cells: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        if not isinstance(panels, Panels):
            raise EctskinError(f"FixedConductors: panels must be Panels, got {type(panels).__name__}")
        self.panels = panels
        self.eps_r = _positive("eps_r", eps_r)
        self.near_factor = _positive("near_factor", near_factor)
        self._sizes = panels.sizes
        self._frames = _panel_frames(panels.u, panels.v)
        P = potential_matrix(panels, self.eps_r, near_factor=self.near_factor)
        if not np.all(np.isfinite(P)):
            raise EctskinError(
                "FixedConductors: a potential coefficient is not finite; two fixed panels coincide"
            )
        try:
            self._L = scipy.linalg.cholesky(P, lower=True, overwrite_a=True, check_finite=False)
        except np.linalg.LinAlgError:
            raise EctskinError(
                "FixedConductors: the potential matrix of the fixed panels is not positive "
                "definite; panels of different conductors probably overlap or touch"
            ) from None
        self._y = scipy.linalg.solve_triangular(
            self._L, incidence(panels), lower=True, check_finite=False
        )  # (N_E, n_c)
        self.K0 = self._y.T @ self._y
        self._self_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._cells: tuple[np.ndarray, np.ndarray] | None = None
        self._G: np.ndarray | None = None
        if cells is not None:
            pts = check_array("cells points", cells[0], (None, 3), finite=True)
            vol = check_array("cells volumes", cells[1], (pts.shape[0],), finite=True)
            if np.any(vol < 0):
                raise EctskinError("FixedConductors: cell volumes must be >= 0 mm^3")
            self._cells = (pts, vol)
            self._G = _cell_field_operator(panels, pts, self.eps_r)  # (3, M, N_E)

    @property
    def n_conductors(self) -> int:
        return self.panels.n_conductors

    def capacitance(
        self, added: Sequence[Panels], *, sensitivity_columns: int | None = None,
        blocks: Sequence[np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Maxwell matrices (k, n_c, n_c) pF of the fixed panels with each of ``added`` (k sets).

        Each added set's conductor ids index the same conductors as the fixed panels
        (``n_conductors`` must agree), and every conductor needs a panel in the fixed or the
        added set. With ``sensitivity_columns`` = n (and ``cells`` given) also returns the
        sensitivities (k, n, n) of :func:`~.mom.dielectric_sensitivity` over the cells for the
        first n conductors' excitations (else None). ``blocks``: each added set's own potential
        matrix, where the caller has it (:func:`~.mom.potential_matrix` of a set it is a rigid
        motion of: a fingertip's shape), else computed here.
        """
        added = list(added)
        if blocks is not None:
            blocks = list(blocks)
            if len(blocks) != len(added) or any(
                np.shape(b) != (p.n_panels, p.n_panels) for b, p in zip(blocks, added)
            ):
                raise EctskinError(
                    f"FixedConductors.capacitance: blocks must be one (N_F, N_F) matrix per "
                    f"added set ({len(added)}), got {len(blocks)} of shapes "
                    f"{[np.shape(b) for b in blocks][:3]}"
                )
        nc = self.n_conductors
        has_fixed = np.bincount(self.panels.conductor, minlength=nc) > 0
        for k, p in enumerate(added):
            if not isinstance(p, Panels):
                raise EctskinError(f"added[{k}] must be Panels, got {type(p).__name__}")
            if p.n_conductors != nc:
                raise EctskinError(
                    f"added[{k}] has n_conductors={p.n_conductors}, the fixed panels {nc}"
                )
            missing = ~has_fixed & (np.bincount(p.conductor, minlength=nc) == 0)
            if missing.any():
                raise EctskinError(
                    f"added[{k}]: conductor(s) {np.flatnonzero(missing).tolist()} have no panels "
                    "(fixed or added)"
                )
        if sensitivity_columns is not None and self._cells is None:
            raise EctskinError("sensitivity_columns needs FixedConductors(..., cells=...)")
        K = np.empty((len(added), nc, nc))
        S = None
        if sensitivity_columns is not None:
            n_s = int(sensitivity_columns)
            if not 1 <= n_s <= nc:
                raise EctskinError(f"sensitivity_columns must be in 1..{nc}, got {n_s}")
            S = np.empty((len(added), n_s, n_s))
        start = 0
        while start < len(added):  # batches of at most BATCH_COLUMNS added panels
            stop, cols = start, 0
            while stop < len(added) and (stop == start or cols + added[stop].n_panels <= BATCH_COLUMNS):
                cols += added[stop].n_panels
                stop += 1
            self._solve_batch(
                added[start:stop], K[start:stop], None if S is None else S[start:stop],
                None if blocks is None else blocks[start:stop],
            )
            start = stop
        return K, S

    def _solve_batch(
        self, added: list[Panels], K_out: np.ndarray, S_out: np.ndarray | None,
        blocks: list[np.ndarray] | None = None,
    ) -> None:
        """The block solve of the module docstring for a batch of added sets (in place)."""
        # the fixed panels' rows of every added set's columns, in one block
        C = _block(
            self.panels, self._sizes, self._frames, Panels.concatenate(added), self.eps_r,
            self.near_factor,
        )
        W_all = scipy.linalg.solve_triangular(self._L, C, lower=True, check_finite=False)
        n_s = 0 if S_out is None else S_out.shape[1]
        rhs_e = np.empty((self.panels.n_panels, n_s * len(added)))  # y − W q_F, per set
        q_fs = []
        offset = 0
        for k, p in enumerate(added):
            W = W_all[:, offset : offset + p.n_panels]
            offset += p.n_panels
            own = self._self_block(p) if blocks is None else blocks[k]
            schur = own - W.T @ W
            try:
                M = scipy.linalg.cholesky(schur, lower=True, overwrite_a=True, check_finite=False)
            except np.linalg.LinAlgError:
                raise EctskinError(
                    f"FixedConductors: the Schur complement of added[{k}] is not positive "
                    "definite; its panels probably overlap or touch the fixed ones"
                ) from None
            H = incidence(p) - W.T @ self._y  # (N_F, n_c)
            Z = scipy.linalg.solve_triangular(M, H, lower=True, check_finite=False)
            Kk = self.K0 + Z.T @ Z
            K_out[k] = 0.5 * (Kk + Kk.T)
            if n_s:
                q_f = scipy.linalg.solve_triangular(
                    M, Z[:, :n_s], lower=True, trans="T", check_finite=False
                )
                q_fs.append(q_f)
                rhs_e[:, k * n_s : (k + 1) * n_s] = self._y[:, :n_s] - W @ q_f
        if S_out is None:
            return
        q_e = scipy.linalg.solve_triangular(self._L, rhs_e, lower=True, trans="T", check_finite=False)
        assert self._cells is not None and self._G is not None  # (checked by the caller)
        pts, vol = self._cells
        m = pts.shape[0]
        E_fixed = self._G.reshape(3 * m, -1) @ q_e  # (3 M, n_s k): all sets in one product
        for k, p in enumerate(added):
            G_f = _cell_field_operator(p, pts, self.eps_r).reshape(3 * m, -1)  # (3 M, N_F)
            E = E_fixed[:, k * n_s : (k + 1) * n_s] + G_f @ q_fs[k]
            E = E.reshape(3, m, n_s).transpose(1, 0, 2)  # (M, 3, n), as field_at
            Ew = E * vol[:, None, None]
            S_out[k] = Ew.reshape(-1, n_s).T @ E.reshape(-1, n_s)

    def _self_block(self, p: Panels) -> np.ndarray:
        """:func:`~.mom.potential_matrix` of ``p``, reused while added sets are rigid motions of
        one another (a finger moved over the fixed panels): P depends only on the panels'
        relative geometry, which the Gram matrix of (centres − first centre, u, v) fixes."""
        X = np.concatenate([p.centres - p.centres[0], p.u, p.v])
        gram = X @ X.T
        cached = self._self_cache
        if cached is not None and cached[0].shape == gram.shape:
            if np.max(np.abs(cached[0] - gram)) <= RIGID_TOL_MM2:
                return cached[1].copy()
        D = potential_matrix(p, self.eps_r, near_factor=self.near_factor)
        self._self_cache = (gram, D.copy())
        return D
