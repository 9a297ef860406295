"""The one policy for result files: atomic writes and strict JSON (NaN/inf → null)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin._files import (
    atomic_write,
    json_text,
    read_json,
    read_json_object,
    temp_path,
    to_jsonable,
    write_json_atomic,
)


def test_non_finite_numbers_become_null_and_numpy_becomes_plain():
    obj = {"a": np.float32(1.5), "b": [math.nan, np.inf, -np.inf], "c": np.arange(3), "d": (1, 2)}
    plain = to_jsonable(obj)
    assert plain == {"a": 1.5, "b": [None, None, None], "c": [0, 1, 2], "d": [1, 2]}
    assert json.loads(json_text(obj)) == plain  # strict JSON: no NaN token
    assert "NaN" not in json_text({"x": np.array([np.nan])}, compact=True)


def test_dict_keys_are_spelled_as_json_spells_them():
    keys = {True: 1, False: 2, None: 3, 7: 4, 2.5: 5, "s": 6}
    assert to_jsonable(keys) == json.loads(json.dumps(keys))  # the json module: the reference
    assert to_jsonable({np.bool_(True): 1, np.int64(7): 2}) == {"true": 1, "7": 2}


def test_to_jsonable_is_what_the_written_file_reads_back(tmp_path: Path):
    """What a resume compares (design scores, the search's settings): settings as a file holds
    them, whatever containers and scalars they were built from."""

    @dataclass
    class Part:
        size: tuple[int, int]
        scale: np.float32

    obj = {
        "regions": (2, 1),
        "seed": np.int64(3),
        "part": Part((1, 2), np.float32(0.25)),
        "path": Path("runs") / "a",
        "nan": [math.nan, np.float64(0.5)],
        True: None,
    }
    expected = {
        "regions": [2, 1],
        "seed": 3,
        "part": {"size": [1, 2], "scale": 0.25},
        "path": str(Path("runs") / "a"),
        "nan": [None, 0.5],
        "true": None,
    }
    assert to_jsonable(obj) == expected
    assert read_json(write_json_atomic(tmp_path / "s.json", obj)) == expected


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path: Path):
    path = tmp_path / "metrics.json"
    write_json_atomic(path, {"old": 1})

    def boom(fh):
        fh.write(b"half")
        raise RuntimeError("disk gone")

    with pytest.raises(RuntimeError):
        atomic_write(path, boom)
    assert read_json(path) == {"old": 1}
    assert not temp_path(path).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_read_json_names_the_file_and_the_problem(tmp_path: Path):
    bad = tmp_path / "config.json"
    bad.write_text("{oops")
    with pytest.raises(EctskinError, match=r"config.json: run config is not valid JSON \(line 1"):
        read_json(bad, "run config")
    with pytest.raises(EctskinError, match="not found"):
        read_json(tmp_path / "missing.json")
    bad.write_text("[1, 2]")
    with pytest.raises(EctskinError, match="must hold a JSON object, found a JSON list"):
        read_json_object(bad)
