"""Conductors with dielectric bodies by a boundary-element method, and accurate panel fields.

:mod:`~ectskin.electrostatics.mom` treats one homogeneous medium. This module adds piecewise
homogeneous dielectrics, as an independent forward model for checking first-order (sensitivity)
results such as ECT Jacobians. Everything lives in a background medium of relative permittivity
``eps_background``; the Green's function is ``1 / (4π ε0 ε_b R)``. Unknowns are uniform charges on

* conductor panels (free charge; the conductors must lie in the background medium), fixed by the
  collocated potential ``Σ_j P_ij q_j = V_i`` (Eq. 1 of :mod:`~.mom`), and
* interface panels between two dielectrics (equivalent polarisation charge). With the panel normal
  n = u × v / |u × v| pointing from the side of permittivity ``ε−`` to the side ``ε+``, continuity
  of the normal displacement ``ε− E_n⁻ = ε+ E_n⁺`` with ``E_n^± = E_n^other ± σ / (2 ε0 ε_b)``
  (the field of a charged sheet just beside it) gives::

      σ_i = 2 ε0 ε_b (ε− − ε+) / (ε− + ε+) · E_n^other(r_i)                                   (2)

  where ``E_n^other`` is the normal field at the panel centre of every charge but the panel's own
  (the principal value: a flat uniform panel has no normal field at its own centre). For a body of
  ``ε_in`` in ``ε_out`` with outward normals this is ``2 ε0 ε_b (ε_in − ε_out)/(ε_in + ε_out) E_n``.

Both conditions together form one dense, unsymmetric system, solved by LU (``scipy.linalg``).
Its right-hand sides are the conductor excitations (conductor c at 1 V, the others at 0 V); the
summed conductor charges are the Maxwell capacitance matrix K (pF), as in :func:`~.mom.maxwell_capacitance`.

Fields
------
:func:`panel_field` is the field of uniformly charged panels at arbitrary points: far pairs as
point charges, near pairs (closer than ``near_factor`` panel diagonals) as the central difference
of the exact panel potential :func:`~.mom.potential_integral`, which is smooth off the panel. The
normal field of one panel at another panel's centre (Eq. 2) is built the same way.

Units: mm, pF, V, pC, V/mm.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg
from scipy.spatial.distance import cdist

from ectskin._check import EctskinError, check_array
from ectskin.electrostatics.mom import (
    EPS0_PF_PER_MM,
    NEAR_FACTOR,
    potential_integral,
    potential_matrix,
)
from ectskin.electrostatics.panels import Panels

logger = logging.getLogger(__name__)

#: Central-difference step of the near field, as a fraction of the source panel's diagonal.
FD_STEP_FRACTION = 1e-4


# ====================================================================== unit fields
def unit_field_matrix(
    panels: Panels, points, *, near_factor: float = NEAR_FACTOR, exclude_self: bool = False
) -> np.ndarray:
    """(M, 3, N) field (V/mm, in vacuum) at ``points`` of 1 pC spread uniformly on each panel.

    ``E[m, :, j]`` is ``−∇ (1 / 4π ε0) ∫_panel_j dA' / (A_j |r − r'|)`` at point m. Pairs closer
    than ``near_factor`` times the panel's diagonal use the central difference of the exact
    integral :func:`~.mom.potential_integral` (step :data:`FD_STEP_FRACTION` of the diagonal); the
    others the point-charge field ``(r − c_j) / |r − c_j|³``. With ``exclude_self=True`` the points
    are the panel centres themselves (M = N) and the diagonal is zero (the principal value of the
    normal field of a flat panel at its own centre; its in-plane field there is zero by symmetry).
    Divide by the medium's ε_r for another medium.
    """
    if not isinstance(panels, Panels):
        raise EctskinError(f"panels must be Panels, got {type(panels).__name__}")
    r = check_array("points", points, (None, 3), finite=True)
    if exclude_self and r.shape[0] != panels.n_panels:
        raise EctskinError(
            f"exclude_self needs the {panels.n_panels} panel centres as points, got {r.shape[0]}"
        )
    c = panels.centres
    d = r[:, None, :] - c[None, :, :]  # (M, N, 3) mm
    d2 = np.einsum("mnk,mnk->mn", d, d)
    if exclude_self:
        d2[np.arange(r.shape[0]), np.arange(r.shape[0])] = np.inf
    near = np.sqrt(d2) < near_factor * panels.sizes[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        w = 1.0 / (d2 * np.sqrt(d2))
    w[~np.isfinite(w)] = 0.0
    E = d * w[..., None]  # (M, N, 3)
    mi, nj = np.nonzero(near)
    if mi.size:
        E[mi, nj] = _near_field(panels, r[mi], nj)
    if exclude_self:
        E[np.arange(r.shape[0]), np.arange(r.shape[0])] = 0.0
    return E.transpose(0, 2, 1) / (4.0 * np.pi * EPS0_PF_PER_MM)


def _near_field(panels: Panels, points: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """(K, 3) ``−∇ ∫ dA'/(A R)`` (1/mm²) at ``points`` (K, 3) of panels ``idx`` (K,), central
    differences of the exact integral along x, y, z."""
    h = FD_STEP_FRACTION * panels.sizes[idx]  # (K,)
    c, u, v = panels.centres[idx], panels.u[idx], panels.v[idx]
    out = np.empty((idx.size, 3))
    for k in range(3):
        step = np.zeros((idx.size, 3))
        step[:, k] = h
        plus = potential_integral(points + step, c, u, v)
        minus = potential_integral(points - step, c, u, v)
        out[:, k] = -(plus - minus) / (2.0 * h)
    return out / panels.areas[idx, None]


def panel_field(
    panels: Panels, charges, points, eps_r: float = 1.0, *, near_factor: float = NEAR_FACTOR
) -> np.ndarray:
    """(M, 3, n_columns) field (V/mm) at ``points`` of the panel charges (N, n_columns) pC.

    Like :func:`~.mom.field_at`, but panels closer than ``near_factor`` diagonals to a point are
    integrated exactly (see :func:`unit_field_matrix`), so the points may come close to the
    panels (not onto them: a point in a panel's plane inside the panel gets the principal value).
    Points are processed in blocks to bound memory.
    """
    q = np.asarray(charges, dtype=np.float64)
    if q.ndim != 2 or q.shape[0] != panels.n_panels:
        raise EctskinError(f"charges must have shape ({panels.n_panels}, n_columns), got {q.shape}")
    if not (np.isfinite(eps_r) and eps_r > 0):
        raise EctskinError(f"eps_r must be a positive finite number, got {eps_r!r}")
    r = check_array("points", points, (None, 3), finite=True)
    block = max(1, 2_000_000 // max(panels.n_panels, 1))
    out = np.empty((r.shape[0], 3, q.shape[1]))
    for s in range(0, r.shape[0], block):
        F = unit_field_matrix(panels, r[s : s + block], near_factor=near_factor)
        out[s : s + block] = F @ q
    return out / eps_r


# ====================================================================== dielectric BEM
def dielectric_capacitance(
    conductors: Panels,
    interfaces: Panels,
    eps_minus,
    eps_plus,
    eps_background: float = 1.0,
    *,
    near_factor: float = NEAR_FACTOR,
    closed: bool = True,
    return_charges: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n_conductors, n_conductors) Maxwell capacitance matrix K (pF) with dielectric bodies.

    Parameters
    ----------
    conductors : Panels
        Conductor panels (in the background medium).
    interfaces : Panels
        Dielectric interface panels; their ``conductor`` field is ignored. Normal u × v points
        from the ``eps_minus`` side to the ``eps_plus`` side.
    eps_minus, eps_plus : float or (N_d,)
        Relative permittivities on either side of each interface panel.
    eps_background : float
        Relative permittivity of the background (the Green's function's medium).
    closed : bool
        The interface panels form closed surfaces, one per value of their ``conductor`` field.
        Then each panel's self term is set so that a uniform unit charge density on its closed
        surface has the normal field ``±1 / (2 ε0 ε_b)`` (Gauss: σ/ε outside, 0 inside, and the
        principal value is the mean), which removes the first-order error of flat panels on a
        curved or edged surface (Eq. 3). With ``closed=False`` the flat-panel principal value 0.
    return_charges : bool
        Also return the conductor charges (N_c, n_conductors) and interface charges
        (N_d, n_conductors), pC per V of each excitation.

    The system (Eq. 1 of :mod:`~.mom` on conductor panels, Eq. 2 here on interface panels)::

        [ P_cc  P_cd ] [q_c]   [B]
        [ −κ F_dc  diag(1/A) − κ F_dd ] [q_d] = [0],    κ_i = 2 ε0 ε_b (ε−_i − ε+_i)/(ε−_i + ε+_i)

    with F the normal fields ``n_i · E_j(r_i)`` of unit panel charges (self excluded) and
    B the excitations. With no interface panel of differing sides it reduces to the homogeneous
    method of moments.
    """
    for name, p in (("conductors", conductors), ("interfaces", interfaces)):
        if not isinstance(p, Panels):
            raise EctskinError(f"{name} must be Panels, got {type(p).__name__}")
    eps_b = float(eps_background)
    if not (np.isfinite(eps_b) and eps_b > 0):
        raise EctskinError(
            f"eps_background must be a positive finite number, got {eps_background!r}"
        )
    nd = interfaces.n_panels
    em = np.broadcast_to(np.asarray(eps_minus, dtype=np.float64), (nd,))
    ep = np.broadcast_to(np.asarray(eps_plus, dtype=np.float64), (nd,))
    for name, e in (("eps_minus", em), ("eps_plus", ep)):
        if not np.all(np.isfinite(e) & (e > 0)):
            raise EctskinError(f"{name} must be positive finite relative permittivities, got {e}")
    nc = conductors.n_panels
    n_cond = conductors.n_conductors
    allp = Panels.concatenate([conductors.with_conductor(0, 1), interfaces.with_conductor(0, 1)])
    A = np.empty((nc + nd, nc + nd))
    # conductor rows: potentials (Eq. 1), every source (conductor and interface charges)
    P = potential_matrix(allp, eps_b, near_factor=near_factor)
    A[:nc] = P[:nc]
    # interface rows: σ_i − κ_i E_n^other(r_i) = 0 (Eq. 2)
    if nd:
        F = unit_field_matrix(allp, interfaces.centres, near_factor=near_factor)  # (nd, 3, N)
        self_idx = np.arange(nd)
        F[self_idx, :, nc + self_idx] = 0.0  # principal value
        Fn = np.einsum("mk,mkn->mn", interfaces.normals, F) / eps_b  # (nd, N), V/mm per pC
        if closed:
            Fn[self_idx, nc + self_idx] = _gauss_self_terms(Fn[:, nc:], interfaces, eps_b)
        kappa = 2.0 * EPS0_PF_PER_MM * eps_b * (em - ep) / (em + ep)  # pF/mm
        A[nc:] = -kappa[:, None] * Fn
        A[nc + self_idx, nc + self_idx] += 1.0 / interfaces.areas
    B = np.zeros((nc + nd, n_cond))
    B[np.arange(nc), conductors.conductor] = 1.0
    try:
        q = scipy.linalg.solve(A, B, check_finite=False)
    except (np.linalg.LinAlgError, scipy.linalg.LinAlgWarning):
        raise EctskinError(
            "dielectric_capacitance: the boundary-element system is singular; do conductor and "
            "interface panels overlap?"
        ) from None
    qc, qd = q[:nc], q[nc:]
    K = np.zeros((n_cond, n_cond))
    np.add.at(K, conductors.conductor, qc)
    logger.debug("dielectric_capacitance: %d conductor + %d interface panels", nc, nd)
    return (K, qc, qd) if return_charges else K


def _gauss_self_terms(Fdd: np.ndarray, interfaces: Panels, eps_b: float) -> np.ndarray:
    """(N_d,) self terms of the interface normal-field matrix from Gauss's law (Eq. 3).

    For a closed surface S carrying a uniform density σ = 1 pC/mm², the principal value of the
    normal field at a point of S is ``+1 / (2 ε0 ε_b)`` with the normal pointing out of S, and
    ``−1 / (2 ε0 ε_b)`` into it::

        Σ_{j ∈ S} Fn_ij A_j = ± 1 / (2 ε0 ε_b)                                                (3)

    The self term is chosen to satisfy it; the sign is the sign of the row's sum without it.
    """
    half = 1.0 / (2.0 * EPS0_PF_PER_MM * eps_b)
    body = interfaces.conductor
    areas = interfaces.areas
    out = np.empty(interfaces.n_panels)
    for s in np.unique(body):
        idx = np.flatnonzero(body == s)
        rows = Fdd[np.ix_(idx, idx)] @ areas[idx]  # self terms are zero here
        out[idx] = (np.where(rows >= 0, half, -half) - rows) / areas[idx]
    return out


def box_panels(centre, size, n: int) -> Panels:
    """The surface of an axis-aligned cube or box as ``6 n²`` panels with outward normals.

    ``size`` is a scalar (cube edge) or three edge lengths, mm. For a dielectric box in a
    background pass ``eps_minus`` = the box's, ``eps_plus`` = the background's permittivity to
    :func:`dielectric_capacitance`.
    """
    c0 = check_array("centre", centre, (3,), finite=True)
    s = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    if not np.all(np.isfinite(s) & (s > 0)) or int(n) < 1:
        raise EctskinError(
            f"box_panels needs positive sizes and n >= 1, got size {size!r}, n {n!r}"
        )
    n = int(n)
    t = (np.arange(n) + 0.5) / n - 0.5  # cell centres on [-1/2, 1/2]
    centres, us, vs = [], [], []
    for axis in range(3):
        a, b = (axis + 1) % 3, (axis + 2) % 3  # e_a × e_b = e_axis (cyclic)
        for sign in (1.0, -1.0):
            ta, tb = np.meshgrid(t * s[a], t * s[b], indexing="ij")
            c = np.zeros((n * n, 3))
            c[:, axis] = sign * s[axis] / 2
            c[:, a] = ta.ravel()
            c[:, b] = tb.ravel()
            u = np.zeros((n * n, 3))
            v = np.zeros((n * n, 3))
            u[:, a] = s[a] / n
            v[:, b] = sign * s[b] / n  # flips the normal on the negative face
            centres.append(c + c0)
            us.append(u)
            vs.append(v)
    m = 6 * n * n
    return Panels(
        np.concatenate(centres), np.concatenate(us), np.concatenate(vs), np.zeros(m, int), 1
    )


# ====================================================================== ECT Jacobian
def permittivity_jacobian(
    panels: Panels,
    charges,
    points,
    volumes,
    pairs,
    electrodes=None,
    eps_r: float = 1.0,
    *,
    near_factor: float = NEAR_FACTOR,
) -> np.ndarray:
    """(n_pairs, M) sensitivity ``∂C_ij / ∂ε_r`` (pF per unit relative permittivity) of voxels.

    First order in the permittivity (the ECT sensitivity map; see
    :func:`~.mom.dielectric_sensitivity`): ``K_ac = ∫ ε0 ε_r ∇φ_a · ∇φ_c dV`` is stationary in
    the potentials, so a change δε_r in voxel m changes ``K_ac`` by ``ε0 δε_r (E_a · E_c)(r_m) V_m``
    (midpoint rule), and the pair readout ``C_ij = −K_ij`` by::

        J[p, m] = ∂C_ij / ∂ε_r(m) = −ε0 (E_i · E_j)(r_m) V_m                                  (4)

    Parameters
    ----------
    panels, charges : the homogeneous solution, e.g. ``maxwell_capacitance(panels, eps_r,
        return_charges=True)``; ``charges`` (N, n_conductors) pC per V of each excitation.
    points : (M, 3) mm voxel centres; volumes : (M,) mm³.
    pairs : (n_pairs, 2) electrode indices (i, j).
    electrodes : (n_electrodes,) conductor index of each electrode (default: electrode k is
        conductor k).
    eps_r : the background's relative permittivity (the fields do not depend on it; the charges
        are proportional to it).

    The fields come from :func:`panel_field` (exact near panels), so voxels may lie close to the
    electrodes. Positive J: more permittivity raises the readout (between electrodes i and j,
    where E_i · E_j < 0).
    """
    vol = np.asarray(volumes, dtype=np.float64).reshape(-1)
    q = np.asarray(charges, dtype=np.float64)
    p = np.asarray(pairs)
    if p.ndim != 2 or p.shape[1] != 2 or p.dtype.kind not in "iu":
        raise EctskinError(f"pairs must be an (n_pairs, 2) integer array, got {p.shape} {p.dtype}")
    e = (
        np.arange(q.shape[1] if q.ndim == 2 else 0)
        if electrodes is None
        else np.asarray(electrodes)
    )
    if p.size and (p.min() < 0 or p.max() >= e.size):
        raise EctskinError(
            f"pairs must index the {e.size} electrodes, got values {p.min()}..{p.max()}"
        )
    E = panel_field(panels, q[:, e] if q.ndim == 2 else q, points, eps_r, near_factor=near_factor)
    if vol.shape[0] != E.shape[0] or not np.all(np.isfinite(vol) & (vol >= 0)):
        raise EctskinError(
            f"volumes must be {E.shape[0]} finite non-negative voxel volumes (mm^3), got shape "
            f"{vol.shape}"
        )
    dot = np.einsum("mkp,mkp->pm", E[:, :, p[:, 0]], E[:, :, p[:, 1]])  # (n_pairs, M)
    return -EPS0_PF_PER_MM * dot * vol[None, :]


def panel_potential(
    panels: Panels, charges, points, eps_r: float = 1.0, *, near_factor: float = NEAR_FACTOR
) -> np.ndarray:
    """(M, n_columns) potential (V) at ``points`` of the panel charges (N, n_columns) pC.

    Near panels (closer than ``near_factor`` diagonals) by the exact integral
    :func:`~.mom.potential_integral`, the others as point charges.
    """
    q = np.asarray(charges, dtype=np.float64)
    if q.ndim != 2 or q.shape[0] != panels.n_panels:
        raise EctskinError(f"charges must have shape ({panels.n_panels}, n_columns), got {q.shape}")
    r = check_array("points", points, (None, 3), finite=True)
    out = np.empty((r.shape[0], q.shape[1]))
    block = max(1, 2_000_000 // max(panels.n_panels, 1))
    for s in range(0, r.shape[0], block):
        d = cdist(r[s : s + block], panels.centres)  # (m, N) mm
        near = d < near_factor * panels.sizes[None, :]
        with np.errstate(divide="ignore"):
            G = 1.0 / d
        mi, nj = np.nonzero(near)
        G[mi, nj] = (
            potential_integral(r[s + mi], panels.centres[nj], panels.u[nj], panels.v[nj])
            / panels.areas[nj]
        )
        out[s : s + block] = G @ q
    return out / (4.0 * np.pi * EPS0_PF_PER_MM * eps_r)


def conductor_jacobian(
    panels: Panels,
    charges,
    points,
    pairs,
    electrodes=None,
    eps_r: float = 1.0,
    *,
    radius_mm: float = 1.0,
    near_factor: float = NEAR_FACTOR,
) -> np.ndarray:
    """(n_pairs, M) change of ``C_ij`` (pF) when a small grounded sphere sits at each point.

    A grounded sphere of radius a (small against the distance to the electrodes) at r takes the
    charge ``−C_s φ_i(r)`` when electrode i is at 1 V (``C_s = 4π ε0 ε_r a``), which induces
    ``C_s φ_i(r) φ_j(r)`` on grounded electrode j (Green's reciprocity), so::

        ΔC_ij = −4π ε0 ε_r a φ_i(r) φ_j(r)                                                    (5)

    with φ_c the potential of electrode c at 1 V, the others at 0 V. It is the first-order
    response to a grounded conductor (a finger), where :func:`permittivity_jacobian` is that to a
    dielectric.
    """
    q = np.asarray(charges, dtype=np.float64)
    p = np.asarray(pairs)
    if p.ndim != 2 or p.shape[1] != 2 or p.dtype.kind not in "iu":
        raise EctskinError(f"pairs must be an (n_pairs, 2) integer array, got {p.shape} {p.dtype}")
    e = np.arange(q.shape[1]) if electrodes is None else np.asarray(electrodes)
    phi = panel_potential(panels, q[:, e], points, eps_r, near_factor=near_factor)  # (M, n_el)
    c_s = 4.0 * np.pi * EPS0_PF_PER_MM * eps_r * float(radius_mm)
    return -c_s * (phi[:, p[:, 0]] * phi[:, p[:, 1]]).T
