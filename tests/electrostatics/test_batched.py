"""Batched method-of-moments solves on a torch device against the one-at-a-time NumPy path.

The reference is :func:`maxwell_capacitance` of each set alone (and
:func:`dielectric_sensitivity` with its charges): the batched solve must agree to round-off,
whatever the order and mix of set sizes in one call. On CI the device is the CPU; the same code
runs on a GPU (``BENCHMARKS.md``).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ectskin._check import EctskinError
from ectskin.electrostatics import (
    EPS0_PF_PER_MM,
    Panels,
    batched,
    dielectric_sensitivity,
    maxwell_capacitance,
    potential_matrix,
    rectangle_panels,
    sphere_panels,
)
from ectskin.electrostatics.batched import (
    SOLVE_DEVICE_ENV,
    maxwell_batch,
    readout_batch,
    solve_device,
)


def _system(x: float, z: float, sphere_n: int = 3, shift: float = 0.0) -> Panels:
    """Two plates (conductors 0, 1) and a sphere (conductor 2) at (x, 0, z)."""
    a = rectangle_panels((-6 + shift, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 0, n_conductors=3)
    b = rectangle_panels((6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 1, n_conductors=3)
    s = sphere_panels(np.array([x, 0.0, z]), 4.0, sphere_n, 2, n_conductors=3)
    return Panels.concatenate([a, b, s])


def _cells(z: float) -> tuple[np.ndarray, np.ndarray]:
    g = np.linspace(-8, 8, 5)
    X, Y = np.meshgrid(g, g)
    pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)]
    return pts, np.full(X.size, 2.0)


def test_a_mixed_batch_equals_each_set_solved_alone():
    # sets of two panel counts (sphere_n 3 and 4), interleaved, so grouping and order matter
    sets = [_system(x, z, n, shift) for x, z, n, shift in
            [(0, 7, 3, 0.0), (3, 6, 4, 0.5), (-4, 9, 3, 1.0), (1, 5.5, 4, 0.0), (2, 12, 3, 0.3)]]
    cells = [_cells(-3.0 - k) for k in range(len(sets))]
    K, S, ok = maxwell_batch(sets, 2.5, device="cpu", cells=cells, sensitivity_columns=2)
    assert ok.all()
    for k, p in enumerate(sets):
        K_ref, q = maxwell_capacitance(p, 2.5, return_charges=True)
        S_ref = dielectric_sensitivity(p, q[:, :2], *cells[k], 2.5)
        np.testing.assert_allclose(K[k], K_ref, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(S[k], S_ref, rtol=1e-10, atol=1e-14 * np.abs(S_ref).max())


def test_known_blocks_are_used_as_given():
    p = _system(0.0, 7.0)
    n_s = 25  # the sphere's panels come last
    first = p.n_panels - n_s
    own = potential_matrix(
        Panels(p.centres[first:], p.u[first:], p.v[first:], p.conductor[first:], 3), 1.0
    )
    K_given, _, _ = maxwell_batch([p], device="cpu", blocks=[[(first, own)]])
    K_ref = maxwell_capacitance(p, blocks=[(first, own)])
    np.testing.assert_allclose(K_given[0], K_ref, rtol=1e-11)
    # a wrong block must change the answer (the block is really used)
    K_wrong, _, _ = maxwell_batch([p], device="cpu", blocks=[[(first, 1.1 * own)]])
    assert np.max(np.abs(K_wrong[0] - K_ref)) > 1e-4 * np.abs(K_ref).max()


def test_the_readout_adds_the_cavity_term_as_the_twin_does():
    sets = [_system(0.0, 7.0), _system(2.0, 8.0)]
    cells = [_cells(-3.0), _cells(-4.0)]
    pairs = np.array([[0, 1]])
    C, ok = readout_batch(sets, eps_r=2.0, n_electrodes=2, pairs=pairs, device="cpu",
                          chamber_eps_r=1.0, cells=cells)
    assert ok.all()
    for k, p in enumerate(sets):
        K, q = maxwell_capacitance(p, 2.0, return_charges=True)
        S = dielectric_sensitivity(p, q[:, :2], *cells[k], 2.0)
        want = -(K[:2, :2] + EPS0_PF_PER_MM * (1.0 - 2.0) * S)[0, 1]
        assert C[k, 0] == pytest.approx(want, rel=1e-11)
    with pytest.raises(EctskinError, match="cavity cells"):
        readout_batch(sets, eps_r=2.0, n_electrodes=2, pairs=pairs, device="cpu", chamber_eps_r=1.0)


@pytest.mark.parametrize("spoil", ["indefinite", "not finite"])
def test_a_set_that_does_not_factor_is_flagged_not_raised(monkeypatch, spoil):
    # the middle set's coefficients spoilt (as a coarse fingertip panel beside a fine wire end
    # makes them indefinite), the others' left as they are
    good = _system(0.0, 7.0)
    real = batched._potential

    def spoilt(*args):
        P = real(*args)
        P[1, 5, 5] = -P[1, 5, 5] if spoil == "indefinite" else float("nan")
        return P

    monkeypatch.setattr(batched, "_potential", spoilt)
    K, _, ok = maxwell_batch([good, good, good], device="cpu")
    assert ok.tolist() == [True, False, True]
    assert np.isnan(K[1]).all()
    for k in (0, 2):
        np.testing.assert_allclose(K[k], maxwell_capacitance(good), rtol=1e-11)


def test_bad_input_is_refused():
    with pytest.raises(EctskinError, match="no panel sets"):
        maxwell_batch([], device="cpu")
    p = _system(0.0, 7.0)
    q = Panels(p.centres, p.u, p.v, p.conductor, 4)  # conductor 3 has no panels
    with pytest.raises(EctskinError, match="n_conductors"):
        maxwell_batch([p, q], device="cpu")
    with pytest.raises(EctskinError, match="sensitivity_columns"):
        maxwell_batch([p], device="cpu", sensitivity_columns=2)


def test_the_device_is_read_from_the_option_then_the_environment(monkeypatch):
    monkeypatch.delenv(SOLVE_DEVICE_ENV, raising=False)
    assert solve_device() is None
    assert solve_device("numpy") is None
    assert solve_device("CPU") == "cpu"
    monkeypatch.setenv(SOLVE_DEVICE_ENV, "cpu")
    assert solve_device() == "cpu"
    assert solve_device("numpy") is None  # the option wins
    monkeypatch.setenv(SOLVE_DEVICE_ENV, "gpu please")
    with pytest.raises(EctskinError, match=SOLVE_DEVICE_ENV):
        solve_device()
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert solve_device("auto") is None
    with pytest.raises(EctskinError, match="no CUDA GPU"):
        solve_device("cuda")


def test_a_large_batch_is_cut_into_parts(monkeypatch):
    monkeypatch.setattr(batched, "MAX_BATCH", 2)
    sets = [_system(x, 7.0) for x in (-2.0, -1.0, 0.0, 1.0, 2.0)]
    K, _, ok = maxwell_batch(sets, device="cpu")
    assert ok.all()
    for k, p in enumerate(sets):
        np.testing.assert_allclose(K[k], maxwell_capacitance(p), rtol=1e-11)


def test_the_schur_batch_equals_the_fixed_conductors_one_at_a_time():
    from ectskin.electrostatics.batched_schur import schur_batch
    from ectskin.electrostatics.schur import FixedConductors

    plates = Panels.concatenate([
        rectangle_panels((-6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 0, n_conductors=3),
        rectangle_panels((6, 0, 0), (1, 0, 0), (0, 1, 0), 8, 20, 3, 6, 1, n_conductors=3),
    ])
    cells = _cells(-3.0)
    fixed = FixedConductors(plates, 2.0, cells=cells)
    shape = sphere_panels(np.zeros(3), 4.0, 3, 2, n_conductors=3)
    own = potential_matrix(shape, 2.0)
    added = [Panels(shape.centres + [x, 1.0, z], shape.u, shape.v, shape.conductor, 3)
             for x, z in [(0, 5), (3, 7), (-5, 4.6), (1, 12)]]
    K_ref, S_ref = fixed.capacitance(added, sensitivity_columns=2, blocks=[own] * 4)
    K, S, ok = schur_batch(fixed, added, [own] * 4, device="cpu", sensitivity_columns=2)
    assert ok.all()
    np.testing.assert_allclose(K, K_ref, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(S, S_ref, rtol=1e-10, atol=1e-14 * np.abs(S_ref).max())
    # the whole system solved at once is the same again (independent of the Schur algebra)
    full = maxwell_capacitance(Panels.concatenate([plates, added[1]]), 2.0)
    np.testing.assert_allclose(K[1], full, rtol=1e-9)
    # a set whose Schur complement is spoilt is flagged; the others are untouched
    bad = [own, -own, own, own]
    K2, _, ok2 = schur_batch(fixed, added, bad, device="cpu")
    assert ok2.tolist() == [True, False, True, True]
    np.testing.assert_allclose(np.delete(K2, 1, 0), np.delete(K, 1, 0), rtol=1e-12)
    with pytest.raises(EctskinError, match="one own block per added set"):
        schur_batch(fixed, added, [own], device="cpu")
