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
    with pytest.raises(
        EctskinError, match="config field 'n_pairs' is 28 but tensor 'net.0.weight'"
    ):
        load_checkpoint(tmp_path / "shape.pt")
    sd["net.0.weight"], sd["net.0.bias"] = payload["state_dict"]["net.0.weight"], torch.zeros(7)
    torch.save({**payload, "state_dict": sd}, tmp_path / "bias.pt")
    with pytest.raises(EctskinError, match=r"bias\.pt: weights do not match"):
        load_checkpoint(tmp_path / "bias.pt")


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


# ----------------------------------------------------------------------------- untrusted content
def _edited(tmp_path, good, name, **changes):
    """A copy of checkpoint ``good`` with payload fields replaced (``config`` and ``state_dict``
    are merged into the stored ones)."""
    payload = read_checkpoint(good)
    for key in ("config", "state_dict", "normalizer"):
        if key in changes:
            changes[key] = {**payload[key], **changes[key]}
    path = tmp_path / name
    torch.save({**payload, **changes}, path)
    return path


def test_a_checkpoint_with_non_finite_weights_or_statistics_is_refused(tmp_path, make_touch_mlp):
    """Defect 2: ``state_dict['x_mean'][:] = nan`` gave a model that "works" (every frame class
    0, probabilities NaN). Catches removing :func:`check_finite` from read_checkpoint."""
    good = save_checkpoint(tmp_path / "model.pt", make_touch_mlp(), normalizer={"x": [1.0, 2.0]})
    nan_mean = torch.full((28,), float("nan"))
    path = _edited(tmp_path, good, "nan.pt", state_dict={"x_mean": nan_mean})
    with pytest.raises(EctskinError, match=r"nan\.pt: tensor 'x_mean' .* non-finite values"):
        load_checkpoint(path)
    with pytest.raises(EctskinError, match=r"nan\.pt: tensor 'x_mean'"):
        read_checkpoint(path)  # also what resuming from last.pt reads
    weight = read_checkpoint(good)["state_dict"]["net.0.weight"].clone()
    weight[3, 4] = float("inf")
    path = _edited(tmp_path, good, "inf.pt", state_dict={"net.0.weight": weight})
    with pytest.raises(EctskinError, match=r"inf\.pt: tensor 'net\.0\.weight' .*1 of 3584"):
        load_checkpoint(path)
    # a non-finite statistic is stored as null (JSON policy): refused as well
    path = _edited(tmp_path, good, "norm.pt", normalizer={"x": [1.0, None]})
    with pytest.raises(EctskinError, match=r"norm\.pt: normaliser field \['x'\]\[1\]"):
        load_checkpoint(path)
    path = _edited(tmp_path, good, "list.pt", state_dict={"x_std": [1.0] * 28})
    with pytest.raises(EctskinError, match=r"list\.pt: state_dict entry 'x_std' is a list"):
        load_checkpoint(path)


@pytest.mark.parametrize(
    "kind, field, value, tensor",
    [
        ("touch_mlp", "n_pairs", 10**9, "x_mean"),
        ("touch_mlp", "hidden", 10**9, "net.0.weight"),
        ("touch_mlp", "n_classes", 10**9, "net.3.weight"),
        ("c2dt", "n_pairs", 10**9, "x_mean"),
        ("c2dt", "window", 10**9, "value_proj.weight"),
        ("c2dt", "ff", 10**9, "linear1.weight"),
        ("c2dt", "d_model", 2**20, "marker_emb"),
        ("c2dt", "n_electrodes", 10**6, "desc"),
        ("c2dt", "n_enc_layers", 10**6, "encoder.layers"),
        ("c2dt", "n_dec_layers", 10**6, "decoder.layers"),
    ],
)
def test_a_crafted_config_is_refused_before_the_model_is_built(
    tmp_path, monkeypatch, make_touch_mlp, make_c2dt, kind, field, value, tensor
):
    """Defect 3: ``config['n_pairs'] = 10**9`` built a 512-GB model before the state dict was
    compared. Now one error names the file and the field, and no model is constructed (the spy
    fails the test if one is). Catches checking the shapes after ``model_cls(config)`` or not at
    all (then ``load_state_dict`` would only be reached after the allocation)."""
    import ectskin.learn.checkpoint as ckpt

    model = make_touch_mlp() if kind == "touch_mlp" else make_c2dt()
    good = save_checkpoint(tmp_path / "model.pt", model)
    path = _edited(tmp_path, good, "crafted.pt", config={field: value})
    real_cls, config_cls = ckpt.MODELS[kind]

    class Spy(real_cls):
        def __init__(self, *a, **k):
            pytest.fail("the model was built before its config was checked")

    monkeypatch.setitem(ckpt.MODELS, kind, (Spy, config_cls))
    with pytest.raises(EctskinError, match=rf"crafted\.pt: config field '{field}' is {value}"):
        load_checkpoint(path)
    try:
        load_checkpoint(path)
    except EctskinError as exc:
        assert tensor in str(exc)


def test_state_shapes_describe_the_real_models(make_c2dt):
    """The shape table the loader checks against (``state_shapes``, ``layer_stacks``) matches
    the tensors each model really has, for several configs."""
    from ectskin.learn.checkpoint import check_state_dict
    from ectskin.learn.models import C2DT, TouchMLP, TouchMLPConfig

    models = [
        TouchMLP(TouchMLPConfig(n_pairs=5, hidden=7, n_classes=3)),
        make_c2dt(),
        make_c2dt(prior=False, window=3),
        C2DT(C2DTConfig(desc_dim=0, n_enc_layers=0, n_dec_layers=3, d_model=8, n_heads=2, ff=12)),
    ]
    for m in models:
        sd = m.state_dict()
        check_state_dict("m.pt", m.kind, m.config, sd)  # no error for the model's own tensors
        for name, dims in type(m).state_shapes(m.config).items():
            want = tuple(getattr(m.config, d) if isinstance(d, str) else d for d in dims)
            assert tuple(sd[name].shape) == want, (m.kind, name)


def test_checkpoint_config_errors_name_the_file(tmp_path, make_touch_mlp):
    good = save_checkpoint(tmp_path / "model.pt", make_touch_mlp())
    for name, change, msg in [
        ("neg.pt", {"hidden": -1}, r"TouchMLPConfig\.hidden must be a positive integer"),
        ("drop.pt", {"dropout": "a lot"}, "invalid TouchMLPConfig"),
        ("new.pt", {"depth": 3}, "unknown TouchMLPConfig field"),
    ]:
        path = _edited(tmp_path, good, name, config=change)
        with pytest.raises(EctskinError, match=rf"{name}: config: {msg}"):
            load_checkpoint(path)


def test_checkpoint_errors_never_suggest_the_unsafe_loader(tmp_path):
    """torch's refusal says "Re-running torch.load with weights_only set to False will likely
    succeed": passed on, that nudges a user to run a stranger's file. Catches quoting torch's
    message (the first line of it held the hint)."""
    _Exploit.target = tmp_path / "pwned"
    torch.save({"format": "ectskin.checkpoint", "x": _Exploit()}, tmp_path / "evil.pt")
    (tmp_path / "noise.pt").write_bytes(np.random.default_rng(1).bytes(4000))
    for name, what in [("evil.pt", r"holds a Python object \(posix.mkdir\)"), ("noise.pt", "not")]:
        with pytest.raises(EctskinError, match=what) as info:
            load_checkpoint(tmp_path / name)
        text = str(info.value).lower()
        assert "weights_only" not in text and "pickle" not in text and "false" not in text


def test_load_checkpoint_checks_the_layout(tmp_path, make_touch_mlp, make_c2dt, layout):
    from dataclasses import replace as dc_replace

    good = save_checkpoint(tmp_path / "model.pt", make_touch_mlp())
    load_checkpoint(good, layout=layout)
    small = dc_replace(layout, regions=layout.regions[:10])
    with pytest.raises(
        EctskinError, match=r"model\.pt: config field 'n_classes' is 19, but layout"
    ):
        load_checkpoint(good, layout=small)
    c2dt = save_checkpoint(tmp_path / "c2dt.pt", make_c2dt())
    few = dc_replace(layout, markers=layout.markers[:3])
    with pytest.raises(EctskinError, match=r"c2dt\.pt: config field 'n_markers' is 5, but layout"):
        load_checkpoint(c2dt, layout=few)
