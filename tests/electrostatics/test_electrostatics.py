"""Method-of-moments electrostatics checked against physics nobody here wrote.

Textbook results (isolated sphere, parallel cylinders, parallel plates with Palmer's fringing
formula), a slow brute-force quadrature of the potential coefficients, the closed-form rectangle
self term, the sign structure of a Maxwell capacitance matrix, and convergence under refinement.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.electrostatics import (
    EPS0_PF_PER_MM,
    Panels,
    cylinder_panels,
    cylinder_quads,
    dielectric_sensitivity,
    ect_readout,
    edge_correction_factor,
    graded_nodes,
    grid_1d,
    maxwell_capacitance,
    potential_integral,
    potential_matrix,
    rectangle_panels,
    rectangle_quads,
    sphere_panels,
    strip_panels,
    strip_quads,
    two_terminal_capacitance,
)

EPS0 = EPS0_PF_PER_MM


# ====================================================================== slow references
def brute_integral(point, centre, u, v, n=400):
    """∫ dA'/|p − r'| over the parallelogram centre ± u/2 ± v/2 by the n × n midpoint rule."""
    g = (np.arange(n) + 0.5) / n - 0.5
    a, b = np.meshgrid(g, g, indexing="ij")
    pts = centre + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    area = np.linalg.norm(np.cross(u, v))
    return float(np.sum(1.0 / np.linalg.norm(pts - point, axis=1)) * area / n**2)


def brute_potential_matrix(panels, sub=20, self_sub=400):
    """P[i, j] by plain midpoint quadrature: one (i, j) at a time, nothing vectorised or clever.

    Off-diagonal: ``sub × sub`` sub-cells. Self terms: the collocation point sits on a sub-cell
    corner (the 1/r singularity is integrable), so a much finer ``self_sub`` grid is used there.
    """
    n = panels.n_panels
    P = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            k = self_sub if i == j else sub
            P[i, j] = (
                brute_integral(panels.centres[i], panels.centres[j], panels.u[j], panels.v[j], k)
                / panels.areas[j]
            )
    P = 0.5 * (P + P.T)
    return P / (4.0 * np.pi * EPS0)


def rectangle_self_integral(a, b):
    """∫∫ dA/r over an a × b rectangle from its centre: 2[a ln((b+d)/a) + b ln((a+d)/b)]."""
    d = np.hypot(a, b)
    return 2.0 * (a * np.log((b + d) / a) + b * np.log((a + d) / b))


def coplanar_strips(n_across, panel_length, end_panel, **kwargs):
    """Two coplanar strips, 1 mm wide, 60 mm long, 10 mm apart (centre lines)."""
    a = strip_panels(
        [0, 0, 0],
        [0, 0, 60],
        1.0,
        [0, 1, 0],
        0,
        n_conductors=2,
        n_across=n_across,
        panel_length=panel_length,
        end_panel=end_panel,
        **kwargs,
    )
    b = strip_panels(
        [10, 0, 0],
        [10, 0, 60],
        1.0,
        [0, 1, 0],
        1,
        n_conductors=2,
        n_across=n_across,
        panel_length=panel_length,
        end_panel=end_panel,
        **kwargs,
    )
    return Panels.concatenate([a, b])


# ====================================================================== panel integral
def test_self_integral_matches_rectangle_closed_form():
    for a, b in [(1.0, 1.0), (2.0, 0.25), (0.25, 2.0), (5.0, 0.1)]:
        got = potential_integral(np.zeros((1, 3)), np.zeros((1, 3)), [[a, 0, 0]], [[0, b, 0]])[0]
        assert got == pytest.approx(rectangle_self_integral(a, b), rel=1e-12)


def test_corner_and_edge_points_match_closed_form():
    """From a corner, ∫∫ dA/r over a × b is a ln((b+d)/a) + b ln((a+d)/b) (a quarter of the
    centre formula for a 2a × 2b rectangle); an edge midpoint sees two such rectangles."""
    a, b = 2.0, 0.25
    pts = np.array([[1.0, 0.125, 0.0], [1.0, 0.0, 0.0]])
    got = potential_integral(pts, np.zeros((2, 3)), [[a, 0, 0]] * 2, [[0, b, 0]] * 2)
    assert got[0] == pytest.approx(rectangle_self_integral(2 * a, 2 * b) / 4, rel=1e-12)
    assert got[1] == pytest.approx(2 * rectangle_self_integral(2 * 2, 2 * 0.125) / 4, rel=1e-12)


@pytest.mark.parametrize(
    "offset",
    [
        [0.3, 2.0, 1.0],  # above, projecting outside
        [3.0, 0.0, 0.0],  # in the plane, outside
        [0.05, 0.1, 0.02],  # just off the panel, inside its outline
        [0.6, 0.2, 0.3],  # above a corner region
        [1.4, 0.3, 0.0],  # in plane, beyond the long edge
    ],
)
def test_potential_integral_matches_brute_force_skewed_panel(offset):
    c = np.array([0.1, -0.2, 0.3])
    u = np.array([2.0, 0.3, 0.1])
    v = np.array([0.2, 0.5, -0.1])
    p = c + np.asarray(offset)
    got = potential_integral(p[None], c[None], u[None], v[None])[0]
    assert got == pytest.approx(brute_integral(p, c, u, v, 600), rel=2e-5)


def test_potential_integral_far_point_tends_to_point_charge():
    c = np.zeros((1, 3))
    for dist in [20.0, 200.0]:
        p = np.array([[0.3 * dist, 0.4 * dist, 0.866 * dist]])
        got = potential_integral(p, c, [[1.0, 0, 0]], [[0, 0.5, 0]])[0]
        assert got * np.linalg.norm(p) / 0.5 == pytest.approx(1.0, abs=1e-3 * (20 / dist) ** 2)


# ====================================================================== potential matrix
def hand_built_panels():
    """Six panels: a rectangle split into three coplanar neighbours (one long, 0.25 × 2 wire-like),
    a skewed parallelogram above them, a perpendicular panel nearby and a far panel."""
    quads = [
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
        [[1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]],
        [[0, 1, 0], [2, 1, 0], [2, 1.25, 0], [0, 1.25, 0]],
        [[0.2, 0.1, 0.7], [1.3, 0.3, 0.7], [1.6, 1.1, 0.8], [0.5, 0.9, 0.8]],
        [[2.5, 0, 0], [2.5, 1, 0], [2.5, 1, 1], [2.5, 0, 1]],
        [[30, 20, 5], [31, 20, 5], [31, 21.5, 5], [30, 21.5, 5]],
    ]
    return Panels.from_quads(np.array(quads, float), [0, 0, 1, 1, 2, 2], 3)


def test_potential_matrix_matches_brute_force_quadrature():
    p = hand_built_panels()
    fast = potential_matrix(p)
    slow = brute_potential_matrix(p)
    np.testing.assert_allclose(fast, slow, rtol=0.01)
    # and the all-exact matrix (every pair by the closed form) agrees to quadrature accuracy
    exact = potential_matrix(p, near_factor=1e6)
    np.testing.assert_allclose(exact, slow, rtol=0.005)


def test_potential_matrix_symmetric_positive_definite_and_scales_with_eps():
    p = hand_built_panels()
    P = potential_matrix(p)
    np.testing.assert_array_equal(P, P.T)
    assert np.all(np.linalg.eigvalsh(P) > 0)
    np.testing.assert_allclose(potential_matrix(p, eps_r=2.5), P / 2.5, rtol=1e-14)
    # diagonal = closed-form self term of the 1 × 1 square / area / (4π ε0)
    assert P[0, 0] == pytest.approx(rectangle_self_integral(1, 1) / (4 * np.pi * EPS0), rel=1e-12)


def test_far_field_approximation_is_small_against_all_exact():
    """The point-charge far field (beyond 3 panel diagonals) changes capacitance by < 0.3 %."""
    p = Panels.concatenate(
        [
            rectangle_panels(
                [0, 0, 0],
                [1, 0, 0],
                [0, 1, 0],
                10,
                10,
                6,
                6,
                0,
                spacing_u="cosine",
                spacing_v="cosine",
            ),
            strip_panels([-10, 8, 2], [10, 8, 2], 1.0, [0, 0, 1], 1),
            sphere_panels([0, 0, 9], 4.0, 4, 2),
        ]
    )
    K = maxwell_capacitance(p)
    K_exact = maxwell_capacitance(p, near_factor=1e6)
    np.testing.assert_allclose(K, K_exact, rtol=3e-3)


# ====================================================================== textbook capacitances
def test_isolated_sphere():
    R = 10.0
    p = sphere_panels([1.0, -2.0, 3.0], R, 6, 0)
    K = maxwell_capacitance(p)
    assert K.shape == (1, 1)
    assert K[0, 0] == pytest.approx(4 * np.pi * EPS0 * R, rel=0.01)
    # a homogeneous dielectric scales capacitance by eps_r
    assert maxwell_capacitance(p, eps_r=2.0)[0, 0] == pytest.approx(2 * K[0, 0], rel=1e-12)


def test_isolated_sphere_inscribed_panels_converge_from_below():
    """Without the true-area correction, flat inscribed panels shrink the sphere: the error is
    negative and shrinks with refinement (an independent check of the correction's direction)."""
    exact = 4 * np.pi * EPS0 * 10.0
    errs = [
        maxwell_capacitance(sphere_panels([0, 0, 0], 10.0, n, 0, true_area=False))[0, 0] / exact - 1
        for n in (3, 6)
    ]
    assert errs[0] < errs[1] < 0
    assert abs(errs[1]) < 0.02


def test_two_distant_spheres_two_terminal():
    """Two spheres R far apart (D = 20 R): C = 4π ε0 / (2/R − 2/D) to O((R/D)^4)."""
    R, D = 3.0, 60.0
    p = Panels.concatenate([sphere_panels([0, 0, 0], R, 5, 0), sphere_panels([D, 0, 0], R, 5, 1)])
    C = two_terminal_capacitance(maxwell_capacitance(p), 0, 1)
    assert C == pytest.approx(4 * np.pi * EPS0 / (2 / R - 2 / D), rel=0.01)


def test_parallel_cylinders_per_length():
    """Two long parallel round wires: C/L = π ε0 / arccosh(d / 2a); ends cancel in the
    difference of two lengths."""
    a, d = 1.0, 10.0
    caps = {}
    for L in (40.0, 80.0):
        n_along = int(L / 2)
        p = Panels.concatenate(
            [
                cylinder_panels([0, 0, 0], [0, 0, L], a, 8, n_along, 0),
                cylinder_panels([d, 0, 0], [d, 0, L], a, 8, n_along, 1),
            ]
        )
        caps[L] = two_terminal_capacitance(maxwell_capacitance(p), 0, 1)
    per_length = (caps[80.0] - caps[40.0]) / 40.0
    assert per_length == pytest.approx(np.pi * EPS0 / np.arccosh(d / (2 * a)), rel=0.03)


def test_parallel_plate_capacitor_with_fringing():
    """Two 50 × 50 mm plates 1 mm apart. Lower bound ε0 A/d (fringing only adds); value within
    3 % of Palmer's fringing formula C = ε0 w l/d · Π_{s∈(w,l)} [1 + d/(π s) (1 + ln(2π s/d))]."""
    w, gap = 50.0, 1.0
    plates = [
        rectangle_panels(
            [0, 0, z],
            [1, 0, 0],
            [0, 1, 0],
            w,
            w,
            16,
            16,
            k,
            spacing_u="cosine",
            spacing_v="cosine",
            edge_correction=True,
        )
        for k, z in enumerate((0.0, gap))
    ]
    C = two_terminal_capacitance(maxwell_capacitance(Panels.concatenate(plates)), 0, 1)
    ideal = EPS0 * w * w / gap
    palmer = ideal * (1 + gap / (np.pi * w) * (1 + np.log(2 * np.pi * w / gap))) ** 2
    assert ideal < C < 1.3 * ideal
    assert C == pytest.approx(palmer, rel=0.03)


# ====================================================================== matrix structure
def random_arrangement(rng, n_bodies):
    """Plates and strips at random orientations, each in its own 6-mm slab (no overlaps)."""
    parts = []
    for k in range(n_bodies):
        centre = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), 6.0 * k])
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        if rng.random() < 0.5:
            size = rng.uniform(1.0, 3.0, 2)
            parts.append(
                rectangle_panels(
                    centre,
                    q[0],
                    q[1],
                    size[0],
                    size[1],
                    int(rng.integers(1, 4)),
                    int(rng.integers(1, 4)),
                    k,
                )
            )
        else:
            half = rng.uniform(2, 4) * q[0]
            parts.append(
                strip_panels(
                    centre - half, centre + half, rng.uniform(0.5, 1.5), q[1], k, panel_length=1.5
                )
            )
    return Panels.concatenate(parts)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_maxwell_matrix_sign_structure(seed):
    rng = np.random.default_rng(seed)
    p = random_arrangement(rng, 4 + seed % 2)
    K = maxwell_capacitance(p)
    n = p.n_conductors
    assert K.shape == (n, n)
    np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-12 * np.abs(K).max())
    assert np.all(np.diag(K) > 0)
    assert np.all(K[~np.eye(n, dtype=bool)] < 0)
    assert np.all(K.sum(axis=1) >= 0)
    # physical sanity: no conductor holds more charge than all of them joined together would
    joined = maxwell_capacitance(p.with_conductor(0, 1))[0, 0]
    assert np.all(np.diag(K) > K.sum(axis=1)) and K.sum() == pytest.approx(joined, rel=1e-9)


def test_panel_charges_reproduce_the_potentials():
    p = random_arrangement(np.random.default_rng(7), 3)
    K, q = maxwell_capacitance(p, return_charges=True)
    P = potential_matrix(p)
    B = np.eye(p.n_conductors)[p.conductor]  # (N, n_conductors): 1 V on conductor c
    np.testing.assert_allclose(P @ q, B, atol=1e-9)
    np.testing.assert_allclose(B.T @ q, K, rtol=1e-9, atol=1e-15)


# ====================================================================== convergence
def test_edge_correction_factor_closed_form_and_limit():
    # one uniform cell collocated at its centre: potential 1 + ln 2 per unit charge (2-D),
    # so a_eq = exp(−(1 + ln 2)) = 1/(2e) and the factor (1/4)/a_eq = e/2
    assert edge_correction_factor(1) == pytest.approx(np.e / 2, rel=1e-12)
    fs = [edge_correction_factor(n, "cosine") for n in (2, 4, 8, 32)]
    assert all(f1 > f2 > 1.0 for f1, f2 in itertools.pairwise(fs))
    assert fs[-1] < 1.005


def test_strip_default_discretisation_converges():
    """Recommended default (2 panels across, 2 mm long, ends refined to w/8, edge-corrected):
    the mutual capacitance of two coplanar strips changes by < 1 % when every panel dimension is
    halved, and agrees within 1 % with a fine mesh that has no edge correction at all."""
    c_default = -maxwell_capacitance(coplanar_strips(2, 2.0, 1 / 8))[0, 1]
    c_doubled = -maxwell_capacitance(coplanar_strips(4, 1.0, 1 / 16))[0, 1]
    c_fine_raw = -maxwell_capacitance(coplanar_strips(8, 1.0, 1 / 16, edge_correction=False))[0, 1]
    assert abs(c_doubled / c_default - 1) < 0.01
    assert abs(c_fine_raw / c_default - 1) < 0.01
    # the uncorrected coarse mesh is measurably worse (the reason for the correction)
    c_coarse_raw = -maxwell_capacitance(coplanar_strips(2, 2.0, 1 / 8, edge_correction=False))[0, 1]
    assert c_coarse_raw < 0.95 * c_fine_raw < c_default


def test_strip_mutual_capacitance_against_two_wire_formula():
    """Long coplanar strips of width w act like round wires of radius w/4 (conformal mapping):
    per length C ≈ π ε0 / arccosh(d / (2 · w/4)); ends cancel in a length difference."""
    caps = []
    for L in (40.0, 80.0):
        p = Panels.concatenate(
            [
                strip_panels([0, 0, 0], [0, 0, L], 1.0, [0, 1, 0], 0, n_conductors=2),
                strip_panels([10, 0, 0], [10, 0, L], 1.0, [0, 1, 0], 1, n_conductors=2),
            ]
        )
        caps.append(two_terminal_capacitance(maxwell_capacitance(p), 0, 1))
    per_length = (caps[1] - caps[0]) / 40.0
    assert per_length == pytest.approx(np.pi * EPS0 / np.arccosh(10.0 / 0.5), rel=0.01)


def test_pad_edge_correction_improves_coarse_mesh():
    """Two coplanar 5 × 5 mm pads 5 mm apart: a 3 × 3 edge-corrected mesh is within 3 % of the
    Richardson extrapolation (error ∝ 1/n²) of uncorrected 8 × 8 and 16 × 16 meshes; the
    uncorrected 3 × 3 mesh is more than 10 % off."""

    def mutual(n, corr):
        pads = [
            rectangle_panels(
                [x, 0, 0],
                [1, 0, 0],
                [0, 0, 1],
                5,
                5,
                n,
                n,
                k,
                n_conductors=2,
                spacing_u="cosine",
                spacing_v="cosine",
                edge_correction=corr,
            )
            for k, x in enumerate((0.0, 10.0))
        ]
        return -maxwell_capacitance(Panels.concatenate(pads))[0, 1]

    c8, c16 = mutual(8, False), mutual(16, False)
    fine = c16 + (c16 - c8) / 3
    assert abs(mutual(3, True) / fine - 1) < 0.03
    assert abs(mutual(3, False) / fine - 1) > 0.1


# ====================================================================== readout helpers
def test_ect_readout_and_two_terminal_hand_case():
    K = np.array([[3.0, -1.0, -0.5], [-1.0, 4.0, -2.0], [-0.5, -2.0, 5.0]])
    # electrodes are conductors 2 and 0 (in that order); conductor 1 is e.g. a grounded finger
    c = ect_readout(K, [2, 0], [[0, 1], [1, 0]])
    np.testing.assert_array_equal(c, [0.5, 0.5])
    assert two_terminal_capacitance(K, 0, 1) == pytest.approx((3 * 4 - 1) / (3 + 4 - 2))


def test_two_terminal_matches_direct_floating_solve():
    """Charge +Q on a, −Q on b, every other conductor at 0 V: solve the bordered MoM system
    for the panel charges and the two unknown potentials directly, C = Q / (V_a − V_b)."""
    p = random_arrangement(np.random.default_rng(11), 3)
    P = potential_matrix(p)
    n = p.n_panels
    ia = (p.conductor == 0).astype(float)
    ib = (p.conductor == 1).astype(float)
    # unknowns [q (n), V_a, V_b]: P q − V_a ia − V_b ib = 0, Σ_a q = 1, Σ_b q = −1
    A = np.zeros((n + 2, n + 2))
    A[:n, :n] = P
    A[:n, n] = -ia
    A[:n, n + 1] = -ib
    A[n, :n] = ia
    A[n + 1, :n] = ib
    rhs = np.zeros(n + 2)
    rhs[n], rhs[n + 1] = 1.0, -1.0
    sol = np.linalg.solve(A, rhs)
    C_direct = 1.0 / (sol[n] - sol[n + 1])
    assert two_terminal_capacitance(maxwell_capacitance(p), 0, 1) == pytest.approx(
        C_direct, rel=1e-9
    )


# ====================================================================== builders
def test_from_quads_parallelogram_roundtrip_and_mean_edges():
    p = hand_built_panels()
    np.testing.assert_allclose(Panels.from_quads(p.corners(), p.conductor).corners(), p.corners())
    # a non-parallelogram quad: centre = mean, u, v = mean opposite edges
    q = np.array([[[0, 0, 0], [2, 0, 0], [2.4, 1, 0.2], [0, 1.2, 0]]], float)
    r = Panels.from_quads(q, 0)
    np.testing.assert_allclose(r.centres[0], q[0].mean(0))
    np.testing.assert_allclose(r.u[0], ((q[0, 1] - q[0, 0]) + (q[0, 2] - q[0, 3])) / 2)
    np.testing.assert_allclose(r.v[0], ((q[0, 3] - q[0, 0]) + (q[0, 2] - q[0, 1])) / 2)


def test_sphere_and_cylinder_areas_and_outward_normals():
    s = sphere_panels([1, 2, 3], 5.0, 4, 0)
    assert s.n_panels == 96
    assert s.areas.sum() == pytest.approx(4 * np.pi * 25.0, rel=1e-10)
    assert np.all(np.einsum("ij,ij->i", s.normals, s.centres - [1, 2, 3]) > 0)
    np.testing.assert_allclose(np.linalg.norm(s.centres - [1, 2, 3], axis=1), 5.0)
    c = cylinder_panels([0, 0, 0], [0, 3, 4], 2.0, 12, 5, 0, caps=True)
    side = 12 * 5
    assert c.areas[:side].sum() == pytest.approx(2 * np.pi * 2.0 * 5.0, rel=1e-10)
    assert c.areas[side:].sum() == pytest.approx(2 * np.pi * 4.0, rel=1e-10)
    axis = np.array([0, 0.6, 0.8])
    radial = c.centres[:side] - np.outer(c.centres[:side] @ axis, axis)
    assert np.all(np.einsum("ij,ij->i", c.normals[:side], radial) > 0)
    assert np.all(c.normals[side : side + (c.n_panels - side) // 2] @ axis > 0.99)  # top cap
    assert np.all(c.normals[side + (c.n_panels - side) // 2 :] @ axis < -0.99)  # bottom cap
    # without the correction the corners lie on the true surface
    q = cylinder_quads([0, 0, 0], [0, 3, 4], 2.0, 12, 5)
    rel = q.reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1), 2.0)


def test_rectangle_and_strip_builders():
    q = rectangle_quads([0, 0, 0], [1, 0, 0], [0, 1, 0], 4.0, 2.0, 4, 3, spacing_v="cosine")
    assert q.shape == (12, 4, 3)
    p = Panels.from_quads(q, 0)
    assert p.areas.sum() == pytest.approx(8.0)
    np.testing.assert_allclose(p.normals, [[0, 0, 1]] * 12)
    np.testing.assert_allclose(grid_1d(2, "cosine"), [-0.5, 0, 0.5], atol=1e-15)
    nodes = graded_nodes(20.0, 2.0, 0.125, refine_start=False)
    assert nodes[0] == 0 and nodes[-1] == 20.0 and np.all(np.diff(nodes) > 0)
    assert np.diff(nodes)[-1] == pytest.approx(0.125) and np.diff(nodes).max() <= 2.0 + 1e-12
    s = strip_quads([0, 0, 0], [0, 0, 20], 1.0, [0, 1, 0])
    pts = s.reshape(-1, 3)
    assert pts[:, 2].min() == pytest.approx(0) and pts[:, 2].max() == pytest.approx(20)
    assert np.ptp(pts[:, 0]) == pytest.approx(edge_correction_factor(2))  # widened strip
    np.testing.assert_allclose(Panels.from_quads(s, 0).normals, [[0, 1, 0]] * len(s), atol=1e-12)


# ====================================================================== errors at the door
def test_bad_input_raises_clear_errors():
    with pytest.raises(EctskinError, match="degenerate"):
        Panels.from_quads(np.zeros((1, 4, 3)), 0)
    with pytest.raises(EctskinError, match=r"conductor\[1\]"):
        Panels(np.zeros((2, 3)), np.eye(3)[[0, 0]], np.eye(3)[[1, 1]], [0, 3], 2)
    with pytest.raises(EctskinError, match="shape"):
        Panels.from_quads(np.zeros((2, 3, 3)), 0)
    with pytest.raises(EctskinError, match="finite"):
        Panels.from_quads(np.full((1, 4, 3), np.nan), 0)
    empty = rectangle_panels([0, 0, 0], [1, 0, 0], [0, 1, 0], 1, 1, 1, 1, 0, n_conductors=2)
    with pytest.raises(EctskinError, match=r"conductor\(s\) \[1\] have no panels"):
        maxwell_capacitance(empty)
    with pytest.raises(EctskinError, match="eps_r"):
        potential_matrix(empty, eps_r=-1)
    with pytest.raises(EctskinError, match="coincide|positive definite"):
        twice = Panels.concatenate([empty, empty.with_conductor(1)])
        maxwell_capacitance(twice)
    with pytest.raises(EctskinError, match="perpendicular"):
        rectangle_quads([0, 0, 0], [1, 0, 0], [1, 1, 0], 1, 1, 1, 1)
    with pytest.raises(EctskinError, match="spacing"):
        grid_1d(3, "chebyshev")
    K = np.array([[1.0, -0.5], [-0.5, 1.0]])
    with pytest.raises(EctskinError, match="electrodes"):
        ect_readout(K, [0, 2], [[0, 1]])
    with pytest.raises(EctskinError, match="pairs"):
        ect_readout(K, [0, 1], [[0, 1, 1]])
    with pytest.raises(EctskinError, match="itself"):
        ect_readout(K, [0, 1], [[1, 1]])
    with pytest.raises(EctskinError, match="different"):
        two_terminal_capacitance(K, 1, 1)


def test_dielectric_sensitivity_matches_the_spherical_capacitor():
    """First-order change of K for a dielectric shell between concentric spheres equals the
    derivative of the analytic series formula 1/C = (1/4πε0) Σ (1/ε_k)(1/r_k − 1/r_{k+1})."""
    a, b, r1, r2 = 5.0, 10.0, 6.5, 8.5
    pan = Panels.concatenate(
        [sphere_panels((0, 0, 0), a, 8, 0, n_conductors=2), sphere_panels((0, 0, 0), b, 8, 1, n_conductors=2)]
    )
    _, q = maxwell_capacitance(pan, 1.0, return_charges=True)
    nr, nt, nph = 4, 24, 48  # midpoint cells of the shell r1 < r < r2
    r = r1 + (np.arange(nr) + 0.5) * (r2 - r1) / nr
    th = (np.arange(nt) + 0.5) * np.pi / nt
    ph = (np.arange(nph) + 0.5) * 2 * np.pi / nph
    R, T, P = np.meshgrid(r, th, ph, indexing="ij")
    pts = np.c_[
        (R * np.sin(T) * np.cos(P)).ravel(), (R * np.sin(T) * np.sin(P)).ravel(), (R * np.cos(T)).ravel()
    ]
    vol = (R**2 * np.sin(T)).ravel() * (r2 - r1) / nr * np.pi / nt * 2 * np.pi / nph
    S = dielectric_sensitivity(pan, q, pts, vol, 1.0)
    k = 4 * np.pi * EPS0_PF_PER_MM
    C = k / (1 / a - 1 / b)
    dC = C**2 / k * (1 / r1 - 1 / r2)  # dC/dε of the shell at ε = 1
    assert EPS0_PF_PER_MM * S[0, 1] == pytest.approx(-dC, rel=0.01)  # mutual term: K01 = −C
    assert EPS0_PF_PER_MM * S[0, 0] == pytest.approx(dC, rel=0.01)
    assert np.allclose(S, S.T)
    with pytest.raises(EctskinError, match="volumes must be"):
        dielectric_sensitivity(pan, q, pts, vol[:-1], 1.0)
