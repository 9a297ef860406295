"""Force with its uncertainty: the split of the force error by a per-frame bound (hand-computed
MAEs), the coverage of a σ against Gaussian errors of known σ, ContactNet's force σ head
learning a known heteroscedastic σ, the classical candidates' out-of-fold σ, and model files
written before the force had a σ (they load and answer with none)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from ectskin._check import EctskinError
from ectskin.learn.checkpoint import load_checkpoint, save_checkpoint
from ectskin.learn.contact_classical import (
    fit_contact_classical,
    load_contact_classical,
    save_contact_classical,
)
from ectskin.learn.metrics.contact import force_coverage, force_split
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS, ContactNet, ContactNetConfig
from ectskin.learn.predict.contact import ContactPredictor
from ectskin.learn.tasks.contact import ContactCriterion, force_split_report

NCOL = len(PRED_COLUMNS) + 2 * len(SLOT_COLUMNS)
F0 = len(PRED_COLUMNS) + SLOT_COLUMNS.index("force_n")  # slot 0's force column
S0 = len(PRED_COLUMNS) + SLOT_COLUMNS.index("force_sigma_n")


# ----------------------------------------------------------------------------- the split
def test_force_split_by_hand():
    true = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 2.0])
    pred = np.array([1.1, 0.75, 1.5, 1.0, 0.6, 2.3])
    bound = np.array([0.05, 0.09, 0.1, 0.3, np.nan, np.nan])  # 0.1 itself: not observable
    sigma = np.array([0.2, 0.1, 0.4, np.nan, 0.3, 0.1])
    got = force_split(true, pred, bound, 0.1, sigma_n=sigma)
    assert got["force_mae_n_observable"] == pytest.approx((0.1 + 0.25) / 2)
    assert got["force_mae_n_not_observable"] == pytest.approx((0.5 + 0.0) / 2)
    assert got["force_mae_n_no_bound"] == pytest.approx((0.4 + 0.3) / 2)
    for part in ("observable", "not_observable", "no_bound"):
        assert got[f"share_{part}"] == pytest.approx(2 / 6) and got[f"n_frames_{part}"] == 2
    assert got["bound_force_n_mean_observable"] == pytest.approx(0.07)
    assert got["bound_force_n_mean_not_observable"] == pytest.approx(0.2)
    assert got["bound_force_n_mean_no_bound"] is None
    # |error| / σ: observable 0.5, 2.5; not observable 1.25 (and one frame without σ);
    # no bound 1.33, 3
    assert got["force_coverage_1sigma_observable"] == 0.5
    assert got["force_coverage_2sigma_observable"] == 0.5
    assert got["force_coverage_1sigma_not_observable"] == 0.0
    assert got["force_coverage_2sigma_not_observable"] == 1.0
    assert got["force_coverage_2sigma_no_bound"] == 0.5
    # a part without frames has no MAE; no bound anywhere: everything is "no bound"
    none = force_split(true, pred, np.full(6, np.nan), 0.1)
    assert none["force_mae_n_observable"] is None and none["share_no_bound"] == 1.0
    with pytest.raises(EctskinError, match="threshold_n"):
        force_split(true, pred, bound, 0.0)
    with pytest.raises(EctskinError, match="one shape"):
        force_split(true, pred[:-1], bound, 0.1)


def test_force_split_report_reads_slot_0_of_the_one_finger_frames():
    pred = np.zeros((4, NCOL))
    pred[:, F0] = [1.5, 9.0, 2.0, 7.0]
    pred[:, F0 + len(SLOT_COLUMNS)] = 5.0  # slot 1: never read
    pred[:, S0] = 1.0
    test = SimpleNamespace(
        n_samples=4,
        count=np.array([1, 0, 1, 2]),  # frames 1 (no finger) and 3 (two) are not counted
        force=np.array([[1.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]),
    )
    got = force_split_report(test, pred, np.array([0.05, 0.05, 0.5, 0.05]), 0.1)
    assert got["n_frames"] == 2
    assert got["force_mae_n_observable"] == pytest.approx(0.5)
    assert got["force_mae_n_not_observable"] == pytest.approx(1.0)
    assert got["force_coverage_1sigma_observable"] == 1.0
    assert got["force_coverage_1sigma_not_observable"] == 1.0
    with pytest.raises(EctskinError, match="shape"):
        force_split_report(test, pred, np.zeros(3), 0.1)


# ----------------------------------------------------------------------------- coverage
def test_coverage_of_gaussian_errors_with_known_sigma():
    rng = np.random.default_rng(0)
    n = 200_000
    sigma = rng.lognormal(-1.0, 0.7, n)  # every frame its own σ
    true = rng.uniform(0.3, 2.0, n)
    pred = true + sigma * rng.standard_normal(n)
    got = force_coverage(true, pred, sigma)
    # Φ(1) − Φ(−1) = 0.6827, Φ(2) − Φ(−2) = 0.9545; binomial sd ≈ 0.001
    assert got["force_coverage_1sigma"] == pytest.approx(0.6827, abs=0.005)
    assert got["force_coverage_2sigma"] == pytest.approx(0.9545, abs=0.003)
    # a σ twice too large covers as a 2σ interval does
    assert force_coverage(true, pred, 2 * sigma)["force_coverage_1sigma"] == pytest.approx(
        0.9545, abs=0.003
    )
    # frames without a σ (NaN, 0) are left out; none at all: no coverage
    s = sigma.copy()
    s[: n // 2] = np.nan
    s[n // 2 : n // 2 + 10] = 0.0
    assert force_coverage(true, pred, s)["n_frames"] == n - n // 2 - 10
    assert force_coverage(true, pred, np.full(n, np.nan))["force_coverage_1sigma"] is None


# ----------------------------------------------------------------------------- ContactNet
def _sigma_true(x0: np.ndarray) -> np.ndarray:
    return 0.05 + 0.3 * np.abs(x0)


def test_the_force_sigma_head_learns_a_heteroscedastic_sigma():
    """Forces 1 + σ(x) ε with σ = 0.05 + 0.3 |x₀|: the head's σ (decode's force_sigma_n) comes
    within 20 % of σ for 0.2 ≤ |x₀| ≤ 0.8 (a constant σ is off by a factor of up to 2.4 there),
    and is smallest at x₀ = 0 (the kink there is smoothed by the network)."""
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    cfg = ContactNetConfig(n_pairs=2, window=1, arch="mlp", hidden=64, dropout=0.0,
                           force_sigma=True)
    model = ContactNet(cfg)
    model.set_normalization(np.zeros(2), np.ones(2), np.zeros((2, 2)), np.ones((2, 2)), 1.0)
    crit = ContactCriterion(model, thickness_mm=20.0)
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    n = 512
    for step in range(1800):
        if step == 1200:
            for g in opt.param_groups:
                g["lr"] = 5e-4
        x = rng.uniform(-1, 1, (n, 1, 2))
        force = 1.0 + _sigma_true(x[:, 0, 0]) * rng.standard_normal(n)
        batch = (
            torch.tensor(x, dtype=torch.float32),
            torch.ones(n, dtype=torch.int64),
            torch.tensor([[0, -1]] * n),
            torch.zeros(n, 2, 2),
            torch.tensor(np.c_[force, np.zeros(n)], dtype=torch.float32),
            torch.zeros(n),
        )
        opt.zero_grad()
        crit.loss(model, batch, None).backward()
        opt.step()
    model.eval()
    x0 = np.r_[np.linspace(-0.8, -0.2, 7), np.linspace(0.2, 0.8, 7), 0.0]
    grid = torch.tensor(np.c_[x0, np.zeros_like(x0)][:, None, :], dtype=torch.float32)
    with torch.no_grad():
        out = model.decode(model(grid)).numpy()
    np.testing.assert_allclose(out[:-1, S0], _sigma_true(x0[:-1]), rtol=0.2)
    assert out[-1, S0] < 0.5 * out[[0, -2], S0].min()
    np.testing.assert_allclose(out[:, F0], 1.0, atol=0.1)  # the force itself: its mean


def test_the_validation_pass_scales_the_force_sigma():
    """finish() sets force_sigma_scale to the RMS of (force error / σ) over the one-finger
    frames of the validation sums, by hand; decode's σ is the head's times it."""
    torch.manual_seed(3)
    model = ContactNet(ContactNetConfig(n_pairs=3, window=1, arch="mlp", hidden=8,
                                        force_sigma=True)).eval()
    model.set_normalization(np.zeros(3), np.ones(3), np.zeros((2, 2)), np.ones((2, 2)), 2.0)
    crit = ContactCriterion(model, thickness_mm=20.0)
    n = 50
    x = torch.randn(n, 1, 3)
    count = torch.tensor([1] * 40 + [0] * 5 + [2] * 5)
    face = torch.tensor([[0, -1]] * 45 + [[0, 1]] * 5)
    force = torch.rand(n, 2) * 2
    batch = (x, count, face, torch.zeros(n, 2, 2), force, torch.zeros(n))
    with torch.no_grad():
        out = model(x)
        sums = crit.eval_sums(model, batch[:3] + batch[3:]) + crit.eval_sums(model, batch)
        crit.finish(sums)
    sd = torch.exp(0.5 * out["force_log_var"][:40, 0]) * 2.0  # N (force_scale 2)
    z = (out["force"][:40, 0] * 2.0 - force[:40, 0]) / sd
    want = float(torch.sqrt(torch.mean(z**2)))
    assert float(model.force_sigma_scale) == pytest.approx(want, rel=1e-5)
    with torch.no_grad():
        cols = model.decode(model(x)).numpy()
    np.testing.assert_allclose(cols[:40, S0], sd.numpy() * want, rtol=1e-5)


def _old_file(tmp_path, force_sigma_head: bool):
    """A ContactNet file as written before the force σ: no ``force_sigma`` in its config."""
    torch.manual_seed(1)
    cfg = ContactNetConfig(n_pairs=28, window=2, hidden=16, channels=8,
                           force_sigma=force_sigma_head)
    path = save_checkpoint(tmp_path / "model.pt", ContactNet(cfg),
                           extra={"faces": ["front", "back"]})
    payload = torch.load(path, weights_only=True)
    payload["config"].pop("force_sigma")
    torch.save(payload, path)
    return path


def test_an_old_contactnet_file_loads_and_answers_without_a_force_sigma(tmp_path):
    path = _old_file(tmp_path, force_sigma_head=False)
    model, config, _ = load_checkpoint(path, kind="contact_net")
    assert config.force_sigma is False and model.force_var_head is None
    x = torch.randn(3, 2, 28)
    cols = model.decode(model(x)).detach().numpy()
    assert cols.shape == (3, NCOL) and (cols[:, S0] == 0).all()  # 0: no σ
    assert np.isfinite(cols[:, F0]).all()
    reading = ContactPredictor.from_run(path).read(np.asarray(x[0]))
    for finger in reading.fingers:
        assert finger.force_sigma_n is None and np.isfinite(finger.force_n)
    # a new file answers with its σ, everywhere a force is returned
    new = save_checkpoint(tmp_path / "new.pt", ContactNet(ContactNetConfig(
        n_pairs=28, window=2, hidden=16, channels=8, force_sigma=True)))
    p = ContactPredictor.from_run(new)
    row = p.predict(np.asarray(x[0]))
    assert np.isfinite(row[S0]) and row[S0] > 0
    two = ContactPredictor.from_run(new).read(np.asarray(x[1]))
    assert all(f.force_sigma_n is not None and f.force_sigma_n > 0 for f in two.fingers)
    assert all("force_sigma_n" in f for f in two.to_dict()["fingers"])


def test_a_file_whose_config_claims_a_force_head_it_lacks_is_refused(tmp_path):
    path = save_checkpoint(tmp_path / "model.pt", ContactNet(ContactNetConfig(
        n_pairs=28, window=2, hidden=16, channels=8, force_sigma=True)))
    payload = torch.load(path, weights_only=True)
    for k in [k for k in payload["state_dict"] if k.startswith("force_var_head")]:
        del payload["state_dict"][k]
    torch.save(payload, path)
    with pytest.raises(EctskinError, match="force_var_head.weight"):
        load_checkpoint(path, kind="contact_net")
    with pytest.raises(EctskinError, match="force_sigma must be true or false"):
        ContactNetConfig(force_sigma="yes")


# ----------------------------------------------------------------------------- classical
def _press_data(n_trials: int, per: int, seed: int, p: int = 6):
    """Frames x (n, 1, p); one finger in contact everywhere; force = 1 + x₀ + σ(x) ε with
    σ = 0.1 + 0.1 (x₀ + 1), linear in the frame (as the σ model is)."""
    rng = np.random.default_rng(seed)
    n = n_trials * per
    x = rng.uniform(-1, 1, (n, 1, p))
    sigma = 0.1 + 0.1 * (x[:, 0, 0] + 1)
    force = 1.0 + x[:, 0, 0] + sigma * rng.standard_normal(n)
    data = SimpleNamespace(
        x=x.astype(np.float32),
        n_samples=n,
        count=np.ones(n, np.int64),
        hover=np.zeros(n, np.float32),
        face=np.tile([0, -1], (n, 1)),
        uv=np.zeros((n, 2, 2), np.float32),
        force=np.c_[force, np.zeros(n)].astype(np.float32),
        group=np.repeat(np.arange(n_trials), per),
        faces=["front", "back"],
        face_extent={"front": ((-20.0, 20.0), (0.0, 110.0)), "back": ((-20.0, 20.0), (0.0, 110.0))},
        pair_names=[f"p{i}" for i in range(p)],
    )
    return data, sigma


def test_ridge_force_sigma_comes_from_out_of_fold_errors():
    train, _ = _press_data(30, 100, seed=0)
    test, sigma = _press_data(10, 2000, seed=1)
    model, _, _ = fit_contact_classical("ridge", train, seed=0)
    assert model.parts["force_sigma"]["folds"] == 3
    cols = model.predict(test.x)
    got = cols[:, S0]
    # the σ model is linear in the frame, as the true σ: it finds it (within 15 %)
    np.testing.assert_allclose(np.median(got / sigma), 1.0, atol=0.1)
    assert np.quantile(np.abs(got / sigma - 1), 0.9) < 0.15
    cov = force_coverage(test.force[:, 0], cols[:, F0], got)
    assert cov["force_coverage_1sigma"] == pytest.approx(0.6827, abs=0.03)
    assert cov["force_coverage_2sigma"] == pytest.approx(0.9545, abs=0.02)


def test_knn_sigma_is_out_of_fold_not_in_sample():
    """k-NN's in-sample errors shrink to its neighbours' spread; held-out trials see the true
    error, so its σ covers the test frames."""
    train, _ = _press_data(30, 100, seed=0)
    test, _ = _press_data(10, 500, seed=1)
    model, _, _ = fit_contact_classical("knn", train, seed=0)
    cols = model.predict(test.x)
    cov = force_coverage(test.force[:, 0], cols[:, F0], cols[:, S0])
    assert cov["force_coverage_1sigma"] == pytest.approx(0.68, abs=0.05)


def test_a_model_skops_without_force_sigma_loads_and_answers_without_one(tmp_path):
    train, _ = _press_data(6, 50, seed=0)
    model, _, _ = fit_contact_classical("ridge", train, seed=0)
    del model.parts["force_sigma"]  # as a file written before the part existed
    save_contact_classical(tmp_path / "model.skops", model)
    old = load_contact_classical(tmp_path / "model.skops")
    cols = old.predict(train.x[:5])
    assert np.isnan(cols[:, S0]).all() and np.isfinite(cols[:, F0]).all()
    reading = ContactPredictor.from_run(tmp_path / "model.skops").read(train.x[0])
    assert reading.fingers[0].force_sigma_n is None
    model.parts["force_sigma"] = {"mean": [0.0], "coef": "x"}
    save_contact_classical(tmp_path / "bad.skops", model)
    with pytest.raises(EctskinError, match="force_sigma"):
        load_contact_classical(tmp_path / "bad.skops")


def test_the_gaussian_process_gives_its_own_force_sigma():
    """The GP's predictive σ of the force column (N): of the order of the force noise (u is in
    mm, 30 times larger: the wrong column would show), and larger far from the training
    frames. (Its kernel and noise level are shared by u, v and force, so it need not be
    calibrated per output.)"""
    train, _ = _press_data(6, 40, seed=0)
    train.uv[:, 0, 0] = 30.0 * train.x[:, 0, 1]
    test, sigma = _press_data(2, 200, seed=1)
    model, _, _ = fit_contact_classical("gp", train, seed=0)
    assert model.parts["force_sigma"] is None  # its own predictive σ instead
    got = model.predict(test.x)[:, S0]
    assert np.all(np.isfinite(got)) and np.all(got > 0)
    assert 0.02 < np.median(got) < 0.5 and np.median(got) < 3 * sigma.max()
    far = model.predict(np.full((1, 1, 6), 4.0))[0, S0]
    assert far > 2 * np.median(got)


def test_the_force_sigma_survives_the_onnx_runtime(tmp_path):
    torch.manual_seed(2)
    path = save_checkpoint(tmp_path / "model.pt", ContactNet(ContactNetConfig(
        n_pairs=28, window=2, hidden=16, channels=8, force_sigma=True)))
    window = np.random.default_rng(0).normal(0, 0.1, (2, 28)).astype(np.float32)
    want = ContactPredictor.from_run(path).predict(window)
    got = ContactPredictor.from_run(path).use_runtime("onnx").predict(window)
    assert want[S0] > 0
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)
