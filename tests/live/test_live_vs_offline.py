"""The live path and the offline path give the same answers: a recording replayed through the
live engine with a trained touch model, frame by frame, against the offline data set and
predictor, so that Eq. 2 and the model inputs cannot drift apart between the two paths.

Both calibrate with paper Eq. 2 against the same reference: the mean readout of the rest-state
trial (uninflated, untouched). Offline that is ``touch_reference(rec)``; live it is the touch
reference captured over the first ``reference_frames`` frames, which here are exactly that
trial's frames.
"""

from __future__ import annotations

import math

import numpy as np

from ectskin.io.calibration import relative_change, touch_reference
from ectskin.learn.data import touch_dataset
from ectskin.learn.predict import TouchPredictor
from ectskin.learn.train import TrainConfig, train
from ectskin.live import LiveEngine, ReplaySource


def test_replay_through_the_engine_matches_offline_prediction_exactly(tmp_path, make_recording):
    n = 30
    rec = make_recording(n_frames=n, markers=False)
    assert rec.trials[0].name == "s0_rest"  # the rest state comes first, as it must live
    data = touch_dataset(rec)  # offline: Eq. 2 against the rest-state mean, float32
    train(
        "touch",
        data,
        data,
        tmp_path / "run",
        TrainConfig(profile="quick", epochs=3, progress=False),
    )
    predictor = TouchPredictor.from_run(tmp_path / "run")

    engine = LiveEngine(
        ReplaySource(rec, speed=math.inf), touch=predictor, reference_frames=n, policy="block"
    )
    outs = []
    engine.run(on_output=outs.append)
    assert [o.seq for o in outs] == list(range(rec.n_frames))
    ref = engine.reference_state()["touch"]
    assert ref["in_use"]["frames"] == [0, n - 1] and ref["in_use"]["warnings"] == []

    # The same reference: Eq. 2 of every live frame equals Eq. 2 against touch_reference()...
    c0 = touch_reference(rec)["s0_rest"]
    raw = np.concatenate([t.capacitance for t in rec.trials])
    live_cal = np.stack([o.calibrated for o in outs[n - 1 :]])
    np.testing.assert_array_equal(live_cal, relative_change(raw[n - 1 :], c0))
    # ...and the model inputs are the offline data set's, bit for bit.
    np.testing.assert_array_equal(live_cal.astype(np.float32), data.x[n - 1 :])

    # Frame by frame the engine's probabilities are the offline predictor's, exactly; before the
    # reference is complete the engine gives none.
    assert all(o.touch_probs is None for o in outs[: n - 1])
    live_probs = np.stack([o.touch_probs for o in outs[n - 1 :]])
    offline_probs = np.stack([predictor.predict(x) for x in data.x[n - 1 :]])
    np.testing.assert_array_equal(live_probs, offline_probs.astype(np.float64))
    np.testing.assert_array_equal(
        [o.touch_cls for o in outs[n - 1 :]], offline_probs.argmax(axis=1)
    )
    # The offline evaluation predicts in batches: the same classes, probabilities to rounding.
    batch = predictor.predict(data.x[n - 1 :])
    np.testing.assert_array_equal(batch.argmax(axis=1), offline_probs.argmax(axis=1))
    np.testing.assert_allclose(batch, offline_probs, rtol=0, atol=1e-6)
