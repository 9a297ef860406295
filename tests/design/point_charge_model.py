"""A point-charge model of a hand-built layout (two wires a face) with a closed-form Jacobian:
the analytic :class:`~ectskin.twin.bound.ResponseProvider` of the information-score tests."""

from __future__ import annotations

import numpy as np

from ectskin.design.family import FaceDesign, LayoutDesign, build_layout
from ectskin.design.information import InformationConfig
from ectskin.twin.bound_fit import FitModel
from ectskin.twin.readout import ReadoutConfig, noise_pf

SCALE_K = 1e-3  # pF per ml: the inflation nuisance costs a share of the information
T_MM = 20.0  # the body between the faces, as the point charges see it
FIT_SCALE_SD = 0.12  # the fit's prior sd of the finger's signal scale
D_MM, B_MM_PER_N, A_PF = 4.0, 1.5, 250.0  # height at 0 N (mm), its drop (mm/N), coupling (pF mm²)


def two_wire_layout():
    """Two wires on each face: 20 and 60 mm long, 24 mm apart (front), 30 and 70 mm, 16 mm apart
    (back): four electrodes, six pairs."""
    face = dict(routing="straight", order="ascending", width_mm=1.0)
    design = LayoutDesign(
        FaceDesign(n_wires=2, span_mm=24.0, length_min_mm=20.0, length_max_mm=60.0, **face),
        FaceDesign(n_wires=2, span_mm=16.0, length_min_mm=30.0, length_max_mm=70.0, **face),
    )
    return build_layout(design, "two-wire")


class PointChargeResponse:
    """The finger a point charge at height z = d − b F + 0.05 mean(inflation) above the touched
    face; electrode k a point at its wire's middle, seen at height z on its own face and z + T
    across the body: φ_k = 1 / sqrt(|x − x_k|² + z_k²). Pair (a, b) reads
    c0_ab + K_ab · q − A φ_a φ_b (the finger takes a share of the field between the two; q the
    inflation nuisance (3,), a standing-capacitance shift)."""

    nuisance_sizes = {"inflation": 3}

    def __init__(self, layout, state):
        self.layout = layout
        self.state = np.asarray(state, float)
        self.xk = np.array([
            [e.polyline_mm[0, 0], 0.5 * (e.polyline_mm[:, 1].min() + e.polyline_mm[:, 1].max())]
            for e in layout.electrodes
        ])
        self.face = [layout.electrode_surface(k) for k in range(layout.n_electrodes)]
        self.pairs = np.asarray(layout.pairs)
        rng = np.random.default_rng(5)
        self.c0 = rng.uniform(1.0, 3.0, layout.n_pairs)
        self.K = rng.normal(scale=SCALE_K, size=(layout.n_pairs, 3))

    def _phi(self, face, uv, z):
        """φ (n, n_electrodes) and the heights z_k (n, n_electrodes)."""
        zk = z[:, None] + np.where(np.array(self.face) == face, 0.0, T_MM)[None, :]
        r2 = ((uv[:, None, :] - self.xk[None]) ** 2).sum(axis=2) + zk**2
        return 1.0 / np.sqrt(r2), zk

    def _z(self, force):
        return D_MM - B_MM_PER_N * force + 0.05 * self.state.mean()

    def readout(self, face, uv, force, height, nuisances=None):
        uv = np.asarray(uv, float).reshape(-1, 2)
        q = np.asarray((nuisances or {}).get("inflation", np.zeros((len(uv), 3))), float)
        phi, _ = self._phi(face, uv, self._z(np.asarray(force, float)))
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        return self.c0 + q @ self.K.T - A_PF * phi[:, a] * phi[:, b]

    def untouched(self):
        """The readout without a finger (φ → 0) at the nominal inflation."""
        return self.c0.copy()

    def jacobian(self, face, uv):
        """Closed form ∂C/∂(u, v, F, q1, q2, q3) at force 1 N, (n_pairs, 6)."""
        uv = np.asarray(uv, float).reshape(1, 2)
        phi, zk = self._phi(face, uv, self._z(np.array([1.0])))
        phi, zk = phi[0], zk[0]
        dphi = np.c_[-(uv[0] - self.xk) * phi[:, None] ** 3, B_MM_PER_N * zk * phi**3]  # (k, 3)
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        J = -A_PF * (phi[a, None] * dphi[b] + phi[b, None] * dphi[a])
        return np.c_[J, self.K]


def closed_form_bounds(provider, face, uv, prior_sd=1.0):
    """(position, force) bound from FIM = Jᵀ Σ⁻¹ J + the prior on q, inverted directly."""
    J = provider.jacobian(face, uv)
    c = provider.readout(face, [uv], [1.0], [0.0])[0]
    s = noise_pf(c, ReadoutConfig())
    fim = (J / s[:, None]).T @ (J / s[:, None]) + np.diag([0, 0, 0, *(3 * [prior_sd**-2])])
    cov = np.linalg.inv(fim)
    return np.sqrt(cov[0, 0] + cov[1, 1]), np.sqrt(cov[2, 2])


def closed_form_fit_error(provider, face, uv, scale_sd=FIT_SCALE_SD, left_sd=1.0):
    """Position error of the fit of (u, v, F, the finger's scale a) with the inflation q left
    out at ``left_sd``: A = J_fᵀ Σ⁻¹ J_f + diag(0, 0, 0, 1/scale_sd²), J_f = [∂C/∂(u, v, F),
    C − c0]; error covariance A⁻¹ + Σ_j left_sd² g_j g_jᵀ, g_j = A⁻¹ J_fᵀ Σ⁻¹ K_j."""
    J = provider.jacobian(face, uv)
    c = provider.readout(face, [uv], [1.0], [0.0])[0]
    s = noise_pf(c, ReadoutConfig())
    Jf = np.c_[J[:, :3], c - provider.c0] / s[:, None]
    inv = np.linalg.inv(Jf.T @ Jf + np.diag([0, 0, 0, scale_sd**-2]))
    cov = inv + sum(np.outer(g, g) for g in (inv @ Jf.T @ (J[:, 3 + j] / s) * left_sd for j in range(3)))
    return np.sqrt(cov[0, 0] + cov[1, 1])


def point_charges(layout, config):
    return {s: PointChargeResponse(layout, s) for s in config.states_ml}


#: the bound estimates the inflation; the fit leaves it out and fits a scale on the finger's signal
CONFIG = InformationConfig(spacing_mm=10.0, nuisances=("inflation",),
                           fit=FitModel(nuisances=(), left_out=("inflation",), scale_sd=FIT_SCALE_SD))
