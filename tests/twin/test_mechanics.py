"""Manipulator mechanics against hand-derived results (volume, beam theory) and clear errors."""

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.twin import Manipulator, ManipulatorConfig, Touch


def test_bulge_conserves_the_injected_volume():
    m = Manipulator()
    c = m.config
    for v_ml in (5.0, 20.0, 30.0):
        h = m.bulge_height_mm([v_ml, 0, 0])
        # integrate the bulge of one face over the chamber footprint numerically
        x = np.linspace(-c.chamber_size_x_mm / 2, c.chamber_size_x_mm / 2, 401)
        z = np.linspace(5, 35, 401)
        X, Z = np.meshgrid(x, z, indexing="ij")
        b = m.bulge_mm(X.ravel(), Z.ravel(), h).reshape(X.shape)
        face_mm3 = np.trapezoid(np.trapezoid(b, z, axis=1), x)
        wall_mm3 = 1000 * c.wall_compliance_ml_per_kpa * m.pressure_kpa([v_ml, 0, 0])[0]
        assert 2 * face_mm3 + wall_mm3 == pytest.approx(v_ml * 1000, rel=2e-3)
    # stiffening: doubling the volume less than doubles the bulge
    h10, h20 = m.bulge_height_mm([10, 10, 10])[0], m.bulge_height_mm([20, 20, 20])[0]
    assert h10 < h20 < 2 * h10


def test_small_force_bending_matches_euler_bernoulli():
    """Uninflated beam, uniform EI: tip deflection of a clamped beam loaded at a = F a²(3L − a)/(6EI)."""
    m = Manipulator(ManipulatorConfig(beam_points=2001))
    ei = m.config.bending_stiffness_nmm2
    a, length, force = 100.0, 120.0, 0.05  # small force: linear regime
    tip = m.deform("right", [[0.0, length]], [0, 0, 0], Touch("front", (0.0, a)), force)[0, 0]
    expected = force * a**2 * (3 * length - a) / (6 * ei)
    assert -tip[1] == pytest.approx(expected, rel=1e-3)  # front touch pushes towards -y


def test_large_deflection_is_geometrically_exact():
    """Material lines keep their length: the tip marker's distance along the axis is conserved."""
    m = Manipulator(ManipulatorConfig(beam_points=2001))
    z = np.linspace(0, 120, 121)
    pts = m.deform("right", np.c_[np.zeros_like(z), z], [0, 0, 0], Touch("back", (0, 110)), 2.5)[0]
    arc = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    assert arc == pytest.approx(120.0, rel=1e-4)
    assert pts[-1, 1] > 10.0  # a back touch bends towards +y, by a lot


def test_inflation_stiffens_bending_and_dimple():
    m = Manipulator()
    t = Touch("front", (0.0, 110.0))
    tip0 = m.deform("right", [[0, 120]], [0, 0, 0], t, 2.0)[0, 0]
    tip20 = m.deform("right", [[0, 120]], [20, 20, 20], t, 2.0)[0, 0]
    assert 10.0 <= abs(tip0[1]) <= 25.0  # typical 2 N touch moves the tip 10–20 mm
    assert abs(tip20[1]) < 0.8 * abs(tip0[1])
    assert m.dimple_depth_mm(2.0, t, [20, 20, 20]) < m.dimple_depth_mm(2.0, t, [0, 0, 0])


def test_face_points_follow_the_bulge_and_wires_stretch():
    m = Manipulator()
    z = np.linspace(45, 75, 61)
    rest = m.deform("front", np.c_[np.zeros_like(z), z], [0, 0, 0])[0]
    infl = m.deform("front", np.c_[np.zeros_like(z), z], [0, 20, 0])[0]
    # the crest reaches the bulge height (material is pulled towards the base, so take the max)
    assert infl[:, 1].max() - rest[30, 1] == pytest.approx(m.bulge_height_mm([0, 20, 0])[1], rel=1e-3)
    assert infl[30, 2] < rest[30, 2]  # pulled in along z

    def length(p):
        return np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1))

    assert length(infl) > 1.02 * length(rest)  # stretched along the wire
    back = m.deform("back", [[0, 60]], [0, 20, 0])[0, 0]
    assert back[1] == pytest.approx(-10 - (infl[30, 1] - 10), rel=1e-9)  # both faces bulge alike


@pytest.mark.parametrize(
    "p, message",
    [([-1, 0, 0], "chamber 1: -1.0 ml"), ([0, 0, 45], "chamber 3: 45.0 ml; expected 0 to 30"),
     ([0, 0], "one volume per chamber"), ([0, float("nan"), 0], "chamber 2")],
)
def test_impossible_inflation_is_a_clear_error(p, message):
    with pytest.raises(EctskinError, match=message):
        Manipulator().check_inflation(p)
