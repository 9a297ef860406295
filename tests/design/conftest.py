"""Fixtures of the design tests: a cheap stand-in for the per-layout scorer."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ectskin._files import write_json_atomic
from ectskin.design.score import SCORE_FILE


class FakeScore:
    """Writes what ``score_layout`` writes (name, counts, settings, layout) in no time and
    records the layouts it was called for; a layout named ``boom`` raises."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def __call__(self, layout, out_dir, config):
        self.calls.append(layout.name)
        if layout.name == "boom":
            raise RuntimeError("killed in the middle")
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        score = {
            "name": layout.name,
            "n_electrodes": layout.n_electrodes,
            "n_pairs": layout.n_pairs,
            "loc_mm_mean": 30.0 - layout.n_electrodes,
            "region_accuracy": 0.5,
            "force_mae_n": 0.1,
            "track_ad_mm": 1.0,
            "loc_mm_per_face": {},
            "loc_map": {},
            "sensor": {"snr_db_min": 60.0},
            "seconds": {"total": 0.0},
            "settings": config.settings(),
            "layout": layout.to_dict(),
        }
        write_json_atomic(out / SCORE_FILE, score)
        (out / "layout.json").write_text(layout.to_json())
        return json.loads((out / SCORE_FILE).read_text())


@pytest.fixture
def fake_score() -> FakeScore:
    return FakeScore()
