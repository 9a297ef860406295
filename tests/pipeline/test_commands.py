"""The command-line vocabulary of train, evaluate, reproduce, demo and characterize: -o/--out,
--overwrite (with the aliases users already type), examples at the end of every --help, and no
silent replacement of an earlier characterisation."""

from __future__ import annotations

import argparse
import importlib

import pytest

from ectskin.cli import build_parser, main

COMMANDS = ("train", "evaluate", "reproduce", "demo", "characterize")


def _subparser(name: str) -> argparse.ArgumentParser:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[name]


@pytest.mark.parametrize("name", COMMANDS)
def test_help_ends_with_examples_and_uses_the_one_vocabulary(name):
    module = importlib.import_module(f"ectskin.commands.{name}")
    assert module.EXAMPLES.strip().startswith(f"ectskin {name}")
    text = _subparser(name).format_help()
    assert text.rstrip().endswith(module.EXAMPLES.rstrip().splitlines()[-1].strip())
    assert "examples:" in text and "-o OUT, --out OUT" in text and "--overwrite" in text
    assert "=True" not in text  # flags, not API wording


def test_what_overwrite_means_is_said_per_command():
    train = _subparser("train").format_help()
    assert "--overwrite, --force" in train and "start the run over" in train
    reproduce = _subparser("reproduce").format_help()
    assert "--overwrite, --force" in reproduce and "redo the steps" in reproduce
    # characterize has no --force alias: --force was always short for --force-n
    args = _subparser("characterize").parse_args(["--force", "2", "-o", "c"])
    assert args.force_n == 2.0 and not args.overwrite


def test_outputs_by_option_or_by_the_old_position():
    p = _subparser("train")
    assert p.parse_args(["touch", "d.h5", "-o", "run", "--force"]).overwrite
    assert p.parse_args(["touch", "d.h5", "--out", "run"]).out == "run"
    assert _subparser("characterize").parse_args(["char"]).out_positional == "char"
    assert _subparser("reproduce").parse_args(["-o", "x"]).out == "x"
    assert _subparser("demo").parse_args([]).out == "demo-output"


def test_train_needs_an_output(tmp_path, capsys):
    assert main(["train", "touch", str(tmp_path / "d.h5")]) == 2
    assert "needs a run directory: give -o/--out PATH" in capsys.readouterr().err


@pytest.mark.parametrize("how", [["{dir}"], ["-o", "{dir}"]])
def test_characterize_never_replaces_an_earlier_characterisation(tmp_path, capsys, how):
    """Defect 16: ``characterize DIR`` replaced the figures and JSON of an earlier run without a
    flag. Catches removing the existence check (the run would start and rewrite the file)."""
    out = tmp_path / "char"
    out.mkdir()
    (out / "characterize.json").write_text('{"mine": 1}')
    argv = ["characterize", *(a.format(dir=out) for a in how)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "characterize.json: written by an earlier characterisation; pass --overwrite" in err
    assert (out / "characterize.json").read_text() == '{"mine": 1}'
