"""Measurement models: the ECT readout electronics and the motion-capture system.

Readout (paper §2, DESIGN.md): 30 fps, 1 fF resolution, SNR above 60 dB, slow baseline drift.
Motion capture: sub-millimetre noise, an unknown constant delay of a few frames between the two
devices per trial (the reason C2DT takes 10 frames), occasional occlusions (NaN).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ReadoutConfig:
    """ECT readout electronics."""

    resolution_pf: float = 0.001  # 1 fF quantisation (paper)
    snr_db: float = 66.0  # > 60 dB (paper): noise std = mean capacitance · 10^(−SNR/20)
    drift_rel: float = 5e-4  # (assumed) amplitude of the slow relative baseline drift
    drift_period_s: float = 1800.0  # (assumed) drift period (thermal), experiment clock


@dataclass(frozen=True)
class MocapConfig:
    """Motion capture of the markers."""

    noise_mm: float = 0.2  # (assumed) sub-millimetre marker noise
    max_delay_frames: int = 3  # per-trial constant delay drawn from 0..max (markers lag)
    occluded_fraction: float = 16 / 162  # (assumed: paper's 146 of 162 touch trials are clean)
    occlusion_events: tuple[int, int] = (1, 3)  # events per occluded trial (min, max)
    occlusion_frames: tuple[int, int] = (5, 30)  # frames per event (min, max)


def readout(
    c_true: np.ndarray,
    t_experiment_s: np.ndarray,
    rng: np.random.Generator,
    config: ReadoutConfig,
    drift_phase: np.ndarray,
) -> np.ndarray:
    """Measured capacitance (n_frames, n_pairs) pF from the true one.

    c = Q( c_true · (1 + a sin(2π t/T + φ_ch)) + n ),  n ~ N(0, (mean_ch · 10^(−SNR/20))²),
    with Q the quantiser to ``resolution_pf`` and t the experiment clock (so the drift is
    continuous across consecutive trials).
    """
    drift = 1.0 + config.drift_rel * np.sin(
        2 * np.pi * t_experiment_s[:, None] / config.drift_period_s + drift_phase[None, :]
    )
    sigma = np.abs(c_true).mean(axis=0) * 10.0 ** (-config.snr_db / 20.0)
    c = c_true * drift + rng.standard_normal(c_true.shape) * sigma[None, :]
    return np.round(c / config.resolution_pf) * config.resolution_pf


def mocap(
    true_markers: np.ndarray,
    rng: np.random.Generator,
    config: MocapConfig,
    delay_frames: int,
    occluded: bool,
) -> np.ndarray:
    """Recorded markers (n_frames, n_markers, 3) mm: delayed, noisy, NaN where occluded.

    The marker stream lags the readout by ``delay_frames``: frame f records the pose of frame
    f − delay (the first frames repeat the first pose).
    """
    n = true_markers.shape[0]
    idx = np.clip(np.arange(n) - delay_frames, 0, n - 1)
    out = true_markers[idx] + rng.normal(0.0, config.noise_mm, true_markers.shape)
    if occluded:
        lo, hi = config.occlusion_events
        for _ in range(int(rng.integers(lo, hi + 1))):
            length = int(rng.integers(config.occlusion_frames[0], config.occlusion_frames[1] + 1))
            start = int(rng.integers(0, max(1, n - length)))
            marker = int(rng.integers(0, true_markers.shape[1]))
            out[start : start + length, marker] = np.nan
    return out
