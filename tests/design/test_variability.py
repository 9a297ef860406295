"""The variability study's parts: fine-tuning, the skins, the summary, the Markdown report; and
(slow) the whole study on a tiny protocol, resumed without redoing a step. Data sets merged across
skins: ``TouchData.concat`` (tests/learn/data/test_data_base.py).

What each test catches: fine-tuning that trains the nominal run in place (the baseline would
be scored with the fine-tuned weights), does not train at all, refits the normaliser, does not
start from the run's weights (0 epochs must answer as the run: the ``--init-from`` path) or
trains with the profile's augmentation instead of the study's settings; summary means that
count a missing value as 0; a table cell that breaks the Markdown table; a resumed study that
simulates again.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np
import pytest
import torch

from ectskin.design import variability as var
from ectskin.design.variability import (
    VariabilityConfig,
    finetune_config,
    finetune_run,
    report_markdown,
    skin_cases,
    summarise,
)
from ectskin.io import write_recording
from ectskin.learn.checkpoint import load_checkpoint
from ectskin.learn.data import touch_dataset
from ectskin.learn.tasks import get_task
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.twin.protocol import Protocol


def _accuracy(model, data) -> float:
    return float((get_task("touch").predict(model, data) == data.y).mean())


@pytest.fixture
def touch_base(tmp_path, make_recording):
    """A touch run trained one epoch (barely: one optimiser step) and another skin's data."""
    rec = tmp_path / "a.h5"
    write_recording(make_recording(n_frames=12, seed=0), rec)
    run = tmp_path / "base"
    config = TrainConfig(profile="quick", epochs=1, progress=False, counts=(4, 1, 1))
    train_from_recording("touch", rec, run, config)
    data = touch_dataset(make_recording(n_frames=12, seed=3), reference="rest")
    return run, data


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_finetune_learns_from_the_run_and_leaves_it_alone(touch_base):
    run, data = touch_base
    before = _digest(run / "model.pt")
    base, _, _ = load_checkpoint(run / "model.pt")
    base.eval()
    acc0 = _accuracy(base, data)
    cfg = replace(
        finetune_config("touch", VariabilityConfig(finetune_epochs=25, finetune_lr=1e-2)),
        threads=1,
    )
    tuned, summary = finetune_run("touch", run, data, data, cfg)
    assert _digest(run / "model.pt") == before  # the nominal run is not trained in place
    assert summary["best_epoch"] > 0 and not tuned.training
    acc1 = _accuracy(tuned, data)
    assert acc1 >= 0.75 and acc1 > acc0 + 0.3
    # the normalisation is the trained run's, not refit on the few samples
    for k in ("x_mean", "x_std"):
        assert torch.equal(tuned.state_dict()[k], base.state_dict()[k])


def test_zero_finetune_epochs_answer_as_the_run(touch_base):
    """The --init-from path: 0 epochs keep the base weights bit for bit."""
    run, data = touch_base
    base, _, _ = load_checkpoint(run / "model.pt")
    cfg = finetune_config("touch", VariabilityConfig(finetune_epochs=0))
    tuned, summary = finetune_run("touch", run, data, data, cfg)
    assert summary["best_epoch"] == 0
    t = get_task("touch")
    np.testing.assert_array_equal(t.predict(tuned, data), t.predict(base.eval(), data))


def test_finetune_settings_are_the_studys():
    """Adam at a constant finetune_lr, batches of 32, every sample once per epoch, no
    augmentation, lowest loss kept; for both tasks' profiles (touch: robust, which augments)."""
    cfg = VariabilityConfig(finetune_epochs=7, finetune_lr=2e-4)
    for task in ("touch", "contact"):
        s = finetune_config(task, cfg).settings_for(task)
        assert (s.epochs, s.batch_size, s.lr) == (7, var.FINETUNE_BATCH, 2e-4)
        assert s.step_size >= s.epochs and s.samples_per_epoch is None
        assert not s.augments and s.label_smoothing == 0 and s.select == "val_loss"


def test_skin_cases_roles_seeds_and_a_zero_scale():
    cfg = VariabilityConfig(skins=3, dr_skins=2, scale_range=(0.0, 1.0))
    cases = skin_cases(cfg)
    assert [c.role for c in cases] == ["nominal"] + ["sampled"] * 3 + ["fault"] * 2 + ["dr"] * 2
    assert [c.scale for c in cases[1:4]] == [0.0, 0.5, 1.0]
    nominal = cases[0].skin.layout.to_dict()
    assert cases[1].skin.layout.to_dict() == nominal  # scale 0: the nominal skin
    assert cases[2].skin.layout.to_dict() != nominal
    for c in cases[4:6]:  # faults on the nominal geometry
        assert c.skin.layout.to_dict() == nominal and c.skin.fault.kind == c.name
    seeds = [c.skin.seed for c in cases[1:]]
    assert len(set(seeds[:3] + seeds[5:])) == 5  # every sampled skin its own draw


def test_summarise_means_over_sampled_skins_skipping_missing():
    def row(b, own, ft):
        keys = ("baseline", "own_reference", "domain_randomisation", "dr_own_reference")
        return {
            **dict(zip(keys, (b, own, b, own))),
            "finetune": {"0": b, "100": ft},
        }

    results = {
        "nominal": {"role": "nominal", "touch": row(0.9, 0.9, 0.9), "contact": row(5, 5, 5)},
        "skin1": {"role": "sampled", "touch": row(0.5, 0.8, 0.6), "contact": row(20, 8, 10)},
        "skin2": {"role": "sampled", "touch": row(0.3, 0.7, 0.4), "contact": row(30, 9, 12)},
        "dead": {"role": "fault", "touch": row(0.1, None, 0.2), "contact": row(50, None, 40)},
    }
    s = summarise(results)
    assert s["touch"]["sampled_mean"]["baseline"] == pytest.approx(0.4)
    assert s["touch"]["sampled_mean"]["finetune_100"] == pytest.approx(0.5)
    assert s["contact"]["sampled_mean"]["own_reference"] == pytest.approx(8.5)
    assert s["contact"]["nominal_baseline"] == 5
    results["skin2"]["touch"]["own_reference"] = None
    assert summarise(results)["touch"]["sampled_mean"]["own_reference"] == pytest.approx(0.8)


@pytest.mark.slow
def test_tiny_study_end_to_end_and_resumed(tmp_path, monkeypatch):
    p = Protocol(
        levels_ml=(0.0, 20.0),
        touch_trials=3,
        duration_s=1.0,
        touch_placement="uniform",
        touch_dwells=1,
        force_nodes=3,
    )
    cfg = VariabilityConfig(
        skins=2,
        dr_skins=1,
        protocol=p,
        epochs=2,
        finetune_frames=(0, 20),
        finetune_epochs=2,
        progress=False,
        workers=1,
    )
    doc = var.run_variability(tmp_path, cfg)
    assert set(doc["skins"]) == {"nominal", "skin1", "skin2", "dead", "short"}
    for r in doc["skins"].values():
        assert set(r["touch"]["finetune"]) == {"0", "20"}
        assert r["touch"]["finetune"]["0"] == r["touch"]["baseline"]  # N = 0 is the baseline
        assert 0 <= r["touch"]["baseline"] <= 1 and r["contact"]["baseline"] > 0
    assert doc["skins"]["dead"]["touch"]["own_reference"] is None
    assert doc["skins"]["nominal"]["rest_deviation_pct"] == 0.0
    assert doc["skins"]["skin2"]["rest_deviation_pct"] > doc["skins"]["skin1"]["rest_deviation_pct"]
    for name in ("variability.json", "variability.md", *doc["figures"]):
        assert (tmp_path / name).is_file()

    def refuse(*a, **k):
        raise AssertionError("a resumed study simulated again")

    monkeypatch.setattr(var, "simulate_skin", refuse)
    again = var.run_variability(tmp_path, replace(cfg))
    assert again["skins"] == doc["skins"]


def test_report_tables_go_through_the_escaping_writer():
    def row(v):
        keys = ("baseline", "own_reference", "domain_randomisation", "dr_own_reference")
        return {**dict.fromkeys(keys, v), "finetune": {"0": v, "100": v}}

    skins = {
        "nominal": {"role": "nominal", "scale": 0.0, "rest_deviation_pct": 0.0},
        "a|b": {"role": "sampled", "scale": 1.5, "rest_deviation_pct": None},
    }
    for r in skins.values():
        r.update(touch=row(0.5), contact=row(None))
    cfg = VariabilityConfig()
    doc = {
        "config": var._config_dict(cfg),
        "skins": skins,
        "summary": summarise(skins),
        "seconds": 60.0,
        "figures": {"variability_curves.png": "curves"},
    }
    lines = report_markdown(doc).splitlines()
    i = lines.index("## touch: accuracy")
    head = "| skin | scale | rest dev. % | baseline | own_reference | domain_randomisation"
    assert lines[i + 2].startswith(head) and lines[i + 2].endswith("| finetune N=100 |")
    assert lines[i + 3] == "|" + "---|" * 8
    assert lines[i + 4] == "| nominal | 0 | 0.0 | 0.500 | 0.500 | 0.500 | 0.500 | 0.500 |"
    assert lines[i + 5] == "| a\\|b | 1.5 | – | 0.500 | 0.500 | 0.500 | 0.500 | 0.500 |"
    assert "| a\\|b | 1.5 | – | – | – | – | – | – |" in lines  # contact: no values
