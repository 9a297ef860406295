"""Manipulator mechanics against hand-derived results (volume, beam theory) and clear errors."""

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.twin import Manipulator, ManipulatorConfig, Touch
from ectskin.twin.mechanics import Handling


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


def test_section_stiffness_from_the_modulus_and_the_chambered_section():
    """Hand-computed for the default body: 50 × 20 mm, a 40 × 12 mm cavity over each chamber."""
    m = Manipulator()
    e = m.config.modulus_mpa
    solid, hollow = m.section_stiffness(np.array([40.0, 20.0]), [0, 0, 0])
    assert solid[0] == pytest.approx(e * 50 * 20**3 / 12)  # 33 333 E
    assert solid[1] == pytest.approx(e * 20 * 50**3 / 12)
    # Saint-Venant: β(a/b = 2.5) = 0.249 (Timoshenko & Goodier's table), G = E/3
    assert solid[2] == pytest.approx(e / 3 * 0.249 * 50 * 20**3, rel=3e-3)
    assert hollow[0] == pytest.approx(e * (50 * 20**3 - 40 * 12**3) / 12)  # 27 573 E
    # Bredt: median line 45 × 16 mm, walls 5 (sides) and 4 (faces) mm
    assert hollow[2] == pytest.approx(e / 3 * 4 * (45 * 16) ** 2 / (2 * 45 / 4 + 2 * 16 / 5))
    inflated = m.section_stiffness(np.array([20.0]), [20, 0, 0])[0]
    assert np.all(inflated > hollow)  # pressure stiffens the chamber's span


def test_small_force_bending_matches_euler_bernoulli():
    """Small force: tip deflection w = ∫₀ᵃ F (a − z)(L − z) / EI(z) dz (unit-load method) with
    the body's varying section."""
    m = Manipulator(ManipulatorConfig(beam_points=481))
    a, length, force = 100.0, 120.0, 0.01
    tip = m.deform("right", [[0.0, length]], [0, 0, 0], Touch("front", (0.0, a)), force)[0, 0]
    z = np.linspace(0, a, 20001)
    ei = m.section_stiffness(z, [0, 0, 0])[:, 0]
    expected = np.trapezoid(force * (a - z) * (length - z) / ei, z)
    assert -tip[1] == pytest.approx(expected, rel=2e-3)  # front touch pushes towards -y


def test_large_deflection_is_geometrically_exact():
    """Material lines keep their length: the tip marker's distance along the axis is conserved."""
    m = Manipulator()
    z = np.linspace(0, 120, 121)
    pts = m.deform("right", np.c_[np.zeros_like(z), z], [0, 0, 0], Touch("back", (0, 110)), 2.5)[0]
    arc = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    assert arc == pytest.approx(120.0, rel=2e-3)
    assert pts[-1, 1] > 20.0  # a back touch bends towards +y, by a lot


def test_off_centre_and_off_axis_loads_twist_and_bend_both_ways():
    m = Manipulator()
    tip = [[0.0, 120.0]]
    # a press on the front at x = +15 mm twists the body: the right side (x = +25) dips further
    # towards -y than the left side (x = -25)
    t = Touch("front", (15.0, 100.0))
    right = m.deform("right", tip, [0, 0, 0], t, 1.0)[0, 0]
    left = m.deform("left", tip, [0, 0, 0], t, 1.0)[0, 0]
    assert right[1] < left[1] - 1.0
    # the hand pushing the right side towards -x bends the body sideways
    push = Handling(push=Touch("right", (0.0, 110.0)), push_force_n=np.array([[-1.0, 0.0, 0.0]]))
    moved = m.deform("front", [[0.0, 120.0]], [0, 0, 0], None, 0.0, push)[0, 0]
    assert moved[0] < -2.0 and abs(moved[1] - 10.0) < 1.0
    # a finger pushing along the face (shear) bends the body along x as well
    shear = Handling(shear_n=np.array([[0.5, 0.0]]))
    sheared = m.deform("front", [[0.0, 120.0]], [0, 0, 0], Touch("front", (0.0, 110.0)), 1.0, shear)
    assert sheared[0, 0, 0] > 1.0
    with pytest.raises(EctskinError, match="frames"):
        m.deform("front", tip, [0, 0, 0], t, [1.0, 2.0], shear)


def test_inflation_stiffens_bending_and_dimple():
    m = Manipulator()
    t = Touch("front", (0.0, 110.0))
    tip0 = m.deform("right", [[0, 120]], [0, 0, 0], t, 2.0)[0, 0]
    tip20 = m.deform("right", [[0, 120]], [20, 20, 20], t, 2.0)[0, 0]
    assert 10.0 <= abs(tip0[1]) <= 40.0  # a firm 2 N press near the tip moves it centimetres
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
