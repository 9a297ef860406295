"""The quasi-static rod against closed-form solutions: Euler-Bernoulli, torsion, the elastica."""

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.twin.rod import PointLoad, rotation_step, solve

L, EI, EI_SIDE, GJ = 120.0, 3.0e4, 1.4e5, 2.0e4


def _tip(alpha: float, n: int = 61):
    s = np.linspace(0, L, n)
    stiffness = np.tile([EI, EI_SIDE, GJ], (n, 1))
    force = alpha * EI / L**2
    r, rot = solve(s, stiffness, [PointLoad(L, (0.0, 0.0), np.array([[0.0, -force, 0.0]]))], 1)
    return r[0, -1], rot[0]


def test_small_tip_load_matches_euler_bernoulli():
    tip, _ = _tip(1e-4)
    force = 1e-4 * EI / L**2
    assert -tip[1] == pytest.approx(force * L**3 / (3 * EI), rel=1e-3)


@pytest.mark.parametrize(
    "alpha, v, h",
    # Bisshopp & Drucker (1945), cantilever with a tip load: α = FL²/EI → δ_v/L, (L − x_tip)/L
    [(1.0, 0.30172, 0.05643), (3.0, 0.60325, 0.25442), (5.0, 0.71379, 0.38763)],
)
def test_large_deflection_matches_the_elastica(alpha, v, h):
    tip, rot = _tip(alpha)
    assert -tip[1] / L == pytest.approx(v, abs=2e-4)
    assert (L - tip[2]) / L == pytest.approx(h, abs=2e-4)
    # the frames stay rotations
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)


def test_a_couple_twists_by_tl_over_gj():
    s = np.linspace(0, L, 61)
    stiffness = np.tile([EI, EI_SIDE, GJ], (61, 1))
    torque = 0.5  # N·mm, from two opposite forces 20 mm apart
    f = torque / 20.0
    loads = [
        PointLoad(L, (10.0, 0.0), np.array([[0.0, f, 0.0]])),
        PointLoad(L, (-10.0, 0.0), np.array([[0.0, -f, 0.0]])),
    ]
    _, rot = solve(s, stiffness, loads, 1)
    angle = np.arctan2(rot[0, -1, 1, 0], rot[0, -1, 0, 0])
    assert angle == pytest.approx(torque * L / GJ, rel=1e-3)


def test_rodrigues_matches_the_matrix_exponential():
    from scipy.linalg import expm

    rng = np.random.default_rng(0)
    for phi in rng.normal(0, 1, (5, 3)).tolist() + [[1e-9, 0, 0]]:
        k = np.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
        np.testing.assert_allclose(rotation_step(np.array(phi)), expm(k), atol=1e-12)


def test_a_load_beyond_the_body_is_a_clear_error():
    s = np.linspace(0, L, 61)
    stiffness = np.tile([EI, EI_SIDE, GJ], (61, 1))
    with pytest.raises(EctskinError, match="no equilibrium"):
        solve(s, stiffness, [PointLoad(L, (0, 0), np.array([[0.0, -50 * EI / L**2, 0.0]]))], 1)
    with pytest.raises(EctskinError, match="stiffness"):
        solve(s, np.zeros((61, 3)), [], 1)
