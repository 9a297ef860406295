"""The protocol's checks at the door (ectskin.twin.protocol): counts, seeds and the size bound of
one simulated experiment, all before anything is planned or simulated."""

from __future__ import annotations

import time

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.twin.protocol import (
    MAX_RECORDING_BYTES,
    MAX_TRIALS,
    Protocol,
    check_recording_size,
    plan_trials,
    recording_nbytes,
)


def test_the_papers_protocol_is_well_inside_the_bounds(layout):
    p = Protocol()
    assert (p.n_states, p.n_trials, p.n_frames) == (27, 189, 900)
    assert recording_nbytes(p, layout) == 189 * 900 * (28 + 3 * layout.n_markers + 5) * 8
    check_recording_size(p, layout)
    assert p.n_trials < MAX_TRIALS / 100 and recording_nbytes(p, layout) < MAX_RECORDING_BYTES / 50


def test_a_huge_experiment_is_refused_before_it_is_planned(layout):
    """Defect 2: 10^8 touch trials were planned one by one (minutes, gigabytes, no output)
    before anything was simulated. Now counted, not listed, and refused with its size. Catches
    removing the bound from plan_trials, and counting trials by listing the states."""
    p = Protocol(levels_ml=(0.0,), touch_trials=100_000_000, duration_s=1.0)
    t0 = time.perf_counter()
    with pytest.raises(EctskinError) as exc:
        plan_trials(p, layout)
    assert time.perf_counter() - t0 < 1.0
    msg = str(exc.value)
    assert "100000001 trials (1 inflation state(s) x 100000001) x 30 frames = 3000000030 frames" in msg
    assert f"(28 pairs + 3 x {layout.n_markers} marker coordinates + 5 per-frame values)" in msg
    assert "at most 100000 trials and 4.0 GiB" in msg
    # 1000 levels on 3 chambers: 10^9 states, counted at once
    many = Protocol(levels_ml=tuple(float(v) for v in np.linspace(0, 20, 1000)), touch_trials=0)
    assert many.n_states == 10**9
    t0 = time.perf_counter()
    with pytest.raises(EctskinError, match="1000000000 trials"):
        check_recording_size(many, layout)
    assert time.perf_counter() - t0 < 1.0


def test_the_bound_is_on_bytes_as_well_as_trials(layout):
    few_long = Protocol(levels_ml=(0.0,), touch_trials=1, duration_s=90_000.0, frame_rate_hz=100.0)
    with pytest.raises(EctskinError, match=r"2 trials .* x 9000000 frames = 18000000 frames"):
        check_recording_size(few_long, layout)
    check_recording_size(Protocol(levels_ml=(0.0,), touch_trials=MAX_TRIALS - 1, duration_s=0.1,
                                  touch_dwells=1),
                         layout)


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"seed": -1}, "protocol: seed must be an integer from 0 to 4294967295, got -1"),
        ({"seed": 2**32}, "seed must be an integer from 0"),
        ({"seed": 1.5}, "seed must be an integer from 0"),
        ({"touch_trials": -1}, "touch_trials must be a whole number from 0 or more, got -1"),
        ({"touch_trials": 2.5}, "touch_trials must be a whole number"),
        ({"touch_dwells": 0}, "touch_dwells must be a whole number from 1 to the frames"),
        ({"touch_dwells": 31, "duration_s": 1.0}, r"frames of a trial \(30\), got 31"),
        ({"duration_s": 0.01}, "holds 0.3 frames; it needs at least one"),
        ({"levels_ml": (0.0, float("nan"))}, "levels_ml must be finite volumes"),
        ({"levels_ml": (0.0, 10.0, 0.0)}, "levels_ml must be distinct inflation levels"),
        ({"n_chambers": 0}, "n_chambers must be a whole number from 1 or more"),
    ],
)
def test_bad_counts_and_seeds_are_refused_naming_the_field(kw, message):
    """Defect 1 and 7: a negative seed reached numpy's generator in plan_trials (a traceback),
    and duplicate levels, more dwells than frames or a trial of no frame were accepted."""
    with pytest.raises(EctskinError, match=message):
        Protocol(**kw)


def test_numpy_integers_are_whole_numbers():
    p = Protocol(levels_ml=(0.0,), touch_trials=np.int64(2), touch_dwells=np.int32(2), seed=3)
    assert p.n_trials == 3
