"""The dielectric boundary-element model against analytic capacitors, and the ECT Jacobians
against finite differences of that independent forward model."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin.electrostatics import (
    EPS0_PF_PER_MM,
    Panels,
    box_panels,
    conductor_jacobian,
    dielectric_capacitance,
    field_at,
    maxwell_capacitance,
    panel_field,
    permittivity_jacobian,
    rectangle_panels,
    sphere_panels,
)


def _shell_capacitor(n: int, eps_shell: float):
    """Inner conductor sphere r=10 (1 V), outer r=30 (0 V), dielectric shell 15..22 mm."""
    a, r1, r2, b = 10.0, 15.0, 22.0, 30.0
    cond = Panels.concatenate(
        [
            sphere_panels(np.zeros(3), a, n, 0, n_conductors=2),
            sphere_panels(np.zeros(3), b, n, 1, n_conductors=2),
        ]
    )
    itf = Panels.concatenate(
        [sphere_panels(np.zeros(3), r1, n, 0), sphere_panels(np.zeros(3), r2, n, 1)]
    )
    outward = np.einsum("nk,nk->n", itf.normals, itf.centres) > 0
    inner = np.linalg.norm(itf.centres, axis=1) < (r1 + r2) / 2
    inside_eps = np.where(inner, 1.0, eps_shell)  # the permittivity inside each sphere surface
    outside_eps = np.where(inner, eps_shell, 1.0)
    em = np.where(outward, inside_eps, outside_eps)
    ep = np.where(outward, outside_eps, inside_eps)
    analytic = (
        4
        * np.pi
        * EPS0_PF_PER_MM
        / ((1 / a - 1 / r1) + (1 / r1 - 1 / r2) / eps_shell + (1 / r2 - 1 / b))
    )
    return cond, itf, em, ep, analytic


def test_spherical_capacitor_with_dielectric_shell_matches_analytic():
    # catches: the wrong sign of κ (Eq. 2: C would fall below the empty capacitor), a missing
    # Gauss self term (Eq. 3: ~7-12 % too high), conductor charges not summed per conductor
    cond, itf, em, ep, analytic = _shell_capacitor(6, 4.0)
    K = dielectric_capacitance(cond, itf, em, ep, 1.0)
    assert -K[0, 1] == pytest.approx(analytic, rel=0.01)
    assert K[0, 0] == pytest.approx(-K[1, 0], rel=0.01)  # all field lines end on the outer shell


def test_shell_of_background_permittivity_is_the_homogeneous_mom():
    # catches: interface rows that do not vanish when both sides agree
    cond, itf, em, ep, _ = _shell_capacitor(4, 1.0)
    K = dielectric_capacitance(cond, itf, em, ep, 1.0)
    np.testing.assert_allclose(K, maxwell_capacitance(cond), rtol=1e-9, atol=1e-12)


def test_panel_field_far_is_point_charges_and_near_is_finite():
    p = rectangle_panels((0, 0, 0), (1, 0, 0), (0, 1, 0), 4, 4, 4, 4, 0)
    q = np.linspace(1.0, 2.0, p.n_panels)[:, None]
    far = np.array([[0.0, 0.0, 50.0], [30.0, 10.0, 5.0]])
    np.testing.assert_allclose(panel_field(p, q, far), field_at(p, q, far), rtol=1e-12)
    # above the plate's middle: the field of a charged sheet, σ/(2 ε0) normal (plus edge terms)
    near = panel_field(p, np.ones((p.n_panels, 1)) / p.areas.sum() * 16, [[0.0, 0.0, 0.01]])
    assert near[0, 2, 0] == pytest.approx(1 / (2 * EPS0_PF_PER_MM), rel=0.01)


@pytest.fixture(scope="module")
def two_plates():
    eb = 2.0
    cond = Panels.concatenate(
        [
            rectangle_panels((-6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 8, 8, 8, 0, n_conductors=2),
            rectangle_panels((6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 8, 8, 8, 1, n_conductors=2),
        ]
    )
    K, q = maxwell_capacitance(cond, eb, return_charges=True)
    return eb, cond, K, q


@pytest.mark.parametrize("pos", [(0.0, 0.0, 3.0), (-6.0, 2.0, 3.0), (3.0, 0.0, 2.0)])
def test_permittivity_jacobian_equals_finite_difference_of_a_dielectric_cube(two_plates, pos):
    # catches: a wrong sign or factor in Eq. 4 (ε0, the volume), E of the wrong electrodes
    eb, cond, _, q = two_plates
    side, delta = 1.0, 0.1
    pairs = np.array([[0, 1]])
    cube = box_panels(pos, side, 4)
    c = [-dielectric_capacitance(cond, cube, eb + s * delta, eb, eb)[0, 1] for s in (1, -1)]
    fd = (c[0] - c[1]) / (2 * delta)
    J = permittivity_jacobian(cond, q, [pos], [side**3], pairs, eps_r=eb)[0, 0]
    assert J == pytest.approx(fd, rel=0.03)  # one midpoint per voxel
    g = (np.arange(3) - 1) * side / 3
    sub = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3) + np.asarray(pos)
    Js = permittivity_jacobian(cond, q, sub, np.full(27, side**3 / 27), pairs, eps_r=eb).sum()
    assert Js == pytest.approx(fd, rel=0.012)  # the voxel integrated 3 × 3 × 3


def test_conductor_jacobian_matches_a_small_grounded_sphere(two_plates):
    # catches: the sign of Eq. 5 (a grounded body lowers C_ij), potentials of the wrong electrode
    eb, cond, K, q = two_plates
    a, pos = 0.4, np.array([0.0, 0.0, 4.0])
    ball = sphere_panels(pos, a, 4, 2, n_conductors=3)
    K3 = maxwell_capacitance(Panels.concatenate([cond.with_conductor(cond.conductor, 3), ball]), eb)
    d_c = -K3[0, 1] + K[0, 1]
    J = conductor_jacobian(cond, q, [pos], np.array([[0, 1]]), eps_r=eb, radius_mm=a)[0, 0]
    assert d_c < 0
    assert J == pytest.approx(d_c, rel=0.1)  # first order in a / distance
