"""Fixtures of the learning tests: small synthetic data sets (factories) and the CLI.

* ``blobs(n_groups, per, seed=...)``: TouchData, Gaussian blobs, group g of class g % n_classes.
* ``displacements(n_groups, per, seed=...)``: TrackData following a bending-like law.
* ``states_data(seed, parity, ...)``: TouchData of (inflation state, class) trials, the classes of
  a state chosen by the parity of state + class (0: "seen" in training, 1: "unseen").
* ``small_c2dt``: model options of a C2DT small enough for a CPU test; ``make_c2dt(**config)``
  such a C2DT on the default layout (seeded), ``randomise_head(model)`` gives its zero-initialised
  head weights (so outputs depend on the input); ``make_touch_mlp()`` a seeded, normalised
  TouchMLP in eval mode.
* ``cli(argv)``: ``ectskin ARGV`` through the real entry point with only train and evaluate.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ectskin.layout import default_layout
from ectskin.learn.data import TouchData, TrackData
from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP, TouchMLPConfig

LAYOUT = default_layout()


def _blobs(n_groups: int, per: int, *, seed: int, n_classes: int = 5, noise: float = 0.25):
    """Gaussian blobs: group g is class g % n_classes around a fixed centre (28 channels)."""
    centres = np.random.default_rng(123).normal(0, 0.2, size=(n_classes, 28))
    rng = np.random.default_rng(seed)
    cls = np.arange(n_groups) % n_classes
    x = centres[np.repeat(cls, per)] + noise * 0.2 * rng.standard_normal((n_groups * per, 28))
    return TouchData(
        x=x.astype(np.float32),
        y=np.repeat(cls, per).astype(np.int64),
        group=np.repeat(np.arange(n_groups), per).astype(np.int64),
        group_names=[f"s{seed}-t{g}" for g in range(n_groups)],
        n_classes=n_classes,
        pair_names=list(LAYOUT.pair_names),
    )


def _displacements(n_groups: int, per: int, *, seed: int, k: int = 4) -> TrackData:
    """A bending-like law: the markers (on a line along z, like the paper's) move along y by
    30 mm x (mean of 6 front pairs' last frame) x (z / 120)², a clamped beam's shape; the other
    22 pairs are distractors. The C2DT must find the right pairs among 28 tokens."""
    rng = np.random.default_rng(seed)
    n = n_groups * per
    x = (0.1 * rng.standard_normal((n, k, 28))).astype(np.float32)
    z = np.array([24.0, 48, 72, 96, 120])
    base = np.stack([np.full(5, 25.0), np.zeros(5), z], axis=1)  # (5, 3)
    init = base + rng.normal(0, 1.0, size=(n_groups, 1, 3))  # per-trajectory offset
    init = np.repeat(init, per, axis=0).astype(np.float32)
    bend = x[:, -1, [0, 1, 2, 7, 8, 13]].mean(1)  # (n,)
    y = init.copy()
    y[:, :, 1] += 30 * bend[:, None] * (z / 120) ** 2
    return TrackData(
        x=x,
        init=init,
        y=y.astype(np.float32),
        group=np.repeat(np.arange(n_groups), per).astype(np.int64),
        frame=np.tile(np.arange(per), n_groups).astype(np.int64),
        group_names=[f"s{seed}-t{g}" for g in range(n_groups)],
        electrode_desc=LAYOUT.electrode_descriptors().astype(np.float32),
        pairs=LAYOUT.pairs.astype(np.int64),
        prior=True,
        pair_names=list(LAYOUT.pair_names),
    )


def _states_data(
    seed: int,
    parity: int,
    *,
    n_states: int = 6,
    n_classes: int = 5,
    per: int = 40,
    no_contact: bool = True,
) -> TouchData:
    """Frames = offset[state] + pattern[class] + noise, one trial per (state, class) with
    (state + class) % 2 == ``parity`` (plus, with ``no_contact``, a class-0 trial per state).
    Offsets (std 1) are twice the class patterns (std 0.5), pattern[0] = 0; both fixed, the noise
    (std 0.1) seeded by ``seed``."""
    fixed = np.random.default_rng(1234)
    offsets = fixed.normal(0, 1.0, (n_states, 28))
    patterns = fixed.normal(0, 0.5, (n_classes, 28))
    patterns[0] = 0
    rng = np.random.default_rng(seed)
    trials = [(s, 0) for s in range(n_states)] if no_contact else []
    trials += [
        (s, k) for s in range(n_states) for k in range(1, n_classes) if (s + k) % 2 == parity
    ]
    x = np.concatenate(
        [offsets[s] + patterns[k] + 0.1 * rng.standard_normal((per, 28)) for s, k in trials]
    )
    return TouchData(
        x=x.astype(np.float32),
        y=np.repeat([k for _, k in trials], per).astype(np.int64),
        group=np.repeat(np.arange(len(trials)), per).astype(np.int64),
        group_names=[f"d{seed}-s{s}-k{k}-{g}" for g, (s, k) in enumerate(trials)],
        n_classes=n_classes,
        pair_names=[f"p{i}" for i in range(28)],
        group_region=np.array([k for _, k in trials], dtype=np.int64),
    )


@pytest.fixture(scope="session")
def blobs():
    return _blobs


@pytest.fixture(scope="session")
def displacements():
    return _displacements


@pytest.fixture(scope="session")
def states_data():
    return _states_data


@pytest.fixture(scope="session")
def small_c2dt() -> dict[str, int]:
    return {"d_model": 16, "n_heads": 2, "ff": 32}


def _make_c2dt(**kw) -> C2DT:
    cfg = C2DTConfig(d_model=16, n_heads=2, ff=32, **kw)
    torch.manual_seed(0)
    return C2DT(cfg, LAYOUT.electrode_descriptors(), LAYOUT.pairs)


def _randomise_head(model: C2DT) -> None:
    """The head starts at zero (output = baseline); give it weights so outputs depend on x."""
    with torch.no_grad():
        model.head.weight.normal_(0, 0.5)
        model.head.bias.normal_(0, 0.5)


def _make_touch_mlp() -> TouchMLP:
    torch.manual_seed(0)
    m = TouchMLP(TouchMLPConfig(n_pairs=28, n_classes=19))
    m.set_normalization(np.linspace(0, 1, 28), np.linspace(1, 2, 28))
    return m.eval()


@pytest.fixture(scope="session")
def make_c2dt():
    return _make_c2dt


@pytest.fixture(scope="session")
def randomise_head():
    return _randomise_head


@pytest.fixture(scope="session")
def make_touch_mlp():
    return _make_touch_mlp


@pytest.fixture
def cli(monkeypatch):
    """``ectskin ARGV`` through the real entry point, with only the learning commands (so the
    tests do not depend on other command modules)."""
    import ectskin.cli

    monkeypatch.setattr(ectskin.cli, "COMMANDS", (("train", "train"), ("evaluate", "evaluate")))
    return ectskin.cli.main
