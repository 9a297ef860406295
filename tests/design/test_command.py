"""``ectskin design``: bad input is one clear error line (exit 2), before any work starts."""

from __future__ import annotations

import json

import pytest

from ectskin.cli import main
from ectskin.layout import default_layout


def _run(capsys, *argv) -> tuple[int, str]:
    code = main(["design", *argv])
    return code, capsys.readouterr().err


def test_a_layout_breaking_a_rule_names_its_file_and_field(tmp_path, capsys):
    d = default_layout().to_dict()
    d["electrodes"][5]["width_mm"] = 0.2
    path = tmp_path / "thin.json"
    path.write_text(json.dumps(d))
    code, err = _run(capsys, "score", str(path), "--out", str(tmp_path / "o"))
    assert code == 2
    assert f"{path}: electrodes[5].width_mm: electrode 'E6' is 0.2 mm wide" in err
    assert not (tmp_path / "o" / "design.json").exists()


@pytest.mark.parametrize(
    "argv, text",
    [
        (
            ("--min-wires", "5", "--max-wires", "3"),
            "search space is empty: --min-wires 5 > --max-wires 3",
        ),
        (("--length-mm", "50"), "--length-mm"),
        (("--sampler", "grid"), "'sampler'"),
        (("--objective", "luck"), "'objective'"),
        (("--bound-states", "0/0"), "--bound-states '0/0': inflation must give one volume per"),
        (("--bound-states", "0/0/x"), "--bound-states: expected states like 0/0/0,20/20/20"),
        (("--bound-mesh", "fine"), "'mesh'"),
    ],
)
def test_bad_search_options_are_one_error(tmp_path, capsys, argv, text):
    code, err = _run(capsys, "search", str(tmp_path / "s"), *argv)
    assert code == 2 and text in err and err.count("\n") == 1


def test_no_subcommand_is_an_error(capsys):
    code, err = _run(capsys)
    assert code == 2 and "score or search" in err


def test_the_score_reads_fields_by_default_and_solves_when_asked():
    """``design score``'s reading picks its protocol's size unless given (the field reading: 12
    trials of 15 s per state; the solve reading: 6 of 3 s), and a given size wins."""
    import argparse

    from ectskin.commands.design import _common, _config

    p = argparse.ArgumentParser()
    _common(p)
    field = _config(p.parse_args([]))
    assert field.response == "field" and field.protocol.response == "field"
    assert (field.protocol.touch_trials, field.protocol.duration_s) == (12, 15.0)
    solve = _config(p.parse_args(["--response", "solve"]))
    assert solve.response == "solve" and solve.protocol.response != "field"
    assert (solve.protocol.touch_trials, solve.protocol.duration_s) == (6, 3.0)
    given = _config(p.parse_args(["--response", "solve", "--touch-trials", "4", "--duration", "5"]))
    assert (given.protocol.touch_trials, given.protocol.duration_s) == (4, 5.0)


def test_a_bad_reading_is_one_error(tmp_path, capsys):
    code, err = _run(capsys, "score", "--out", str(tmp_path / "o"), "--response", "luck")
    assert code == 2 and "--response" in err and "luck" in err and err.count("\n") == 1
