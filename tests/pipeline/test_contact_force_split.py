"""The force split of the reproduction: the bound on the force at each test frame (frame by
frame the same bound as the bound step's per-state one, on analytic fields), and its keys in
metrics.json's ``contact`` block."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin.io import Recording, Trial
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.pipeline.bound import frame_force_bounds
from ectskin.pipeline.metrics import combine_metrics, force_split_keys
from ectskin.pipeline.runner import StepRunner
from ectskin.twin.bound_field import field_bounds, field_nuisances
from ectskin.twin.field import ResponseField
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

WINDOW = ((-4.0, 4.0), (40.0, 52.0))
#: slot 0's force column of the contact predictions
F_COL = len(PRED_COLUMNS) + SLOT_COLUMNS.index("force_n")
STATES = ((0.0, 20.0, 0.0), (20.0, 0.0, 20.0))


def _field(layout, state, seed):
    """Readouts linear in (u, v, F): every bound is that of a known Jacobian."""
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
    n, k = contact.shape
    return Trial(
        name, np.ones((n, layout.n_pairs)), np.arange(n) / 30.0, np.zeros(n, np.int16),
        inflation=state, force=np.where(contact, force, 0.0), contact=contact, finger_uv_mm=uv,
        finger_height_mm=np.where(contact, 0.0, 5.0), finger_surface=("front",) * k,
    )


@pytest.fixture(scope="module")
def fields(layout):
    return {s: _field(layout, s, k) for k, s in enumerate(STATES)}


def test_the_bound_at_each_test_frame(layout, fields):
    rng = np.random.default_rng(5)
    n = 8
    uv = np.c_[rng.uniform(-3, 3, n), rng.uniform(41, 51, n)][:, None, :]
    force = rng.uniform(0.5, 1.5, (n, 1))
    force[0] = 0.1  # below the field's range: bounded at its edge
    on = np.ones((n, 1), bool)
    on[1] = False  # no finger on the skin: no bound
    two_uv = np.concatenate([uv, uv + [1.0, 1.0]], axis=1)
    two_on = np.ones((n, 2), bool)
    two_on[:4, 1] = False  # frames 0-3 one finger, 4-7 two (no bound)
    rec = Recording(layout, [
        _trial(layout, "a", STATES[0], uv, force, on),
        _trial(layout, "b", STATES[1], two_uv, np.c_[force, force], two_on),
        _trial(layout, "c", (10.0, 10.0, 10.0), uv, force, on),  # no field at this state
    ], 30.0)
    cols = {s: field_nuisances(f) for s, f in fields.items()}
    got = frame_force_bounds(fields, cols, rec, ["a", "b", "c"])
    assert set(got) == {"a", "b", "c"} and all(v.shape == (n,) for v in got.values())
    keep = np.r_[0, 2:8]
    f = np.clip(force[keep, 0], *fields[STATES[0]].spec.force_range_n)
    ref = field_bounds(fields[STATES[0]], "front", uv[keep, 0], f, columns=cols[STATES[0]])
    np.testing.assert_allclose(got["a"][keep], ref["all"]["force_n"], rtol=1e-12)
    assert np.isnan(got["a"][1])
    ref_b = field_bounds(fields[STATES[1]], "front", uv[:4, 0], np.clip(
        force[:4, 0], *fields[STATES[1]].spec.force_range_n), columns=cols[STATES[1]])
    np.testing.assert_allclose(got["b"][:4], ref_b["all"]["force_n"], rtol=1e-12)
    assert np.isnan(got["b"][4:]).all() and np.isnan(got["c"]).all()
    # another case: the bound without nuisances is lower (or equal) everywhere
    none = frame_force_bounds(fields, cols, rec, ["a"], case="none")
    assert np.all(none["a"][keep] <= got["a"][keep] + 1e-15)


def test_one_threshold_for_the_bound_the_split_and_the_inversion():
    from ectskin.pipeline.bound import contact_force_split
    from ectskin.pipeline.inversion import FORCE_OBSERVABLE_N
    from ectskin.twin.bound import FORCE_THRESHOLD_N

    assert FORCE_OBSERVABLE_N == FORCE_THRESHOLD_N == 0.1
    assert contact_force_split.__kwdefaults__["threshold_n"] == FORCE_THRESHOLD_N


def _split(mae_obs, mae_not):
    return {"force_mae_n_observable": mae_obs, "force_mae_n_not_observable": mae_not,
            "force_mae_n_no_bound": 0.3, "share_observable": 0.25,
            "share_not_observable": 0.5, "share_no_bound": 0.25,
            "force_coverage_1sigma_observable": 0.7, "bound_force_n_mean_observable": 0.04}


def test_the_split_goes_into_the_contact_block(tmp_path):
    split = {"model": "contactnet", "threshold_n": 0.1, "case": "all",
             "models": {"contactnet": _split(0.05, 0.4), "ridge": _split(0.08, 0.41)}}
    contact = {"force_mae_n": 0.3, "baselines": {"ridge": {"force_mae_n": 0.31},
                                                 "knn": {"force_mae_n": 0.4}}}
    force_split_keys(contact, split)
    assert contact["force_mae_n_observable"] == 0.05
    assert contact["force_mae_n_not_observable"] == 0.4
    assert contact["force_share_observable"] == 0.25
    assert contact["force_coverage_1sigma_observable"] == 0.7
    assert contact["baselines"]["ridge"]["force_mae_n_observable"] == 0.08
    assert "force_mae_n_observable" not in contact["baselines"]["knn"]  # not in the split
    assert contact["force_split"]["threshold_n"] == 0.1
    # combine_metrics: from the bound step's result into metrics.json's contact block
    runner = StepRunner(tmp_path, False)
    run = {"contact": {"force_mae_n": 0.3, "force_coverage_1sigma": 0.66,
                       "baselines": {"ridge": {"force_mae_n": 0.31}}}}
    m = combine_metrics({}, runner, profile="quick", seed=0, protocol=None, data_settings={},
                        data_path=tmp_path / "none.h5", contact=run,
                        bound={"states": [], "force_split": split})
    assert m["contact"]["force_mae_n_observable"] == 0.05
    assert m["contact"]["force_coverage_1sigma"] == 0.66
    assert m["contact"]["baselines"]["ridge"]["force_mae_n_observable"] == 0.08
    m = combine_metrics({}, runner, profile="quick", seed=0, protocol=None, data_settings={},
                        data_path=tmp_path / "none.h5", contact=run)
    assert "force_mae_n_observable" not in m["contact"]


def test_the_split_of_a_trained_run_reads_each_frames_own_bound(tmp_path, contact_recording):
    """A ridge run on the flat skin: the bound says "observable" at the even frames of every
    test trial but the last (which has none); each part's MAE is the one computed here by hand
    from the run's own model on those frames (a bound read at the wrong frame would mix them)."""
    from ectskin.io import write_recording
    from ectskin.learn.contact_classical import load_contact_classical
    from ectskin.learn.data.contact import contact_dataset
    from ectskin.learn.evaluate import calibration, read_run
    from ectskin.learn.train import TrainConfig, train_from_recording
    from ectskin.pipeline.bound import contact_force_split

    rec = contact_recording(n_frames=20, n_trials=24)
    path = write_recording(rec, tmp_path / "contact.h5")
    run_dir = tmp_path / "run"
    train_from_recording("contact", path, run_dir, TrainConfig(
        profile="quick", seed=0, window=1, model="ridge", progress=False))
    run = read_run(run_dir)
    test = list(run.split["test"])
    bounds = {n: np.where(np.arange(20) % 2 == 0, 0.05, 0.5) for n in test[:-1]}
    bounds[test[-1]] = np.full(20, np.nan)
    got = contact_force_split(run_dir, rec, bounds, seed=0, baselines=False)
    assert got["model"] == "ridge" and set(got["models"]) == {"ridge"}
    # by hand: the model file on each test trial's calibrated frames
    model = load_contact_classical(run_dir / "model.skops")
    ref = calibration(run, rec, None).value
    err = {"observable": [], "not_observable": [], "no_bound": []}
    for name in test:
        d = contact_dataset(rec, window=1, reference=ref, trials=[name])
        pred = model.predict(d.x)[:, F_COL]
        one = d.count == 1
        e = np.abs(pred - d.force[:, 0])[one]
        even = (d.frame % 2 == 0)[one]
        if name == test[-1]:
            err["no_bound"] += e.tolist()
        else:
            err["observable"] += e[even].tolist()
            err["not_observable"] += e[~even].tolist()
    split = got["models"]["ridge"]
    n = sum(len(v) for v in err.values())
    for part, e in err.items():
        assert split[f"force_mae_n_{part}"] == pytest.approx(np.mean(e), rel=1e-6), part
        assert split[f"share_{part}"] == pytest.approx(len(e) / n)
    assert split["force_coverage_1sigma_observable"] is not None  # ridge gives its σ
