"""The reproduction's contact experiment read from response fields: the protocol, the fields'
specs and cache, the simulation with them, and the count of distinct touch points."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import Recording, Trial
from ectskin.layout import default_layout
from ectskin.pipeline import ReproduceConfig
from ectskin.pipeline import field as pfield
from ectskin.pipeline.contact import _simulate_contact, n_touch_points
from ectskin.pipeline.runner import StepRunner
from ectskin.twin import Protocol
from ectskin.twin.field_spec import QUICK_FIELD, FieldGrid

#: a grid of few nodes: the step's code path, not its accuracy
SMALL_GRID = FieldGrid(spacing_mm=(10.0, 27.5), force_nodes=4, height_nodes=4)


def test_the_contact_experiment_is_dense_and_draws_its_own_streams():
    paper = ReproduceConfig("o", seed=0).simulation_protocol()
    c = ReproduceConfig("o", seed=0).contact_protocol()
    assert (c.response, c.touch_placement, c.stream, c.seed) == ("field", "uniform", 1, 0)
    assert c.levels_ml == (0.0, 20.0) and c.n_states == 8
    assert c.touch_dwells == 60 and c.dwell_slide_s == pytest.approx(0.5 / 3)
    assert c.touch_trials == 9 and c.lifts and c.hover and c.approach and c.second_finger == 0.3
    assert paper.stream == 0 and paper.response == "solve"  # the paper's reading as documented
    # a short trial keeps a point every 0.5 s
    short = ReproduceConfig("o", protocol=Protocol(duration_s=2.0)).contact_protocol()
    assert short.touch_dwells == 4
    solve = ReproduceConfig("o", contact_response="solve").contact_protocol()
    assert (solve.response, solve.touch_trials, solve.touch_dwells, solve.stream) == (
        "solve", 4, 2, 1)
    with pytest.raises(EctskinError, match="contact_response"):
        ReproduceConfig("o", contact_response="mesh")


def test_the_field_cache_folder(monkeypatch, tmp_path):
    monkeypatch.delenv(pfield.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert pfield.field_cache_dir() == tmp_path / "xdg" / "ectskin" / "fields"
    monkeypatch.setenv(pfield.CACHE_ENV, str(tmp_path / "c"))
    assert pfield.field_cache_dir() == tmp_path / "c" / "fields"
    assert pfield.field_cache_dir(tmp_path / "mine") == tmp_path / "mine"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.delenv(pfield.CACHE_ENV)
    assert pfield.field_cache_dir().parts[-3:] == (".cache", "ectskin", "fields")


def test_one_field_per_contact_state_of_the_simulated_body():
    config = ReproduceConfig("o", seed=0)
    specs = pfield.contact_field_specs(config)
    states = config.contact_protocol().states()
    assert [s.inflation_ml for s in specs] == states
    for s in specs:
        assert s.layout.to_json() == default_layout().to_json()
        assert s.face_names == ("front", "back") and s.force_range_n == (0.3, 2.0)
        assert s.spacing_mm == QUICK_FIELD.spacing_mm and s.finger.radius_mm == 8.0
    assert len({s.key() for s in specs}) == 8
    assert pfield.contact_field_specs(ReproduceConfig("o", recording=_rec([]))) == []


def test_all_states_adds_the_paper_experiments_other_states_built_alike(tmp_path):
    protocol = Protocol(levels_ml=(0.0, 10.0, 20.0), seed=3)
    contact = pfield.contact_field_specs(ReproduceConfig(tmp_path, protocol=protocol))
    keys = [s.key() for s in contact]
    default = pfield.physics_field_specs(ReproduceConfig(tmp_path, protocol=protocol))
    assert [s.key() for s in default] == keys
    both = pfield.physics_field_specs(
        ReproduceConfig(tmp_path, protocol=protocol, field_states="all"))
    assert [s.key() for s in both[: len(contact)]] == keys  # the contact fields first, as they are
    assert len(contact) == 8 and len(both) == 27  # 3 levels on 3 chambers
    states = [s.inflation_ml for s in both]
    assert len(set(states)) == 27 and (0.0, 10.0, 20.0) in states
    for extra in both[len(contact):]:  # the same finger, forces, heights, grid and mesh
        same = dataclasses.replace(contact[0], inflation_ml=extra.inflation_ml)
        assert extra.key() == same.key()
    with pytest.raises(EctskinError, match="field_states"):
        ReproduceConfig(tmp_path, field_states="some")


def test_the_contact_step_builds_the_fields_then_reads_them(tmp_path, monkeypatch):
    """One state, short trials, a coarse grid (the step's code path, not its accuracy): the
    fields are built into the cache, their build time is recorded, every touch trial is read
    from its state's field, and a second call finds them cached."""
    monkeypatch.setitem(pfield.FIELD_GRIDS, "quick", SMALL_GRID)
    protocol = Protocol(levels_ml=(0.0,), touch_trials=1, duration_s=2.0, touch_dwells=1)
    config = ReproduceConfig(tmp_path / "out", protocol=protocol, workers=1, progress=False,
                             field_cache=tmp_path / "cache")
    contact = config.contact_protocol()
    runner = StepRunner(tmp_path / "out", force=False)
    rec = _simulate_contact(contact, config, runner)
    assert runner.timings["contact_fields"] > 0
    spec = pfield.contact_field_specs(config)[0]
    assert (tmp_path / "cache" / spec.key() / "field.npz").is_file()
    touch = [t for t in rec.trials if t.meta["kind"] == "touch"]
    assert len(touch) == 9 and all(t.meta["response_field"] == spec.key() for t in touch)
    fields = pfield.contact_fields(config)
    assert list(fields) == [(0.0, 0.0, 0.0)] and fields[(0.0, 0.0, 0.0)].key == spec.key()


def _trial(name: str, meta: dict, contact=None) -> Trial:
    P = default_layout().n_pairs
    n = 6 if contact is None else len(contact)
    return Trial(name, capacitance=np.ones((n, P)), timestamps=np.arange(n) / 30.0,
                 labels=np.zeros(n, dtype=np.int16), meta=meta,
                 contact=None if contact is None else np.asarray(contact))


def _rec(trials) -> Recording:
    return Recording(default_layout(), trials, 30.0)


def test_a_dwell_spent_off_the_skin_places_no_finger():
    """Three dwells of two frames each; the finger touches in the first and the last only (the
    middle one is a lift): two points. Two fingers (contact (n, 2)): the first finger's column."""
    meta = {"surface": "front", "touch_uv_mm": [[1.0, 50.0], [2.0, 60.0], [3.0, 70.0]]}
    one = _trial("a", meta, [True, False, False, False, False, True])
    assert n_touch_points(_rec([one])) == 2
    two = _trial("b", meta, [[True, True], [False, True], [False, True], [False, False],
                             [True, False], [False, False]])
    assert n_touch_points(_rec([two])) == 2
    assert n_touch_points(_rec([_trial("c", meta)])) == 3  # no per-frame contact: all planned
