"""TouchMLP, C2DT, checkpoints and predictors (ectskin.learn.models / checkpoint / predict)."""

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
from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP, TouchMLPConfig
from ectskin.learn.models.c2dt import coordinate_stats
from ectskin.learn.predict import TouchPredictor, TrackPredictor

torch.set_num_threads(1)


def _small_c2dt(**kw) -> C2DT:
    layout = default_layout()
    cfg = C2DTConfig(d_model=16, n_heads=2, ff=32, **kw)
    torch.manual_seed(0)
    return C2DT(cfg, layout.electrode_descriptors(), layout.pairs)


def _randomise_head(model: C2DT) -> None:
    """The head starts at zero (output = baseline); give it weights so outputs depend on x."""
    with torch.no_grad():
        model.head.weight.normal_(0, 0.5)
        model.head.bias.normal_(0, 0.5)


# ============================================================================ TouchMLP
def test_touch_mlp_is_the_papers_architecture():
    model = TouchMLP()
    lin1, act, drop, lin2 = model.net
    assert (lin1.in_features, lin1.out_features) == (28, 128)
    assert isinstance(act, nn.ReLU)
    assert isinstance(drop, nn.Dropout) and drop.p == 0.1
    assert (lin2.in_features, lin2.out_features) == (128, 19)
    # 28*128 + 128 + 128*19 + 19 trainable numbers, nothing else
    assert sum(p.numel() for p in model.parameters()) == 28 * 128 + 128 + 128 * 19 + 19
    assert model(torch.zeros(7, 28)).shape == (7, 19)


def test_touch_mlp_normalisation_is_applied_inside():
    torch.manual_seed(1)
    x = torch.randn(5, 28) * 0.3 + 0.1
    mean, std = np.linspace(-0.2, 0.2, 28), np.linspace(0.5, 2.0, 28)
    a = TouchMLP().eval()
    b = TouchMLP().eval()
    b.load_state_dict(a.state_dict())
    b.set_normalization(mean, std)
    z = (x - torch.tensor(mean, dtype=torch.float32)) / torch.tensor(std, dtype=torch.float32)
    torch.testing.assert_close(b(x), a(z))
    with pytest.raises(EctskinError, match="x_mean must have shape"):
        b.set_normalization(np.zeros(27), np.ones(28))


@pytest.mark.parametrize(
    "kw, msg",
    [({"n_pairs": 0}, "n_pairs"), ({"n_classes": 1}, "n_classes"), ({"dropout": 1.0}, "dropout")],
)
def test_touch_config_is_checked(kw, msg):
    with pytest.raises(EctskinError, match=msg):
        TouchMLPConfig(**kw)


# ============================================================================ C2DT
def test_c2dt_shapes_and_untrained_model_is_the_no_motion_baseline():
    model = _small_c2dt().eval()
    x = torch.randn(4, 10, 28)
    init = torch.randn(4, 5, 3) * 30
    out = model(x, init)
    assert out.shape == (4, 5, 3)
    # zero-initialised head: prediction = init exactly ("markers do not move")
    assert torch.equal(out, init)


def test_c2dt_pair_embedding_is_one_shared_mlp_and_order_invariant():
    model = _small_c2dt().eval()
    desc, pairs = model.desc, model.pairs
    emb = model.electrode_mlp
    by_hand = torch.stack([emb(desc[p]) + emb(desc[q]) for p, q in pairs.tolist()])
    torch.testing.assert_close(model.pair_embedding(), by_hand)
    _randomise_head(model)
    x, init = torch.randn(3, 10, 28), torch.randn(3, 5, 3)
    swapped = pairs.flip(1)  # (Q, P) instead of (P, Q) for every pair
    torch.testing.assert_close(model(x, init, pairs=swapped), model(x, init))


def test_c2dt_is_a_set_function_of_the_pair_tokens():
    """No positional encoding besides the pair identity: listing the pairs in another order (x
    columns and pair table together) gives the same coordinates."""
    model = _small_c2dt().eval()
    _randomise_head(model)
    x, init = torch.randn(3, 10, 28), torch.randn(3, 5, 3)
    perm = torch.randperm(28, generator=torch.Generator().manual_seed(3))
    model_p = _small_c2dt().eval()
    model_p.load_state_dict(model.state_dict())
    with torch.no_grad():
        model_p.pairs.copy_(model.pairs[perm])
        model_p.x_mean.copy_(model.x_mean[perm])
        model_p.x_std.copy_(model.x_std[perm])
    torch.testing.assert_close(model_p(x[:, :, perm], init), model(x, init), atol=1e-5, rtol=1e-5)
    # ... and the pair identity matters: the same columns with the original table differ
    assert not torch.allclose(model(x[:, :, perm], init), model(x, init), atol=1e-4)


def test_c2dt_without_prior_ignores_init_and_starts_at_the_mean_pose():
    model = _small_c2dt(prior=False).eval()
    out_mean = np.arange(15, dtype=np.float32).reshape(5, 3)
    model.set_normalization(np.zeros(28), np.ones(28), np.zeros(3), 1.0, out_mean, 2.0)
    x = torch.randn(2, 10, 28)
    torch.testing.assert_close(model(x), torch.tensor(out_mean).expand(2, 5, 3))
    _randomise_head(model)
    torch.testing.assert_close(model(x, torch.randn(2, 5, 3)), model(x, None))


def test_c2dt_learned_pair_table_when_there_are_no_descriptors():
    cfg = C2DTConfig(n_pairs=27, desc_dim=0, n_electrodes=0, d_model=16, n_heads=2, ff=32)
    model = C2DT(cfg).eval()
    assert not hasattr(model, "desc")
    assert model(torch.randn(2, 10, 27), torch.zeros(2, 5, 3)).shape == (2, 5, 3)


def test_c2dt_checks_inputs_and_config():
    model = _small_c2dt()
    with pytest.raises(EctskinError, match=r"x of shape \(B, 10, 28\), got \(2, 10, 27\)"):
        model(torch.zeros(2, 10, 27), torch.zeros(2, 5, 3))
    with pytest.raises(EctskinError, match="init of shape"):
        model(torch.zeros(2, 10, 28))
    with pytest.raises(EctskinError, match="divisible by n_heads"):
        C2DTConfig(d_model=30, n_heads=4)
    with pytest.raises(EctskinError, match="pairs must have shape"):
        C2DT(C2DTConfig(), np.zeros((8, 6)), np.zeros((27, 2), dtype=int))
    with pytest.raises(EctskinError, match="indices must be in 0..7"):
        C2DT(C2DTConfig(), np.zeros((8, 6)), np.full((28, 2), 8))


def test_coordinate_stats_hand_computed():
    init = np.zeros((2, 1, 3))
    y = np.array([[[3.0, 0, 0]], [[0, 0, 4.0]]])
    s = coordinate_stats(init, y, prior=True)
    # displacements (3,0,0) and (0,0,4): mean square per component = (9 + 16) / 6
    assert s["out_scale"] == pytest.approx(np.sqrt(25 / 6))
    assert np.all(s["out_mean"] == 0)
    s = coordinate_stats(init, y, prior=False)
    np.testing.assert_allclose(s["out_mean"], [[1.5, 0, 2.0]])
    # residuals (±1.5, 0, ∓2): mean square per component = 2 (2.25 + 4) / 6
    assert s["out_scale"] == pytest.approx(np.sqrt(12.5 / 6))
    np.testing.assert_allclose(s["pos_mean"], [1.5, 0, 2.0])
    assert coordinate_stats(init, init, prior=True)["out_scale"] == 1e-3  # markers never move


@pytest.mark.parametrize("prior", [True, False])
def test_every_c2dt_parameter_learns(prior):
    """After one Adam step (which moves the zero-initialised head) every parameter gets a
    gradient: the electrode MLP, the initial-coordinate MLP and all layers are in the graph."""
    model = _small_c2dt(prior=prior)
    opt = torch.optim.Adam(model.parameters(), 1e-2)
    x, init = torch.randn(16, 10, 28), torch.randn(16, 5, 3)
    y = init + torch.randn(16, 5, 3)
    for _ in range(2):
        opt.zero_grad()
        ((model(x, init) - y) ** 2).mean().backward()
        opt.step()
    silent = [n for n, p in model.named_parameters() if p.grad is None or not p.grad.any()]
    assert not silent
    assert hasattr(model, "init_mlp") is prior


# ============================================================================ checkpoints
def _touch_model() -> TouchMLP:
    torch.manual_seed(0)
    m = TouchMLP(TouchMLPConfig(n_pairs=28, n_classes=19))
    m.set_normalization(np.linspace(0, 1, 28), np.linspace(1, 2, 28))
    return m.eval()


def test_checkpoint_rebuilds_the_model_from_the_file_alone(tmp_path):
    model = _touch_model()
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

    c2dt = _small_c2dt(prior=True)
    _randomise_head(c2dt)
    c2dt.set_normalization(np.ones(28), 2 * np.ones(28), np.ones(3), 3.0, np.zeros((5, 3)), 4.0)
    save_checkpoint(tmp_path / "c2dt.pt", c2dt.eval())
    loaded, config, _ = load_checkpoint(tmp_path / "c2dt.pt")
    assert config == c2dt.config
    x, init = torch.randn(2, 10, 28), torch.randn(2, 5, 3)
    torch.testing.assert_close(loaded(x, init), c2dt(x, init), rtol=0, atol=0)


def test_checkpoint_errors_name_the_file(tmp_path):
    model = _touch_model()
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


def test_save_refuses_foreign_models(tmp_path):
    with pytest.raises(EctskinError, match="not an ectskin model"):
        save_checkpoint(tmp_path / "x.pt", nn.Linear(2, 2))
    with pytest.raises(EctskinError, match="needs a TouchMLPConfig"):
        save_checkpoint(tmp_path / "x.pt", _touch_model(), C2DTConfig())


# ============================================================================ predictors
def test_touch_predictor(tmp_path):
    model = _touch_model()
    names = list(default_layout().pair_names)
    save_checkpoint(tmp_path / "model.pt", model, extra={"pair_names": names})
    pred = TouchPredictor.from_run(tmp_path)
    assert (pred.n_pairs, pred.n_classes, pred.pair_names) == (28, 19, names)
    x = np.random.default_rng(0).normal(size=(6, 28)).astype(np.float32)
    probs = pred.predict(x)
    expected = torch.softmax(model(torch.from_numpy(x)), dim=1).detach().numpy()
    np.testing.assert_allclose(probs, expected, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(probs.sum(1), 1, rtol=1e-6)
    np.testing.assert_allclose(pred.predict(x[2].tolist()), probs[2], rtol=1e-6, atol=1e-7)
    assert pred.classify(x[2]) == int(probs[2].argmax())
    np.testing.assert_array_equal(pred.classify(x), probs.argmax(1))
    with pytest.raises(EctskinError, match=r"shape \(28\) or \(B, 28\), got \(27,\)"):
        pred.predict(np.zeros(27))
    bad = x[0].copy()
    bad[3] = np.nan
    with pytest.raises(EctskinError, match=f"channel {names[3]!r}"):
        pred.predict(bad)
    with pytest.raises(EctskinError, match="expected a 'c2dt' model"):
        TrackPredictor.from_run(tmp_path)


def test_track_predictor(tmp_path):
    model = _small_c2dt().eval()
    _randomise_head(model)
    save_checkpoint(tmp_path / "model.pt", model)
    pred = TrackPredictor.from_run(tmp_path / "model.pt")
    assert (pred.n_pairs, pred.window, pred.n_markers, pred.prior) == (28, 10, 5, True)
    rng = np.random.default_rng(1)
    w, init = rng.normal(size=(3, 10, 28)), rng.normal(size=(3, 5, 3)) * 10
    out = pred.predict(w, init)
    expected = model(torch.tensor(w, dtype=torch.float32), torch.tensor(init, dtype=torch.float32))
    np.testing.assert_allclose(out, expected.detach().numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(pred.predict(w[1], init[1]), out[1], rtol=1e-5, atol=1e-5)
    with pytest.raises(EctskinError, match="uses prior knowledge; pass init"):
        pred.predict(w[0])
    with pytest.raises(EctskinError, match="disagree in batch size"):
        pred.predict(w, init[:2])
    with pytest.raises(EctskinError, match=r"window must have shape \(10, 28\)"):
        pred.predict(w[:, :9], init)
