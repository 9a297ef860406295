"""`ectskin bound`: bound.json with the documented keys and bound.png, no silent overwrite, the
Dask cluster giving what the serial run gives, and bad options named in one clear error."""

from __future__ import annotations

import json

import pytest

from ectskin.cli import main

# one state, one face, a 40-mm grid (1 x 3 cells), the finger only: 3 points of 9 solves each
SMALL = ["--states", "0,0,0", "--faces", "front", "--spacing-mm", "40", "--nuisance", "finger",
         "--priors", "none", "--no-progress"]


#: a run that would take a second if a bad option slipped through (the last value of an option wins)
CHEAP = ["--no-progress", "--workers", "0", "--faces", "front", "--spacing-mm", "200",
         "--nuisance", "none"]


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bound")
    assert main(["bound", str(out), *SMALL, "--workers", "0"]) == 0
    return out


def test_bound_writes_the_documented_keys(serial_run):
    doc = json.loads((serial_run / "bound.json").read_text())
    assert (serial_run / "bound.png").stat().st_size > 0
    assert {"schema", "version", "layout", "settings", "cases", "modes", "skins", "wires",
            "states", "summary", "timing"} <= set(doc)
    assert doc["schema"] == "ectskin.bound" and doc["cases"] == ["none", "finger"]
    assert doc["settings"]["position"] == "sqrt(var_u + var_v)"
    assert doc["settings"]["mesh"] == "coarse" and doc["settings"]["prior_sd"] == {}
    face = doc["states"][0]["faces"]["front"]
    assert doc["states"][0]["inflation_ml"] == [0.0, 0.0, 0.0]
    assert face["u_mm"] == [0.0] and len(face["v_mm"]) == 3
    for case in ("none", "finger"):
        entry = face["contact"][case]
        assert {"position_mm", "force_n", "summary"} <= set(entry)
        assert len(entry["force_n"]) == 3 and len(entry["force_n"][0]) == 1
        s = entry["summary"]
        assert {"mean", "median", "p95"} == set(s["position_mm"]) == set(s["force_n"])
        assert 0 <= s["force_observable_share"] <= 1 and s["resolved_share"] == 1
    # an unknown finger never lowers a bound
    none, finger = face["contact"]["none"], face["contact"]["finger"]
    for q in ("position_mm", "force_n"):
        assert all(f[0] >= n[0] for f, n in zip(finger[q], none[q]))
    assert doc["timing"]["points"] == 3


def test_bound_refuses_to_overwrite(serial_run, capsys):
    before = (serial_run / "bound.json").read_bytes()
    assert main(["bound", str(serial_run), *SMALL, "--workers", "0"]) == 2
    assert "file exists; use --overwrite" in capsys.readouterr().err
    assert (serial_run / "bound.json").read_bytes() == before


def test_the_dask_cluster_gives_the_serial_maps(serial_run, tmp_path):
    out = tmp_path / "dask"
    assert main(["bound", "-o", str(out), *SMALL, "--workers", "1"]) == 0
    a = json.loads((serial_run / "bound.json").read_text())["states"]
    b = json.loads((out / "bound.json").read_text())["states"]
    assert a == b


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--spacing-mm", "0"], "--spacing-mm"),
        (["--force-n", "0.01"], "--force-n"),
        (["--workers", "-1"], "--workers"),
        (["--nuisance", "wind"], "--nuisance"),
        (["--priors", "wind=1"], "--priors"),
        (["--priors", "inflation=-1"], "--priors"),
        (["--states", "0,0"], "--states must hold 3 numbers"),
        (["--states", "0,0,0", "--levels", "0,20"], "give --states or --levels"),
        (["--levels", "0,45"], "impossible inflation for chamber"),
        (["--faces", "top"], "--faces"),
        (["--mesh", "fine"], "--mesh"),
        (["--scheduler", "localhost:1"], "--scheduler"),
    ],
)
def test_bad_options_are_one_error_naming_the_option(tmp_path, capsys, argv, message):
    try:
        code = main(["bound", str(tmp_path / "out"), *CHEAP, *argv])
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out" / "bound.json").exists()
