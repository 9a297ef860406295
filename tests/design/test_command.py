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
