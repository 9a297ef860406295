"""ECT reconstructions against hand-computed tiny cases."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.electrostatics import (
    Reconstructor,
    centroid_location,
    collapse_layers,
    landweber,
    normalise_sensitivity,
    peak_location,
)

# J (2 × 3): after normalisation with unit row scales the columns have norms 1, 2, 1, so
# S = [[1, 0, 1], [0, 1, 0]], SSᵀ = diag(2, 1), σ_max² = 2.
J = np.array([[1.0, 0.0, 1.0], [0.0, 2.0, 0.0]])
ONES = np.ones(2)
DC = -np.array([1.0, 2.0])  # a touch lowers the readouts: b = −Δc = (1, 2)


def test_normalisation_by_hand():
    S, w, d = normalise_sensitivity(J, ONES)
    np.testing.assert_allclose(S, [[1, 0, 1], [0, 1, 0]])
    np.testing.assert_allclose(d, [1, 0.5, 1])
    S2, w2, _ = normalise_sensitivity(J)  # default row scale: Σ_k |J_mk| = (2, 2)
    np.testing.assert_allclose(w2, [0.5, 0.5])


def test_lbp_by_hand():
    # catches: a missing sign flip (the image of a touch would be negative), Sᵀ vs S
    y = Reconstructor.build(J, "lbp", row_scale=ONES).image(DC)
    np.testing.assert_allclose(y, [1, 2, 1])


def test_tikhonov_by_hand():
    # y = Sᵀ (SSᵀ + α I)⁻¹ b with α = λ σ_max² = 0.5 · 2 = 1: [1/3, 2/2, 1/3]
    # catches: λ not scaled by σ_max², the filter σ/(σ² + α) written as 1/(σ² + α)
    r = Reconstructor.build(J, "tikhonov", row_scale=ONES, lam=0.5)
    np.testing.assert_allclose(r.image(DC), [1 / 3, 1, 1 / 3], rtol=1e-12)
    np.testing.assert_allclose(
        r.image(np.stack([DC, 2 * DC])), [[1 / 3, 1, 1 / 3], [2 / 3, 2, 2 / 3]]
    )


def test_landweber_converges_to_minimum_norm_solution():
    # the minimum-norm solution of S y = b: Sᵀ (SSᵀ)⁻¹ b = [0.5, 2, 0.5] (non-negative, so the
    # projection does not bind); catches ω beyond 2/σ_max² (diverges) and a wrong gradient sign
    r = Reconstructor.build(J, "landweber", row_scale=ONES, iterations=200, relaxation=1.0)
    np.testing.assert_allclose(r.image(DC), [0.5, 2, 0.5], rtol=1e-6)
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 10))
    b = rng.normal(size=6)
    s = np.linalg.svd(A, compute_uv=False)[0]
    y = landweber(A, b, s, 3000, 1.5, nonneg=False)
    np.testing.assert_allclose(y, np.linalg.pinv(A) @ b, atol=1e-8)


def test_landweber_projection_keeps_images_non_negative():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 12))
    y = landweber(A, rng.normal(size=(3, 5)), np.linalg.svd(A, compute_uv=False)[0], 30, 1.0)
    assert y.shape == (3, 12) and np.all(y >= 0)


def test_lbp_image_of_one_voxel_peaks_there():
    # Cauchy-Schwarz on unit columns; catches a missing column normalisation
    rng = np.random.default_rng(2)
    Jr = np.abs(rng.normal(size=(28, 60))) * np.exp(rng.normal(scale=2, size=60))[None, :]
    r = Reconstructor.build(Jr, "lbp")
    for k in range(60):
        assert np.argmax(r.image(-Jr[:, k])) == k


def test_bad_options_are_refused():
    with pytest.raises(EctskinError, match="method"):
        Reconstructor.build(J, "gauss-newton")
    with pytest.raises(EctskinError, match="relaxation"):
        Reconstructor.build(J, "landweber", relaxation=2.5)
    with pytest.raises(EctskinError, match="row_scale"):
        normalise_sensitivity(J, [1.0, 0.0])


def test_localisation_by_hand():
    face = np.array([0, 0, 0, 1])
    uv = np.array([[0.0, 0.0], [4.0, 0.0], [8.0, 0.0], [4.0, 0.0]])
    img = np.array([1.0, 3.0, 2.0, 2.9])
    f, p, v = peak_location(img, face, uv)
    assert (f, v) == (0, 3.0) and tuple(p) == (4.0, 0.0)
    # threshold 0.5 · 3 = 1.5: weights 1.5 (u=4), 0.5 (u=8); pixel 0 below, pixel 3 other face
    f, p, _ = centroid_location(img, face, uv, radius_mm=5.0, threshold=0.5)
    assert f == 0 and p == pytest.approx([(1.5 * 4 + 0.5 * 8) / 2.0, 0.0])
    np.testing.assert_allclose(collapse_layers([1.0, 2.0, 3.0, 4.0], [0, 1, 0, 1], 2), [4, 6])
