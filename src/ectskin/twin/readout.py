"""Measurement models: the ECT readout electronics and the motion-capture system.

Readout (paper §3: "1 fF capacitance measurement resolution and over 60 dB signal to noise ratio
for all measurement channels", 30 fps). Both statements hold at once, on every pair, because the
electronics convert far faster than the 30 frames per second they report: each output frame is
the average of ``samples_per_frame`` conversions.

* A conversion resolves ``resolution_pf`` (1 fF, the paper's figure). Its analog noise dithers
  the converter, so the quantisation error of a conversion is uniform with variance q²/12 and
  independent from conversion to conversion; the average of N conversions has quantisation
  noise q/√(12 N) and is a multiple of q/N. With N = 256 (assumed: ECT electronics run at
  hundreds to thousands of frames per second, and a 30-fps output leaves room to average that
  many conversions per channel) that is 0.018 fF of noise on a 0.004 fF grid: no staircase.
* The excitation and the gain of the charge amplifier fluctuate from frame to frame, a noise
  proportional to the capacitance: relative size 10^(−``gain_snr_db``/20) (assumed 66 dB).
* A slow relative drift (thermal) of the baseline, ``drift_rel`` over ``drift_period_s``.
* ``noise_scale`` (default 1) multiplies the σ of both random noises, the gain noise and the
  averaged quantisation noise (:func:`noise_pf` and :func:`readout` alike): 3 is a readout with
  three times the noise (SNR 9.5 dB lower), 0 a noiseless one, whose output is the drifting true
  capacitance, not rounded to the output grid either (there is no conversion noise to average).
  The drift is unchanged. The random numbers are drawn at every scale, so a trial's other draws
  (the markers' noise) stay the same. A study knob (``ectskin study reading``), not a property
  of the paper's electronics.

The SNR of a pair is 20 log10(C / σ) with σ² the sum of both noises; for the twin's smallest
pairs (~30 fF) it is about 62 dB, above the paper's 60 dB, and it rises with the capacitance.
:func:`noise_pf` gives σ per pair; ``ectskin characterize`` reports it with the SNR.

Motion capture: sub-millimetre noise, an unknown constant delay of a few frames between the two
devices per trial (the reason C2DT takes 10 frames), occasional occlusions (NaN).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError


@dataclass(frozen=True)
class ReadoutConfig:
    """ECT readout electronics."""

    resolution_pf: float = 0.001  # one conversion resolves 1 fF (paper)
    samples_per_frame: int = 256  # (assumed) conversions averaged into one 30-fps frame
    gain_snr_db: float = 66.0  # (assumed) frame-to-frame gain noise: σ = C · 10^(−this/20)
    drift_rel: float = 5e-4  # (assumed) amplitude of the slow relative baseline drift
    drift_period_s: float = 1800.0  # (assumed) drift period (thermal), experiment clock
    noise_scale: float = 1.0  # multiplies the σ of the gain and quantisation noise; 0: noiseless

    def __post_init__(self) -> None:
        for name in ("resolution_pf", "gain_snr_db", "drift_period_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise EctskinError(f"readout: {name} must be a finite number > 0, got {v!r}")
        if not (isinstance(self.samples_per_frame, int) and self.samples_per_frame >= 1):
            raise EctskinError(
                f"readout: samples_per_frame must be an integer >= 1, got {self.samples_per_frame!r}"
            )
        if not (np.isfinite(self.drift_rel) and 0 <= self.drift_rel < 0.1):
            raise EctskinError(f"readout: drift_rel must be in [0, 0.1), got {self.drift_rel!r}")
        v = self.noise_scale
        if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v >= 0):
            raise EctskinError(
                f"readout: noise_scale must be a finite number >= 0 (1: the electronics' noise, "
                f"0: none), got {v!r}"
            )

    @property
    def output_step_pf(self) -> float:
        """The grid of an output frame: the average of N conversions is a multiple of q/N."""
        return self.resolution_pf / self.samples_per_frame


def noise_pf(c_pf: np.ndarray, config: ReadoutConfig) -> np.ndarray:
    """Standard deviation (pF) of one output frame's noise at capacitance ``c_pf`` (both noises
    times ``config.noise_scale``)."""
    gain = np.abs(c_pf) * 10.0 ** (-config.gain_snr_db / 20.0) * config.noise_scale
    quant = config.resolution_pf / np.sqrt(12.0 * config.samples_per_frame) * config.noise_scale
    return np.sqrt(gain**2 + quant**2)


def snr_db(c_pf: np.ndarray, config: ReadoutConfig) -> np.ndarray:
    """20 log10(C / σ) of each channel."""
    return 20.0 * np.log10(np.abs(c_pf) / noise_pf(c_pf, config))


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

    c = Q_{q/N}( c_true · (1 + a sin(2π t/T + φ_ch)) · (1 + g) + e ), with g the gain noise,
    e ~ N(0, q²/(12N)) the averaged quantisation noise of N dithered conversions and Q_{q/N} the
    grid of their average; t is the experiment clock (so the drift is continuous across
    consecutive trials). ``config.noise_scale`` s multiplies both noises' σ; at s = 0 the output
    is c_true · (1 + a sin(...)), unrounded (the same random numbers are drawn at every s).
    """
    drift = 1.0 + config.drift_rel * np.sin(
        2 * np.pi * t_experiment_s[:, None] / config.drift_period_s + drift_phase[None, :]
    )
    s = config.noise_scale
    gain = 1.0 + rng.standard_normal(c_true.shape) * 10.0 ** (-config.gain_snr_db / 20.0) * s
    quant = config.resolution_pf / np.sqrt(12.0 * config.samples_per_frame) * s
    c = c_true * drift * gain + rng.standard_normal(c_true.shape) * quant
    if s == 0:
        return c
    step = config.output_step_pf
    return np.round(c / step) * step


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
