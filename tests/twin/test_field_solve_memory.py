"""A process that solves field nodes keeps the memory it frees: ``solve_chunk`` asks the
project's :func:`ectskin._malloc.keep_freed_memory` (the CLI's and the Dask workers' setting),
once per process, and goes on whatever it answers (the solves are the same numbers either way)."""

from __future__ import annotations

import numpy as np

from ectskin.twin import field_solve


def test_the_projects_setting_is_asked_once_per_process(monkeypatch):
    calls = []
    monkeypatch.setattr(field_solve, "_MALLOC_SET", [])
    monkeypatch.setattr(field_solve, "keep_freed_memory", lambda: calls.append(1) or True)
    assert field_solve._keep_freed_memory_once() is True
    assert field_solve._keep_freed_memory_once() is True
    assert calls == [1]


def test_without_glibc_the_solves_go_on(monkeypatch):
    monkeypatch.setattr(field_solve, "_MALLOC_SET", [])
    monkeypatch.setattr(field_solve, "keep_freed_memory", lambda: False)
    assert field_solve._keep_freed_memory_once() is False


def test_solve_chunk_asks_once_and_solves(monkeypatch):
    """Two chunks solved in this process ask once, and the untouched chunk is the sensor's own
    untouched readout whatever the answer."""
    from ectskin.layout import default_layout
    from ectskin.twin.field_solve import Chunk, solve_chunk
    from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

    calls = []
    monkeypatch.setattr(field_solve, "_MALLOC_SET", [])
    monkeypatch.setattr(field_solve, "keep_freed_memory", lambda: calls.append(1) or False)
    spec = FieldSpec(default_layout(), (0.0, 0.0, 0.0), discretisation=COARSE_FIELD_MESH)
    a = solve_chunk(spec, Chunk("untouched"))
    b = solve_chunk(spec, Chunk("untouched"))
    assert calls == [1]
    np.testing.assert_array_equal(a, b)
    # (the chunk solves on one BLAS thread: the same readout to round-off)
    np.testing.assert_allclose(a, spec.sensor().capacitance((0.0, 0.0, 0.0))[0], rtol=1e-12)
