"""The paper's models: TouchMLP and C2DT (ectskin.learn.models)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from ectskin._check import EctskinError
from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP, TouchMLPConfig
from ectskin.learn.models.c2dt import coordinate_stats


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
def test_c2dt_shapes_and_untrained_model_is_the_no_motion_baseline(make_c2dt):
    model = make_c2dt().eval()
    x = torch.randn(4, 10, 28)
    init = torch.randn(4, 5, 3) * 30
    out = model(x, init)
    assert out.shape == (4, 5, 3)
    # zero-initialised head: prediction = init exactly ("markers do not move")
    assert torch.equal(out, init)


def test_c2dt_pair_embedding_is_one_shared_mlp_and_order_invariant(make_c2dt, randomise_head):
    model = make_c2dt().eval()
    desc, pairs = model.desc, model.pairs
    emb = model.electrode_mlp
    by_hand = torch.stack([emb(desc[p]) + emb(desc[q]) for p, q in pairs.tolist()])
    torch.testing.assert_close(model.pair_embedding(), by_hand)
    randomise_head(model)
    x, init = torch.randn(3, 10, 28), torch.randn(3, 5, 3)
    swapped = pairs.flip(1)  # (Q, P) instead of (P, Q) for every pair
    torch.testing.assert_close(model(x, init, pairs=swapped), model(x, init))


def test_c2dt_is_a_set_function_of_the_pair_tokens(make_c2dt, randomise_head):
    """No positional encoding besides the pair identity: listing the pairs in another order (x
    columns and pair table together) gives the same coordinates."""
    model = make_c2dt().eval()
    randomise_head(model)
    x, init = torch.randn(3, 10, 28), torch.randn(3, 5, 3)
    perm = torch.randperm(28, generator=torch.Generator().manual_seed(3))
    model_p = make_c2dt().eval()
    model_p.load_state_dict(model.state_dict())
    with torch.no_grad():
        model_p.pairs.copy_(model.pairs[perm])
        model_p.x_mean.copy_(model.x_mean[perm])
        model_p.x_std.copy_(model.x_std[perm])
    torch.testing.assert_close(model_p(x[:, :, perm], init), model(x, init), atol=1e-5, rtol=1e-5)
    # ... and the pair identity matters: the same columns with the original table differ
    assert not torch.allclose(model(x[:, :, perm], init), model(x, init), atol=1e-4)


def test_c2dt_without_prior_ignores_init_and_starts_at_the_mean_pose(make_c2dt, randomise_head):
    model = make_c2dt(prior=False).eval()
    out_mean = np.arange(15, dtype=np.float32).reshape(5, 3)
    model.set_normalization(np.zeros(28), np.ones(28), np.zeros(3), 1.0, out_mean, 2.0)
    x = torch.randn(2, 10, 28)
    torch.testing.assert_close(model(x), torch.tensor(out_mean).expand(2, 5, 3))
    randomise_head(model)
    torch.testing.assert_close(model(x, torch.randn(2, 5, 3)), model(x, None))


def test_c2dt_learned_pair_table_when_there_are_no_descriptors():
    cfg = C2DTConfig(n_pairs=27, desc_dim=0, n_electrodes=0, d_model=16, n_heads=2, ff=32)
    model = C2DT(cfg).eval()
    assert not hasattr(model, "desc")
    assert model(torch.randn(2, 10, 27), torch.zeros(2, 5, 3)).shape == (2, 5, 3)


def test_c2dt_checks_inputs_and_config(make_c2dt):
    model = make_c2dt()
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
def test_every_c2dt_parameter_learns(prior, make_c2dt):
    """After one Adam step (which moves the zero-initialised head) every parameter gets a
    gradient: the electrode MLP, the initial-coordinate MLP and all layers are in the graph."""
    model = make_c2dt(prior=prior)
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
