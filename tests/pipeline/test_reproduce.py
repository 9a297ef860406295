"""The reproduce pipeline (ectskin.pipeline) and its commands, end to end on tiny recordings.

The hand-made recording below follows the twin's conventions (a rest trial per inflation state
with ``meta["kind"] = "no_contact"``, touch trials labelled with their region, 5 markers that bend
with the touch force) but costs nothing to make, so the whole pipeline runs in seconds.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import Recording, Trial, read_recording
from ectskin.layout import default_layout
from ectskin.pipeline import ReproduceConfig, reproduce

FPS = 30.0


def synthetic_recording(levels=(0.0, 20.0), touch_trials=4, n_frames=60, seed=0) -> Recording:
    """Unlike the conftest's ``make_recording``, a touch signal a model learns in a few epochs
    and markers that move with the force, as the pipeline's assertions need.

    States = every combination of ``levels`` over 3 chambers; per state one rest trial and
    ``touch_trials`` touch trials (alternating front / back regions). Readouts (pF): a base per
    pair, a small inflation term (same-face pairs rise, cross-face pairs fall) and a touch term
    that lifts 4 region-specific pairs in proportion to the force (easy to learn). Markers bend in
    y with the force, more towards the tip."""
    lay = default_layout()
    rng = np.random.default_rng(seed)
    base = 1.0 + 0.05 * np.arange(lay.n_pairs)
    sign = np.where(lay.same_surface, 1.0, -1.0)
    pattern = 0.05 * rng.uniform(0.0, 1.0, (lay.n_regions + 1, lay.n_pairs))
    for r in range(1, lay.n_regions + 1):
        pattern[r, rng.choice(lay.n_pairs, 4, replace=False)] = 1.0
    z = np.array([m.uv_mm[1] for m in lay.markers])
    rest = np.stack([np.full_like(z, 25.0), np.zeros_like(z), z], axis=1)  # (5, 3) mm
    t = np.arange(n_frames) / FPS
    trials = []
    states = [(a, b, c) for a in levels for b in levels for c in levels]
    k = 0
    for p in states:
        infl = 1.0 + 0.002 * sum(p) * sign
        for j in range(touch_trials + 1):
            region = 0 if j == 0 else 1 + (k % 9) + (9 if j % 2 == 0 else 0)
            force = (
                np.zeros(n_frames) if region == 0 else 1.0 + 0.8 * np.sin(2 * np.pi * t / 1.5 + k)
            )
            cap = base * (infl + 0.3 * force[:, None] * pattern[region])
            cap = cap + rng.normal(0, 2e-4, cap.shape)
            side = 1.0 if region <= 9 else -1.0
            markers = np.repeat(rest[None], n_frames, axis=0)
            markers[:, :, 1] += side * 4.0 * force[:, None] * (z / z.max()) ** 2
            markers += rng.normal(0, 0.05, markers.shape)
            trials.append(
                Trial(
                    name=f"trial_{len(trials):04d}",
                    capacitance=cap,
                    timestamps=t,
                    labels=np.full(n_frames, region),
                    inflation=p,
                    region=region,
                    markers=markers,
                    force=force,
                    meta={"kind": "no_contact" if region == 0 else "touch"},
                )
            )
            k += region > 0
    return Recording(lay, trials, FPS, meta={"source": "test"})


def cli(argv, monkeypatch=None) -> int:
    """``ectskin ARGV`` through the real entry point, with only the commands tested here (so the
    test does not depend on other command modules)."""
    import ectskin.cli

    if monkeypatch is not None:
        monkeypatch.setattr(
            ectskin.cli,
            "COMMANDS",
            (("reproduce", "reproduce"), ("demo", "demo")),
        )
    return ectskin.cli.main(argv)


# ----------------------------------------------------------------------------- commands, config
def test_reproduce_command_refuses_bad_threads_before_any_work(tmp_path, monkeypatch, capsys):
    assert cli(["reproduce", str(tmp_path / "x"), "--threads", "0"], monkeypatch) == 2
    assert "--threads must be a number >= 1, 'auto' or 'torch'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


# ----------------------------------------------------------------------------- reproduce
def test_step_runner_reuses_refuses_and_forces(tmp_path):
    from ectskin.pipeline.runner import StepRunner

    target = tmp_path / "a.txt"

    def write(text):
        return lambda: target.write_text(text) and text

    assert StepRunner(tmp_path, force=False).step("a", {"x": 1}, [target], write("one")) == "one"
    again = StepRunner(tmp_path, force=False)  # a later run reads reproduce.json
    assert again.step("a", {"x": 1}, [target], write("two")) is None
    assert again.reused == ["a"] and target.read_text() == "one"
    with pytest.raises(
        EctskinError, match=r"step 'a' would overwrite a.txt.*x: 1 -> 2.*--overwrite"
    ):
        again.step("a", {"x": 2}, [target], write("two"))
    assert StepRunner(tmp_path, force=True).step("a", {"x": 2}, [target], write("two")) == "two"
    (tmp_path / "b.txt").write_text("mine")
    with pytest.raises(EctskinError, match="origin is unknown"):
        StepRunner(tmp_path, force=False).step("b", {}, [tmp_path / "b.txt"], write("x"))
    assert (tmp_path / "b.txt").read_text() == "mine"


def test_step_runner_runs_independent_steps_in_processes(tmp_path):
    """Steps that must run go to other processes (their pids are not ours), are recorded done
    with their own time, and are reused afterwards; a failing one is recorded not done and
    raised once the others have finished."""
    import json as _json
    import os
    from functools import partial
    from pathlib import Path as _Path

    from ectskin.pipeline.runner import Job, StepRunner

    runner = StepRunner(tmp_path, force=False)
    jobs = [Job(f"s{k}", {"k": k}, [tmp_path / f"s{k}.txt"], os.getpid) for k in range(3)]
    jobs.append(Job("w", {}, [tmp_path / "w.txt"], partial(_Path.write_text, tmp_path / "w.txt", "w")))
    out = runner.steps(jobs, workers=2)
    assert set(out) == {"s0", "s1", "s2", "w"} and out["w"] == 1
    assert os.getpid() not in {out["s0"], out["s1"], out["s2"]}
    state = _json.loads((tmp_path / "reproduce.json").read_text())["steps"]
    assert all(state[n]["done"] and state[n]["seconds"] >= 0 for n in out)
    again = StepRunner(tmp_path, force=False)
    assert again.steps(jobs[3:], workers=2) == {} and again.reused == ["w"]
    bad = [Job("bad", {}, [], partial(int, "x")), Job("ok", {}, [], partial(abs, -3))]
    with pytest.raises(ValueError, match="invalid literal"):
        again.steps(bad, workers=2)
    state = _json.loads((tmp_path / "reproduce.json").read_text())["steps"]
    assert state["ok"]["done"] and not state["bad"]["done"]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"profile": "fast"}, "Invalid value for 'profile'"),
        ({"seed": 1.5}, "seed must be an integer"),
        ({"workers": 0}, "workers must be an integer >= 1, got 0"),
        ({"epochs": 0}, "epochs must be an integer >= 1, got 0"),
        ({"epochs": {"track": 0}}, r"epochs\['track'\] must be an integer >= 1"),
        ({"epochs": {"tuch": 3}}, r"unknown run name\(s\) \['tuch'\]"),
        ({"threads": 0}, "threads must be an integer >= 1, 'auto' or None"),
        ({"threads": "many"}, "threads must be an integer >= 1, 'auto' or None"),
    ],
)
def test_config_is_checked_when_made(tmp_path, kwargs, message):
    with pytest.raises(EctskinError, match=message):
        ReproduceConfig(tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists()


def test_config_protocol_or_recording_and_epochs_per_run():
    from ectskin.pipeline import RUNS
    from ectskin.twin import Protocol

    with pytest.raises(EctskinError, match="not both"):
        ReproduceConfig("o", protocol=Protocol(), recording=synthetic_recording(levels=(0.0,)))
    assert ReproduceConfig("o", seed=3).simulation_protocol() == Protocol(seed=3)
    c = ReproduceConfig("o", epochs={"touch": 7, "track": 2})
    assert [c.epochs_for(n) for n in RUNS] == [7, 7, 2, 2, 2, None]  # contact: its profile's
    quick, paper = ReproduceConfig("o"), ReproduceConfig("o", profile="paper")
    assert [quick.epochs_for(n) for n in RUNS] == [None, None, None, 12, 12, None]
    assert [paper.epochs_for(n) for n in RUNS] == [None] * 6
    assert quick.run_profile("touch_robust") == "robust" and quick.run_profile("track") == "quick"
    assert ReproduceConfig("o", robust=False, ablations=False).run_names == ("touch", "track")


def test_reproduce_trains_with_the_threads_asked_for(tmp_path):
    """Bug fix: ``ectskin reproduce --threads N`` trained with 1 thread whatever N, because the
    training step did not pass the thread count on. Every run trains with the count that
    ``threads`` resolves to, and the caller's setting is restored afterwards."""
    import torch

    before = torch.get_num_threads()
    out = tmp_path / "out"
    config = ReproduceConfig(
        out,
        recording=synthetic_recording(),
        profile="quick",
        epochs=1,
        ablations=False,
        baselines=False,
        threads=2,
        progress=False,
    )
    reproduce(config)
    for run in ("touch", "touch_robust", "track"):
        run_config = json.loads((out / "runs" / run / "config.json").read_text())
        assert run_config["torch_threads"] == 2, run
    assert torch.get_num_threads() == before


def test_reproduce_command_builds_the_config(tmp_path, monkeypatch, capsys):
    import ectskin.pipeline

    seen = []

    def fake_reproduce(config):
        seen.append(config)
        return {"timings_s": {"total": 1.0}}

    monkeypatch.setattr(ectskin.pipeline, "reproduce", fake_reproduce)
    argv = ["reproduce", str(tmp_path / "o"), "--threads", "2", "--epochs", "3", "--seed", "4"]
    assert cli(argv + ["--no-robust", "--no-progress", "--force"], monkeypatch) == 0
    assert cli(["demo", "--out", str(tmp_path / "d"), "--threads", "torch"], monkeypatch) == 0
    argv = ["reproduce", "-o", str(tmp_path / "p"), "--overwrite", "--format", "svg"]
    assert cli(argv + ["--dpi", "200"], monkeypatch) == 0
    assert cli(["demo", "-o", str(tmp_path / "e"), "--format", "pdf"], monkeypatch) == 0
    c, d, r, e = seen
    assert (c.out_dir, c.profile, c.threads, c.epochs, c.seed) == (tmp_path / "o", "paper", 2, 3, 4)
    assert not c.robust and not c.progress and c.force and c.ablations and c.baselines
    assert (c.figure_format, c.dpi) == ("png", 150)
    assert (d.out_dir, d.profile, d.threads, d.force) == (tmp_path / "d", "quick", None, False)
    assert (r.out_dir, r.force, r.figure_format, r.dpi) == (tmp_path / "p", True, "svg", 200)
    assert (e.out_dir, e.figure_format) == (tmp_path / "e", "pdf")
    assert "report: " in capsys.readouterr().out
    # one output, named once; a bad figure option is one clear error before any work
    assert cli(["reproduce", str(tmp_path / "a"), "-o", str(tmp_path / "b")], monkeypatch) == 2
    assert "two outputs given" in capsys.readouterr().err
    assert cli(["reproduce"], monkeypatch) == 2
    assert "needs an output folder: give -o/--out PATH" in capsys.readouterr().err
    assert cli(["reproduce", "-o", str(tmp_path / "q"), "--dpi", "0"], monkeypatch) == 2
    assert "dpi must be an integer from 30 to 1200, got 0" in capsys.readouterr().err
    assert len(seen) == 4


def test_reproduce_end_to_end_reuse_and_force(tmp_path):
    rec = synthetic_recording()
    out = tmp_path / "out"
    config = ReproduceConfig(
        out, recording=rec, profile="quick", epochs={"touch": 30, "track": 1}, progress=False
    )
    m = reproduce(config)
    for name in ("report.md", "report.html", "metrics.json", "data.h5", "reproduce.json"):
        assert (out / name).is_file(), name
    for fig in ("fig7_confusion.png", "fig9_tracking.png", "fig10_trajectory.png"):
        assert (out / "figures" / fig).is_file(), fig
    saved = json.loads((out / "metrics.json").read_text())
    for key in (
        "touch.accuracy",
        "touch.n_test_frames",
        "touch.n_misclassified",
        "track.ad_mm_mean",
        "track.ad_mm_std",
        "track.baselines.no_motion.ad_mm_mean",
        "track.ablations.no_prior.ad_mm_mean",
        "track.ablations.window_1.ad_mm_mean",
        "timings_s.train_touch",
        "timings_s.train_track",
        "timings_s.simulate",
        "timings_s.total",
        "machine.cpu_count",
    ):
        cur = saved
        for part in key.split("."):
            assert part in cur, key
            cur = cur[part]
        assert cur is not None, key
    assert saved["track"]["ablations"]["window_1"]["window"] == 1
    assert saved["track"]["ablations"]["no_prior"]["prior"] is False
    # the no-motion AD equals the mean displacement of the test samples, so it is > 0 here
    assert saved["track"]["baselines"]["no_motion"]["ad_mm_mean"] > 0.5
    md = (out / "report.md").read_text()
    assert f"{100 * m['touch']['accuracy']:.2f} %" in md
    assert f"{m['track']['ad_mm_mean']:.3f} ± {m['track']['ad_mm_std']:.3f} mm" in md
    assert "![Fig. 9" in md

    # same call again: every step is reused, nothing retrained
    mtime = (out / "runs" / "track" / "model.pt").stat().st_mtime_ns
    m2 = reproduce(config)
    assert set(m2["reused"]) >= {
        "simulate",
        "train_touch",
        "train_track",
        "evaluate_touch",
        "train_track_no_prior",
        "train_track_window_1",
    }
    assert (out / "runs" / "track" / "model.pt").stat().st_mtime_ns == mtime
    assert m2["track"]["ad_mm_mean"] == m["track"]["ad_mm_mean"]

    # an interrupted training (step started, not finished) resumes from last.pt in place
    state = json.loads((out / "reproduce.json").read_text())
    state["steps"]["train_track"]["done"] = False
    (out / "reproduce.json").write_text(json.dumps(state))
    m_res = reproduce(config)
    assert "train_track" not in m_res["reused"] and "train_touch" in m_res["reused"]
    assert (out / "runs" / "track" / "model.pt").stat().st_mtime_ns == mtime  # nothing retrained
    assert json.loads((out / "reproduce.json").read_text())["steps"]["train_track"]["done"]

    # other settings: refused without force, redone with it
    with pytest.raises(EctskinError, match=r"train_touch.*--overwrite"):
        reproduce(replace(config, epochs=1, ablations=False))
    m3 = reproduce(replace(config, epochs=1, ablations=False, baselines=False, force=True))
    assert "train_touch" not in m3["reused"] and "simulate" in m3["reused"]
    assert m3["touch"]["training"]["epochs"] == 1
    assert "ablations" not in m3["track"]


def test_reproduce_trains_evaluates_and_reports_the_robust_model(tmp_path):
    out = tmp_path / "out"
    config = ReproduceConfig(
        out,
        recording=synthetic_recording(),
        profile="quick",
        epochs={"touch": 8, "track": 1},
        ablations=False,
        baselines=False,
        progress=False,
    )
    m = reproduce(config)
    r = m["touch"]["robust"]
    for key in ("accuracy", "n_test_frames", "n_misclassified", "n_misclassified_adjacent"):
        assert r[key] is not None, key
    assert r["n_test_frames"] == m["touch"]["n_test_frames"]
    assert len(r["per_trial"]) == m["touch"]["split"]["test"]
    assert r["training"]["profile"] == "robust" and r["training"]["epochs"] == 8
    assert r["training"]["recipe"]["mixup_alpha"] == 1.0
    assert "mixup within each class (Beta 1, 1)" in r["recipe_description"]
    assert m["touch"]["training"]["profile"] == "quick"  # the paper-recipe run is untouched
    split = [
        json.loads((out / "runs" / n / "split.json").read_text()) for n in ("touch", "touch_robust")
    ]
    assert split[0]["test"] == split[1]["test"] and split[0]["train"] == split[1]["train"]
    assert (out / "figures" / "fig7_confusion_robust.png").is_file()
    md = (out / "report.md").read_text()
    assert "TouchMLP, robust recipe (ours)" in md
    assert f"{100 * r['accuracy']:.2f} %" in md
    assert f"instead of the paper's recipe: {r['recipe_description']}." in md
    assert "(figures/fig7_confusion_robust.png)" in md

    again = reproduce(config)
    assert {"train_touch_robust", "evaluate_touch_robust"} <= set(again["reused"])
    assert again["touch"]["robust"]["accuracy"] == r["accuracy"]
    with pytest.raises(EctskinError, match=r"train_touch_robust.*--overwrite"):
        reproduce(replace(config, epochs={"touch": 8, "touch_robust": 2, "track": 1}))
    skipped = reproduce(replace(config, robust=False))
    assert "robust" not in skipped["touch"]


def test_reproduce_refuses_a_foreign_data_file(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "data.h5").write_bytes(b"not mine")
    with pytest.raises(EctskinError, match="data.h5.*--overwrite"):
        reproduce(
            ReproduceConfig(out, recording=synthetic_recording(levels=(0.0,)), progress=False)
        )
    assert (out / "data.h5").read_bytes() == b"not mine"


def test_demo_and_reproduce_defaults():
    import argparse

    from ectskin.commands import demo, reproduce

    p = argparse.ArgumentParser()
    demo.add_arguments(p)
    args = p.parse_args([])
    assert (args.out, args.profile, args.overwrite, args.threads, args.figure_format) == (
        "demo-output",
        "quick",
        False,
        "auto",
        "png",
    )
    p = argparse.ArgumentParser()
    reproduce.add_arguments(p)
    args = p.parse_args(["out", "--profile", "quick", "--workers", "2"])
    assert (args.out_positional, args.profile, args.workers) == ("out", "quick", 2)
    with pytest.raises(SystemExit):
        p.parse_args(["out", "--profile", "fast"])


@pytest.mark.slow
def test_reproduce_tiny_twin_experiment(tmp_path, monkeypatch):
    """The real chain: the digital twin simulates a tiny protocol (levels 0/20 ml, one touch trial
    per state, 2-s trials), characterises the skin, trains, evaluates and reports. The contact
    experiment's response fields are built coarse (a 10 × 27.5 mm grid) into a cache of the
    test's own (~30 s each), and the bound and the inversion run on them (without the person's
    finger: its 32 finger fields would add minutes; tests/pipeline/test_inversion_step.py runs
    it on a field of its own)."""
    from ectskin.pipeline import field as pfield
    from ectskin.twin import Protocol
    from ectskin.twin.field_spec import FieldGrid

    small = FieldGrid(spacing_mm=(10.0, 27.5), force_nodes=4, height_nodes=4)
    monkeypatch.setitem(pfield.FIELD_GRIDS, "quick", small)
    out = tmp_path / "tiny"
    protocol = Protocol(levels_ml=(0.0, 20.0), touch_trials=1, duration_s=2.0, seed=0,
                        touch_dwells=1)
    config = ReproduceConfig(
        out,
        protocol=protocol,
        workers=1,
        profile="quick",
        epochs={"touch": 5, "track": 1},
        progress=False,
        field_cache=tmp_path / "fields",
        inversion_finger="off",
    )
    m = reproduce(config)
    assert len(list((tmp_path / "fields").iterdir())) == 8  # one field per contact state
    # the physical limit and the training-free inversion, on the contact run's test frames
    assert m["bound"]["test"]["n_points"] > 0 and m["bound"]["per_state"]
    inv = m["inversion"]
    # the bound at the training frames beside the inversion's error there (it is not trained)
    assert m["bound"]["train_alone"]["n_points"] > 0
    assert inv["train_trials"]["bound_alone_loc_mm_mean"] == m["bound"]["train_alone"]["loc_mm_mean"]
    split = json.loads((out / "runs" / "contact" / "split.json").read_text())
    assert inv["n_test_trials"] == len(split["test"])
    assert inv["n_frames"] > 0 and inv["n_frames_without_field"] >= 0
    assert 0 <= inv["count_accuracy"] <= 1 and inv["ms_per_frame_median"] > 0
    assert set(inv["per_state"]) <= set(m["bound"]["per_state"]) | set(
        inv["frames_without_field"])
    assert (out / "inversion" / "metrics.json").is_file()
    assert {"bound", "inversion"} <= set(m["timings_s"])
    # the inversion's error beside the bound and its forces with their standard errors, in the
    # report's figures
    for stem in ("error_vs_bound", "force_sigma"):
        assert f"figures/inversion_{stem}.png" in m["figures"].values(), stem
        assert (out / "figures" / f"inversion_{stem}.png").is_file(), stem
    # the contact model of the field states, chosen on validation frames where there are any
    choice = inv["choice"]
    assert choice is None or (choice["selected"] in choice["order"]
                              and set(choice["candidates"]) == set(choice["order"]))
    assert m["data"]["trials"] == protocol.n_trials == 16
    assert m["protocol"]["levels_ml"] == [0.0, 20.0]
    for rel in (
        "characterize/fig3_inflation.png",
        "characterize/fig4_touch.png",
        "figures/fig7_confusion.png",
        "figures/fig9_tracking.png",
        "report.html",
    ):
        assert (out / rel).is_file(), rel
    md = (out / "report.md").read_text()
    assert "(characterize/fig3_inflation.png)" in md and "(characterize/fig4_touch.png)" in md
    assert {"simulate", "characterize", "train_touch", "evaluate_track"} <= set(m["timings_s"])
    # the twin's touch trials say where their fingers were placed: at least one point each
    n_touch = sum(1 for t in read_recording(out / "contact.h5").trials if t.meta.get("touch_uv_mm"))
    assert m["contact"]["n_touch_points"] >= 1 and n_touch >= 1
    assert f"placed at {m['contact']['n_touch_points']} distinct points" in md
    # manual handling off: the contact run's test trials simulated again without the hand, in
    # place of their hand-on versions; everything else as it was
    off = m["contact"]["handling_off"]
    assert off["loc_mm_mean"] > 0 and set(off["baselines"]) == {"region_centre", "knn", "ridge"}
    assert "Manual handling on and off" in md
    assert "The physical inversion (no training)" in md and "Cramér–Rao bound" in md
    test = json.loads((out / "runs" / "contact" / "split.json").read_text())["test"]
    on_rec, off_rec = (
        read_recording(out / "contact.h5"),
        read_recording(out / "contact_handling_off.h5"),
    )
    assert [t.name for t in off_rec.trials] == [t.name for t in on_rec.trials]
    assert off_rec.meta["handling_off_trials"] == sorted(test)
    for a, b in zip(on_rec.trials, off_rec.trials, strict=True):
        same = np.array_equal(a.capacitance, b.capacitance)
        # a test trial with a touch changes (the hand pushed during it); the rest are copies
        assert same == (a.name not in test or a.meta.get("kind") != "touch"), a.name
        np.testing.assert_array_equal(a.force, b.force)
    # the same protocol is found in data.h5 by a fresh output folder's state: reuse, no simulation
    (out / "reproduce.json").unlink()
    import ectskin.pipeline.steps

    monkeypatch.setattr(
        ectskin.pipeline.steps,
        "simulate_experiment",
        lambda *a, **k: pytest.fail("simulated again"),
    )
    with pytest.raises(EctskinError, match="origin is unknown"):
        reproduce(config)
