"""The reproduction's bound step with the pulp's modulus among its nuisances: the modulus table
solved per state and named in bound.json, and a headline bound never below the one without it
(the same cells, the same other columns)."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin.pipeline.bound import BOUND_DIR, bound_step
from ectskin.pipeline.config import ReproduceConfig
from ectskin.pipeline.runner import StepRunner
from ectskin.twin.bound import NUISANCES
from ectskin.twin.bound_field import field_bound_maps, field_nuisances
from ectskin.twin.field import ResponseField
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

STATE = (0.0, 20.0, 0.0)


def _field(layout):
    """Readouts linear in u, v, F over a small window of both faces (an analytic field; the
    nuisance columns come from the twin's direct solves of its spec)."""
    spec = FieldSpec(layout, STATE, discretisation=COARSE_FIELD_MESH, spacing_mm=(2.0, 3.0),
                     window_mm=((-4.0, 4.0), (40.0, 52.0)), force_nodes=4, height_nodes=0)
    rng = np.random.default_rng(3)
    a = rng.uniform(0.5, 2.0, layout.n_pairs)
    b, c, d = rng.normal(0, 1e-3, (3, layout.n_pairs))
    vals = {}
    for face in spec.face_names:
        u, v = spec.grid(face)
        vals[face] = (a + b * u[:, None, None, None] + c * v[None, :, None, None]
                      + d * spec.forces()[None, None, :, None])
    return ResponseField(spec, a, vals, {})


def test_the_bound_step_with_the_modulus(layout, tmp_path):
    fields = {STATE: _field(layout)}
    with threadpool_limits(1):
        out = bound_step(StepRunner(tmp_path, False), ReproduceConfig(out_dir=tmp_path), fields,
                         nuisances=(*NUISANCES, "modulus"), spacing_mm=4.0)
        assert (tmp_path / BOUND_DIR / "bound.json").is_file()
        assert out["cases"] == ["none", *NUISANCES, "modulus", "all"]
        assert out["settings"]["nuisances"] == [*NUISANCES, "modulus"]
        table = out["nuisance_columns"][0]["modulus"]
        assert table["nodes"] == {"front": [4, 4], "back": [4, 4]} and len(table["forces_n"]) == 6
        assert table["n_solves"] == 2 * 2 * 16 * 6
        cols = {STATE: field_nuisances(fields[STATE])}
        without = field_bound_maps(fields, cols, layout, spacing_mm=4.0, nuisances=NUISANCES)
    for face in ("front", "back"):
        got = np.array(out["states"][0]["faces"][face]["contact"]["all"]["force_n"])
        ref = without["states"][0]["faces"][face]["contact"]["all"]["force_n"]
        assert np.all(got >= ref * (1 - 1e-9)) and np.any(got > ref * 1.001)
