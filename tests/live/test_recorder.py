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
from ectskin.live.recorder import Recorder, record_stream
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


def test_record_stream_duration_and_overwrite(tmp_path):
    src = write_recording(_recording(), tmp_path / "in.h5")
    out = tmp_path / "rec.h5"
    summary = record_stream(f"replay:{src}", out, duration_s=0.5, speed=2.0, loop=True)
    rec = read_recording(out)
    assert summary["frames"] == rec.n_frames > 0
    assert not summary["interrupted"]
    # 0.5 s at 2x real speed of a 30 fps recording: about 30 frames
    assert 15 <= rec.n_frames <= 40
    with pytest.raises(EctskinError, match="exists"):
        record_stream(f"replay:{src}", out, duration_s=0.1)
    with pytest.raises(EctskinError, match="duration must be > 0"):
        record_stream(f"replay:{src}", tmp_path / "x.h5", duration_s=0)


_CHILD = r"""
import sys
from ectskin.live.recorder import record_stream

def on_frame(f):
    sys.stdout.write(f"{f.seq}\n")
    sys.stdout.flush()

record_stream("replay:" + sys.argv[1], sys.argv[2], speed=float(sys.argv[3]), loop=True,
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
    assert main(["record", "-o", str(out), "--source", f"replay:{src}", "--speed", "inf"]) == 0
    printed = capsys.readouterr().out
    assert f"recorded 285 frames in 3 trial(s) to {out}: timestamps span" in printed
    assert "(nominal 30 fps;" in printed
    back = read_recording(out)
    assert back.n_frames == 285 and back.meta["source"] == f"replay:{src}"
    # refusing to overwrite, and a bad spec: exit code 2 and one clear line, no traceback
    assert main(["record", "-o", str(out), "--source", f"replay:{src}"]) == 2
    assert f"{out} exists; pass --overwrite to replace it" in capsys.readouterr().err
    assert main(["record", str(tmp_path / "y.h5"), "--source", "usb:3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ectskin record: error: Invalid value for 'source kind'")
    assert "Traceback" not in err
    # the old positional form and the old --force still work
    argv = ["record", str(out), "--source", f"replay:{src}", "--speed", "inf", "--force"]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(["record", "--source", "sim"]) == 2
    assert "needs an output recording: give -o/--out PATH" in capsys.readouterr().err


def test_cli_record_never_writes_onto_the_file_it_replays(tmp_path, capsys):
    from ectskin.cli import main

    src = write_recording(_recording(), tmp_path / "in.h5")
    before = src.read_bytes()
    for spelled in (str(src), str(tmp_path / "." / "in.h5")):
        argv = ["record", "-o", spelled, "--source", f"replay:{src}", "--overwrite"]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "is the file the source" in err and "refusing to write onto" in err
    assert src.read_bytes() == before
    with pytest.raises(EctskinError, match="own input"):
        record_stream(f"replay:{src}", src, overwrite=True)


def test_source_given_as_a_file_suggests_replay(tmp_path, capsys):
    from ectskin.cli import main

    src = write_recording(_recording(), tmp_path / "s.h5")
    assert main(["record", "-o", str(tmp_path / "o.h5"), "--source", str(src)]) == 2
    assert f"to replay a recording, write replay:{src}" in capsys.readouterr().err


def _slow_recording(fps: float) -> Recording:
    """Nominally 30 fps, but the frames' timestamps are 1/fps apart (a source that fell behind)."""
    n = 60
    trial = Trial("t", 20 + np.zeros((n, P)), np.arange(n) / fps, np.zeros(n))
    return Recording(LAYOUT, [trial], 30.0)


def test_record_reports_rate_from_timestamps_and_warns_below_nominal(tmp_path, caplog, capsys):
    """`record` once printed the wall-clock seconds and no warning while the source delivered
    17 fps of a nominal 30. The summary must say what the timestamps say."""
    from ectskin.cli import main

    slow = write_recording(_slow_recording(15.0), tmp_path / "slow.h5")
    with caplog.at_level("WARNING"):
        summary = record_stream(f"replay:{slow}", tmp_path / "a.h5", speed=math.inf)
    assert summary["rate_hz"] == pytest.approx(15.0)
    assert summary["timestamps_s"] == pytest.approx(59 / 15)
    assert summary["nominal_hz"] == 30.0
    (warning,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert "delivered 15.0 frames per second, fewer than its nominal 30" in warning
    assert (
        main(
            ["record", "-o", str(tmp_path / "b.h5"), "--source", f"replay:{slow}", "--speed", "inf"]
        )
        == 0
    )
    assert "timestamps span 3.9 s at 15.0 fps (nominal 30 fps;" in capsys.readouterr().out
    # at the nominal rate: no warning; trials whose clocks restart are summed, not overlapped
    caplog.clear()
    with caplog.at_level("WARNING"):
        summary = record_stream(
            f"replay:{_nominal_recording(tmp_path)}", tmp_path / "c.h5", speed=math.inf
        )
    assert not [r for r in caplog.records if r.levelname == "WARNING"]
    assert summary["rate_hz"] == pytest.approx(30.0)
    assert summary["timestamps_s"] == pytest.approx(3 * 59 / 30)


def _nominal_recording(tmp_path):
    """Three trials at exactly 30 fps, each with its own clock starting at 0."""
    trials = [
        Trial(f"t{k}", 20 + np.zeros((60, P)), np.arange(60) / 30.0, np.zeros(60)) for k in range(3)
    ]
    return write_recording(Recording(LAYOUT, trials, 30.0), tmp_path / "nominal.h5")


class _SlowTwin:
    """The LiveTwin protocol; a new touch state takes 0.3 s to solve (as the MoM twin's does)."""

    layout, frame_rate_hz = LAYOUT, 30.0
    region = None

    def set_inflation(self, p):
        pass

    def set_touch(self, region, force_n=1.0):
        if region:
            time.sleep(0.3)
        self.region = region

    def next_frame(self):
        r = self.region or 0
        return np.full(P, 10.0 + r), np.zeros((M, 3)), r


def test_sim_timestamps_show_a_pause_of_the_twin():
    """A paced twin that pauses to solve a new state shows the pause in its timestamps (as a
    device's clock would), so the rate they give is what was really delivered."""
    from ectskin.live.sources import TwinSource, TwinStep

    steps = [TwinStep(0.2, (0, 0, 0), None), TwinStep(0.2, (0, 0, 0), 4)]
    frames = list(TwinSource(_SlowTwin(), paced=True, scenario=steps))
    ts = np.array([f.t for f in frames])
    assert len(frames) == 12 and np.all(np.diff(ts) > 0)
    assert ts[6] - ts[5] > 0.25  # the 0.3 s solve, not one frame period


def test_sim_trials_metadata_match_their_frames(tmp_path):
    """A recorded sim trial once said region 0 while its frames said 10. Each step of the
    scenario is now a trial whose region and inflation are those of its frames."""
    from itertools import islice

    from ectskin.io.calibration import rest_trials
    from ectskin.live.sources import TwinSource, TwinStep, demo_scenario

    scenario = [
        TwinStep(0.2, (0, 0, 0), None),
        TwinStep(0.2, (0, 0, 0), 10, 1.5),
        TwinStep(0.2, (20, 20, 10), 4),
    ]
    src = TwinSource(_SlowTwin(), paced=False, scenario=scenario)
    out = tmp_path / "sim.h5"
    with Recorder(out, LAYOUT, 30.0, trial_info=src.trial_info) as r:
        for f in src:
            r.write(f)
    rec = read_recording(out)
    assert [t.name for t in rec.trials] == ["sim_0000", "sim_0001", "sim_0002"]
    for t, step in zip(rec.trials, scenario, strict=True):
        assert t.region == (step.region or 0)
        np.testing.assert_array_equal(t.labels, t.region)
        assert t.inflation == tuple(float(v) for v in step.inflation_ml)
    assert rec.trials[0].meta["kind"] == "no_contact" and rec.trials[1].meta["kind"] == "touch"
    assert [t.name for t in rest_trials(rec)] == ["sim_0000"]  # offline Eq. 2 finds the rest
    # the real twin: the default scenario's first touch (region 10) likewise
    steps = list(islice(demo_scenario(LAYOUT, seed=0, rest_s=0.1, step_s=0.1), 2))
    src = TwinSource(paced=False, scenario=steps)
    frames = list(src)
    assert {f.trial for f in frames} == {"sim_0000", "sim_0001"}
    for f in frames:
        assert f.label == src.trial_info(f.trial)["region"] and f.inflation == (0.0, 0.0, 0.0)
    assert frames[-1].label == 10


def _stop_with(spawn_cli, sig: int, argv: list[str], wait_for: str) -> tuple[int, str]:
    """Run ``python -m ectskin.cli ARGV``, wait until stderr shows ``wait_for`` and ~1 s more,
    send ``sig``; returns (exit code, stderr)."""
    proc, lines, seen, th = spawn_cli(argv, wait_for)
    try:
        assert seen.wait(60), "".join(lines)
        time.sleep(1.0)
        os.kill(proc.pid, sig)
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    th.join(timeout=5)
    return rc, "".join(lines)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_record_closes_the_file_complete_on_sigterm_and_sighup(tmp_path, sig, spawn_cli):
    """`kill PID` or a closed terminal once left the recording incomplete, and
    every reader then refused it."""
    src = write_recording(_recording(), tmp_path / "in.h5")
    out = tmp_path / "rec.h5"
    argv = ["record", "-o", str(out), "--source", f"replay:{src}", "--loop"]
    rc, err = _stop_with(spawn_cli, sig, argv, "recording replay:")
    assert rc == 0, err
    rec = read_recording(out)  # complete: no allow_partial needed
    assert rec.n_frames > 10
    assert f"{signal.Signals(sig).name} received; closing the recording" in err
