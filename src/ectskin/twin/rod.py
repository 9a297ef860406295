"""A quasi-static Kirchhoff rod: the manipulator's axis under point loads, with large rotations.

The body is a rod clamped at s = 0 and free at its tip. Its axis r(s) and section frames R(s)
(columns: the section's x, y axes and the tangent) follow from the moment balance of the loads
beyond each section (statically determinate, so no time stepping is needed):

    m(s) = Σ_loads beyond s (p_load − r(s)) × F_load            (internal moment, world axes)
    κ(s) = B⁻¹ R(s)ᵀ m(s),   B = diag(EI_x, EI_y, GJ)(s)         (constitutive law, body axes)
    R'(s) = R(s) [κ(s)]×,    r'(s) = R(s) e_z                      (kinematics, inextensible)

The load points move with the body (a load is fixed to a material point: the arc position and an
offset in the section), so the loads' lever arms are taken on the deformed rod: a fixed-point
iteration over the shape, started from the straight rod, until the tip moves less than ``tol_mm``.
Rotations are integrated exactly per step (Rodrigues), so deflections of tens of degrees are
handled; for FL²/EI up to a few the iteration converges in ~10 passes (checked in the tests
against the elastica's closed-form tip deflections).

Why not a dynamic Cosserat rod (PyElastica): the trials are quasi-static (a finger pressing over
seconds), a dynamic solver would integrate ~1e5 explicit steps to reach each of the 900 frames'
equilibria, while the static balance above is exact for an inextensible, unshearable rod (the
Kirchhoff limit of Cosserat theory) and vectorises over all frames of a trial. Shear and axial
strain of the body are negligible next to bending at these slendernesses (length 120 mm over
thickness 20 mm); the inflation's axial strain enters through the arc-length grid.

Shapes: ``F`` frames, ``N`` axial grid points, ``L`` loads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError


@dataclass(frozen=True)
class PointLoad:
    """A force fixed to a material point of the body.

    ``s_mm``: arc position of the section it acts on; ``offset_mm``: (x, y) position in that
    section's frame; ``force_n``: (F, 3) force in world axes, one per frame.
    """

    s_mm: float
    offset_mm: tuple[float, float]
    force_n: np.ndarray


def _rodrigues(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients a = sin θ/θ and b = (1 − cos θ)/θ² of exp([φ]×), θ = |φ|, shape (..., 1)."""
    angle = np.linalg.norm(phi, axis=-1, keepdims=True)
    small = angle < 1e-6
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return a, b


def rotation_step(phi: np.ndarray) -> np.ndarray:
    """(..., 3, 3) exp([φ]×) = I + a[φ]× + b(φφᵀ − |φ|²I) (Rodrigues) for (..., 3) vectors φ."""
    a, b = _rodrigues(phi)
    x, y, z = phi[..., 0:1], phi[..., 1:2], phi[..., 2:3]
    sq = b * np.sum(phi * phi, axis=-1, keepdims=True)
    out = np.empty(phi.shape[:-1] + (3, 3))
    out[..., 0, 0] = (1 - sq + b * x * x)[..., 0]
    out[..., 1, 1] = (1 - sq + b * y * y)[..., 0]
    out[..., 2, 2] = (1 - sq + b * z * z)[..., 0]
    out[..., 0, 1] = (b * x * y - a * z)[..., 0]
    out[..., 1, 0] = (b * x * y + a * z)[..., 0]
    out[..., 0, 2] = (b * x * z + a * y)[..., 0]
    out[..., 2, 0] = (b * x * z - a * y)[..., 0]
    out[..., 1, 2] = (b * y * z - a * x)[..., 0]
    out[..., 2, 1] = (b * y * z + a * x)[..., 0]
    return out


def integrate(s: np.ndarray, kappa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis and frames from body-frame curvatures.

    s : (N,) arc positions, s[0] = 0 at the clamp. kappa : (F, N, 3) curvature (1/mm).
    Returns r (F, N, 3) mm and R (F, N, 3, 3); the clamp has r = 0, R = I. Each step rotates by
    the mean curvature of its two ends, and advances along the tangent at the step's middle,
    R_i exp(½[φ]×) e_z (second order in the step).
    """
    n_f, n = kappa.shape[:2]
    ds = np.diff(s)
    phi = 0.5 * (kappa[:, 1:] + kappa[:, :-1]) * ds[None, :, None]  # (F, N-1, 3)
    steps = rotation_step(phi)
    a, b = _rodrigues(0.5 * phi)
    h = 0.5 * phi
    # exp(½[φ]×) e_z in the body frame: e_z + a (h × e_z) + b (h (h·e_z) − |h|² e_z)
    mid = np.concatenate(
        [
            a * h[..., 1:2] + b * h[..., 0:1] * h[..., 2:3],
            -a * h[..., 0:1] + b * h[..., 1:2] * h[..., 2:3],
            1.0 + b * (h[..., 2:3] ** 2 - np.sum(h * h, axis=-1, keepdims=True)),
        ],
        axis=-1,
    )  # (F, N-1, 3)
    rot = np.empty((n_f, n, 3, 3))
    rot[:, 0] = np.eye(3)
    for i in range(n - 1):  # the frames, step by step
        np.matmul(rot[:, i], steps[:, i], out=rot[:, i + 1])
    # then the axis: r_{i+1} = r_i + R_i mid_i ds_i, summed in order (the same sums as a loop)
    r = np.zeros((n_f, n, 3))
    np.cumsum(np.einsum("fnij,fnj->fni", rot[:, :-1], mid) * ds[None, :, None], axis=1,
              out=r[:, 1:])
    return r, rot


def _at(s: np.ndarray, values: np.ndarray, s_q: float) -> np.ndarray:
    """Linear interpolation of (F, N, ...) values along the rod at one arc position."""
    j = min(max(int(np.searchsorted(s, s_q)) - 1, 0), s.size - 2)  # (np.clip's, quicker)
    w = (s_q - s[j]) / (s[j + 1] - s[j])
    return (1.0 - w) * values[:, j] + w * values[:, j + 1]


def solve(
    s: np.ndarray,
    stiffness: np.ndarray,
    loads: list[PointLoad],
    n_frames: int,
    *,
    tol_mm: float = 1e-3,
    max_iter: int = 100,
    relax: float = 0.6,
) -> tuple[np.ndarray, np.ndarray]:
    """Static equilibrium of the clamped rod under ``loads``.

    s : (N,) arc grid, mm. stiffness : (N, 3) (EI_x, EI_y, GJ) in N·mm² at each grid point.
    Returns r (F, N, 3) and R (F, N, 3, 3). The curvature is under-relaxed between passes
    (``relax``: the weight of the new pass), which keeps the fixed point converging for loads up
    to FL²/EI of about 5. Raises EctskinError if it does not converge (a load far beyond what the
    body can carry).
    """
    stiffness = np.asarray(stiffness, dtype=np.float64)
    if not np.all(stiffness > 0):
        raise EctskinError("rod: every stiffness (EI_x, EI_y, GJ) must be > 0")
    r = np.zeros((n_frames, s.size, 3))
    r[..., 2] = s
    rot = np.broadcast_to(np.eye(3), (n_frames, s.size, 3, 3)).copy()
    active = [ld for ld in loads if np.any(ld.force_n)]
    if not active:
        return r, rot
    beyond = np.stack([s <= ld.s_mm for ld in active])  # (L, N)
    kappa = None
    for _ in range(max_iter):
        m = np.zeros((n_frames, s.size, 3))
        for ld, mask in zip(active, beyond):
            off = np.array([ld.offset_mm[0], ld.offset_mm[1], 0.0])
            p = _at(s, r, ld.s_mm) + np.einsum("fij,j->fi", _at(s, rot, ld.s_mm), off)  # (F, 3)
            arm = p[:, None, :] - r  # (F, N, 3)
            m += np.cross(arm, np.asarray(ld.force_n, dtype=np.float64)[:, None, :]) * mask[None, :, None]
        new = np.einsum("fnji,fnj->fni", rot, m) / stiffness[None]  # Rᵀ m / B
        kappa = new if kappa is None else (1.0 - relax) * kappa + relax * new
        r_new, rot = integrate(s, kappa)
        change = np.max(np.abs(r_new[:, -1] - r[:, -1]))
        r = r_new
        if change < tol_mm:
            return r, rot
    raise EctskinError(
        f"rod: no equilibrium after {max_iter} passes (tip still moving {change:.3g} mm per "
        f"pass): the loads are beyond what the body carries; lower the forces"
    )
