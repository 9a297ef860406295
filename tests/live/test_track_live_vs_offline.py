"""The live tracking head gives what the offline path gives: a tracking trial replayed through the
engine with a trained C2DT, frame by frame, against the tracking data set's windows and
``TrackPredictor.predict`` called on them directly.

Offline (``track_dataset``, prior knowledge, the paper's §4.2) a trajectory is calibrated by Eq. 2
against its own first frame, ``init`` holds that frame's markers and the first k−1 windows are
padded with the first frame. Live, the tracking reference is the mean of the first
``reference_frames`` frames: with one frame, the trajectory's first frame exactly; before the
stream has k frames the engine repeats the first one. So every frame agrees to the last bit.
"""

from __future__ import annotations

import math

import numpy as np

from ectskin.io.recording import Recording
from ectskin.learn.data import track_dataset
from ectskin.learn.predict import TrackPredictor
from ectskin.learn.train import TrainConfig, train
from ectskin.live import LiveEngine, ReplaySource

WINDOW = 4


def test_live_tracking_equals_the_offline_predictor_on_the_same_windows(tmp_path, make_recording):
    rec = make_recording(n_frames=24)
    data = track_dataset(rec, window=WINDOW)
    train(
        "track",
        data,
        data,
        tmp_path / "run",
        TrainConfig(
            profile="quick",
            epochs=1,
            batch_size=32,
            progress=False,
            settings={"samples_per_epoch": None, "val_samples": None},
            model_options={"d_model": 16, "n_heads": 2, "ff": 32},
        ),
    )
    predictor = TrackPredictor.from_run(tmp_path / "run")
    assert predictor.window == WINDOW and predictor.prior

    trial = rec.trial("s0_r7")
    one = Recording(rec.layout, [trial], rec.frame_rate_hz)
    offline = track_dataset(one, window=WINDOW)
    assert offline.n_samples == trial.n_frames  # padded: one window per frame

    engine = LiveEngine(
        ReplaySource(one, speed=math.inf), track=predictor, reference_frames=1, policy="block"
    )
    engine.capture_reference("track")  # the trajectory's start; no touch reference (it is touched)
    outs = []
    engine.run(on_output=outs.append)
    assert [o.seq for o in outs] == list(range(trial.n_frames))
    assert engine.reference_state()["tracking"]["in_use"]["frames"] == [0, 0]

    want = np.stack([predictor.predict(x, i) for x, i in zip(offline.x, offline.init)])
    live = np.stack([o.markers_pred for o in outs])
    np.testing.assert_array_equal(live, want.astype(np.float64))
    for o in outs:
        np.testing.assert_array_equal(o.markers_reference, trial.markers[0])
    # the model moved the markers: equal outputs are not the initial coordinates passed through
    assert np.abs(live - trial.markers[0]).max() > 1e-3
    assert all(o.touch_probs is None and o.calibrated is None for o in outs)
