"""Training-free ECT images: linear back-projection, Tikhonov and projected Landweber.

Pure numpy/scipy over a sensitivity matrix (Jacobian) ``J`` (n_meas, n_vox) in pF per unit
relative permittivity, e.g. :func:`~ectskin.electrostatics.dielectric.permittivity_jacobian`.

Sign
----
A touching finger is a grounded conductor: it takes field lines away from the electrode pairs
near it, so it *lowers* their readouts, like a *drop* of permittivity would (J > 0 where the
field lines of a pair run). The images here are of ``b = −Δc`` (``Δc = c − c_0``, pF), so a touch
is a positive blob: ``−Δc ≈ J x`` with ``x ≥ 0`` the equivalent permittivity *decrease*.

Normalisation (ECT practice)
----------------------------
* Rows (measurements) are divided by a per-measurement scale ``s_m`` (pF): the reference readout
  ``c_0`` when given, since the readout noise is a gain noise (proportional to ``c_0``) and
  ``Δc / c_0`` is the calibrated change of paper Eq. 2; otherwise the row's full scale
  ``Σ_k |J_mk|`` (the change if every voxel changed by one), as in ECT's normalised capacitance.
* Columns (voxels) are divided by their norm ``‖(W J)_:k‖₂``, so that every voxel has unit
  sensitivity: ``S = W J D``, ``W = diag(1/s)``, ``D = diag(1/‖(W J)_:k‖)``. Images are of the
  normalised unknown ``y = D⁻¹ x``; voxels near an electrode no longer dominate.

Methods (``b̂ = −W Δc``, or ``+W Δc`` for a conductor Jacobian, see ``response_sign``)
-----------------------
* LBP: ``y = Sᵀ b̂``. For a single voxel k, ``y_j = (S_:j · S_:k) y_k ≤ y_k`` (Cauchy–Schwarz on
  unit columns), so its image peaks at k.
* Tikhonov: ``y = (SᵀS + α I)⁻¹ Sᵀ b̂ = V diag(σ / (σ² + α)) Uᵀ b̂`` with ``S = U Σ Vᵀ`` (SVD),
  ``α = λ σ_max²`` (λ relative to the largest singular value). Precomputed as one
  (n_vox, n_meas) matrix, so a frame is one matrix–vector product.
* Projected Landweber: ``y ← max(0, y + ω Sᵀ(b̂ − S y))`` from ``y = 0``, ``ω = relax / σ_max²``
  (converges for ``0 < relax < 2``); without the projection it tends to the minimum-norm
  least-squares solution ``S⁺ b̂``.

Localisation (:func:`peak_location`, :func:`centroid_location`) works on per-voxel images with
the voxels' (face, u, v) coordinates; heights are summed first (:func:`collapse_layers`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ectskin._check import EctskinError, check_array, check_option

METHODS = ("lbp", "tikhonov", "landweber")

#: default Tikhonov λ relative to σ_max² (assumed; chosen on held-apart twin trials, docs/ect-images.md)
DEFAULT_LAMBDA = 1.0
#: default projected-Landweber iterations and relaxation ω σ_max² (assumed)
DEFAULT_ITERATIONS = 50
DEFAULT_RELAXATION = 1.5


def normalise_sensitivity(J, row_scale=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(S, w, d)``: the normalised sensitivity ``S = diag(w) J diag(d)`` (n_meas, n_vox).

    ``w = 1 / row_scale`` (default row scale: ``Σ_k |J_mk|``) and ``d = 1 / ‖(diag(w) J)_:k‖₂``
    (a voxel no measurement sees gets d = 0). See the module docstring.
    """
    J = check_array("J", J, (None, None), finite=True)
    if row_scale is None:
        s = np.abs(J).sum(axis=1)
    else:
        s = check_array("row_scale", row_scale, (J.shape[0],), finite=True)
    if np.any(~(np.abs(s) > 0)):
        m = int(np.flatnonzero(~(np.abs(s) > 0))[0])
        raise EctskinError(f"row_scale[{m}] is {s[m]}: every measurement needs a non-zero scale")
    w = 1.0 / np.abs(s)
    WJ = J * w[:, None]
    norms = np.linalg.norm(WJ, axis=0)
    d = np.divide(1.0, norms, out=np.zeros_like(norms), where=norms > 0)
    return WJ * d[None, :], w, d


@dataclass(frozen=True)
class Reconstructor:
    """A precomputed ECT reconstruction: ``image(delta_c)`` → (n_vox,) normalised image.

    Build with :meth:`build`. ``matrix`` (n_vox, n_meas) maps ``Δc`` (pF) straight to the image
    for the linear methods (the sign flip and the row normalisation folded in); Landweber uses
    ``S`` and ``w`` per frame.
    """

    method: str
    S: np.ndarray  # (n_meas, n_vox) normalised sensitivity
    w: np.ndarray  # (n_meas,) signed row weights s/row_scale, 1/pF
    d: np.ndarray  # (n_vox,) column weights
    matrix: np.ndarray | None  # (n_vox, n_meas) for lbp / tikhonov
    sigma_max: float
    lam: float
    iterations: int
    relaxation: float

    @classmethod
    def build(
        cls,
        J,
        method: str = "tikhonov",
        *,
        row_scale=None,
        lam: float = DEFAULT_LAMBDA,
        iterations: int = DEFAULT_ITERATIONS,
        relaxation: float = DEFAULT_RELAXATION,
        response_sign: float = -1.0,
    ) -> Reconstructor:
        """Normalise ``J`` (see :func:`normalise_sensitivity`) and precompute ``method``.

        ``response_sign`` s: a touch gives ``Δc ≈ s J x`` with x ≥ 0, and the image is of
        ``b = s Δc``. −1 (default) for a permittivity Jacobian (a finger acts as a permittivity
        decrease), +1 for a Jacobian that is the response to the finger itself (a grounded
        conductor, :func:`~ectskin.electrostatics.dielectric.conductor_jacobian`).
        """
        check_option("method", method, METHODS)
        if response_sign not in (-1, 1):
            raise EctskinError(f"response_sign must be -1 or +1, got {response_sign!r}")
        if not (np.isfinite(lam) and lam > 0):
            raise EctskinError(f"lam must be a positive number (relative to σ_max²), got {lam!r}")
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
            raise EctskinError(f"iterations must be a positive integer, got {iterations!r}")
        if not (np.isfinite(relaxation) and 0 < relaxation < 2):
            raise EctskinError(f"relaxation must be in (0, 2), got {relaxation!r}")
        S, w, d = normalise_sensitivity(J, row_scale)
        U, sig, Vt = scipy.linalg.svd(S, full_matrices=False)
        smax = float(sig[0]) if sig.size else 0.0
        if not smax > 0:
            raise EctskinError("J is zero: no voxel is seen by any measurement")
        matrix = None
        w = float(response_sign) * w  # b̂ = s W Δc
        if method == "lbp":
            matrix = S.T * w[None, :]
        elif method == "tikhonov":
            alpha = lam * smax**2
            filt = sig / (sig**2 + alpha)
            matrix = ((Vt.T * filt[None, :]) @ U.T) * w[None, :]
        return cls(method, S, w, d, matrix, smax, float(lam), int(iterations), float(relaxation))

    @property
    def n_voxels(self) -> int:
        return int(self.S.shape[1])

    @property
    def n_measurements(self) -> int:
        return int(self.S.shape[0])

    def image(self, delta_c) -> np.ndarray:
        """(n_vox,) or (F, n_vox) normalised image ``y`` of ``Δc`` (n_meas,) or (F, n_meas), pF."""
        dc = np.asarray(delta_c, dtype=np.float64)
        if dc.shape[-1] != self.n_measurements or dc.ndim > 2:
            raise EctskinError(
                f"delta_c must have shape ({self.n_measurements},) or (F, {self.n_measurements}), "
                f"got {dc.shape}"
            )
        if self.matrix is not None:
            return dc @ self.matrix.T
        return landweber(
            self.S, dc * self.w, self.sigma_max, self.iterations, self.relaxation, nonneg=True
        )


def landweber(S, b, sigma_max: float, iterations: int, relaxation: float, *, nonneg: bool = True):
    """Projected Landweber ``y ← P(y + ω Sᵀ(b − S y))`` from y = 0, ``ω = relaxation / σ_max²``.

    ``b`` (n_meas,) or (F, n_meas); returns (n_vox,) or (F, n_vox). ``P`` clips at 0 when
    ``nonneg``; without it the iteration converges to the minimum-norm least-squares solution.
    """
    b = np.asarray(b, dtype=np.float64)
    omega = relaxation / sigma_max**2
    # y_{k+1} = y_k + ω Sᵀ b − ω SᵀS y_k; precompute G = ω SᵀS only when it is small
    y = np.zeros(b.shape[:-1] + (S.shape[1],))
    g = omega * (b @ S)
    for _ in range(iterations):
        y = y + g - omega * ((y @ S.T) @ S)
        if nonneg:
            np.maximum(y, 0.0, out=y)
    return y


# ====================================================================== localisation
def collapse_layers(image, pixel_index, n_pixels: int) -> np.ndarray:
    """(…, n_pixels) sum of voxel intensities over the layers of each pixel.

    ``pixel_index`` (n_vox,) gives each voxel's pixel (a (face, u, v) cell) in 0..n_pixels-1.
    """
    y = np.asarray(image, dtype=np.float64)
    idx = np.asarray(pixel_index)
    if idx.shape != y.shape[-1:]:
        raise EctskinError(f"pixel_index must have shape ({y.shape[-1]},), got {idx.shape}")
    out = np.zeros(y.shape[:-1] + (int(n_pixels),))
    # numpy's stubs refuse the Ellipsis in ufunc.at's index, which numpy accepts
    np.add.at(out, (..., idx), y)  # type: ignore[arg-type]
    return out


def layer_sum_matrix(pixel_index, n_pixels: int) -> np.ndarray:
    """(n_pixels, n_vox) 0/1 matrix summing voxels over layers (fold it into a linear method)."""
    idx = np.asarray(pixel_index)
    M = np.zeros((int(n_pixels), idx.size))
    M[idx, np.arange(idx.size)] = 1.0
    return M


def peak_location(image, face, uv) -> tuple[int, np.ndarray, float]:
    """``(face, (u, v), value)`` of the image's largest pixel.

    ``image`` (n_pix,), ``face`` (n_pix,) int, ``uv`` (n_pix, 2) mm.
    """
    y = np.asarray(image, dtype=np.float64)
    k = int(np.argmax(y))
    return int(np.asarray(face)[k]), np.asarray(uv, dtype=np.float64)[k].copy(), float(y[k])


def centroid_location(
    image, face, uv, *, radius_mm: float, threshold: float = 0.5
) -> tuple[int, np.ndarray, float]:
    """``(face, (u, v), peak value)``: the intensity-weighted centroid around the peak.

    Only pixels on the peak's face within ``radius_mm`` of the peak pixel and at least
    ``threshold`` × the peak value count, weighted by ``intensity − threshold × peak`` (so the
    centroid ignores the flat floor of the image and is pulled only by the blob itself).
    """
    y = np.asarray(image, dtype=np.float64)
    f = np.asarray(face)
    p = np.asarray(uv, dtype=np.float64)
    k = int(np.argmax(y))
    peak = y[k]
    if not peak > 0:
        return int(f[k]), p[k].copy(), float(peak)
    floor = threshold * peak
    sel = (f == f[k]) & (np.linalg.norm(p - p[k], axis=1) <= radius_mm) & (y >= floor)
    wgt = y[sel] - floor
    if not wgt.sum() > 0:
        return int(f[k]), p[k].copy(), float(peak)
    return int(f[k]), (wgt[:, None] * p[sel]).sum(axis=0) / wgt.sum(), float(peak)
