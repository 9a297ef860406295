"""The Schur path (fixed conductors factored once, panels added) against brute force.

The reference is the plain method of moments on all panels together (``maxwell_capacitance`` of
the concatenation, ``dielectric_sensitivity`` with its charges), and for the potential block a
slow loop over panel pairs; the fast path must agree to round-off.
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.electrostatics import (
    EPS0_PF_PER_MM,
    NEAR_FACTOR,
    Panels,
    dielectric_sensitivity,
    maxwell_capacitance,
    potential_integral,
    rectangle_panels,
    sphere_panels,
)
from ectskin.electrostatics import schur as schur_mod
from ectskin.electrostatics.schur import FixedConductors, potential_block


def _plates() -> Panels:
    """Two coplanar 'electrodes' (conductors 0, 1) of a 3-conductor system (2 = the finger)."""
    a = rectangle_panels((-6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 0, n_conductors=3)
    b = rectangle_panels((6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 1, n_conductors=3)
    return Panels.concatenate([a, b])


def _finger(x: float, z: float, rot: float = 0.0, radius: float = 4.0) -> Panels:
    """A sphere (conductor 2) at (x, 0, z), turned by ``rot`` about the y axis."""
    s = sphere_panels(np.zeros(3), radius, 3, 2, n_conductors=3)
    c, s_ = np.cos(rot), np.sin(rot)
    R = np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])
    return Panels(s.centres @ R.T + [x, 0.0, z], s.u @ R.T, s.v @ R.T, s.conductor, 3)


def _brute_block(rows: Panels, cols: Panels, eps_r: float) -> np.ndarray:
    """The (rows, cols) block of Eq. (1), one pair at a time (near pairs by the exact integral of
    ``potential_integral``, far ones as point charges, then the symmetric mean)."""
    out = np.empty((rows.n_panels, cols.n_panels))
    for i in range(rows.n_panels):
        for j in range(cols.n_panels):
            d = np.linalg.norm(rows.centres[i] - cols.centres[j])
            if d < NEAR_FACTOR * max(rows.sizes[i], cols.sizes[j]):
                pij = potential_integral(
                    rows.centres[i : i + 1], cols.centres[j : j + 1], cols.u[j : j + 1],
                    cols.v[j : j + 1],
                )[0] / cols.areas[j]
                pji = potential_integral(
                    cols.centres[j : j + 1], rows.centres[i : i + 1], rows.u[i : i + 1],
                    rows.v[i : i + 1],
                )[0] / rows.areas[i]
            else:
                pij = pji = 1.0 / d
            out[i, j] = 0.5 * (pij + pji) / (4 * np.pi * EPS0_PF_PER_MM * eps_r)
    return out


def _cells() -> tuple[np.ndarray, np.ndarray]:
    """Sample cells below the plates (a 'cavity')."""
    g = np.linspace(-10, 10, 5)
    X, Y = np.meshgrid(g, g)
    pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, -5.0)]
    return pts, np.full(X.size, 8.0)


def test_potential_block_is_the_brute_force_block():
    rows, cols = _plates(), _finger(2.0, 5.0)
    got = potential_block(rows, cols, 2.0)
    np.testing.assert_allclose(got, _brute_block(rows, cols, 2.0), rtol=1e-12, atol=0)
    # and it is the corresponding block of the full matrix's symmetric counterpart
    np.testing.assert_allclose(potential_block(cols, rows, 2.0), got.T, rtol=1e-12)


@pytest.mark.parametrize("eps_r", [1.0, 2.5])
def test_schur_capacitance_equals_the_full_solve(eps_r):
    fixed = _plates()
    solver = FixedConductors(fixed, eps_r)
    fingers = [_finger(x, z) for x, z in [(0.0, 5.0), (4.0, 6.5), (-7.0, 5.2), (12.0, 9.0)]]
    K, S = solver.capacitance(fingers)
    assert S is None and K.shape == (4, 3, 3)
    for k, f in enumerate(fingers):
        ref = maxwell_capacitance(Panels.concatenate([fixed, f]), eps_r)
        np.testing.assert_allclose(K[k], ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
    # the finger matters: the readouts differ from the fixed panels alone and between positions
    assert np.abs(K[0, 0, 1] - K[2, 0, 1]) > 1e-3 * abs(K[0, 0, 1])
    assert np.allclose(solver.K0[2], 0.0)


def test_added_panels_may_join_a_fixed_conductor():
    """Added panels of conductor 0 (a wire extended) as well as a new conductor."""
    fixed = _plates()
    extra = rectangle_panels((-6, 14, 0), (1, 0, 0), (0, 1, 0), 8, 6, 3, 2, 0, n_conductors=3)
    both = Panels.concatenate([extra, _finger(3.0, 6.0)])
    K, _ = FixedConductors(fixed, 2.0).capacitance([both])
    ref = maxwell_capacitance(Panels.concatenate([fixed, both]), 2.0)
    np.testing.assert_allclose(K[0], ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())


def test_sensitivity_equals_dielectric_sensitivity_of_the_full_charges():
    fixed, cells = _plates(), _cells()
    solver = FixedConductors(fixed, 2.0, cells=cells)
    fingers = [_finger(1.0, 5.5), _finger(-3.0, 7.0)]
    K, S = solver.capacitance(fingers, sensitivity_columns=2)
    assert S is not None and S.shape == (2, 2, 2)
    for k, f in enumerate(fingers):
        allp = Panels.concatenate([fixed, f])
        ref_K, q = maxwell_capacitance(allp, 2.0, return_charges=True)
        ref_S = dielectric_sensitivity(allp, q[:, :2], cells[0], cells[1], 2.0)
        np.testing.assert_allclose(K[k], ref_K, rtol=1e-10, atol=1e-12 * np.abs(ref_K).max())
        np.testing.assert_allclose(S[k], ref_S, rtol=1e-9, atol=1e-12 * np.abs(ref_S).max())


def test_rigid_motions_share_the_self_block_and_other_shapes_do_not():
    """The finger's own block is reused for a moved and turned copy, never for another shape:
    each result still equals its full solve."""
    fixed = _plates()
    solver = FixedConductors(fixed, 2.0)
    fingers = [_finger(0.0, 5.0), _finger(3.0, 6.0, rot=0.3), _finger(1.0, 6.0, radius=3.0)]
    for f in fingers:  # one at a time: the cache carries over between calls
        K, _ = solver.capacitance([f])
        ref = maxwell_capacitance(Panels.concatenate([fixed, f]), 2.0)
        np.testing.assert_allclose(K[0], ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_batches_give_the_same_result(monkeypatch):
    fixed = _plates()
    fingers = [_finger(x, 5.5) for x in (-4.0, 0.0, 4.0)]
    whole, _ = FixedConductors(fixed, 2.0).capacitance(fingers)
    monkeypatch.setattr(schur_mod, "BATCH_COLUMNS", 10)  # one finger per batch
    split, _ = FixedConductors(fixed, 2.0).capacitance(fingers)
    np.testing.assert_allclose(split, whole, rtol=1e-12)


def test_bad_input_is_refused():
    fixed = _plates()
    solver = FixedConductors(fixed, 2.0)
    with pytest.raises(EctskinError, match="n_conductors"):
        solver.capacitance([sphere_panels((0, 0, 5), 3, 2, 2, n_conductors=4)])
    with pytest.raises(EctskinError, match="no panels"):  # conductor 2 nowhere
        solver.capacitance([rectangle_panels((0, 30, 0), (1, 0, 0), (0, 1, 0), 4, 4, 2, 2, 1,
                                             n_conductors=3)])
    with pytest.raises(EctskinError, match="cells"):
        solver.capacitance([_finger(0.0, 5.0)], sensitivity_columns=2)
    # a 'finger' lying on a plate: its panels coincide with the fixed ones
    with pytest.raises(EctskinError):
        on_plate = rectangle_panels((-6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 2,
                                    n_conductors=3)
        solver.capacitance([on_plate])
