"""What the node solves keep between nodes, and that keeping it changes nothing.

A response field's nodes share work that does not depend on the node: the fingertip's shape and
its own block of the potential matrix (per finger, mesh and force: ``sensor.finger_shape`` /
``finger_block``), the untouched electrodes factored for the hover rows (per sensor and state:
``field_solve.untouched_conductors``) and the state part of the electrode corners' and cavity
cells' deformation (``Manipulator.deform(keep_rest=True)``). The references here are
independent of those caches: the fingertip built the old way, in world axes about its axis
(sphere, flattened pad, ``cylinder_panels``), and the full potential matrix of every panel, or
the same call with every cache emptied. Each cache is warmed with *other* keys first (another
force, finger, state, point set), so that a key missing one of its inputs would hand back a
wrong entry and fail the comparison.
"""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.electrostatics import (
    Panels,
    cylinder_panels,
    maxwell_capacitance,
    potential_matrix,
    sphere_panels,
)
from ectskin.electrostatics.meshing import orthonormal_frame
from ectskin.electrostatics.schur import FixedConductors
from ectskin.twin import Finger, Touch, field_solve, rod
from ectskin.twin import sensor as sensor_mod
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec
from ectskin.twin.finger import flatten_cap
from ectskin.twin.mechanics import Manipulator

STATES = ((0.0, 0.0, 0.0), (20.0, 0.0, 20.0))
FORCES = np.array([0.4, 1.1, 1.9])
REL = 1e-12


@pytest.fixture(autouse=True, scope="module")
def _blas_one_thread():
    with threadpool_limits(limits=1):
        yield


def _clear_caches(sensor=None) -> None:
    sensor_mod.finger_shape.cache_clear()
    sensor_mod.finger_block.cache_clear()
    field_solve._UNTOUCHED.clear()
    if sensor is not None:
        sensor.manipulator._rests.clear()


@pytest.fixture
def sensor(layout):
    return FieldSpec(layout, STATES[0], discretisation=COARSE_FIELD_MESH).sensor()


def _old_finger(sensor, tip, f: int) -> Panels:
    """The fingertip of frame f built as before the shape cache: in world axes about its axis,
    the shaft by ``cylinder_panels`` from the centre along the axis."""
    fg, d = tip.finger, sensor.discretisation
    n, centre, depth = tip.axis[f], tip.centre_mm[f], tip.pad_depth_mm[f]
    cond = sensor.n_electrodes
    unit = sphere_panels(np.zeros(3), fg.radius_mm, d.finger_sphere_n, cond)
    keep = unit.centres[:, 2] < -1e-6 * fg.radius_mm
    e1, e2 = orthonormal_frame(n)
    rot = np.stack([e1, e2, n], axis=1)
    c, u, v = flatten_cap(unit.centres[keep], unit.u[keep], unit.v[keep], fg.radius_mm - depth)
    cap = Panels(centre + c @ rot.T, u @ rot.T, v @ rot.T, unit.conductor[keep], cond + 1)
    shaft = cylinder_panels(centre, centre + n * fg.shaft_length_mm, fg.radius_mm,
                            d.finger_shaft_around, d.finger_shaft_along, cond, caps=False)
    return Panels.concatenate([cap, shaft])


def _reference(sensor, state, touch, forces, heights=None) -> np.ndarray:
    """(F, n_pairs) the readout by the full potential matrix of every panel, the finger built
    the old way: nothing taken from a cache."""
    tips = sensor.fingertips(state, touch, forces, heights_mm=heights)
    pe = sensor.electrode_panels(state, touch, forces)
    pts, vols = sensor.cavity_cells(state, touch, forces)
    return np.stack([
        sensor._readout(Panels.concatenate([pe[f], _old_finger(sensor, tips[0], f)]),
                        (pts[f], vols[f]))
        for f in range(len(pe))
    ])


def _close(got, ref, rel=REL) -> None:
    err = np.max(np.abs(got - ref) / np.abs(ref))
    assert err <= rel, f"relative error {err:.3g} > {rel:g}"


# ---------------------------------------------------------------------- contact nodes
@pytest.mark.parametrize("state", STATES)
def test_contact_nodes_with_warm_caches_equal_the_uncached_solve(sensor, state):
    points = [Touch("front", (3.3, 47.0)), Touch("back", (-12.0, 96.0))]
    _clear_caches(sensor)
    # warm every cache with other forces, another finger, the other state
    other = STATES[1] if state == STATES[0] else STATES[0]
    sensor.capacitance(other, Touch("front", (-5.0, 20.0)), FORCES[::-1] + 0.05)
    sensor.with_fingers(Finger(radius_mm=9.5)).capacitance(state, points[0], FORCES)
    for touch in points:
        warm = sensor.capacitance(state, touch, FORCES)
        _close(warm, _reference(sensor, state, touch, FORCES))
        _clear_caches(sensor)
        np.testing.assert_array_equal(warm, sensor.capacitance(state, touch, FORCES))


def test_two_forces_do_not_share_a_fingertip(sensor):
    """The fingertip's block is keyed on its pad depth: a force solved after another gets its
    own (a key without the depth would hand the first force's block to the second)."""
    touch, state = Touch("front", (0.0, 60.0)), STATES[1]
    _clear_caches(sensor)
    first = sensor.capacitance(state, touch, [0.5])
    second = sensor.capacitance(state, touch, [1.8])
    _close(second, _reference(sensor, state, touch, [1.8]))
    assert sensor_mod.finger_block.cache_info().currsize == 2
    assert not np.allclose(first, second, rtol=1e-3)


def test_fingers_and_permittivities_do_not_share_a_fingertip(sensor, layout):
    touch, state = Touch("front", (4.0, 58.0)), STATES[0]
    _clear_caches(sensor)
    sensor.capacitance(state, touch, FORCES)
    big = sensor.with_fingers(Finger(radius_mm=10.0, shaft_length_mm=40.0))
    _close(big.capacitance(state, touch, FORCES), _reference(big, state, touch, FORCES))
    other = FieldSpec(layout, state, discretisation=COARSE_FIELD_MESH, eps_r=3.0).sensor()
    _close(other.capacitance(state, touch, FORCES), _reference(other, state, touch, FORCES))


def test_two_fingers_take_each_fingertips_own_block(sensor):
    state = STATES[1]
    touches = (Touch("front", (3.0, 40.0)), Touch("front", (-10.0, 80.0)))
    forces = np.array([[0.5, 1.2], [1.0, 0.4]])
    _clear_caches(sensor)
    got = sensor.capacitance(state, touches, forces)
    tips = sensor.fingertips(state, touches, forces)
    pe = sensor.electrode_panels(state, touches, forces)
    pts, vols = sensor.cavity_cells(state, touches, forces)
    for f in range(2):
        panels = Panels.concatenate([pe[f]] + [_old_finger(sensor, t, f) for t in tips])
        _close(got[f], sensor._readout(panels, (pts[f], vols[f])))


# ---------------------------------------------------------------------- hover nodes
@pytest.mark.parametrize("state", STATES)
def test_hover_rows_with_a_shared_factor_equal_fresh_ones(sensor, state):
    heights = np.array([0.7, 3.0, 11.0])
    v = np.array([30.0, 61.0])
    _clear_caches(sensor)
    fresh = field_solve.hover_row(sensor, state, "back", 5.0, v, heights)
    # the state's factor and the fingertip shared with rows of another state and face
    other = STATES[1] if state == STATES[0] else STATES[0]
    field_solve.hover_row(sensor, other, "front", -3.0, v, heights)
    field_solve.hover_row(sensor, state, "front", 9.0, v, heights)
    shared = field_solve.hover_row(sensor, state, "back", 5.0, v, heights)
    np.testing.assert_array_equal(shared, fresh)
    for k, vk in enumerate(v):  # and the Schur path against the full solve of every panel
        ref = _reference(sensor, state, Touch("back", (5.0, float(vk))), np.zeros(3), heights)
        _close(shared[k], ref, rel=1e-10)


def test_the_factor_is_the_states_own(sensor):
    _clear_caches(sensor)
    a = field_solve.untouched_conductors(sensor, STATES[0])
    b = field_solve.untouched_conductors(sensor, STATES[1])
    assert a is not b and field_solve.untouched_conductors(sensor, STATES[1]) is b
    for solver, state in ((a, STATES[0]), (b, STATES[1])):
        np.testing.assert_array_equal(
            solver.panels.centres, sensor.electrode_panels(state, None, [0.0])[0].centres
        )


def test_given_blocks_equal_computed_ones_and_bad_ones_are_refused(sensor):
    state = STATES[1]
    solver = field_solve.untouched_conductors(sensor, state)
    sets = sensor.finger_sets(state, Touch("front", (2.0, 55.0)), [0.0, 0.0], heights_mm=[1.0, 4.0])
    panels = [p for p, _ in sets]
    K0, _ = FixedConductors(solver.panels, sensor.eps_r).capacitance(panels)
    K1, _ = solver.capacitance(panels, blocks=[b[0][1] for _, b in sets])
    np.testing.assert_allclose(K1, K0, rtol=1e-12, atol=1e-15)
    with pytest.raises(EctskinError, match="one .N_F, N_F. matrix per added set"):
        solver.capacitance(panels, blocks=[np.eye(3), np.eye(3)])


# ---------------------------------------------------------------------- the pieces
def test_a_known_block_leaves_every_other_entry_as_it_was(sensor):
    state, touch = STATES[1], Touch("front", (1.0, 50.0))
    pe = sensor.electrode_panels(state, touch, [1.0])[0]
    pf, blocks = sensor.finger_sets(state, touch, [1.0])[0]
    panels = Panels.concatenate([pe, pf])
    n = pe.n_panels
    full = potential_matrix(panels, sensor.eps_r)
    given = potential_matrix(panels, sensor.eps_r, blocks=[(n, blocks[0][1])])
    np.testing.assert_array_equal(given[:n], full[:n])
    np.testing.assert_array_equal(given[:, :n], full[:, :n])
    np.testing.assert_array_equal(given[n:, n:], blocks[0][1])
    np.testing.assert_allclose(given[n:, n:], full[n:, n:], rtol=1e-13, atol=0)
    K = maxwell_capacitance(panels, sensor.eps_r, blocks=[(n, blocks[0][1])])
    np.testing.assert_allclose(K, maxwell_capacitance(panels, sensor.eps_r), rtol=1e-11, atol=1e-16)


@pytest.mark.parametrize(
    "blocks, match",
    [
        ([(0, np.eye(3)), (2, np.eye(3))], "overlaps"),
        ([(5, np.ones((3, 2)))], "square"),
        ([(-1, np.eye(2))], "within"),
        ([(4, np.eye(3))], "within"),
        ([(0, np.full((2, 2), np.nan))], "non-finite"),
        ([(0.0, np.eye(2))], "start must be an int"),
        ([(1, np.eye(2), 3)], "pair"),
    ],
)
def test_bad_blocks_are_refused(blocks, match):
    panels = sphere_panels(np.zeros(3), 1.0, 1, 0)  # 6 panels
    with pytest.raises(EctskinError, match=match):
        potential_matrix(panels, 1.0, blocks=blocks)


def test_kept_rest_points_deform_as_fresh_ones():
    m = Manipulator()
    rng = np.random.default_rng(1)
    uv = np.c_[rng.uniform(-24, 24, 300), rng.uniform(0, 120, 300)]
    for state in ((0, 0, 0), (20, 0, 20), (5, 10, 30)):
        for touch in (None, Touch("front", (3.0, 50.0)), Touch("back", (-10.0, 100.0))):
            for surface in ("front", "back", "right"):
                fresh = m.deform(surface, uv, state, touch, [0.3, 1.7])
                np.testing.assert_array_equal(
                    m.deform(surface, uv, state, touch, [0.3, 1.7], keep_rest=True), fresh)
                np.testing.assert_array_equal(  # (the kept entry)
                    m.deform(surface, uv, state, touch, [0.3, 1.7], keep_rest=True), fresh)
    # the caller's array changed after it was kept: the new points are deformed
    moved = uv.copy()
    m.deform("front", moved, (20, 0, 20), None, [0.0], keep_rest=True)
    moved[:, 1] += 1.0
    np.testing.assert_array_equal(
        m.deform("front", moved, (20, 0, 20), None, [0.0], keep_rest=True),
        m.deform("front", moved, (20, 0, 20), None, [0.0]),
    )


def _integrate_loop(s, kappa):
    """The rod's axis and frames step by step (the loop :func:`rod.integrate` replaced)."""
    n_f, n = kappa.shape[:2]
    ds = np.diff(s)
    phi = 0.5 * (kappa[:, 1:] + kappa[:, :-1]) * ds[None, :, None]
    steps = rod.rotation_step(phi)
    a, b = rod._rodrigues(0.5 * phi)
    h = 0.5 * phi
    mid = np.concatenate([
        a * h[..., 1:2] + b * h[..., 0:1] * h[..., 2:3],
        -a * h[..., 0:1] + b * h[..., 1:2] * h[..., 2:3],
        1.0 + b * (h[..., 2:3] ** 2 - np.sum(h * h, axis=-1, keepdims=True)),
    ], axis=-1)
    r = np.zeros((n_f, n, 3))
    rot = np.zeros((n_f, n, 3, 3))
    rot[:, 0] = np.eye(3)
    for i in range(n - 1):
        r[:, i + 1] = r[:, i] + np.einsum("fij,fj->fi", rot[:, i], mid[:, i]) * ds[i]
        rot[:, i + 1] = rot[:, i] @ steps[:, i]
    return r, rot


@pytest.mark.parametrize("n_frames", [1, 4])
def test_the_rods_integration_is_the_step_by_step_one(n_frames):
    rng = np.random.default_rng(n_frames)
    s = np.linspace(0.0, 120.0, 61)
    kappa = rng.normal(size=(n_frames, 61, 3)) * 0.01
    r, rot = rod.integrate(s, kappa)
    r0, rot0 = _integrate_loop(s, kappa)
    np.testing.assert_array_equal(rot, rot0)
    np.testing.assert_array_equal(r, r0)
