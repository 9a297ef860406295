"""The reproduction's bound step and metrics.json's ``bound`` block, on analytic fields (readouts
linear in u, v, F, so every bound is ``crb`` of a known Jacobian) and a hand-made recording."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.collections import QuadMesh

from ectskin._check import EctskinError
from ectskin._files import write_json_atomic
from ectskin.io import Recording, Trial, write_recording
from ectskin.pipeline.bound import BOUND_DIR, bound_step, frame_bounds, frame_points, state_key
from ectskin.pipeline.config import ReproduceConfig
from ectskin.pipeline.metrics import bound_block, combine_metrics
from ectskin.pipeline.runner import StepRunner
from ectskin.twin.bound_field import field_bound_maps, field_bounds, field_nuisances
from ectskin.twin.field import ResponseField
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec
from ectskin.viz.bound import plot_error_vs_bound

WINDOW = ((-4.0, 4.0), (40.0, 52.0))
STATES = ((0.0, 20.0, 0.0), (20.0, 0.0, 20.0))


def _field(layout, state, seed):
    spec = FieldSpec(layout, state, discretisation=COARSE_FIELD_MESH, spacing_mm=(2.0, 3.0),
                     window_mm=WINDOW, force_nodes=4, height_nodes=0)
    rng = np.random.default_rng(seed)
    p = layout.n_pairs
    a = rng.uniform(0.5, 2.0, p)
    b, c, d = rng.normal(0, 1e-3, (3, p))
    F = spec.forces()
    vals = {}
    for face in spec.face_names:
        u, v = spec.grid(face)
        vals[face] = (a + b * u[:, None, None, None] + c * v[None, :, None, None]
                      + d * F[None, None, :, None])
    return ResponseField(spec, a, vals, {})


def _trial(layout, name, state, uv, force, contact):
    """One trial of one or two fingers on the front face: ``uv`` (n, K, 2), ``force``, ``contact``
    (n, K)."""
    n, k = contact.shape
    return Trial(
        name, np.ones((n, layout.n_pairs)), np.arange(n) / 30.0, np.zeros(n, np.int16),
        inflation=state, force=np.where(contact, force, 0.0), contact=contact, finger_uv_mm=uv,
        finger_height_mm=np.where(contact, 0.0, 5.0), finger_surface=("front",) * k,
    )


@pytest.fixture(scope="module")
def fields(layout):
    return {s: _field(layout, s, k) for k, s in enumerate(STATES)}


def _recording(layout):
    rng = np.random.default_rng(5)
    n = 8
    uv = np.c_[rng.uniform(-3, 3, n), rng.uniform(41, 51, n)][:, None, :]
    force = rng.uniform(0.5, 1.5, (n, 1))
    force[0] = 0.1  # below the field's range: bounded at its edge, counted
    on = np.ones((n, 1), bool)
    on[1] = False  # no finger on the skin: not a test point
    two_uv = np.concatenate([uv, uv + [1.0, 1.0]], axis=1)
    two_on = np.ones((n, 2), bool)
    two_on[:4, 1] = False  # frames 0-3 one finger, 4-7 two: only 0-3 count
    trials = [
        _trial(layout, "a", STATES[0], uv, force, on),
        _trial(layout, "b", STATES[1], two_uv, np.c_[force, force], two_on),
        _trial(layout, "c", (10.0, 10.0, 10.0), uv, force, on),  # no field for this state
        _trial(layout, "train", STATES[0], uv, force, on),  # not a test trial
    ]
    return Recording(layout, trials, 30.0), uv, force


def test_test_points_are_the_single_finger_frames(layout):
    rec, uv, force = _recording(layout)
    pts = frame_points(rec, ["a", "b", "c"])
    got_uv, got_f = pts[STATES[0]]["front"]
    keep = np.r_[0, 2:8]
    np.testing.assert_array_equal(got_uv, uv[keep, 0])
    np.testing.assert_array_equal(got_f, force[keep, 0])
    assert len(pts[STATES[1]]["front"][1]) == 4
    assert state_key((0.0, 20.0, 0.0)) == "0/20/0 ml"  # as contact metrics' per_state names
    # alone: trial b's one-finger frames have its other finger 5 mm above the skin
    alone = frame_points(rec, ["a", "b", "c"], alone=True)
    assert STATES[1] not in alone
    np.testing.assert_array_equal(alone[STATES[0]]["front"][0], uv[keep, 0])


def test_bound_step_writes_the_maps_and_the_test_frames_bound(layout, fields, tmp_path):
    rec, uv, force = _recording(layout)
    write_recording(rec, tmp_path / "contact.h5")
    run_dir = tmp_path / "runs" / "contact"
    run_dir.mkdir(parents=True)
    write_json_atomic(run_dir / "split.json", {"test": ["a", "b", "c"]})
    emap = {f: {"u_edges": [-4.0, 0.0, 4.0], "v_edges": [40.0, 46.0, 52.0],
                "mean_mm": [[2.0, None], [3.0, 4.0]], "count": [[1, 0], [1, 1]]}
            for f in ("front", "back")}
    write_json_atomic(run_dir / "metrics.json", {"contact": {"map": emap}})
    config = ReproduceConfig(out_dir=tmp_path)
    runner = StepRunner(tmp_path, False)
    data = (tmp_path / "contact.h5", {"source": "test"})
    out = bound_step(runner, config, fields, data, spacing_mm=4.0)
    for name in ("bound.json", "bound.png", "bound_vs_error.png"):
        assert (tmp_path / BOUND_DIR / name).is_file()
    # the test frames of state 0/20/0 (trial a, frames 0, 2-7) by hand from field_bounds
    cols = field_nuisances(fields[STATES[0]])
    keep = np.r_[0, 2:8]
    f = np.clip(force[keep, 0], *fields[STATES[0]].spec.force_range_n)
    ref = field_bounds(fields[STATES[0]], "front", uv[keep, 0], f, columns=cols)["all"]
    got = out["test"]["per_state"]["0/20/0 ml"]
    assert got["n_points"] == 7 and got["n_frames_clipped"] == 1
    assert got["loc_mm_mean"] == pytest.approx(float(np.mean(ref["position_mm"])), rel=1e-9)
    assert got["force_n_mean"] == pytest.approx(float(np.mean(ref["force_n"])), rel=1e-9)
    assert out["test"]["states_without_field"] == {"10/10/10 ml": 7}
    assert out["test"]["per_state"]["20/0/20 ml"]["n_points"] == 4
    # without another finger above the skin: trial a's frames only
    assert out["test_alone"]["per_state"]["0/20/0 ml"] == got
    assert "20/0/20 ml" not in out["test_alone"]["per_state"]
    # the maps: both states, both faces, the cell centres of 4-mm cells over the window
    assert [s["inflation_ml"] for s in out["states"]] == [list(s) for s in STATES]
    assert out["states"][0]["faces"]["back"]["u_mm"] == [-2.0, 2.0]
    # done once: a second call reuses the step
    again = bound_step(runner, config, fields, data, spacing_mm=4.0)
    assert "bound" in runner.reused and again["test"] == out["test"]

    # metrics.json's bound block beside the contact model's per-state errors
    contact = {"per_state": {"0/20/0 ml": {"loc_mm_mean": 3.5}},
               "baselines": {"knn": {"per_state": {"0/20/0 ml": {"loc_mm_mean": 5.0}}}}}
    b = bound_block(out, contact)
    st = b["per_state"]["0/20/0 ml"]
    assert st["contact_loc_mm_mean"] == 3.5 and st["baseline_loc_mm_mean"] == {"knn": 5.0}
    assert st["test"]["loc_mm_mean"] == got["loc_mm_mean"]
    assert b["test_alone"] == out["test_alone"]["pooled"]
    head = out["summary"]["contact"]["all"]
    assert b["case"] == "all" and b["loc_mm_mean"] == head["loc_mm_mean"]
    assert b["force_n_mean"] == head["force_n_mean"]
    # per face: the mean over both states' cells of that face, by hand
    cells = np.concatenate([
        np.ravel(s["faces"]["front"]["contact"]["all"]["position_mm"]) for s in out["states"]
    ])
    assert b["per_face"]["front"]["loc_mm_mean"] == pytest.approx(float(np.mean(cells)))
    assert set(b["per_face"]) == {"front", "back"}


def test_the_training_frames_alone_are_bounded_when_asked(layout, fields, tmp_path):
    """``train_trials``: the training trials' frames with one finger and no other above the
    skin, by hand from field_bounds; the test frames' blocks unchanged; off: no such block."""
    rec, uv, force = _recording(layout)
    moved = uv + [0.5, -0.8]  # not the test trial's points: its bound differs
    t = _trial(layout, "moved", STATES[0], moved, force, np.ones((len(force), 1), bool))
    rec = Recording(layout, [*rec.trials, t], 30.0)
    write_recording(rec, tmp_path / "contact.h5")
    run_dir = tmp_path / "runs" / "contact"
    run_dir.mkdir(parents=True)
    # trial b's one-finger frames have its other finger above the skin: not bounded here
    write_json_atomic(run_dir / "split.json", {"test": ["a"], "train": ["moved", "b", "c"]})
    config = ReproduceConfig(out_dir=tmp_path)
    data = (tmp_path / "contact.h5", {"source": "test"})
    off = bound_step(StepRunner(tmp_path, False), config, fields, data, spacing_mm=4.0)
    assert "train_alone" not in off
    out = bound_step(StepRunner(tmp_path, True), config, fields, data, spacing_mm=4.0,
                     train_trials=True)
    f = np.clip(force[:, 0], *fields[STATES[0]].spec.force_range_n)
    ref = field_bounds(fields[STATES[0]], "front", moved[:, 0], f,
                       columns=field_nuisances(fields[STATES[0]]))["all"]
    got = out["train_alone"]["per_state"]["0/20/0 ml"]
    assert got["n_points"] == len(force)
    assert got["loc_mm_mean"] == pytest.approx(float(np.mean(ref["position_mm"])), rel=1e-9)
    assert got["loc_mm_mean"] != pytest.approx(out["test_alone"]["per_state"]["0/20/0 ml"]["loc_mm_mean"])
    assert list(out["train_alone"]["per_state"]) == ["0/20/0 ml"]
    assert out["train_alone"]["states_without_field"] == {"10/10/10 ml": 7}
    assert out["test"] == off["test"] and out["test_alone"] == off["test_alone"]
    assert bound_block(out, None)["train_alone"] == out["train_alone"]["pooled"]
    assert bound_block(off, None)["train_alone"] is None
    with pytest.raises(EctskinError, match="train_trials must be True or False"):
        bound_step(StepRunner(tmp_path, False), config, fields, data, train_trials="yes")  # type: ignore[arg-type]


def test_frame_bounds_counts_a_face_the_field_lacks(layout, fields):
    pts = {STATES[0]: {"left": (np.zeros((2, 2)), np.ones(2))}}
    res = frame_bounds(fields, {}, pts, nuisances=(), case="none")
    assert res["states_without_field"] == {"0/20/0 ml left": 2} and res["per_state"] == {}


def test_metrics_json_carries_the_bound_only_when_given(tmp_path):
    runner = StepRunner(tmp_path, False)
    kw = dict(profile="quick", seed=0, protocol=None, data_settings={},
              data_path=tmp_path / "none.h5")
    assert "bound" not in combine_metrics({}, runner, **kw)
    bound = {"headline_case": "none", "states": [],
             "summary": {"contact": {"none": {"loc_mm_mean": 0.1, "force_n_mean": 0.02}}}}
    m = combine_metrics({}, runner, bound=bound, **kw)
    assert m["bound"]["loc_mm_mean"] == 0.1 and m["bound"]["force_n_mean"] == 0.02


def test_the_error_and_bound_maps_share_one_scale(layout, fields):
    """The figure beside the step: per face the model's error and the bound averaged over the
    states on one log scale spanning both; an error map of no face of the maps is refused."""

    maps = field_bound_maps(fields, None, layout, spacing_mm=4.0, nuisances=())
    emap = {"front": {"u_edges": [-4.0, 4.0], "v_edges": [40.0, 52.0], "mean_mm": [[30.0]]}}
    fig = plot_error_vs_bound(emap, maps, case="none")
    panels = [a for a in fig.axes if a.get_title()]  # (the colour bar's axes has none)
    meshes = [c for a in panels for c in a.collections if isinstance(c, QuadMesh)]
    assert len(meshes) == 2 and meshes[0].norm is meshes[1].norm
    b = np.mean([s["faces"]["front"]["contact"]["none"]["position_mm"] for s in maps["states"]],
                axis=0)
    np.testing.assert_allclose(np.asarray(meshes[1].get_array()).reshape(b.shape), b)
    assert meshes[0].norm.vmax == pytest.approx(30.0) and meshes[0].norm.vmin == pytest.approx(b.min())
    with pytest.raises(EctskinError, match="no face in common"):
        plot_error_vs_bound({"left": emap["front"]}, maps, case="none")
