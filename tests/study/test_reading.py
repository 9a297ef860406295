"""The reading ablation (``ectskin study reading``): its rows, splits, resumable cells, table and
command line, and one tiny cell end to end through the real simulation and trainings."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin._files import read_json
from ectskin.cli import main
from ectskin.io import write_recording
from ectskin.learn.data.touch import touch_dataset
from ectskin.learn.splits import TOUCH_SPLIT
from ectskin.study import reading_eval
from ectskin.study.reading import run_reading
from ectskin.study.reading_rows import (
    ONE_POINT,
    ROW_NAMES,
    ROWS,
    SPLIT_COUNTS,
    cell_settings,
    get_rows,
    result_path,
)
from ectskin.study.reading_table import summarise, table_markdown, write_table
from ectskin.twin import Protocol


def _flat(d, prefix=""):
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        out.update(_flat(v, key + ".") if isinstance(v, dict) else {key: v})
    return out


@pytest.mark.parametrize("seed", [0, 2])
def test_each_row_changes_exactly_the_fields_it_names(seed):
    base = _flat(replace(Protocol(seed=seed), **ONE_POINT).to_dict())
    for row in ROWS:
        proto = _flat(row.protocol(seed).to_dict())
        changed = {k for k in base if base[k] != proto[k]}
        assert changed == set(row.changes), row.name
        for k, v in row.changes.items():
            assert proto[k] == v, (row.name, k)
    # the named rows the brief asks for, each changing what its name says
    by = {r.name: dict(r.changes) for r in ROWS}
    assert by["one_point"] == {} and by["random_split"] == {}
    assert by["dwells_8"] == {"touch_dwells": 8}
    assert by["sliding"] == {"touch_dwells": 8, "dwell_slide_s": None}
    # the sliding row is today's default reading, the one-point row the earlier one
    assert get_rows(["sliding"])[0].protocol(seed) == Protocol(seed=seed)
    assert get_rows(["one_point"])[0].protocol(seed).slide_s == 0.0
    assert by["hand_off"] == {"push_max_n": 0.0}
    assert by["noise_x3"] == {"readout.noise_scale": 3.0}
    assert by["fingers_same"] == {"finger_variability": False}
    # only the diagnostic splits by frame, and it reads the default row's data
    assert [r.name for r in ROWS if r.split == "frame"] == ["random_split"]
    assert get_rows(["random_split"])[0].data_name == "one_point"
    with pytest.raises(EctskinError, match="unknown row"):
        get_rows(["dwells_16"])
    assert SPLIT_COUNTS == TOUCH_SPLIT  # the split every row's cell trains on


def test_the_diagnostic_splits_frames_and_the_default_keeps_trials_whole(tmp_path, make_recording):
    rec = make_recording(n_frames=40, states=((0, 0, 0), (10, 0, 0), (20, 0, 0)),
                         regions=(1, 5, 9, 10, 14, 18))
    data = touch_dataset(rec)
    ids = reading_eval.frame_split(data.n_samples, 3, (125, 32, 32))
    n = data.n_samples  # 21 trials x 40 frames
    assert sorted(np.concatenate(list(ids.values())).tolist()) == list(range(n))
    assert [ids[k].size for k in ("train", "val", "test")] == [556, 142, 142]  # 840 x 125:32:32
    train_trials = set(data.group[ids["train"]].tolist())
    test_trials = set(data.group[ids["test"]].tolist())
    assert test_trials <= train_trials  # every test frame's trial is in training: it leaks
    # the trial-exclusive split of the other rows (the reproduction's): no trial in two parts
    path = write_recording(rec, tmp_path / "data.h5")
    out = reading_eval._trial_split(path, tmp_path / "work", seed=3)
    split = read_json(tmp_path / "work" / "runs" / "paper" / "split.json")
    parts = [set(split[k]) for k in ("train", "val", "test")]
    assert not (parts[0] & parts[1] or parts[0] & parts[2] or parts[1] & parts[2])
    assert set().union(*parts) == {t.name for t in rec.trials}
    assert out["paper"]["n_test_frames"] == 40 * len(parts[2])  # whole trials
    assert out["split"]["kind"] == "trial" and out["paper"]["epochs"] == 30
    assert set(out["baselines"]) == {"majority", "logreg", "random_forest", "knn"}


def _cell(paper, epoch, robust, base_name, base_acc):
    return {
        "paper": {"accuracy": paper, "best_epoch": epoch, "epochs": 30},
        "robust": {"accuracy": robust, "best_epoch": 3, "epochs": 20},
        "baselines": {"majority": 0.15, base_name: base_acc},
        "best_baseline": {"name": base_name, "accuracy": base_acc},
        "seconds": {"simulate": 60.0, "train_paper": 20.0, "train_robust": 15.0, "evaluate": 9.0},
    }


def _write_cell(out, row, seed, body):
    path = result_path(out, row, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    settings = cell_settings(get_rows([row])[0], seed)
    path.write_text(json.dumps({"settings": settings, **body}))


def test_the_table_from_hand_made_results(tmp_path):
    _write_cell(tmp_path, "one_point", 0, _cell(0.80, 1, 0.96, "logreg", 0.94))
    _write_cell(tmp_path, "one_point", 1, _cell(0.91, 8, 1.00, "logreg", 0.9575))
    _write_cell(tmp_path, "hand_off", 0, _cell(0.995, 12, 0.999, "knn", 0.97))
    (tmp_path / "results" / "notes.json").write_text("{}")  # not a result: ignored
    table, figure = write_table(tmp_path)
    text = table.read_text()
    lines = {ln.split("|")[1].strip(): ln for ln in text.splitlines() if ln.startswith("| `")}
    assert list(lines) == ["`one_point`", "`hand_off`"]  # in ROWS order
    cells = [c.strip() for c in lines["`one_point`"].split("|")[2:-1]]
    assert cells[0] == "80.00 (1/30) · 96.00 · logreg 94.00"
    assert cells[1] == "91.00 (8/30) · 100.00 · logreg 95.75"
    # the mean over the two seeds, by hand: (80 + 91) / 2, (96 + 100) / 2, (94 + 95.75) / 2
    assert cells[2] == "85.50 · 98.00 · 94.88"
    hand = [c.strip() for c in lines["`hand_off`"].split("|")[2:-1]]
    assert hand == ["99.50 (12/30) · 99.90 · knn 97.00", "–", "99.50 · 99.90 · 97.00 (1 seed)"]
    assert figure is not None and figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # only seed 1 asked for
    one = table_markdown({r: {1: c[1]} for r, c in summarise(tmp_path).items() if 1 in c})
    assert "seed 0" not in one and "91.00 (8/30)" in one


def test_cells_are_resumable_and_run_seed_by_seed(tmp_path):
    calls = []

    def fake(protocol, row, work, workers, keep):
        calls.append((row.name, protocol.seed, keep))
        return _cell(0.5 + protocol.seed / 10, 1, 0.9, "logreg", 0.8)

    rows = ["hand_off", "random_split", "one_point"]
    run_reading(tmp_path, [0, 1], rows, measure=fake)
    assert [(r, s) for r, s, _ in calls] == [  # RUN_ORDER, seed by seed
        ("one_point", 0), ("random_split", 0), ("hand_off", 0),
        ("one_point", 1), ("random_split", 1), ("hand_off", 1),
    ]
    # the default's data is kept for the diagnostic that reads it, not after
    assert [k for r, _, k in calls if r == "one_point"] == [True, True]
    assert not any(k for r, _, k in calls if r != "one_point")
    calls.clear()
    run_reading(tmp_path, [0, 1], rows, measure=fake)  # everything there: nothing computed
    assert calls == []
    # a result of other settings (another version's protocol) is computed again, alone
    path = result_path(tmp_path, "hand_off", 1)
    doc = json.loads(path.read_text())
    doc["settings"]["protocol"]["push_max_n"] = 1.0
    path.write_text(json.dumps(doc))
    run_reading(tmp_path, [0, 1, 2], ["hand_off"], measure=fake)
    assert calls == [("hand_off", 1, False), ("hand_off", 2, False)]
    assert json.loads(path.read_text())["settings"] == cell_settings(get_rows(["hand_off"])[0], 1)
    with pytest.raises(EctskinError, match="seeds must be integers"):
        run_reading(tmp_path, [-1], rows, measure=fake)


def test_the_command_line(tmp_path, capsys):
    _write_cell(tmp_path, "noise_x0", 0, _cell(0.99, 2, 1.0, "logreg", 0.99))
    assert main(["study", "reading", "--out", str(tmp_path), "--table-only"]) == 0
    assert "noise_x0" in (tmp_path / "reading_ablation.md").read_text()
    assert "table:" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["study", "reading", "--out", str(tmp_path), "--rows", "nope"])
    assert set(ROW_NAMES) >= {"dwells_2", "dwells_4", "force_wide", "no_pad_slide", "noise_x3"}


def test_a_tiny_cell_end_to_end(tmp_path):
    """One inflation state, 6 touch trials of 1 s: the real simulation, split, both trainings
    and the baselines, for the default row and the diagnostic on the same data."""
    base = replace(Protocol(), levels_ml=(0.0,), duration_s=1.0, **ONE_POINT)
    run_reading(tmp_path, [0], ["one_point", "random_split"], workers=1, base=base)
    default = read_json(result_path(tmp_path, "one_point", 0))
    diag = read_json(result_path(tmp_path, "random_split", 0))
    assert default["settings"]["protocol"]["levels_ml"] == [0.0]
    for doc in (default, diag):
        assert 0.0 <= doc["paper"]["accuracy"] <= 1.0 and doc["paper"]["epochs"] == 30
        assert 1 <= doc["paper"]["best_epoch"] <= 30 and doc["robust"]["epochs"] == 20
        assert doc["best_baseline"]["accuracy"] == max(doc["baselines"].values())
        assert doc["seconds"]["simulate"] > 0
    assert default["split"]["kind"] == "trial" and diag["split"]["kind"] == "frame"
    assert default["paper"]["n_test_frames"] % 30 == 0  # whole trials of 30 frames
    # the diagnostic read the default's simulation (same time), then the work folder went
    assert diag["seconds"]["simulate"] == default["seconds"]["simulate"]
    assert not (tmp_path / "work").exists() or not any((tmp_path / "work").iterdir())
