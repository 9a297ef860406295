"""The trained score's field reading (``ScoreConfig.response="field"``): the recording it trains
on is the twin's own ``simulate_experiment`` from the same fields, its settings differ from the
solve reading's (a score made otherwise is not resumed), the seeds of a layout read fields
built once, and bad options are refused. Fields here are tiny (one state, 10 × 27.5 mm steps,
the coarse field mesh), as in tests/twin/test_simulate_field.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin._files import write_json_atomic
from ectskin.design import score as score_mod
from ectskin.design.family import FaceDesign, LayoutDesign, build_layout
from ectskin.design.information import MESHES
from ectskin.design.score import (
    SCORE_FILE,
    ScoreConfig,
    design_protocol,
    finished_score,
    score_layout,
    scored_layout,
)
from ectskin.design.score_field import dense_protocol, field_specs, score_fields
from ectskin.design.sweep import score_layouts
from ectskin.layout import default_layout
from ectskin.pipeline.field import protocol_field_specs
from ectskin.twin import field_build as field_build_mod
from ectskin.twin import simulate_experiment
from ectskin.twin.field_build import field_dir
from ectskin.twin.field_solve import chunks_of
from ectskin.twin.field_spec import FIELD_GRIDS, FieldGrid

#: cheap, not accurate: 5 × 5 nodes a face, 4 force and 4 height nodes
TINY = FieldGrid(spacing_mm=(10.0, 27.5), force_nodes=4, height_nodes=4)


def _config(cache: Path, **kw) -> ScoreConfig:
    """One state (0 ml), 4 touch trials of 2 s (4 points each), contact only, 1 epoch."""
    protocol = design_protocol(
        0, response="field", levels_ml=(0.0,), touch_trials=4, duration_s=2.0
    )
    return ScoreConfig(
        protocol=protocol, epochs={"contact": 1}, tasks=("contact",), field_grid=TINY,
        field_cache=str(cache), **kw,
    )


class Stop(Exception):
    pass


def test_the_score_trains_on_what_simulate_experiment_makes_from_the_same_fields(
    tmp_path, monkeypatch
):
    """The recording ``score_layout`` writes (caught before training) equals the twin's own
    simulation of the same protocol, scored layout and mesh from the same cached fields, bit
    for bit. Catches the score simulating another layout (the layout without its scoring
    regions is refused by the simulation), another mesh or protocol, or the solve reading
    (which has no field key)."""
    cfg = _config(tmp_path / "cache")
    seen = []

    def catch(rec, path, **kw):
        seen.append(rec)
        raise Stop

    monkeypatch.setattr(score_mod, "write_recording", catch)
    paper = default_layout()
    with threadpool_limits(1), pytest.raises(Stop):
        score_layout(paper, tmp_path / "a", cfg)
    got = seen[0]
    scored = scored_layout(paper, cfg)
    (spec,) = field_specs(cfg.protocol, scored, TINY)
    assert field_dir(spec, tmp_path / "cache").is_dir()  # built into the config's cache
    want = simulate_experiment(
        cfg.protocol, layout=scored, discretisation=MESHES[cfg.mesh], workers=1, progress=False,
        fields={spec.inflation_ml: field_dir(spec, tmp_path / "cache")},
    )
    assert got.meta["protocol"]["response"] == "field"
    assert [t.name for t in got.trials] == [t.name for t in want.trials]
    touch = [t for t in got.trials if t.meta["kind"] == "touch"]
    assert len(touch) == 4
    for tg, tw in zip(got.trials, want.trials):
        np.testing.assert_array_equal(tg.capacitance, tw.capacitance)
        np.testing.assert_array_equal(tg.force, tw.force)
    for t in touch:  # read from this field, 4 points a trial (2 s, a new point every 0.5 s)
        assert t.meta["response_field"] == spec.key()
        assert len(t.meta["touch_uv_mm"]) == 4


def test_the_field_protocol_by_hand_and_the_reproductions_field_specs():
    p = design_protocol(3, response="field")
    # 12 trials of 15 s a state, a new point every 0.5 s (30), sliding a third of each dwell
    assert (p.response, p.touch_trials, p.duration_s, p.touch_dwells) == ("field", 12, 15.0, 30)
    assert p.dwell_slide_s == pytest.approx(0.5 / 3)
    assert (p.seed, p.levels_ml, p.lifts, p.touch_placement) == (3, (0.0, 20.0), True, "uniform")
    solve = design_protocol(3)
    assert (solve.response, solve.touch_trials, solve.duration_s, solve.touch_dwells) == (
        "solve", 6, 3.0, 2)
    short = design_protocol(0, response="field", duration_s=2.0, touch_trials=1)
    assert (short.touch_dwells, short.touch_trials) == (4, 1)
    assert design_protocol(0, response="field", touch_dwells=3).touch_dwells == 3
    # the score's specs are the reproduction's for the same grid (no second recipe)
    layout = scored_layout(default_layout(), ScoreConfig(response="solve"))
    ours = field_specs(p, layout, FIELD_GRIDS["quick"])
    theirs = protocol_field_specs(p, layout, "quick")
    assert len(ours) == 8 and [s.key() for s in ours] == [s.key() for s in theirs]
    # not on the seed: every seed of a layout reads the same fields
    other = field_specs(design_protocol(7, response="field"), layout, FIELD_GRIDS["quick"])
    assert [s.key() for s in other] == [s.key() for s in ours]


def test_the_settings_differ_between_readings_and_a_score_made_otherwise_is_not_resumed(
    tmp_path, fake_score
):
    solve, field = ScoreConfig(response="solve"), ScoreConfig()
    assert field.response == "field" and field.protocol.response == "field"  # the default
    assert solve.protocol.response == "solve" and solve.protocol.touch_trials == 6
    # the solve reading's settings are those of scores made before the field reading
    assert "response" not in solve.settings() and "field_grid" not in solve.settings()
    assert field.settings()["response"] == "field"
    assert field.settings()["protocol"] != solve.settings()["protocol"]
    fine = ScoreConfig(response="field", field_grid="fine")
    assert fine.settings()["field_grid"] != field.settings()["field_grid"]
    assert fine.settings()["field_grid"]["fine_spacing_mm"] == (1.0, 1.0)
    # the response follows the protocol when not given
    assert ScoreConfig(protocol=design_protocol(response="field")).response == "field"
    for cfg in (solve, field, fine, ScoreConfig(response="field", field_grid=TINY)):
        assert ScoreConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    # a finished score is reused only under its own reading
    paper = default_layout()
    fake_score(paper, tmp_path / "s", solve)
    assert finished_score(tmp_path / "s", paper, solve) is not None
    assert finished_score(tmp_path / "s", paper, field) is None
    fake_score(paper, tmp_path / "f", field)
    assert finished_score(tmp_path / "f", paper, field) is not None
    assert finished_score(tmp_path / "f", paper, fine) is None
    assert finished_score(tmp_path / "f", paper, solve) is None


class FieldFake:
    """A trained score in no time that reads its layout's fields the way ``score_layout`` does
    (:func:`score_fields`, which builds what is missing) and records what it read."""

    def __init__(self):
        self.calls = []

    def __call__(self, layout, out_dir, config):
        dirs, built = score_fields(
            config.protocol, scored_layout(layout, config), config.grid, config.field_cache
        )
        self.calls.append((layout.name, config.seed, built["solved"], built["keys"]))
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        score = {
            "name": layout.name, "n_electrodes": layout.n_electrodes, "n_pairs": layout.n_pairs,
            "loc_mm_mean": 10.0 + config.seed, "region_accuracy": 0.5, "force_mae_n": 0.1,
            "track_ad_mm": None, "loc_mm_per_face": {}, "loc_map": {},
            "sensor": {"snr_db_min": 60.0}, "seconds": {"total": 1.0},
            "fields_solved": built["solved"],
            "settings": config.settings(), "layout": layout.to_dict(),
        }
        write_json_atomic(out / SCORE_FILE, score)
        return json.loads((out / SCORE_FILE).read_text())


def test_the_seeds_of_a_layout_share_its_fields_built_once(tmp_path, monkeypatch):
    """Every chunk of every layout's field is solved once for 3 seeds (before the seeds' tasks,
    which only read them), and not again on a new sweep with other seeds."""
    solved = []
    real = field_build_mod.solve_chunk

    def counting(spec, chunk, physics=None):
        solved.append((spec.key(), chunk.name))
        return real(spec, chunk, physics)

    monkeypatch.setattr(field_build_mod, "solve_chunk", counting)
    cfg = _config(tmp_path / "cache")
    three = build_layout(LayoutDesign(FaceDesign(3), FaceDesign(3)), "three")
    fake = FieldFake()
    with threadpool_limits(1):
        design = score_layouts(
            [("three", three)], tmp_path / "out", cfg, n_workers=0, score_fn=fake,
            seeds=[0, 1, 2], report=False,
        )
    specs = {
        name: field_specs(cfg.protocol, scored_layout(layout, cfg), TINY)
        for name, layout in (("paper-2x4-wires", default_layout()), ("three", three))
    }
    chunks = sorted((s.key(), c.name) for v in specs.values() for s in v for c in chunks_of(s))
    assert sorted(solved) == chunks  # each chunk once, 2 layouts x 1 state
    assert len({k for k, _ in solved}) == 2
    assert sorted((n, s) for n, s, _, _ in fake.calls) == sorted(
        (n, s) for n in ("paper-2x4-wires", "three") for s in (0, 1, 2))
    for name, _seed, n_solved, keys in fake.calls:
        assert n_solved == 0  # built before the seeds' tasks
        assert keys == [s.key() for s in specs[name]]
    assert design["fields"]["solved"] == len(chunks) and design["fields"]["fields"] == 2
    solved.clear()
    with threadpool_limits(1):
        again = score_layouts(
            [("three", three)], tmp_path / "out", cfg, n_workers=0, score_fn=fake,
            seeds=[3, 4], report=False,
        )
    assert solved == [] and again["fields"]["cached"] == len(chunks)


def test_bad_options_are_refused():
    with pytest.raises(EctskinError, match="response.*'solve', 'field'.*'mesh'"):
        ScoreConfig(response="mesh")
    with pytest.raises(EctskinError, match="response 'field' needs a protocol with response='field'"):
        ScoreConfig(response="field", protocol=design_protocol())
    with pytest.raises(EctskinError, match="response 'solve' needs a protocol with response='solve'"):
        ScoreConfig(response="solve", protocol=design_protocol(response="field"))
    with pytest.raises(EctskinError, match="field_grid.*'quick', 'fine'.*'medium'"):
        ScoreConfig(response="field", field_grid="medium")
    with pytest.raises(EctskinError, match="field_grid must be a grid name"):
        ScoreConfig(response="field", field_grid=(2.0, 4.0))
    with pytest.raises(EctskinError, match="field_cache must be a folder"):
        ScoreConfig(response="field", field_cache=3)
    with pytest.raises(EctskinError, match="protocol must be a Protocol"):
        ScoreConfig(protocol={"seed": 0})
    with pytest.raises(EctskinError, match="response.*'x'"):
        design_protocol(0, response="x")
    with pytest.raises(EctskinError, match="dwell_s must be a number > 0"):
        dense_protocol(design_protocol(), dwell_s=0.0)


def test_the_report_says_how_the_touch_trials_were_read():
    from ectskin._files import to_jsonable
    from ectskin.design.report import _about

    def about(cfg):
        return _about({"settings": to_jsonable(cfg.to_dict()), "sweep_seconds": 1.0,
                       "engine": {"address": "serial", "n_workers": 1}})

    assert "solved per dwell" in about(ScoreConfig(response="solve"))
    text = about(ScoreConfig(response="field"))
    assert "read from the states' response fields (spacing [2.0, 4.0] mm)" in text
    assert "12 touch trials per state of 15 s, 30 dwells" in text


@pytest.mark.slow
def test_on_a_two_worker_cluster_the_fields_are_built_on_it_before_the_seeds(tmp_path):
    """The build goes to the sweep's own cluster (its scheduler's address) and the seeds'
    tasks, on the same workers, find every field complete."""
    cfg = _config(tmp_path / "cache")
    fake = FieldFake()
    design = score_layouts(
        [], tmp_path / "out", cfg, n_workers=2, score_fn=fake, seeds=[0, 1], report=False
    )
    (spec,) = field_specs(cfg.protocol, scored_layout(default_layout(), cfg), TINY)
    assert design["engine"]["n_workers"] == 2
    assert design["fields"]["solved"] == len(chunks_of(spec)) and design["fields"]["cached"] == 0
    assert (field_dir(spec, tmp_path / "cache") / "field.npz").is_file()
    for seed in (0, 1):
        score = json.loads(
            (tmp_path / "out" / "layouts" / "paper" / f"seed-{seed}" / SCORE_FILE).read_text()
        )
        assert score["settings"]["response"] == "field"
        assert score["fields_solved"] == 0  # the task found its field built
