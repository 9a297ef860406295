"""Crash-safe recorder: bit-exact round trip of a replayed recording, trial handling, periodic
flushing, and a REAL recorder process killed with SIGKILL that loses at most one second."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io.hdf5 import read_recording, write_recording
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.live.recorder import Recorder, record_main
from ectskin.live.sources import Frame, ReplaySource

LAYOUT = default_layout()
P, M = LAYOUT.n_pairs, LAYOUT.n_markers


def _recording(seed=0) -> Recording:
    rng = np.random.default_rng(seed)
    trials = []
    for k, n in enumerate((120, 75, 90)):
        markers = rng.normal(size=(n, M, 3)) * 10 if k != 1 else None
        if markers is not None:
            markers[5, 2] = np.nan  # an occlusion must survive the round trip
        cap = 20 + rng.random((n, P))
        cap[7, 3] = np.nan  # a masked channel too
        trials.append(
            Trial(
                f"trial_{k:03d}",
                capacitance=cap,
                # irregular, non-round timestamps: any rounding would show
                timestamps=np.cumsum(rng.uniform(0.02, 0.05, n)) + 0.1 * k,
                labels=rng.integers(0, LAYOUT.n_classes, n),
                inflation=(0.0, 10.0 * k, 20.0),
                region=3 * k,
                markers=markers,
                meta={"kind": "touch", "k": k},
            )
        )
    return Recording(LAYOUT, trials, 30.0, meta={"protocol": "test"})


def _frame(seq, t, value=1.0, label=None, markers=None, trial=None):
    return Frame(
        seq=seq, t=t, capacitance=np.full(P, value), label=label, markers=markers, trial=trial
    )


def test_replayed_recording_records_again_bit_exactly(tmp_path):
    rec = _recording()
    src_path = write_recording(rec, tmp_path / "in.h5")
    source = ReplaySource(src_path, speed=math.inf)
    out = tmp_path / "out.h5"
    with Recorder(out, source.layout, source.frame_rate_hz, trial_info=source.trial_info) as r:
        for f in source:
            r.write(f)
    back = read_recording(out)
    assert [t.name for t in back.trials] == [t.name for t in rec.trials]
    for a, b in zip(rec.trials, back.trials):
        # bit-exact: compare the bytes, so NaNs and -0.0 count too
        assert a.capacitance.tobytes() == b.capacitance.tobytes()
        assert a.timestamps.tobytes() == b.timestamps.tobytes()
        np.testing.assert_array_equal(a.labels, b.labels)
        if a.markers is None:
            assert b.markers is None
        else:
            assert a.markers.tobytes() == b.markers.tobytes()
        assert (a.inflation, a.region) == (b.inflation, b.region)
        assert b.meta["k"] == a.meta["k"]


def test_live_frames_trials_clock_reset_and_unknown_labels(tmp_path):
    out = tmp_path / "live.h5"
    with Recorder(out, LAYOUT, 30.0) as r:
        for i in range(10):
            r.write(_frame(i, 100.0 + i / 30, value=i))
        r.add_event("finger down")  # at the last frame's time
        for i in range(10, 15):  # the device restarted its clock
            r.write(_frame(i, (i - 10) / 30, value=i))
        r.new_trial("pressing", inflation=(0, 0, 20), region=4)
        for i in range(15, 20):
            r.write(_frame(i, 1.0 + i / 30, value=i, label=4, markers=np.zeros((M, 3))))
    rec = read_recording(out)
    assert [t.name for t in rec.trials] == ["live_0000", "live_0001", "pressing"]
    assert [t.n_frames for t in rec.trials] == [10, 5, 5]
    assert rec.trials[0].meta["labels"] == "unknown" and rec.trials[0].markers is None
    assert rec.trials[2].region == 4 and rec.trials[2].inflation == (0.0, 0.0, 20.0)
    np.testing.assert_array_equal(rec.trials[2].labels, 4)
    np.testing.assert_array_equal(rec.trials[1].capacitance[:, 0], np.arange(10, 15))
    events = rec.meta["events"]
    texts = [e["text"] for e in events]
    assert "finger down" in texts
    back = [e for e in events if "clock went back" in e["text"]]
    assert len(back) == 1 and "at frame 10" in back[0]["text"]


def test_frames_are_flushed_without_new_frames(tmp_path):
    """A frame written and then silence: it must reach the disk within the flush interval."""
    out = tmp_path / "idle.h5"
    r = Recorder(out, LAYOUT, 30.0, flush_interval_s=0.2)
    try:
        for i in range(7):
            r.write(_frame(i, i / 30))
        time.sleep(0.6)
        partial = read_recording(out, allow_partial=True)  # read while the writer is open
        assert partial.n_frames == 7
    finally:
        r.close()
    assert read_recording(out).n_frames == 7


def test_writer_errors_reach_the_producer(tmp_path):
    out = tmp_path / "bad.h5"
    r = Recorder(out, LAYOUT, 30.0)
    r.write(Frame(seq=0, t=0.0, capacitance=np.ones(P - 1)))  # wrong channel count
    with pytest.raises(EctskinError, match="recording failed.*capacitance"):
        r.flush()
    with pytest.raises(EctskinError, match="recording failed"):
        r.write(_frame(1, 0.1))
    with pytest.raises(EctskinError, match="recording failed"):
        r.close()


def test_record_main_duration_and_overwrite(tmp_path):
    src = write_recording(_recording(), tmp_path / "in.h5")
    out = tmp_path / "rec.h5"
    summary = record_main(f"replay:{src}", out, duration_s=0.5, speed=2.0, loop=True)
    rec = read_recording(out)
    assert summary["frames"] == rec.n_frames > 0
    assert not summary["interrupted"]
    # 0.5 s at 2x real speed of a 30 fps recording: about 30 frames
    assert 15 <= rec.n_frames <= 40
    with pytest.raises(EctskinError, match="exists"):
        record_main(f"replay:{src}", out, duration_s=0.1)
    with pytest.raises(EctskinError, match="duration must be > 0"):
        record_main(f"replay:{src}", tmp_path / "x.h5", duration_s=0)


_CHILD = r"""
import sys
from ectskin.live.recorder import record_main

def on_frame(f):
    sys.stdout.write(f"{f.seq}\n")
    sys.stdout.flush()

record_main("replay:" + sys.argv[1], sys.argv[2], speed=float(sys.argv[3]), loop=True,
            on_frame=on_frame)
"""


def test_sigkill_loses_at_most_one_second(tmp_path):
    """Kill a real recorder process with SIGKILL after ~3 s of recording at 300 frames/s."""
    rec = _recording()
    src = write_recording(rec, tmp_path / "in.h5")
    out = tmp_path / "killed.h5"
    speed = 10.0  # 30 fps recording -> 300 frames/s
    rate = 30.0 * speed
    proc = subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(src), str(out), str(speed)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    last = {"seq": -1, "first_at": None}

    def reader():
        for line in proc.stdout:
            last["seq"] = int(line)
            if last["first_at"] is None:
                last["first_at"] = time.monotonic()

    th = threading.Thread(target=reader, daemon=True)
    th.start()
    try:
        deadline = time.monotonic() + 20
        while last["first_at"] is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert last["first_at"] is not None, "the recorder process produced no frame"
        time.sleep(max(0.0, last["first_at"] + 3.0 - time.monotonic()))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    th.join(timeout=5)
    assert proc.returncode == -signal.SIGKILL
    sent = last["seq"] + 1  # frames handed to the recorder before the kill (at least)
    assert sent > 2 * rate  # it really ran ~3 s

    partial = read_recording(out, allow_partial=True)
    got = partial.n_frames
    lost = sent - got
    assert 0 < got <= sent
    assert lost <= rate * 1.0, f"lost {lost} frames = {lost / rate:.2f} s"
    # what is there is exactly the replayed stream's beginning (looping over the trials)
    flat = np.concatenate([t.capacitance for t in rec.trials])
    reps = int(np.ceil(got / len(flat))) + 1
    expect = np.concatenate([flat] * reps)[:got]
    recorded = np.concatenate([t.capacitance for t in partial.trials])
    assert recorded.tobytes() == expect.tobytes()
    assert partial.meta.get("source", "").startswith("replay:")


def test_cli_record(tmp_path, capsys):
    from ectskin.cli import main

    src = write_recording(_recording(), tmp_path / "in.h5")
    out = tmp_path / "cli.h5"
    assert main(["record", str(out), "--source", f"replay:{src}", "--speed", "inf"]) == 0
    assert "recorded 285 frames in 3 trial(s)" in capsys.readouterr().out
    back = read_recording(out)
    assert back.n_frames == 285 and back.meta["source"] == f"replay:{src}"
    # refusing to overwrite, and a bad spec: exit code 2 and one clear line, no traceback
    assert main(["record", str(out), "--source", f"replay:{src}"]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["record", str(tmp_path / "y.h5"), "--source", "usb:3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ectskin record: error: Invalid value for 'source kind'")
    assert "Traceback" not in err
