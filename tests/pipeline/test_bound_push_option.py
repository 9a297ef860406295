"""The bound's push columns as a reproduction option: ``ReproduceConfig.bound_push_columns``,
``--bound-push-columns`` of ``reproduce``/``demo``, handed to the bound step, and named in
metrics.json's bound settings."""

from __future__ import annotations

import importlib

import pytest
from test_reproduce import cli  # tests/pipeline

from ectskin._check import EctskinError
from ectskin.pipeline.config import BOUND_PUSH_COLUMNS, ReproduceConfig
from ectskin.pipeline.metrics import bound_block
from ectskin.twin.bound_field import PUSH_COLUMNS

# the module (ectskin.pipeline.reproduce is also the name of the package's function)
rep = importlib.import_module("ectskin.pipeline.reproduce")


def test_the_config_names_the_bound_step_options():
    # the config keeps its own copy (it does not import the bound's module): they must agree
    assert BOUND_PUSH_COLUMNS == PUSH_COLUMNS
    with pytest.raises(EctskinError, match="bound_push_columns.*'finger'.*'table'"):
        ReproduceConfig("/tmp/x", bound_push_columns="table")
    assert ReproduceConfig("/tmp/x").bound_push_columns == "untouched"


def test_the_command_sets_the_option(tmp_path, monkeypatch):
    import ectskin.pipeline

    seen = []
    monkeypatch.setattr(ectskin.pipeline, "reproduce",
                        lambda config: seen.append(config) or {"timings_s": {"total": 1.0}})
    assert cli(["demo", "-o", str(tmp_path / "a"), "--bound-push-columns", "finger"],
               monkeypatch) == 0
    assert cli(["reproduce", "-o", str(tmp_path / "b")], monkeypatch) == 0
    assert [c.bound_push_columns for c in seen] == ["finger", "untouched"]


def test_the_reproduction_hands_it_to_the_bound_step(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(rep, "contact_fields", lambda config, specs: {(0.0, 0.0, 0.0): object()})
    monkeypatch.setattr(rep, "physics_field_specs", lambda config: [])
    monkeypatch.setattr(rep, "bound_step",
                        lambda *a, **kw: calls.append(kw.get("push_columns")) or {"b": 1})
    monkeypatch.setattr(rep, "inversion_step", lambda *a, **kw: {"i": 1})

    class Runner:
        timings: dict = {}

    for option in ("finger", "untouched"):
        config = ReproduceConfig(tmp_path, bound_push_columns=option)
        assert rep._physics_steps(Runner(), config, (tmp_path, {}), {}) == ({"b": 1}, {"i": 1})
    assert calls == ["finger", "untouched"]


def test_metrics_name_the_push_columns():
    bound = {"settings": {"push_columns": "finger", "nuisances": ["push"]}, "cases": {}}
    assert bound_block(bound, None)["settings"]["push_columns"] == "finger"
