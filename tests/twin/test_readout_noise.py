"""The readout's noise scale (``ReadoutConfig.noise_scale``): 1 is the electronics as before,
0 a noiseless readout, 3 three times the noise σ; the drift stays."""

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout


def _readout_before_noise_scale(c_true, t, rng, config, drift_phase):
    """The readout as it was written before ``noise_scale`` existed (the reference of the
    default's bit-identity)."""
    drift = 1.0 + config.drift_rel * np.sin(
        2 * np.pi * t[:, None] / config.drift_period_s + drift_phase[None, :]
    )
    gain = 1.0 + rng.standard_normal(c_true.shape) * 10.0 ** (-config.gain_snr_db / 20.0)
    quant = config.resolution_pf / np.sqrt(12.0 * config.samples_per_frame)
    c = c_true * drift * gain + rng.standard_normal(c_true.shape) * quant
    step = config.output_step_pf
    return np.round(c / step) * step


@pytest.fixture()
def inputs():
    rng = np.random.default_rng(7)
    c = rng.uniform(0.03, 2.0, 28)  # pF: the twin's pairs span about this range
    n = 3000
    t = np.linspace(0.0, 900.0, n)  # half the drift period: the drift varies
    phase = rng.uniform(0, 2 * np.pi, 28)
    return np.repeat(c[None], n, axis=0), t, phase


def test_default_scale_is_bit_identical_to_the_readout_before_it(inputs):
    c, t, phase = inputs
    cfg = ReadoutConfig()
    assert cfg.noise_scale == 1.0
    new = readout(c, t, np.random.default_rng(3), cfg, phase)
    old = _readout_before_noise_scale(c, t, np.random.default_rng(3), cfg, phase)
    assert np.array_equal(new, old)
    # noise_pf at the default: the two noises of the module docstring, by hand
    c0 = c[0]
    hand = np.hypot(c0 * 10 ** (-66.0 / 20), 0.001 / np.sqrt(12 * 256))
    np.testing.assert_allclose(noise_pf(c0, cfg), hand, rtol=1e-12)


def test_scale_zero_is_the_drifting_true_capacitance(inputs):
    c, t, phase = inputs
    cfg = ReadoutConfig(noise_scale=0.0)
    out = readout(c, t, np.random.default_rng(3), cfg, phase)
    drift = 1.0 + cfg.drift_rel * np.sin(2 * np.pi * t[:, None] / cfg.drift_period_s + phase)
    np.testing.assert_allclose(out, c * drift, rtol=1e-15, atol=0)
    assert np.all(noise_pf(c[0], cfg) == 0.0)
    # the drift is kept: over half a period every pair moves by about its amplitude
    assert np.all(np.ptp(out / c, axis=0) > 0.5 * cfg.drift_rel)


def test_scale_three_triples_the_noise_sigma(inputs):
    c, t, _ = inputs
    t, phase = np.zeros_like(t), np.zeros(c.shape[1])  # no drift: the noise alone
    for scale in (1.0, 3.0):
        cfg = ReadoutConfig(noise_scale=scale)
        out = readout(c, t, np.random.default_rng(11), cfg, phase)
        # (3000 frames: the sample σ is within ~6 % of the true one at 4 standard errors)
        np.testing.assert_allclose(out.std(axis=0), noise_pf(c[0], cfg), rtol=0.08)
    np.testing.assert_allclose(
        noise_pf(c[0], ReadoutConfig(noise_scale=3.0)), 3 * noise_pf(c[0], ReadoutConfig()),
        rtol=1e-12,
    )
    # the same draws at every scale: x3 is the default's deviation from the truth, times 3
    # (up to the output grid of 0.004 fF)
    one = readout(c, t, np.random.default_rng(5), ReadoutConfig(), phase)
    three = readout(c, t, np.random.default_rng(5), ReadoutConfig(noise_scale=3.0), phase)
    np.testing.assert_allclose(three - c, 3 * (one - c), rtol=0, atol=4 * ReadoutConfig().output_step_pf)


@pytest.mark.parametrize("bad", [-0.5, float("nan"), float("inf"), True, "1"])
def test_a_bad_noise_scale_is_refused(bad):
    with pytest.raises(EctskinError, match="noise_scale"):
        ReadoutConfig(noise_scale=bad)
