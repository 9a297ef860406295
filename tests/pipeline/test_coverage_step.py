"""The robust run's coverage trials in the reproduction (ectskin.pipeline.steps.coverage_data):
the twin is stood in for by hand-made recordings, so the wiring runs in seconds."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import pytest
from test_reproduce import synthetic_recording  # tests/pipeline

import ectskin.pipeline.steps as steps
from ectskin._check import EctskinError
from ectskin.io import Recording
from ectskin.layout import default_layout
from ectskin.pipeline import ReproduceConfig, reproduce
from ectskin.twin import Protocol
from ectskin.twin.coverage import coverage_protocol


def test_the_robust_run_alone_trains_on_the_coverage_trials(tmp_path, monkeypatch):
    asked = []

    def fake_twin(protocol, **kw):  # a recording that says which protocol made it
        asked.append(protocol)
        rec = synthetic_recording(seed=len(asked))
        return Recording(rec.layout, rec.trials, rec.frame_rate_hz,
                         meta={"protocol": protocol.to_dict()})

    monkeypatch.setattr(steps, "simulate_experiment", fake_twin)
    protocol = Protocol(seed=4, touch_trials=2)
    out = tmp_path / "out"
    config = ReproduceConfig(out, protocol=protocol, epochs={"touch": 2, "track": 1},
                             ablations=False, characterize=False, contact=False, progress=False)
    m = reproduce(config)
    assert asked == [protocol, coverage_protocol(protocol, default_layout())]
    runs = {n: json.loads((out / "runs" / n / "split.json").read_text())
            for n in ("touch", "touch_robust")}
    assert "extra_train" not in runs["touch"]
    assert [e["file"] for e in runs["touch_robust"]["extra_train"]] == [
        str((out / "coverage.h5").resolve())
    ]
    # the same validation and test trials: only training grew
    assert [runs["touch"][k] for k in ("val", "test")] == [
        runs["touch_robust"][k] for k in ("val", "test")
    ]
    assert "extra training trials of coverage.h5" in m["touch"]["robust"]["recipe_description"]
    assert "the twin's coverage trials" in (out / "report.md").read_text()
    # again: reused, nothing simulated; without coverage the robust run's settings differ
    assert "simulate_coverage" in reproduce(config)["reused"] and len(asked) == 2
    with pytest.raises(EctskinError, match=r"train_touch_robust.*--overwrite"):
        reproduce(replace(config, coverage=False))
    off = reproduce(replace(config, coverage=False, force=True))
    assert "extra_train" not in json.loads(
        (out / "runs" / "touch_robust" / "split.json").read_text()
    )
    assert "extra training" not in off["touch"]["robust"]["recipe_description"]
    # a coverage.h5 made beforehand (`ectskin simulate --coverage`) is adopted, not made again
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    shutil.copy(out / "coverage.h5", fresh / "coverage.h5")
    n = len(asked)
    assert "simulate_coverage" in reproduce(replace(config, out_dir=fresh))["reused"]
    assert asked[n:] == [protocol]  # data.h5 alone


def test_no_coverage_without_a_robust_run_or_for_a_given_recording():
    assert ReproduceConfig("o", robust=False).coverage_protocol() is None
    assert ReproduceConfig("o", coverage=False).coverage_protocol() is None
    assert ReproduceConfig("o", recording=synthetic_recording()).coverage_protocol() is None
    assert ReproduceConfig("o", seed=2).coverage_protocol() == coverage_protocol(
        Protocol(seed=2), default_layout()
    )
