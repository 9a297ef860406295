"""The method of moments' quick paths against the formula they evaluate: the panel integral
of many pairs taken a chunk at a time (each pair's arithmetic is its own, so the numbers are
the same as all at once) and from contiguous columns (the potential matrix's path), and the
potential matrix against the same matrix built pair by pair from the panel integral."""

from __future__ import annotations

import numpy as np

import ectskin.electrostatics.mom as mom
from ectskin.electrostatics import Panels, potential_integral, potential_matrix
from ectskin.electrostatics.mom import EPS0_PF_PER_MM


def _pairs(m: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u, v = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    rel = rng.normal(size=(m, 3)) * 2.0
    rel[::7] = 0.0  # self terms: the point at the panel's centre
    rel[1::7, :2] = 0.0  # on the panel's normal through its centre
    return rel, mom._panel_frames(u, v)


def test_the_integral_by_chunks_is_the_integral_at_once(monkeypatch):
    """A chunk size that leaves a short last chunk: every pair once, in its place, bit for
    bit (a chunk dropped, repeated or shifted changes whole runs of pairs)."""
    rel, frames = _pairs(1000)
    whole = mom._integral_columns(np.ascontiguousarray(rel.T), np.ascontiguousarray(frames.T))
    monkeypatch.setattr(mom, "_CHUNK", 64)
    np.testing.assert_array_equal(mom._integral(rel, frames), whole)
    monkeypatch.setattr(mom, "_CHUNK", 999)
    np.testing.assert_array_equal(mom._integral(rel, frames), whole)
    monkeypatch.setattr(mom, "_CHUNK", 5000)
    np.testing.assert_array_equal(mom._integral(rel, frames), whole)


def test_the_potential_matrix_is_built_pair_by_pair():
    """Every entry of the potential matrix of a small irregular set against the same entry built
    from :func:`potential_integral` one pair at a time (near pairs, both ways, symmetrised) or
    the point charge (far pairs), to round-off: a gather of the wrong panel's frame or centre
    for the columns' path is off by far more."""
    rng = np.random.default_rng(4)
    quads = []
    for _ in range(40):
        corner = rng.uniform(0, 12, 3)
        a, b = rng.normal(size=3), rng.normal(size=3)
        quads.append([corner, corner + a, corner + a + b, corner + b])
    p = Panels.from_quads(np.array(quads), np.arange(40) % 3, 3)
    got = potential_matrix(p, 2.5)
    scale = 1.0 / (4.0 * np.pi * EPS0_PF_PER_MM * 2.5)
    c, reach = p.centres, 3.0 * p.sizes
    ref = np.empty_like(got)
    for i in range(40):
        for j in range(40):
            d = np.linalg.norm(c[i] - c[j])
            if d < max(reach[i], reach[j]):
                ij = potential_integral(c[i:i + 1], c[j:j + 1], p.u[j:j + 1], p.v[j:j + 1])[0]
                ji = potential_integral(c[j:j + 1], c[i:i + 1], p.u[i:i + 1], p.v[i:i + 1])[0]
                ref[i, j] = 0.5 * (ij / p.areas[j] + ji / p.areas[i]) * scale
            else:
                ref[i, j] = scale / d
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=0)
