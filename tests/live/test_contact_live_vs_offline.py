"""The live contact head gives what the offline path gives: a recording replayed through the
engine with a trained ContactNet, frame by frame, against the contact data set's windows and
``ContactPredictor.read`` called on them directly.

The offline windows are calibrated by Eq. 2 against ``touch_reference`` (the rest trial's mean)
and padded per trial with the trial's first frame; live, the reference is the mean of the first
``reference_frames`` frames (exactly the rest trial) and the window runs across trials. So the
two agree bit for bit on every frame whose window lies inside one trial, and on no other.
"""

from __future__ import annotations

import math

import numpy as np

from ectskin.io.recording import Recording, Trial
from ectskin.learn.predict import ContactPredictor
from ectskin.learn.tasks import get_task
from ectskin.learn.train import TrainConfig, train
from ectskin.live import LiveEngine, ReplaySource

WINDOW = 4


def _flat_skin(layout, n_rest=30, n_frames=16, n_trials=8, seed=1) -> Recording:
    """Rest, then one finger per trial on a front or back region: each pair's change is a
    Gaussian bump of the finger's distance to the pair's own spot, times the force."""
    rng = np.random.default_rng(seed)
    p = layout.n_pairs
    base = rng.uniform(0.5, 2.0, p)
    spots = np.column_stack([rng.uniform(-25, 25, p), rng.uniform(0, 120, p)])
    side = rng.choice([-1.0, 1.0], p)  # which face moves each pair more
    none = {"contact": np.zeros(n_rest, bool), "force": np.zeros(n_rest)}
    trials = [
        Trial(
            "rest",
            base + rng.normal(0, 1e-5, (n_rest, p)),
            np.arange(n_rest) / 30,
            np.zeros(n_rest),
            inflation=(0.0, 0.0, 0.0),
            meta={"kind": "no_contact"},
            finger_uv_mm=np.full((n_rest, 2), np.nan),
            finger_height_mm=np.full(n_rest, np.nan),
            **none,
        )
    ]
    regions = list(layout.regions)
    for k in range(n_trials):
        reg = regions[(5 * k) % len(regions)]
        uv = np.array([rng.uniform(*reg.u_mm), rng.uniform(*reg.v_mm)])
        force = np.linspace(0.4, 1.4, n_frames)
        sign = 1.0 if reg.surface == "front" else -1.0
        bump = np.exp(-((spots - uv) ** 2).sum(1) / (2 * 30.0**2)) * (1 + 0.5 * sign * side)
        c = base * (1 - 0.05 * force[:, None] * bump[None, :])
        trials.append(
            Trial(
                f"touch_{k}",
                c + rng.normal(0, 1e-5, c.shape),
                np.arange(n_frames) / 30,
                np.full(n_frames, reg.id),
                inflation=(0.0, 0.0, 0.0),
                region=reg.id,
                meta={"kind": "touch"},
                contact=np.ones(n_frames, bool),
                finger_uv_mm=np.repeat(uv[None], n_frames, 0),
                finger_height_mm=np.zeros(n_frames),
                force=force,
                finger_surface=reg.surface,
            )
        )
    return Recording(layout, trials, 30.0)


def test_live_contact_readings_equal_the_offline_predictor_on_the_same_windows(tmp_path, layout):
    rec = _flat_skin(layout)
    data = get_task("contact").dataset(rec, window=WINDOW)
    train(
        "contact",
        data,
        data,
        tmp_path / "run",
        TrainConfig(
            profile="quick",
            epochs=1,
            progress=False,
            settings={"samples_per_epoch": 128, "val_samples": 64},
            model_options={"hidden": 16, "channels": 8},
        ),
    )
    predictor = ContactPredictor.from_run(tmp_path / "run", layout=layout)
    assert predictor.window == WINDOW and predictor.faces == ["front", "back"]

    n_rest = rec.trials[0].n_frames
    engine = LiveEngine(
        ReplaySource(rec, speed=math.inf),
        contact=predictor,
        reference_frames=n_rest,
        policy="block",
    )
    fed = []
    (head,) = engine.heads
    assert head.key == "contact"
    inputs = head.inputs
    head.inputs = lambda w, c0: fed.append(inputs(w, c0)) or fed[-1]  # what the model got
    outs = []
    engine.run(on_output=outs.append)
    assert [o.seq for o in outs] == list(range(rec.n_frames))
    assert all(o.contact is None for o in outs[: n_rest - 1])
    live = outs[n_rest - 1 :]
    assert len(fed) == len(live)

    # frames whose window lies inside one trial: the data set's window, bit for bit
    inside = (data.frame >= WINDOW - 1)[n_rest - 1 :]
    inside[0] = True  # the rest trial's last frame: its window is the rest trial's too
    assert inside.sum() > 0.6 * len(live)
    offline_x = data.x[n_rest - 1 :]
    for i in np.flatnonzero(inside):
        np.testing.assert_array_equal(fed[i], offline_x[i])
    # ...and the same reading as ContactPredictor.read on it, to the last bit
    counts = set()
    for i in np.flatnonzero(inside):
        want = predictor.read(offline_x[i])
        assert live[i].contact == want, (i, live[i].contact, want)
        assert live[i].to_json_dict()["contact"] == want.to_dict()
        counts.add(want.count)
    assert counts & {1, 2}, "the model never saw a finger: the comparison would be weak"
    # across a trial boundary the live window holds the previous trial's frames (no padding)
    j = int(np.flatnonzero(~inside)[0])
    assert not np.array_equal(fed[j], offline_x[j])
