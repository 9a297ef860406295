"""Design sweeps: resume after a crash without redoing finished layouts; the two-worker Dask
cluster against the serial run; conditioning on hand-built matrices; the scheduler error."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.design.cluster import open_runner
from ectskin.design.family import FaceDesign, LayoutDesign, build_layout
from ectskin.design.score import ScoreConfig, conditioning, design_protocol, scoring_regions
from ectskin.design.sweep import score_layouts


def _layouts():
    a = build_layout(LayoutDesign(FaceDesign(3), FaceDesign(3)), "three")
    b = build_layout(LayoutDesign(FaceDesign(5, 36.0, routing="fan")), "five")
    return a, b


def test_a_sweep_killed_in_the_middle_resumes_without_redoing_finished_layouts(
    tmp_path, fake_score
):
    a, b = _layouts()
    boom = build_layout(LayoutDesign(FaceDesign(2)), "boom")
    cfg = ScoreConfig(response="solve")  # (the field reading would build fields)
    fake_score.calls.clear()
    with pytest.raises(RuntimeError, match="killed"):
        score_layouts(
            [("a", a), ("boom", boom), ("b", b)],
            tmp_path,
            cfg,
            n_workers=0,
            score_fn=fake_score,
            report=False,
        )
    assert fake_score.calls == ["paper-2x4-wires", "three", "boom"]
    design = json.loads((tmp_path / "design.json").read_text())
    assert [e["name"] for e in design["layouts"]] == ["paper", "a"] and not design["complete"]
    # the rerun (the crash fixed) scores only what is missing
    fixed = build_layout(LayoutDesign(FaceDesign(2)), "boom-fixed")
    fake_score.calls.clear()
    design = score_layouts(
        [("a", a), ("boom", fixed), ("b", b)],
        tmp_path,
        cfg,
        n_workers=0,
        score_fn=fake_score,
        report=False,
    )
    assert fake_score.calls == ["boom-fixed", "five"]
    assert design["complete"] and [e["name"] for e in design["layouts"]] == [
        "paper",
        "a",
        "boom",
        "b",
    ]
    # other settings: everything is scored again
    fake_score.calls.clear()
    other = ScoreConfig(seed=1, response="solve")
    score_layouts([("a", a)], tmp_path, other, n_workers=0, score_fn=fake_score, report=False)
    assert fake_score.calls == ["paper-2x4-wires", "three"]


def test_a_changed_layout_under_the_same_name_is_scored_again(tmp_path, fake_score):
    a, b = _layouts()
    fake_score.calls.clear()
    cfg = ScoreConfig(response="solve")
    score_layouts(
        [("x", a)], tmp_path, cfg, n_workers=0, score_fn=fake_score, report=False,
        include_paper=False,
    )
    score_layouts(
        [("x", b)], tmp_path, cfg, n_workers=0, score_fn=fake_score, report=False,
        include_paper=False,
    )
    assert fake_score.calls == ["three", "five"]


def test_duplicate_and_bad_names_are_refused(tmp_path, fake_score):
    a, _ = _layouts()
    with pytest.raises(EctskinError, match="used twice"):
        score_layouts([("a", a), ("a", a)], tmp_path, n_workers=0, score_fn=fake_score)
    with pytest.raises(EctskinError, match="design name 'a/b'"):
        score_layouts([("a/b", a)], tmp_path, n_workers=0, score_fn=fake_score)


def test_conditioning_on_hand_built_matrices():
    eq = conditioning(np.hstack([np.eye(4), np.zeros((4, 2))]))
    assert eq["condition_number"] == pytest.approx(1.0)
    assert eq["effective_rank"] == pytest.approx(4.0)  # k equal singular values give k
    assert eq["rank_1pct"] == 4
    d = conditioning(np.diag([1.0, 0.5, 0.001]))
    assert d["condition_number"] == pytest.approx(1000.0)
    assert d["rank_1pct"] == 2
    p = np.array([1.0, 0.5, 0.001]) / 1.501
    assert d["effective_rank"] == pytest.approx(np.exp(-np.sum(p * np.log(p))))


def test_an_unreachable_scheduler_is_one_clear_error_naming_it():
    t0 = time.perf_counter()
    with pytest.raises(EctskinError, match=r"--scheduler tcp://127\.0\.0\.1:9: no Dask scheduler"):
        with open_runner(scheduler="tcp://127.0.0.1:9"):
            pass
    assert time.perf_counter() - t0 < 30
    with pytest.raises(EctskinError, match="tcp://HOST:PORT"):
        with open_runner(scheduler="localhost:8786"):
            pass


def _tiny_config():
    # one inflation state, 8 touch trials of 2 s (2 per scoring region), 1 dwell, 2 force nodes
    protocol = design_protocol(
        0, levels_ml=(0.0,), touch_trials=8, duration_s=2.0, touch_dwells=1, force_nodes=2
    )
    return ScoreConfig(protocol=protocol, epochs={"touch": 2, "contact": 2, "track": 1})


@pytest.mark.slow
def test_two_local_dask_workers_give_the_serial_results(tmp_path):
    a, b = _layouts()
    cfg = _tiny_config()
    named = [("a", a), ("b", b)]
    serial = score_layouts(named, tmp_path / "serial", cfg, n_workers=0, include_paper=False)
    dask = score_layouts(named, tmp_path / "dask", cfg, n_workers=2, include_paper=False)
    assert dask["engine"]["n_workers"] == 2 and serial["engine"]["address"] == "serial"
    keys = ("loc_mm_mean", "region_accuracy", "force_mae_n", "track_ad_mm", "n_electrodes")
    assert [e["name"] for e in serial["layouts"]] == [e["name"] for e in dask["layouts"]]
    for s, d in zip(serial["layouts"], dask["layouts"]):
        assert s["loc_mm_mean"] is not None  # the test split holds touches
        for k in keys:
            assert s[k] == d[k], (s["name"], k)
        assert s["sensor"] == d["sensor"]
    assert (tmp_path / "dask" / "design.html").is_file()
    assert (tmp_path / "dask" / "figures" / "a_errors.png").is_file()


def test_scoring_regions_by_hand():
    a, _ = _layouts()
    regions = scoring_regions(a, 2, 1)  # base and tip half of each 40 x 110 mm face
    got = [(r.id, r.surface, r.u_mm, r.v_mm) for r in regions]
    assert got == [
        (1, "front", (-20.0, 20.0), (5.0, 60.0)),
        (2, "front", (-20.0, 20.0), (60.0, 115.0)),
        (3, "back", (-20.0, 20.0), (5.0, 60.0)),
        (4, "back", (-20.0, 20.0), (60.0, 115.0)),
    ]


def test_the_mesh_option_reaches_the_simulation_and_the_settings(tmp_path, monkeypatch):
    from ectskin.design import score as score_mod
    from ectskin.design.score import score_layout
    from ectskin.twin.bound import COARSE

    # coarse is the default
    coarse, default = ScoreConfig(response="solve"), ScoreConfig(mesh="default", response="solve")
    assert coarse.mesh == "coarse" and coarse.protocol.touch_trials == 6
    assert "mesh" not in default.settings()  # scores on the twin's mesh made before it resume
    assert coarse.settings()["mesh"] == "coarse"
    assert ScoreConfig.from_dict(coarse.to_dict()) == coarse
    assert ScoreConfig.from_dict(default.to_dict()) == default
    with pytest.raises(EctskinError, match="mesh"):
        ScoreConfig(mesh="fine")
    seen = []

    class Stop(Exception):
        pass

    def fake_simulate(protocol, **kw):
        seen.append(kw["discretisation"])
        raise Stop

    monkeypatch.setattr(score_mod, "simulate_experiment", fake_simulate)
    a, _ = _layouts()
    for cfg in (coarse, default):
        with pytest.raises(Stop):
            score_layout(a, tmp_path / "a", cfg)
    assert seen[0] == COARSE and seen[1] != COARSE
