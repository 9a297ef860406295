"""Live engine: reference capture, Eq. 2 calibration, the C2DT window, initial markers, the
skip-to-newest / block policies with drop accounting, recording every frame, robustness to bad
input and to failing callbacks, the JSON messages, and real predictors loaded from run dirs."""

from __future__ import annotations

import json
import math
import threading
import time

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io.hdf5 import read_recording
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.live.engine import LiveEngine, Output
from ectskin.live.recorder import Recorder
from ectskin.live.sources import Frame, ReplaySource, SerialSource

LAYOUT = default_layout()
P, M, C = LAYOUT.n_pairs, LAYOUT.n_markers, LAYOUT.n_classes


class FakeTouch:
    """TouchPredictor protocol; remembers its inputs; class = round(10 * mean input) mod C."""

    n_pairs, n_classes = P, C

    def __init__(self, delay_s=0.0):
        self.inputs = []
        self.delay_s = delay_s

    def predict(self, x):
        self.inputs.append(np.array(x))
        if self.delay_s:
            time.sleep(self.delay_s)
        p = np.full(C, 0.01)
        p[int(round(10 * float(np.mean(x)))) % C] = 1.0
        return p / p.sum()


class FakeTrack:
    """TrackPredictor protocol; remembers (window, init); predicts init + mean(window)."""

    n_pairs, n_markers = P, M

    def __init__(self, window=4):
        self.window = window
        self.calls = []

    def predict(self, w, init):
        self.calls.append((np.array(w), np.array(init)))
        return init + float(np.mean(w))


def _rec(cap, markers=None, labels=None) -> Recording:
    n = cap.shape[0]
    return Recording(
        LAYOUT,
        [
            Trial(
                "t",
                cap,
                np.arange(n) / 30.0,
                np.zeros(n) if labels is None else labels,
                markers=markers,
            )
        ],
        30.0,
    )


def _run(cap, markers=None, **kw):
    touch = kw.pop("touch", FakeTouch())
    track = kw.pop("track", None)
    src = ReplaySource(_rec(cap, markers), speed=kw.pop("speed", math.inf))
    eng = LiveEngine(src, touch=touch, track=track, policy=kw.pop("policy", "block"), **kw)
    outs: list[Output] = []
    stats = eng.run(on_output=outs.append)
    return eng, outs, stats, touch, track


# ------------------------------------------------------------------ reference + Eq. 2
def test_reference_is_mean_of_first_frames_and_eq2_calibration():
    rng = np.random.default_rng(1)
    base = 10 + rng.random(P)
    ref_frames = base * (1 + 0.01 * rng.standard_normal((4, P)))
    later = np.stack([base * 1.25, base * 0.9])
    cap = np.concatenate([ref_frames, later])
    cap[1, 5] = np.nan  # a masked reading inside the reference: NaN-aware mean
    _, outs, stats, touch, _ = _run(cap, reference_frames=4)
    c0 = np.nanmean(ref_frames.copy(), axis=0)
    c0[5] = np.mean(ref_frames[[0, 2, 3], 5])
    # hand-computed Eq. 2 for the frames after the reference
    for out, frame in zip(outs[4:], later):
        np.testing.assert_allclose(out.calibrated, (frame - c0) / c0, rtol=1e-12)
    # reference frames themselves are output too: raw only before the reference completes
    assert all(o.calibrated is None and o.touch_probs is None for o in outs[:3])
    assert outs[3].calibrated is not None  # the 4th frame completes the reference
    assert stats["processed"] == 6 and stats["reference_ready"]
    np.testing.assert_allclose(touch.inputs[-2], (later[0] - c0) / c0, rtol=1e-6)
    assert outs[-2].touch_cls == int(round(10 * np.mean((later[0] - c0) / c0))) % C


def test_masked_reference_channel_is_nan_and_fed_as_zero():
    cap = np.full((6, P), 20.0)
    cap[:3, 7] = np.nan  # channel 7 never seen during the reference
    cap[3:, :] = 22.0
    _, outs, _, touch, _ = _run(cap, reference_frames=3)
    assert np.isnan(outs[-1].calibrated[7])
    np.testing.assert_allclose(np.delete(outs[-1].calibrated, 7), 0.1)
    assert touch.inputs[-1][7] == 0.0 and np.isfinite(touch.inputs[-1]).all()
    msg = outs[-1].to_json_dict()
    assert msg["calibrated"][7] is None
    json.dumps(msg, allow_nan=False)  # strict JSON: no NaN literals


# ------------------------------------------------------------------ tracking
def test_track_window_oldest_first_and_initial_markers_from_reference():
    n = 12
    cap = np.full((n, P), 10.0) * (1 + 0.01 * np.arange(n))[:, None]  # frame i: 10 * (1 + i/100)
    markers = np.zeros((n, M, 3))
    markers[:, :, 2] = np.arange(n)[:, None]  # z = frame index
    markers[1, 0, 2] = np.nan  # occluded once during the reference
    track = FakeTrack(window=4)
    _, outs, _, _, _ = _run(cap, markers, track=track, reference_frames=3)
    c0 = cap[:3].mean(0)
    w, init = track.calls[-1]  # the last frame, index 11: window = frames 8..11
    np.testing.assert_allclose(w, (cap[8:12] - c0) / c0, rtol=1e-6)
    expect_init = np.zeros((M, 3))
    expect_init[:, 2] = 1.0  # mean z over frames 0..2
    expect_init[0, 2] = 1.0  # marker 0: mean of frames 0 and 2 only = 1.0
    np.testing.assert_allclose(init, expect_init)
    # the window on the frame that completes the reference (index 2) is padded with frame 0
    w2, _ = track.calls[0]
    np.testing.assert_allclose(w2, (cap[[0, 0, 1, 2]] - c0) / c0, rtol=1e-6)
    last = outs[-1].to_json_dict()["markers"]
    assert np.allclose(last["pred"], np.asarray(last["reference"]) + np.mean(w))
    assert last["true"][0][2] == 11.0


def test_reference_markers_argument_when_source_has_none():
    cap = np.full((5, P), 10.0)
    rest = np.arange(3 * M, dtype=float).reshape(M, 3)
    track = FakeTrack(window=2)
    _run(cap, None, track=track, reference_frames=2, reference_markers=rest)
    np.testing.assert_array_equal(track.calls[-1][1], rest)
    with pytest.raises(EctskinError, match="tracking needs initial marker coordinates"):
        LiveEngine(ReplaySource(_rec(cap)), track=FakeTrack())
    with pytest.raises(EctskinError, match=r"reference_markers must have shape \(5, 3\)"):
        LiveEngine(ReplaySource(_rec(cap)), track=FakeTrack(), reference_markers=np.zeros((4, 3)))


def test_capture_reference_on_command_touch_only():
    n = 40
    cap = np.full((n, P), 10.0)
    cap[20:] = 12.0  # the state changes at frame 20
    markers = np.zeros((n, M, 3))
    markers[20:] = 5.0
    src = ReplaySource(_rec(cap, markers), speed=math.inf)
    track = FakeTrack(window=2)
    eng = LiveEngine(
        src, touch=FakeTouch(), track=track, reference_frames=5, policy="block", queue_size=1
    )
    outs = []

    def on_output(o):
        outs.append(o)
        if o.seq == 24:
            eng.capture_reference("touch")

    eng.run(on_output=on_output)
    assert outs[24].calibrated[0] == pytest.approx(0.2)
    # the command takes effect from the next frames; queue_size=1 keeps at most 2 frames ahead
    recaptured = [
        o.seq for o in outs if o.calibrated is not None and o.calibrated[0] == 0.0 and o.seq > 24
    ]
    assert recaptured and recaptured[0] <= 32 and outs[-1].calibrated[0] == 0.0
    # tracking kept its first reference (10 pF, markers 0) and init
    w, init = track.calls[-1]
    np.testing.assert_allclose(w, 0.2, rtol=1e-6)
    assert np.all(init == 0.0)
    with pytest.raises(EctskinError, match="Invalid value for 'which'"):
        eng.capture_reference("everything")


# ------------------------------------------------------------------ reference at rest
def test_touch_reference_refuses_a_window_with_contact_and_captures_again(caplog):
    """The newcomer's trap: a replay that starts with a touch. The touch reference must not be
    taken from the touched frames; it is taken from the first window at rest."""
    n = 30
    cap = np.full((n, P), 10.0)
    cap[:12] = 11.0  # touched for the first 12 frames
    labels = np.zeros(n)
    labels[:12] = 10
    src = ReplaySource(_rec(cap, labels=labels), speed=math.inf)
    eng = LiveEngine(src, touch=FakeTouch(), reference_frames=5, policy="block")
    outs: list[Output] = []
    with caplog.at_level("WARNING"):
        eng.run(on_output=outs.append)
    ref = eng.reference_state()["touch"]
    # windows 0..4, 5..9 and 10..14 hold touched frames: refused; 15..19 is the first at rest
    assert ref["refusals"] == 3 and ref["state"] == "ready"
    assert ref["in_use"]["frames"] == [15, 19] and ref["in_use"]["warnings"] == []
    assert [o.calibrated is None for o in outs[:19]] == [True] * 19
    assert outs[19].calibrated is not None and np.all(outs[-1].calibrated == 0.0)
    refused = [r.getMessage() for r in caplog.records if "reference refused" in r.getMessage()]
    assert "touch reference refused (frames 0..4): 5 frame(s) with contact (label 10" in refused[0]
    assert "must be untouched and uninflated" in refused[0]
    # the tracking reference does not refuse (its state may be anything), it warns
    assert eng.reference_state()["tracking"]["refusals"] == 0


def test_touch_reference_refuses_an_inflated_window():
    cap = np.full((20, P), 10.0)
    rec = Recording(
        LAYOUT,
        [
            Trial("inflated", cap[:10] + 1, np.arange(10) / 30, np.zeros(10), inflation=(20, 0, 0)),
            Trial("rest", cap[10:], np.arange(10) / 30, np.zeros(10), inflation=(0, 0, 0)),
        ],
        30.0,
    )
    eng = LiveEngine(ReplaySource(rec, speed=math.inf), reference_frames=5, policy="block")
    eng.run()
    state = eng.reference_state()
    assert state["touch"]["refusals"] == 2 and state["touch"]["in_use"]["frames"] == [10, 14]
    assert state["tracking"]["in_use"]["frames"] == [0, 4]  # the start of the trajectory


def _unlabelled(cap, markers=None):
    """A custom source whose frames carry no label and no inflation (a live device)."""
    return _ListSource(
        [
            Frame(i, i / 30, cap[i], markers=None if markers is None else markers[i])
            for i in range(len(cap))
        ]
    )


def test_reference_warns_on_drift_far_above_the_noise_but_not_on_noise(caplog):
    rng = np.random.default_rng(3)
    noisy = 10 + 0.05 * rng.standard_normal((40, P))  # large white noise: no warning
    eng = LiveEngine(_unlabelled(noisy), reference_frames=30, policy="block")
    eng.run()
    assert eng.reference_state()["touch"]["in_use"]["warnings"] == []
    # a touch that begins half-way through the capture: +0.5 % on 3 channels, noise 0.001 %
    cap = 10 + 1e-4 * rng.standard_normal((40, P))
    cap[15:, [2, 7, 20]] *= 1.005
    eng = LiveEngine(_unlabelled(cap), reference_frames=30, policy="block")
    with caplog.at_level("WARNING"):
        eng.run()
    ref = eng.reference_state()["touch"]
    assert ref["state"] == "ready" and ref["refusals"] == 0  # accepted (labels unknown), but:
    (warning,) = ref["in_use"]["warnings"]
    assert "3 channel(s) changed during the capture far beyond their noise" in warning
    assert LAYOUT.pair_names[7] in warning
    assert any("Re-capture it with the skin untouched" in r.getMessage() for r in caplog.records)


def test_reference_warns_when_the_markers_move():
    cap = np.full((30, P), 10.0)
    markers = np.zeros((30, M, 3))
    markers[:, 4, 1] = np.linspace(0, 6, 30)  # the tip slides 6 mm during the capture
    eng = LiveEngine(_unlabelled(cap, markers), reference_frames=30, policy="block")
    eng.run()
    (warning,) = eng.reference_state()["tracking"]["in_use"]["warnings"]
    assert warning.startswith("markers moved 3.") and "more than 1 mm" in warning


def test_sim_starts_at_rest_so_the_reference_is_taken_there():
    """The default sim scenario rests (untouched, uninflated) long enough for the default
    reference (30 frames), so the engine captures it at once, without a refusal."""
    from itertools import islice

    from ectskin.live.sources import TwinSource, demo_scenario

    steps = list(islice(demo_scenario(LAYOUT, seed=0), 3))
    assert steps[0].region is None and steps[0].inflation_ml == (0.0, 0.0, 0.0)
    assert steps[0].duration_s * 30 >= 30 and steps[1].region == 10  # a touch follows

    class Twin:  # the LiveTwin protocol; labels = the touched region
        layout, frame_rate_hz = LAYOUT, 30.0
        region = None

        def set_inflation(self, p):
            pass

        def set_touch(self, region, force_n=1.0):
            self.region = region

        def next_frame(self):
            r = self.region or 0
            return np.full(P, 10.0 + r), np.zeros((M, 3)), r

    src = TwinSource(Twin(), paced=False, scenario=steps)
    eng = LiveEngine(src, touch=FakeTouch(), reference_frames=30, policy="block")
    eng.run()
    ref = eng.reference_state()["touch"]
    assert ref["refusals"] == 0 and ref["in_use"]["frames"] == [0, 29]


# ------------------------------------------------------------------ policies
def test_block_processes_every_frame_in_order():
    cap = 10 + np.random.default_rng(2).random((60, P))
    _, outs, stats, _, _ = _run(
        cap, touch=FakeTouch(delay_s=0.002), reference_frames=5, queue_size=4
    )
    assert [o.seq for o in outs] == list(range(60))
    assert stats["dropped"] == 0 and stats["processed"] == stats["frames"] == 60


def test_skip_to_newest_drops_when_behind_but_records_every_frame(tmp_path):
    n = 150  # 0.5 s at 300 frames/s; the model takes 10 ms per frame (100 frames/s)
    cap = 10 + np.random.default_rng(3).random((n, P))
    src = ReplaySource(_rec(cap), speed=10.0)
    rec = Recorder(tmp_path / "live.h5", LAYOUT, 30.0)
    eng = LiveEngine(src, touch=FakeTouch(delay_s=0.010), reference_frames=5, recorder=rec)
    outs = []
    stats = eng.run(on_output=outs.append)
    rec.close()
    assert stats["frames"] == n
    assert stats["dropped"] > n // 3  # it really fell behind ...
    assert stats["processed"] + stats["dropped"] + stats["queue"] == n  # ... and counted it all
    seqs = [o.seq for o in outs]
    assert seqs == sorted(seqs) and seqs[-1] == n - 1  # always moved on to the newest
    # bounded latency: a frame waits at most max_lag (50 ms) + one model call (10 ms) + slack
    assert stats["latency_ms_p99"] < 120
    assert read_recording(tmp_path / "live.h5").n_frames == n  # the recorder got every frame
    assert stats["recorded"] == n


def test_skip_to_newest_keeps_every_frame_when_it_keeps_up():
    cap = 10 + np.random.default_rng(4).random((90, P))
    _, outs, stats, _, _ = _run(cap, speed=3.0, policy="skip-to-newest", reference_frames=5)
    assert stats["dropped"] == 0 and len(outs) == 90
    assert 60 < stats["fps_in"] < 120  # ~90 frames/s in
    assert stats["latency_ms_p50"] < 20


# ------------------------------------------------------------------ robustness
def test_bad_serial_input_is_counted_not_fatal():
    import serial

    port = serial.serial_for_url("loop://", timeout=0.05)
    good = ",".join(["10.0"] * P) + "\n"
    lines = [good] * 3 + [",".join(["1"] * 5) + "\n", "abc\n", "t=x;" + good, good, good]
    port.write("".join(lines).encode())
    src = SerialSource("loop://", opener=lambda *a: port)
    eng = LiveEngine(src, LAYOUT, touch=FakeTouch(), reference_frames=2, policy="block")
    stats = eng.run(max_frames=5, duration_s=5.0)
    assert stats["frames"] == stats["processed"] == 5
    assert stats["wrong_channels"] == 2 and stats["malformed"] == 1  # 'abc' = 1 value of 28
    assert stats["seq_gaps"] == 3


class _ListSource:
    """A minimal custom source (iterable of Frames with close())."""

    def __init__(self, frames, fail_at=None):
        self.frames, self.fail_at = frames, fail_at
        self.layout = LAYOUT
        self.n_pairs = P

    def __iter__(self):
        for i, f in enumerate(self.frames):
            if i == self.fail_at:
                raise RuntimeError("driver crashed")
            yield f

    def close(self):
        pass


def test_wrong_shape_frames_from_custom_source_are_skipped_and_source_crash_reported():
    frames = [Frame(i, i / 30, np.full(P if i != 3 else P - 2, 10.0)) for i in range(8)]
    eng = LiveEngine(_ListSource(frames), reference_frames=2, policy="block")
    stats = eng.run()
    assert stats["frames"] == 7 and stats["wrong_channels"] == 1
    eng = LiveEngine(_ListSource(frames, fail_at=5), reference_frames=2, policy="block")
    with pytest.raises(EctskinError, match="failed: RuntimeError: driver crashed"):
        eng.run()


def test_recording_failure_stops_the_run_with_its_reason():
    class FullDisk:
        stats = {}

        def write(self, frame):
            if frame.seq == 3:
                raise EctskinError("live.h5: recording failed: OSError: No space left on device")

        def add_event(self, text, t_s=None):
            pass

    src = ReplaySource(_rec(np.full((20, P), 10.0)), speed=math.inf)
    eng = LiveEngine(src, reference_frames=2, policy="block", recorder=FullDisk())
    with pytest.raises(EctskinError, match="^live.h5: recording failed: OSError: No space"):
        eng.run()


def test_failing_callback_is_counted_and_stop_from_other_thread():
    cap = np.full((3000, P), 10.0)  # 100 s at real speed: only stop() ends this run
    src = ReplaySource(_rec(cap), speed=1.0)
    eng = LiveEngine(src, reference_frames=2)

    def bad_callback(out):
        raise ValueError("dashboard bug")

    threading.Timer(0.4, eng.stop).start()
    t0 = time.perf_counter()
    stats = eng.run(on_output=bad_callback)
    assert time.perf_counter() - t0 < 2.0
    assert stats["errors"] == stats["processed"] >= 5
    with pytest.raises(EctskinError, match="runs once"):
        eng.run()


def test_construction_errors():
    src = ReplaySource(_rec(np.ones((3, P))))

    class T27(FakeTouch):
        n_pairs = 27

    class T5(FakeTouch):
        n_classes = 5

    with pytest.raises(EctskinError, match="touch model expects 27 channels, layout"):
        LiveEngine(src, touch=T27())
    with pytest.raises(EctskinError, match="touch model has 5 classes"):
        LiveEngine(src, touch=T5())
    with pytest.raises(EctskinError, match="Invalid value for 'policy'"):
        LiveEngine(src, policy="fast")
    with pytest.raises(EctskinError, match="reference_frames must be an integer >= 1"):
        LiveEngine(src, reference_frames=0)


def test_model_channels_mapped_by_name():
    """A model trained on a subset of channels (unmeasured pairs left out) gets those channels."""
    keep = [0, 3, 5]

    class Sub(FakeTouch):
        n_pairs = 3
        pair_names = [LAYOUT.pair_names[k] for k in keep]

    cap = np.full((4, P), 10.0) * (1 + 0.01 * np.arange(P))
    cap[2:] *= 1 + 0.1 * np.arange(P) / P
    _, outs, _, touch, _ = _run(cap, touch=Sub(), reference_frames=2)
    np.testing.assert_allclose(touch.inputs[-1], outs[-1].calibrated[keep], rtol=1e-6)


# ------------------------------------------------------------------ messages
def test_json_messages_follow_the_protocol():
    n = 8
    cap = np.full((n, P), 10.0)
    markers = np.ones((n, M, 3))
    eng, outs, _, _, _ = _run(cap, markers, track=FakeTrack(window=2), reference_frames=2)
    msg = json.loads(json.dumps(outs[-1].to_json_dict(), allow_nan=False))
    assert msg["type"] == "frame" and msg["seq"] == n - 1
    assert len(msg["raw"]) == P and len(msg["calibrated"]) == P
    assert len(msg["touch"]["probs"]) == C and isinstance(msg["touch"]["cls"], int)
    assert np.asarray(msg["markers"]["pred"]).shape == (M, 3)
    assert np.asarray(msg["markers"]["reference"]).shape == (M, 3)
    for key in (
        "frames",
        "processed",
        "dropped",
        "malformed",
        "reconnects",
        "latency_ms_p50",
        "latency_ms_p99",
        "fps_in",
        "fps_out",
        "policy",
        "reference_ready",
    ):
        assert key in msg["stats"]
    meta = json.loads(json.dumps(eng.meta(), allow_nan=False))
    assert meta["n_classes"] == C and meta["policy"] == "block" and meta["track_model"]
    assert meta["reference_markers"] == [[1.0, 1.0, 1.0]] * M
    np.testing.assert_array_equal(eng.reference_markers, np.ones((M, 3)))


# ------------------------------------------------------------------ real predictors
def test_real_predictors_from_run_dirs(tmp_path):
    import torch

    from ectskin.learn.checkpoint import save_checkpoint
    from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP, TouchMLPConfig
    from ectskin.learn.predict import TouchPredictor, TrackPredictor

    torch.manual_seed(0)
    extra = {"pair_names": list(LAYOUT.pair_names)}
    save_checkpoint(tmp_path / "touch" / "model.pt", TouchMLP(TouchMLPConfig()), extra=extra)
    c2dt = C2DT(C2DTConfig(), desc=LAYOUT.electrode_descriptors(), pairs=LAYOUT.pairs)
    save_checkpoint(tmp_path / "track" / "model.pt", c2dt, extra=extra)
    touch = TouchPredictor.from_run(tmp_path / "touch")
    track = TrackPredictor.from_run(tmp_path / "track")
    rng = np.random.default_rng(5)
    n = 40
    cap = 10 + rng.random((n, P))
    markers = np.tile(rng.normal(size=(1, M, 3)) * 20, (n, 1, 1))
    _, outs, stats, _, _ = _run(cap, markers, touch=touch, track=track, reference_frames=10)
    assert stats["processed"] == n and stats["errors"] == 0
    last = outs[-1]
    assert last.touch_probs.shape == (C,) and last.touch_probs.sum() == pytest.approx(1, abs=1e-5)
    assert last.markers_pred.shape == (M, 3) and np.isfinite(last.markers_pred).all()
    # the model really got Eq. 2 input: same answer as calling it by hand
    c0 = cap[:10].mean(0)
    np.testing.assert_allclose(last.touch_probs, touch.predict((cap[-1] - c0) / c0), rtol=1e-5)


# ------------------------------------------------------------------ CLI
def test_cli_live_replay_with_models_jsonl_and_record(tmp_path, capsys):
    import torch

    from ectskin.cli import main
    from ectskin.io.hdf5 import write_recording
    from ectskin.learn.checkpoint import save_checkpoint
    from ectskin.learn.models import TouchMLP, TouchMLPConfig

    n = 60
    cap = 10 + np.random.default_rng(6).random((n, P))
    src = write_recording(_rec(cap), tmp_path / "in.h5")
    save_checkpoint(tmp_path / "touch" / "model.pt", TouchMLP(TouchMLPConfig()))
    jsonl, rec = tmp_path / "out.jsonl", tmp_path / "live.h5"
    threads = str(torch.get_num_threads())  # leave this test process's setting as it is
    rc = main(
        [
            "live",
            "--source",
            f"replay:{src}",
            "--speed",
            "inf",
            "--policy",
            "block",
            "--touch-model",
            str(tmp_path / "touch"),
            "--reference-frames",
            "10",
            "--jsonl",
            str(jsonl),
            "--record",
            str(rec),
            "--threads",
            threads,
        ]
    )
    assert rc == 0
    lines = [json.loads(x) for x in jsonl.read_text().splitlines()]
    assert [m["seq"] for m in lines] == list(range(n))
    assert lines[5]["touch"] is None and len(lines[-1]["touch"]["probs"]) == C
    assert read_recording(rec).n_frames == n
    err = capsys.readouterr().err
    assert "final (the source ended): frames 60, processed 60, dropped 0" in err
    assert "touch reference: frames 0..9, captured " in err
    # a track model but a source without markers: a clear error, exit code 2
    from ectskin.learn.models import C2DT, C2DTConfig

    src2 = write_recording(_rec(cap), tmp_path / "nomarkers.h5")
    save_checkpoint(
        tmp_path / "track" / "model.pt",
        C2DT(C2DTConfig(), desc=LAYOUT.electrode_descriptors(), pairs=LAYOUT.pairs),
    )
    rc = main(
        [
            "live",
            "--source",
            f"replay:{src2}",
            "--track-model",
            str(tmp_path / "track"),
            "--threads",
            threads,
            "--runtime",
            "torch",  # the error comes after the models are loaded: skip the export
        ]
    )
    assert rc == 2
    assert "tracking needs initial marker coordinates" in capsys.readouterr().err
