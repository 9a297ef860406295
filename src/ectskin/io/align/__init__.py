"""Align a capacitance-meter export with a motion-capture take and build a :class:`Recording`.

The readout and the cameras run on separate clocks started together (the paper's "auto-click
script"), which leaves a constant delay of a few frames between them.
:func:`~ectskin.io.align.delay.estimate_delay` finds it from the data: both devices see the same
touch-induced motion, so the marker coordinates are best explained by the readouts (a linear fit,
:func:`~ectskin.io.align.signals.lagged_fit`) when the two are shifted by the delay;
alternatively the motion-energy signals of both (how fast the standardised readouts change, how
fast the markers move) correlate best at that shift.

Convention: ``delay_s > 0`` means the markers lag, i.e. what the readout sees at time t the markers
show at t + delay_s. :func:`~ectskin.io.align.delay.resample_markers` therefore samples the
marker trajectories at ``frame_t + delay_s``.

Modules: :mod:`~ectskin.io.align.signals` (resampling, motion energy, lagged scores),
:mod:`~ectskin.io.align.delay` (the estimate and the resampling), :mod:`~ectskin.io.align.build`
(one trial from two files, or many from a manifest).
"""

from __future__ import annotations

from ectskin.io.align.build import build_recording, build_recording_from_manifest
from ectskin.io.align.delay import (
    MAX_GRID_SAMPLES,
    WEAK_CONTRAST,
    DelayEstimate,
    estimate_delay,
    resample_markers,
)
from ectskin.io.align.signals import (
    capacitance_energy,
    interp_linear,
    lagged_fit,
    marker_speed,
    normalised_xcorr,
    signal_weight,
)

__all__ = [
    "MAX_GRID_SAMPLES",
    "WEAK_CONTRAST",
    "DelayEstimate",
    "build_recording",
    "build_recording_from_manifest",
    "capacitance_energy",
    "estimate_delay",
    "interp_linear",
    "lagged_fit",
    "marker_speed",
    "normalised_xcorr",
    "resample_markers",
    "signal_weight",
]
