"""Self-describing model files (ectskin.learn.checkpoint)."""

from __future__ import annotations

import pickle
from dataclasses import asdict

import numpy as np
import pytest
import torch
from torch import nn

from ectskin._check import EctskinError
from ectskin.layout import default_layout
from ectskin.learn.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
from ectskin.learn.models import C2DTConfig


def test_checkpoint_rebuilds_the_model_from_the_file_alone(
    tmp_path, make_c2dt, randomise_head, make_touch_mlp
):
    model = make_touch_mlp()
    path = save_checkpoint(
        tmp_path / "run" / "model.pt",
        model,
        normalizer={"x": np.arange(3.0)},
        extra={"pair_names": list(default_layout().pair_names), "epoch": np.int64(7)},
    )
    assert sorted(p.name for p in path.parent.iterdir()) == ["model.pt"]  # no temporary left
    loaded, config, payload = load_checkpoint(path)
    assert config == model.config and not loaded.training
    assert payload["format"] == "ectskin.checkpoint" and payload["version"] == 1
    assert payload["kind"] == "touch_mlp" and payload["config"] == asdict(model.config)
    assert payload["normalizer"] == {"x": [0.0, 1.0, 2.0]} and payload["extra"]["epoch"] == 7
    x = torch.randn(4, 28)
    torch.testing.assert_close(loaded(x), model(x), rtol=0, atol=0)

    c2dt = make_c2dt(prior=True)
    randomise_head(c2dt)
    c2dt.set_normalization(np.ones(28), 2 * np.ones(28), np.ones(3), 3.0, np.zeros((5, 3)), 4.0)
    save_checkpoint(tmp_path / "c2dt.pt", c2dt.eval())
    loaded, config, _ = load_checkpoint(tmp_path / "c2dt.pt")
    assert config == c2dt.config
    x, init = torch.randn(2, 10, 28), torch.randn(2, 5, 3)
    torch.testing.assert_close(loaded(x, init), c2dt(x, init), rtol=0, atol=0)


def test_checkpoint_errors_name_the_file(tmp_path, make_touch_mlp):
    model = make_touch_mlp()
    good = save_checkpoint(tmp_path / "model.pt", model)
    # wrong kind / wrong channel count
    with pytest.raises(EctskinError, match="holds a 'touch_mlp' model, expected a 'c2dt'"):
        load_checkpoint(good, kind="c2dt")
    with pytest.raises(EctskinError, match=r"model\.pt: model expects 28 channels, dataset has 27"):
        load_checkpoint(good, n_pairs=27)
    # truncated / random bytes
    data = good.read_bytes()
    (tmp_path / "cut.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(EctskinError, match=r"cut\.pt: not a readable ectskin checkpoint"):
        load_checkpoint(tmp_path / "cut.pt")
    (tmp_path / "noise.pt").write_bytes(np.random.default_rng(0).bytes(4000))
    with pytest.raises(EctskinError, match=r"noise\.pt: not a readable"):
        load_checkpoint(tmp_path / "noise.pt")
    with pytest.raises(EctskinError, match="no such checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")
    # a torch file that is not ours, one from the future, one with an unknown config field
    torch.save({"weights": torch.zeros(3)}, tmp_path / "other.pt")
    with pytest.raises(EctskinError, match="not an ectskin checkpoint"):
        load_checkpoint(tmp_path / "other.pt")
    payload = read_checkpoint(good)
    torch.save({**payload, "version": 99}, tmp_path / "future.pt")
    with pytest.raises(EctskinError, match="version 99 is newer"):
        load_checkpoint(tmp_path / "future.pt")
    torch.save({**payload, "config": {**payload["config"], "depth": 3}}, tmp_path / "field.pt")
    with pytest.raises(EctskinError, match="unknown TouchMLPConfig field"):
        load_checkpoint(tmp_path / "field.pt")
    sd = dict(payload["state_dict"])
    sd["net.0.weight"] = torch.zeros(128, 27)
    torch.save({**payload, "state_dict": sd}, tmp_path / "shape.pt")
    with pytest.raises(EctskinError, match="weights do not match"):
        load_checkpoint(tmp_path / "shape.pt")


class _Exploit:
    def __reduce__(self):
        import os

        return (os.mkdir, (str(_Exploit.target),))


def test_checkpoint_never_executes_pickled_code(tmp_path):
    _Exploit.target = tmp_path / "pwned"
    with open(tmp_path / "evil.pt", "wb") as fh:
        pickle.dump({"format": "ectskin.checkpoint", "payload": _Exploit()}, fh)
    torch.save({"format": "ectskin.checkpoint", "x": _Exploit()}, tmp_path / "evil2.pt")
    for name in ("evil.pt", "evil2.pt"):
        with pytest.raises(EctskinError, match="not a readable ectskin checkpoint"):
            load_checkpoint(tmp_path / name)
    assert not _Exploit.target.exists()


def test_save_refuses_foreign_models(tmp_path, make_touch_mlp):
    with pytest.raises(EctskinError, match="not an ectskin model"):
        save_checkpoint(tmp_path / "x.pt", nn.Linear(2, 2))
    with pytest.raises(EctskinError, match="needs a TouchMLPConfig"):
        save_checkpoint(tmp_path / "x.pt", make_touch_mlp(), C2DTConfig())
