"""Building response fields: the cache key, the chunk cache (resume after a kill), Dask workers.

The fields here are tiny (a 2 × 2 grid, two forces, two heights): what is checked is the
bookkeeping, not the physics (``test_field.py``).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.twin import (
    Finger,
    ManipulatorConfig,
    Touch,
    field_build,
    field_solve,
    field_spec,
)
from ectskin.twin.field_build import (
    FIELD_FILE,
    MANIFEST,
    build_chunks,
    build_field,
    field_dir,
    load_field,
)
from ectskin.twin.field_solve import chunks_of
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec, physics_modules

COARSE = COARSE_FIELD_MESH


@pytest.fixture(autouse=True, scope="module")
def _blas_one_thread():
    with threadpool_limits(limits=1):
        yield


@pytest.fixture(scope="module")
def spec(layout):
    return FieldSpec(
        layout, (0.0, 20.0, 0.0), discretisation=COARSE, spacing_mm=(2.0, 2.0),
        window_mm=((0.0, 2.0), (54.0, 56.0)), force_nodes=2, height_nodes=2,
    )


@pytest.fixture(scope="module")
def one_go(spec, tmp_path_factory):
    """The reference: the whole field in one build, here (no cluster)."""
    return build_field(spec, tmp_path_factory.mktemp("one_go"), workers=0, progress=False)


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.untouched, b.untouched)
    for face in a.faces:
        np.testing.assert_array_equal(a.node_values(face), b.node_values(face))
        np.testing.assert_array_equal(a.node_values(face, "hover"), b.node_values(face, "hover"))


# ---------------------------------------------------------------------- the spec and its key
def test_the_key_is_stable_and_follows_every_input(spec):
    assert spec.key() == FieldSpec.from_dict(json.loads(json.dumps(spec.to_dict()))).key()
    assert len(spec.key()) == 64
    changes = {
        "inflation_ml": (0.0, 20.0, 1.0),
        "manipulator": ManipulatorConfig(modulus_mpa=1.5),
        "discretisation": dataclasses.replace(COARSE, finger_sphere_n=4),
        "eps_r": 2.1,
        "chamber_eps_r": None,
        "finger": Finger(radius_mm=9.0),
        "spacing_mm": (1.0, 2.0),
        "force_range_n": (0.3, 2.5),
        "force_nodes": 3,
        "height_range_mm": (0.5, 10.0),
        "height_nodes": 0,
        "faces": ("back", "front"),
        "window_mm": ((0.0, 2.0), (54.0, 57.0)),
        "fine_spacing_mm": (1.0, 1.0),
    }
    keys = {spec.key()}
    for name, value in changes.items():
        keys.add(dataclasses.replace(spec, **{name: value}).key())
    assert len(keys) == len(changes) + 1


def test_the_key_follows_the_physics_code(spec, monkeypatch):
    """An edit of the physics (a new digest) is a new key; the digest covers the sensor, the
    mechanics, the rod, the electrostatics and the field's solver."""
    mods = physics_modules()
    for name in ("ectskin.twin.sensor", "ectskin.twin.mechanics", "ectskin.twin.rod",
                 "ectskin.electrostatics.mom", "ectskin.electrostatics.schur",
                 "ectskin.twin.field_solve", "ectskin.layout.layout"):
        assert name in mods
    assert "ectskin.twin.field" not in mods  # the interpolation is rebuilt at load
    before = spec.key()
    monkeypatch.setattr(field_spec, "physics_digest", lambda: "0" * 64)
    assert spec.key() != before


def test_a_non_finite_setting_round_trips(spec):
    stiff = dataclasses.replace(spec, finger=Finger(cover_modulus_mpa=float("inf")))
    again = FieldSpec.from_dict(json.loads(json.dumps(stiff.to_dict())))
    assert again.finger.cover_modulus_mpa == float("inf") and again.key() == stiff.key()


@pytest.mark.parametrize(
    "change, match",
    [
        ({"inflation_ml": (0.0, 20.0)}, "inflation|chamber"),
        ({"spacing_mm": (0.0, 1.0)}, "spacing_mm"),
        ({"force_range_n": (2.0, 1.0)}, "force_range_n"),
        ({"force_nodes": 1}, "force_nodes"),
        ({"height_nodes": 1}, "height_nodes"),
        ({"height_range_mm": (0.0, 5.0)}, "height_range_mm"),
        ({"faces": ("top",)}, "faces"),
        ({"window_mm": ((30.0, 40.0), (54.0, 56.0))}, "leaves nothing"),
        ({"eps_r": 0.5}, "eps_r"),
        ({"fine_spacing_mm": (3.0, 1.0)}, "fine_spacing_mm .* <= spacing_mm"),
        ({"refine_u_mm": ((0.0, 1.0),)}, "refine_u_mm needs fine_spacing_mm"),
        ({"fine_spacing_mm": (1.0, 1.0), "refine_v_mm": ((3.0, 1.0),)}, "refine_v_mm .* lo < hi"),
        ({"fine_spacing_mm": (1.0, 1.0), "refine_v_mm": (3.0,)}, r"refine_v_mm must be \(\(lo"),
    ],
)
def test_bad_specs_are_refused(spec, change, match):
    with pytest.raises(EctskinError, match=match):
        dataclasses.replace(spec, **change)


def test_a_graded_grid_by_hand(layout):
    """Inside a refinement interval the coarse nodes give way to fine steps from the interval's
    start; a fine node within half a fine step of a coarse one is left out; the key, the
    round trip and the chunks follow the graded grid."""
    spec = FieldSpec(
        layout, (0.0, 20.0, 0.0), spacing_mm=(2.0, 4.0), window_mm=((-4.0, 4.0), (50.0, 62.0)),
        fine_spacing_mm=(1.0, 1.5), refine_u_mm=((1.0, 9.0),), refine_v_mm=((53.0, 56.0),),
    )
    u, v = spec.grid("front")
    np.testing.assert_allclose(u, [-4, -2, 0, 1, 2, 3, 4])
    np.testing.assert_allclose(v, [50, 53, 54.5, 56, 58, 62])
    again = FieldSpec.from_dict(json.loads(json.dumps(spec.to_dict())))
    assert again.key() == spec.key() and again.refine_v_mm == ((53.0, 56.0),)
    assert dataclasses.replace(spec, refine_u_mm=((1.0, 8.0),)).key() != spec.key()
    assert len(chunks_of(spec)) == 1 + 2 * (2 * u.size)  # both faces, contact and hover


def test_a_graded_field_interpolates_what_its_splines_can_hold(layout):
    """On a graded grid the field still passes through its nodes and reproduces, between them,
    a readout its splines hold exactly (cubic in u and v, quadratic in F through 3 force nodes,
    quadratic in ln h): node values put on the wrong nodes would not."""
    from ectskin.twin.field import ResponseField

    spec = FieldSpec(
        layout, (0.0, 20.0, 0.0), spacing_mm=(2.0, 4.0), faces=("front",), force_nodes=3,
        height_nodes=3, window_mm=((-4.0, 4.0), (50.0, 70.0)), fine_spacing_mm=(0.5, 1.0),
        refine_u_mm=((1.0, 4.0),), refine_v_mm=((55.0, 59.0),),
    )
    u, v = spec.grid("front")
    assert np.ptp(np.diff(u)) > 1.0 and np.ptp(np.diff(v)) > 2.0  # graded in both

    def truth(uu, vv, x):
        base = uu**3 / 50 - uu * vv / 30 + (vv - 60) ** 2 / 40 + 1
        return 1e-3 * (base * (1 + 0.3 * x - 0.1 * x**2))[..., None] * np.arange(1, spec.n_pairs + 1)

    U, V = np.meshgrid(u, v, indexing="ij")
    F, H = spec.forces(), np.log(spec.heights())
    contact = truth(U[..., None], V[..., None], F[None, None])
    hover = truth(U[..., None], V[..., None], H[None, None])
    field = ResponseField(spec, np.zeros(spec.n_pairs), {"front": contact}, {"front": hover})
    rng = np.random.default_rng(2)
    pu, pv = rng.uniform(-4, 4, 20), rng.uniform(50, 70, 20)
    pf = rng.uniform(*spec.force_range_n, 20)
    ph = np.exp(rng.uniform(*np.log(spec.height_range_mm), 20))
    np.testing.assert_allclose(field.readout("front", pu, pv, pf), truth(pu, pv, pf),
                               rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(field.readout("front", pu, pv, 0.0, ph), truth(pu, pv, np.log(ph)),
                               rtol=1e-9, atol=1e-15)


def test_the_demo_grid_refines_beside_the_chambers(layout):
    """The demo's spec: 2 × 4 mm steps, 1 mm within 5 mm of the chambers' side walls
    (u = ±20 mm on the default body) and within 3 mm of their ends (z = 5, 35, 45, 75, 85,
    115 mm; the 10-mm gaps between chambers joined), 6 force and 6 height nodes."""
    u_bands, v_bands = field_spec.chamber_refinement(ManipulatorConfig(), 5.0, 3.0, 4.0)
    assert u_bands == ((-25.0, -15.0), (15.0, 25.0))
    assert v_bands == ((2.0, 8.0), (32.0, 48.0), (72.0, 88.0), (112.0, 118.0))
    spec = field_spec.contact_field_spec(layout, (0.0, 20.0, 0.0), finger=Finger(radius_mm=9.0))
    grid = field_spec.FINE_FIELD
    assert (spec.spacing_mm, spec.force_nodes, spec.height_nodes) == (
        grid.spacing_mm, grid.force_nodes, grid.height_nodes)
    assert spec.finger.radius_mm == 9.0 and spec.discretisation == COARSE
    u, v = spec.grid("front")
    assert np.diff(u).max() <= 2.0 + 1e-9 and np.diff(v).max() <= 4.0 + 1e-9
    np.testing.assert_allclose(u[u >= 15.0], [15, 16, 17, 18, 19, 20])
    np.testing.assert_allclose(np.diff(v[(v >= 32.0) & (v <= 47.0)]), 1.0)
    plain = field_spec.contact_field_spec(
        layout, (0.0, 20.0, 0.0), dataclasses.replace(grid, fine_spacing_mm=None))
    assert plain.grid("front")[0].size == 21 and plain.refine_u_mm == ()
    with pytest.raises(EctskinError, match="come from grid"):
        field_spec.contact_field_spec(layout, (0.0, 20.0, 0.0), spacing_mm=(1.0, 1.0))


# ---------------------------------------------------------------------- the cache
def test_a_killed_build_resumes_to_the_same_field(spec, one_go, tmp_path):
    total = len(chunks_of(spec))
    part = build_chunks([spec], tmp_path, workers=0, progress=False, max_chunks=3)
    assert (part.solved, part.complete) == (3, False)
    with pytest.raises(EctskinError, match="no complete response field"):
        load_field(spec, tmp_path)
    rest = build_chunks([spec], tmp_path, workers=0, progress=False)
    assert (rest.cached, rest.solved, rest.complete) == (3, total - 3, True)
    _same(load_field(spec, tmp_path), one_go)
    # complete: loading solves nothing
    again = build_chunks([spec], tmp_path, workers=0, progress=False)
    assert (again.cached, again.solved) == (total, 0)


def test_a_lost_completion_is_rebuilt_from_the_chunks(spec, one_go, tmp_path):
    build_field(spec, tmp_path, workers=0, progress=False)
    folder = field_dir(spec, tmp_path)
    (folder / FIELD_FILE).unlink()
    man = json.loads((folder / MANIFEST).read_text())
    man["complete"] = False
    (folder / MANIFEST).write_text(json.dumps(man))
    report = build_chunks([spec], tmp_path, workers=0, progress=False)
    assert report.solved == 0 and report.complete
    _same(load_field(spec, tmp_path), one_go)


def test_a_damaged_chunk_is_solved_again(spec, one_go, tmp_path):
    build_field(spec, tmp_path, workers=0, progress=False)
    folder = field_dir(spec, tmp_path)
    (folder / FIELD_FILE).unlink()
    chunk = sorted((folder / "chunks").iterdir())[0]
    chunk.write_bytes(b"not an array")
    report = build_chunks([spec], tmp_path, workers=0, progress=False)
    assert report.solved == 1
    _same(load_field(spec, tmp_path), one_go)


def test_a_chunk_error_names_the_chunk_and_keeps_the_others(spec, tmp_path, monkeypatch):
    calls = []

    def failing(s, chunk, physics=None, device=None):
        calls.append(chunk.name)
        if len(calls) == 3:
            raise EctskinError("boom")
        return field_solve.solve_chunk(s, chunk, physics, device)

    monkeypatch.setattr(field_build, "solve_chunk", failing)
    with pytest.raises(EctskinError, match=f"field chunk {chunks_of(spec)[2].name}: boom"):
        build_chunks([spec], tmp_path, workers=0, progress=False)
    assert len(list((field_dir(spec, tmp_path) / "chunks").iterdir())) == 2


def test_the_hover_path_refuses_a_finger_that_moves_the_body(spec, monkeypatch):
    sensor = spec.sensor()
    real = sensor.electrode_panels

    def moved(inflation, touch, forces, handling=None):
        out = real(inflation, touch, forces, handling)
        if touch is None:
            return out
        p = out[0]
        return [type(p)(p.centres + 0.01, p.u, p.v, p.conductor, p.n_conductors)]

    monkeypatch.setattr(sensor, "electrode_panels", moved)
    with pytest.raises(EctskinError, match="moves the electrode panels"):
        field_solve.hover_row(sensor, spec.inflation_ml, "front", 0.0, np.array([54.0]), [1.0])


def test_a_hover_row_batched_on_a_torch_device_equals_the_numpy_schur_path(spec, monkeypatch):
    sensor = spec.sensor()
    v = np.array([54.0, 55.0, 56.0])
    heights = spec.heights()
    ref = field_solve.hover_row(sensor, spec.inflation_ml, "front", 2.0, v, heights)
    fast = field_solve.hover_row(sensor, spec.inflation_ml, "front", 2.0, v, heights, "cpu")
    np.testing.assert_allclose(fast, ref, rtol=1e-11, atol=1e-15)
    # a batch with a set that does not factor goes point by point, then to the direct solve,
    # as the NumPy path does
    real = field_solve.schur_batch

    def first_set_fails(solver, panels, blocks, **kw):
        K, S, ok = real(solver, panels, blocks, **kw)
        ok[0] = False
        return K, S, ok

    monkeypatch.setattr(field_solve, "schur_batch", first_set_fails)
    slow = field_solve.hover_row(sensor, spec.inflation_ml, "front", 2.0, v, heights, "cpu")
    direct = sensor.capacitance(spec.inflation_ml, Touch("front", (2.0, 54.0)),
                                np.zeros(heights.size), heights_mm=heights)
    np.testing.assert_allclose(slow[0], direct, rtol=1e-10, atol=0)
    np.testing.assert_allclose(slow, ref, rtol=1e-10, atol=0)


def test_the_hover_path_falls_back_to_the_direct_solve(spec, monkeypatch):
    sensor = spec.sensor()
    heights = spec.heights()
    v = np.array([54.0, 56.0])
    fast = field_solve.hover_row(sensor, spec.inflation_ml, "front", 2.0, v, heights)

    def fail(*args, **kwargs):
        raise EctskinError("not positive definite")

    monkeypatch.setattr(field_solve, "_readouts", fail)
    slow = field_solve.hover_row(sensor, spec.inflation_ml, "front", 2.0, v, heights)
    np.testing.assert_allclose(slow, fast, rtol=1e-10, atol=0)


def test_a_contact_row_batched_on_a_torch_device_equals_the_direct_solves(spec, monkeypatch):
    sensor = spec.sensor()
    v = np.array([54.0, 56.0])
    forces = spec.forces()  # 2 forces: the row's nodes are (v0, f0), (v0, f1), (v1, f0), (v1, f1)
    direct = field_solve.contact_row(sensor, spec.inflation_ml, "front", 2.0, v, forces)
    fast = field_solve.contact_row(sensor, spec.inflation_ml, "front", 2.0, v, forces, device="cpu")
    np.testing.assert_allclose(fast, direct, rtol=1e-11, atol=1e-15)
    # a node the batch cannot factor (node 2: v1 at f0) is solved with a refined fingertip, as the
    # direct solve does; the others keep the batch's values
    real = field_solve.readout_batch

    def node_2_fails(sets, **kw):
        out, ok = real(sets, **kw)
        ok[2], out[2] = False, np.nan
        return out, ok

    monkeypatch.setattr(field_solve, "readout_batch", node_2_fails)
    got = field_solve.contact_row(sensor, spec.inflation_ml, "front", 2.0, v, forces, device="cpu")
    touch = Touch("front", (2.0, 56.0))
    refined = sensor.refined_readout(
        spec.inflation_ml, touch, forces, None, None, 0,
        *sensor.solve_sets(spec.inflation_ml, touch, forces)[0],
    )
    np.testing.assert_array_equal(got[1, 0], refined)
    assert np.max(np.abs(refined - direct[1, 0])) > 0  # the refined fingertip is another mesh
    np.testing.assert_allclose(np.delete(got.reshape(4, -1), 2, 0),
                               np.delete(direct.reshape(4, -1), 2, 0), rtol=1e-11, atol=1e-15)


# ---------------------------------------------------------------------- Dask
def test_one_and_two_workers_give_the_same_bits(spec, one_go, tmp_path):
    a = build_field(spec, tmp_path / "w1", workers=1, progress=False)
    b = build_field(spec, tmp_path / "w2", workers=2, progress=False)
    _same(a, b)
    _same(a, one_go)


def test_a_build_with_batched_solves_on_workers_is_the_field_to_round_off(spec, one_go, tmp_path):
    # the device reaches the workers: their contact rows are the batched solves, not the bits of
    # the NumPy path, yet the same field to round-off
    a = build_field(spec, tmp_path / "torch", workers=1, progress=False, device="cpu")
    np.testing.assert_array_equal(a.untouched, one_go.untouched)
    for face in a.faces:
        got, want = a.node_values(face), one_go.node_values(face)
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-15)
        assert not np.array_equal(got, want)
        got, want = a.node_values(face, "hover"), one_go.node_values(face, "hover")
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-15)
        assert not np.array_equal(got, want)


def test_a_running_scheduler_builds_the_same_field(spec, one_go, tmp_path):
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster:
        got = build_field(spec, tmp_path, scheduler=cluster.scheduler_address, progress=False)
    _same(got, one_go)


def test_a_worker_with_other_physics_refuses(spec):
    with pytest.raises(EctskinError, match="same ectskin"):
        field_solve.solve_chunk(spec, chunks_of(spec)[0], physics="0" * 64)


def test_a_bad_scheduler_is_one_clear_error(spec, tmp_path, monkeypatch):
    with pytest.raises(EctskinError, match="tcp://HOST:PORT"):
        build_field(spec, tmp_path, scheduler="localhost:8786", progress=False)
    monkeypatch.setattr(field_build, "CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(EctskinError, match="no Dask scheduler answered"):
        build_field(spec, tmp_path, scheduler="tcp://127.0.0.1:9", progress=False)
    with pytest.raises(EctskinError, match="workers"):
        build_field(spec, tmp_path, workers=-1, progress=False)
