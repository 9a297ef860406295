"""Frame sources: the line protocol, replay, twin, serial (loop://), TCP (a real local server) and
LSL (a real pylsl outlet on loopback). Every malformed input is checked for its counter and for a
message naming the line/frame and the channel."""

from __future__ import annotations

import math
import socket
import threading
import time

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.live.sources import (
    Frame,
    LineError,
    ReplaySource,
    SerialSource,
    TcpSource,
    TwinSource,
    TwinStep,
    open_source,
    parse_line,
)

LAYOUT = default_layout()
P = LAYOUT.n_pairs  # 28
M = LAYOUT.n_markers  # 5


def _safety(src, seconds: float = 10.0) -> threading.Timer:
    """Close ``src`` after ``seconds`` so that a broken source cannot hang the suite."""
    timer = threading.Timer(seconds, src.close)
    timer.daemon = True
    timer.start()
    return timer


def _line(values, prefix: str = "") -> str:
    return prefix + ",".join(f"{v:.6f}" for v in values) + "\n"


def _recording(n_frames=(40, 25), seed=0, markers=True) -> Recording:
    rng = np.random.default_rng(seed)
    trials = []
    for k, n in enumerate(n_frames):
        trials.append(
            Trial(
                f"t{k}",
                capacitance=20 + rng.random((n, P)),
                timestamps=np.arange(n) / 30.0,
                labels=rng.integers(0, LAYOUT.n_classes, n),
                inflation=(0.0, 10.0 * k, 0.0),
                region=k,
                markers=rng.normal(size=(n, M, 3)) if markers else None,
            )
        )
    return Recording(LAYOUT, trials, 30.0)


# ------------------------------------------------------------------ line protocol
def test_parse_line_fields_and_values():
    vals = np.arange(P) + 0.5
    p = parse_line(_line(vals, "t=12.345; seq=7; label=3;"), P)
    assert p.t == 12.345 and p.seq == 7 and p.label == 3 and p.markers is None
    np.testing.assert_array_equal(p.capacitance, vals)
    # markers field, NaN channel, trailing comma, CRLF and a trailing comment
    m = np.arange(3 * M, dtype=float)
    text = "markers=" + ",".join(map(str, m)) + ";" + ",".join(["1.5"] * (P - 1)) + ",nan,\r\n"
    p = parse_line(text.replace("\r\n", " # note\r\n"), P, M)
    np.testing.assert_array_equal(p.markers, m.reshape(M, 3))
    assert np.isnan(p.capacitance[-1]) and p.capacitance[0] == 1.5
    assert parse_line("   # just a comment\n", P) is None
    assert parse_line("\n", P) is None


@pytest.mark.parametrize(
    "text, kind, fragment",
    [
        (",".join(["1"] * 27), "wrong_channels", "expected 28 channel values, got 27"),
        (",".join(["1"] * 29), "wrong_channels", "expected 28 channel values, got 29"),
        (",".join(["1"] * 4 + ["abc"] + ["1"] * 23), "malformed", "channel 5 of 28: 'abc'"),
        (",".join(["1"] * 27 + ["inf"]), "malformed", "channel 28 of 28: 'inf' is not finite"),
        ("t=abc;" + ",".join(["1"] * 28), "malformed", "field 't' must be a number"),
        ("seq=-1;" + ",".join(["1"] * 28), "malformed", "field 'seq' must be >= 0"),
        # a garbled counter is one bad line, not 1e23 frames lost
        ("seq=" + "9" * 23 + ";" + ",".join(["1"] * 28), "malformed", "'seq' must be at most"),
        ("seq=" + "9" * 5000 + ";" + ",".join(["1"] * 28), "malformed", "(5000 characters)"),
        ("foo=1;" + ",".join(["1"] * 28), "malformed", "unknown field 'foo'"),
        ("t=1;t=2;" + ",".join(["1"] * 28), "malformed", "field 't' given twice"),
        ("t=1;", "malformed", "no channel values"),
        (
            "markers=1,2,3;" + ",".join(["1"] * 28),
            "wrong_channels",
            "field 'markers': expected 15 coordinate values, got 3",
        ),
    ],
)
def test_parse_line_errors_name_line_and_channel(text, kind, fragment):
    with pytest.raises(LineError) as exc:
        parse_line(text, P, M, where="tcp:x:1 line 17")
    assert exc.value.kind == kind
    assert "tcp:x:1 line 17" in str(exc.value) and fragment in str(exc.value)


# ------------------------------------------------------------------ replay
def test_replay_as_fast_as_possible_yields_every_frame_in_order():
    rec = _recording()
    src = ReplaySource(rec, speed=math.inf)
    frames = list(src)
    assert len(frames) == rec.n_frames
    assert [f.seq for f in frames] == list(range(rec.n_frames))
    t1 = rec.trials[1]
    f = frames[40 + 3]
    assert f.trial == "t1" and f.t == t1.timestamps[3] and f.label == t1.labels[3]
    np.testing.assert_array_equal(f.capacitance, t1.capacitance[3])
    np.testing.assert_array_equal(f.markers, t1.markers[3])
    assert src.counters["frames"] == rec.n_frames
    assert src.trial_info("t1")["inflation"] == (0.0, 10.0, 0.0)
    with pytest.raises(EctskinError, match="only once"):
        iter(src)


def test_replay_paced_speed_and_loop():
    rec = _recording((30, 30))  # 2 s of recording at 30 fps
    src = ReplaySource(rec, speed=10.0)
    t0 = time.perf_counter()
    n = sum(1 for _ in src)
    wall = time.perf_counter() - t0
    # 60 frames: 29 + 1 + 29 frame periods of 1/30 s at 10x = 0.197 s
    assert n == 60 and 0.17 < wall < 0.6
    src = ReplaySource(rec, speed=math.inf, loop=True)
    seqs = []
    for f in src:
        seqs.append((f.seq, f.trial))
        if f.seq == 130:
            src.close()
    assert seqs[-1] == (130, "t0") and seqs[60] == (60, "t0")


def test_replay_close_from_other_thread_stops_iteration():
    src = ReplaySource(_recording((300,)), speed=1.0)  # 10 s at real speed
    _safety(src, 0.2)
    t0 = time.perf_counter()
    n = sum(1 for _ in src)
    assert time.perf_counter() - t0 < 1.0 and 3 <= n <= 12


def test_replay_bad_arguments():
    with pytest.raises(EctskinError, match="speed must be > 0"):
        ReplaySource(_recording(), speed=0)
    with pytest.raises(EctskinError, match="no trial 'nope'"):
        ReplaySource(_recording(), trials=["nope"])


def test_replay_from_hdf5_file(tmp_path):
    from ectskin.io.hdf5 import write_recording

    rec = _recording()
    path = write_recording(rec, tmp_path / "r.h5")
    src = open_source(f"replay:{path}", speed=math.inf)
    frames = list(src)
    np.testing.assert_array_equal(
        np.stack([f.capacitance for f in frames[:40]]), rec.trials[0].capacitance
    )
    assert src.layout.to_dict() == rec.layout.to_dict() and src.frame_rate_hz == 30.0


# ------------------------------------------------------------------ twin
class FakeTwin:
    """The LiveTwin protocol: capacitance = 10 + region + inflation sum / 100 per pair."""

    frame_rate_hz = 30.0

    def __init__(self):
        self.layout = LAYOUT
        self.n_pairs, self.n_markers = P, M
        self.region = None
        self.p = (0.0, 0.0, 0.0)

    def set_inflation(self, p_ml):
        self.p = tuple(p_ml)

    def set_touch(self, region, force_n=1.0, uv_mm=None):
        self.region = region

    def next_frame(self):
        r = self.region or 0
        return np.full(P, 10.0 + r + sum(self.p) / 100), np.zeros((M, 3)), r


def test_twin_source_follows_the_scenario():
    steps = [TwinStep(0.1, (0, 0, 0), None), TwinStep(0.1, (10, 20, 0), 4)]
    src = TwinSource(FakeTwin(), paced=False, scenario=steps)
    frames = list(src)
    assert len(frames) == 6  # 3 frames per 0.1 s step at 30 fps
    assert [f.label for f in frames] == [0, 0, 0, 4, 4, 4]
    assert frames[4].capacitance[0] == pytest.approx(14.3)
    assert frames[5].t == pytest.approx(5 / 30) and frames[5].markers.shape == (M, 3)


def test_twin_source_paced_runs_at_frame_rate():
    src = TwinSource(FakeTwin(), paced=True, scenario=[TwinStep(0.3, (0, 0, 0), 1)])
    t0 = time.perf_counter()
    n = sum(1 for _ in src)
    assert n == 9 and 0.24 < time.perf_counter() - t0 < 0.6  # 8 periods of 1/30 s


# ------------------------------------------------------------------ serial
def test_serial_loop_counts_bad_lines_and_names_them():
    import serial

    port = serial.serial_for_url("loop://", timeout=0.05)
    good = np.arange(P) + 1.0
    lines = [
        "# header comment\n",
        _line(good, "t=0.000;"),
        ",".join(["1"] * 27) + "\n",  # line 3: wrong channel count
        _line(good[:5])[:-1] + ",x" + "\n",  # line 4: too few values AND a bad one
        ",".join(["2"] * 10 + ["oops"] + ["2"] * 17) + "\n",  # line 5: channel 11 bad
        b"\xff\xfe garbage\n",  # line 6: not UTF-8
        _line(good, "label=19;"),  # line 7: the paper's layout has classes 0..18
        _line(good + 1, "t=0.067;label=18;"),
    ]
    for ln in lines:
        port.write(ln if isinstance(ln, bytes) else ln.encode())
    src = SerialSource("loop://", 9600, opener=lambda *a: port)
    _safety(src)
    frames = []
    for f in src:
        frames.append(f)
        if len(frames) == 2:
            break
    assert [f.t for f in frames] == [0.0, 0.067]
    np.testing.assert_array_equal(frames[1].capacitance, good + 1)
    # implicit frame numbers count every data line, so the 4 bad lines leave a gap of 4
    assert [f.seq for f in frames] == [0, 6] and src.counters["seq_gaps"] == 5
    assert frames[1].label == 18
    c = src.counters
    assert c["malformed"] == 3 and c["wrong_channels"] == 2 and c["frames"] == 2
    probs = list(src.problems)
    assert "serial:loop://@9600 line 3: expected 28 channel values, got 27" in probs[0]
    assert "line 4: expected 28 channel values, got 6" in probs[1]
    assert "line 5: channel 11 of 28: 'oops' is not a number" in probs[2]
    assert "line 6: not UTF-8" in probs[3]
    assert "line 7: field 'label' is 19, expected 0..18" in probs[4]
    src.close()


class _FlakyPort:
    """A serial port that fails on its 2nd read (device unplugged), like pyserial would."""

    def __init__(self, chunks):
        self.chunks = list(chunks)
        self.in_waiting = 0

    def read(self, n):
        if not self.chunks:
            time.sleep(0.01)
            return b""
        item = self.chunks.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    def close(self):
        pass


def test_serial_disconnect_is_counted_and_port_reopened():
    import serial

    good = _line(np.ones(P)).encode()
    ports = [
        _FlakyPort([good, good[:10], serial.SerialException("device disconnected")]),
        _FlakyPort([good, good]),
    ]
    opened = []

    def opener(port, baud, timeout):
        if len(opened) == 1:  # the first reopen attempt fails: device not back yet
            opened.append(None)
            raise serial.SerialException("could not open port")
        p = ports.pop(0)
        opened.append(p)
        return p

    src = SerialSource("/dev/ttyFAKE", opener=opener, backoff_s=(0.01, 0.05))
    _safety(src)
    frames = []
    for f in src:
        frames.append(f)
        if len(frames) == 3:
            break
    c = src.counters
    assert c["disconnects"] == 1 and c["reconnects"] == 1
    assert c["malformed"] == 1  # the half line cut by the disconnect
    assert any("line 2: cut by a disconnect" in p for p in src.problems)
    src.close()


def test_serial_open_failure_is_a_clear_error():
    with pytest.raises(EctskinError, match="serial:/dev/nonexistent_ectskin@115200: cannot open"):
        open_source("serial:/dev/nonexistent_ectskin")


# ------------------------------------------------------------------ tcp
class _LineServer:
    """A TCP server on 127.0.0.1 that plays scripted sessions: each a list of bytes to send,
    after which it closes the connection (the 'device goes away')."""

    def __init__(self, sessions, pause_s=0.0):
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # rebind after a pause
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(4)
        self.port = self.sock.getsockname()[1]
        self.sessions = sessions
        self.pause_s = pause_s
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        for k, chunks in enumerate(self.sessions):
            conn, _ = self.sock.accept()
            for c in chunks:
                conn.sendall(c)
                time.sleep(0.005)
            if k == len(self.sessions) - 1:
                time.sleep(5)  # keep the last connection open; the client closes
            conn.close()
            if self.pause_s:  # server down for a while: connections are refused
                self.sock.close()
                time.sleep(self.pause_s)
                self.sock = socket.socket()
                self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self.sock.bind(("127.0.0.1", self.port))
                self.sock.listen(4)

    def close(self):
        self.sock.close()


def test_tcp_reconnects_with_backoff_and_counts():
    a = [_line(np.full(P, 1.0), f"seq={i};t={i / 30:.4f};").encode() for i in range(3)]
    b = [_line(np.full(P, 2.0), f"seq={i};t={i / 30:.4f};").encode() for i in range(5, 8)]
    half = _line(np.full(P, 9.0), "seq=3;")[:20].encode()  # cut by the disconnect
    bad = ("seq=4;" + ",".join(["1"] * 28) + ",1\n").encode()  # 29 values
    server = _LineServer([a + [bad, half], b], pause_s=0.3)
    src = TcpSource("127.0.0.1", server.port, backoff_s=(0.05, 0.2))
    frames = []
    safety = _safety(src)
    try:
        for f in src:
            frames.append(f)
            if len(frames) == 6:
                break
    finally:
        safety.cancel()
        src.close()
        server.close()
    assert [f.seq for f in frames] == [0, 1, 2, 5, 6, 7]
    assert frames[3].capacitance[0] == 2.0 and frames[3].t == pytest.approx(0.1667)
    c = src.counters
    assert c["disconnects"] == 1 and c["reconnects"] == 1
    assert c["wrong_channels"] == 1 and c["malformed"] == 1
    assert c["seq_gaps"] == 2  # seq 3 and 4 never arrived as frames
    assert any("line 4: expected 28 channel values, got 29" in p for p in src.problems)
    assert any("line 5: cut by a disconnect" in p for p in src.problems)


def test_tcp_refused_connection_is_a_clear_error():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    with pytest.raises(EctskinError, match=rf"tcp:127.0.0.1:{port}: cannot connect .*tried for"):
        TcpSource("127.0.0.1", port, connect_timeout_s=0.2)


def test_tcp_overlong_line_is_discarded():
    long = b"1," * (40000) + b"\n"  # 80 kB without a newline until the end
    good = _line(np.full(P, 3.0)).encode()
    server = _LineServer([[good, long, good]])
    src = open_source(f"tcp:127.0.0.1:{server.port}")
    frames = []
    safety = _safety(src)
    for f in src:
        frames.append(f)
        if len(frames) == 2:
            break
    safety.cancel()
    src.close()
    server.close()
    assert src.counters["malformed"] == 1
    assert any("line 2: longer than 65536 bytes" in p for p in src.problems)
    assert frames[1].capacitance[0] == 3.0


def _ten_mb_session():
    """A good line, one 10 MB line (sent in 64 kB pieces, as a stream delivers it), a good line."""
    good = _line(np.full(P, 3.0)).encode()
    piece = b"1," * 32768
    return [good] + [piece] * 160 + [b"1\n", good.replace(b"3.0", b"4.0")]


def _check_one_problem(src, frames):
    """The 10 MB line is ONE malformed line, reported as line 2, and it takes
    one frame number (the next frame is seq 2, not seq 81)."""
    assert src.counters["malformed"] == 1, list(src.problems)
    (problem,) = src.problems
    assert "line 2: longer than 65536 bytes" in problem
    assert [f.seq for f in frames] == [0, 2] and src.counters["seq_gaps"] == 1
    assert frames[1].capacitance[0] == 4.0


def test_tcp_ten_megabyte_line_is_one_problem():
    server = _LineServer([_ten_mb_session()])
    src = open_source(f"tcp:127.0.0.1:{server.port}")
    frames = []
    safety = _safety(src, 30.0)
    try:
        for f in src:
            frames.append(f)
            if len(frames) == 2:
                break
    finally:
        safety.cancel()
        src.close()
        server.close()
    _check_one_problem(src, frames)


def test_serial_ten_megabyte_line_is_one_problem():
    port = _FlakyPort(_ten_mb_session())
    src = SerialSource("socket://rig:7000", opener=lambda *a: port)
    frames = []
    safety = _safety(src, 30.0)
    try:
        for f in src:
            frames.append(f)
            if len(frames) == 2:
                break
    finally:
        safety.cancel()
        src.close()
    _check_one_problem(src, frames)


# ------------------------------------------------------------------ lsl
def _outlet(name, n_channels, source_id):
    import pylsl

    info = pylsl.StreamInfo(name, "ECT", n_channels, 30.0, pylsl.cf_double64, source_id)
    return pylsl.StreamOutlet(info)


def test_lsl_stream_frames_markers_and_reconnect():
    import pylsl  # noqa: F401  (a dependency of the live extra: it must be there)
    name = f"ectskin-test-{time.monotonic_ns()}"
    out = _outlet(name, P + 3 * M, "ectskin-test-src")
    src = open_source(f"lsl:{name}", resolve_timeout_s=5.0, backoff_s=(0.05, 0.2))
    assert src.provides_markers is True
    frames = []

    def produce():
        nonlocal out
        time.sleep(0.2)
        for i in range(3):
            out.push_sample(np.concatenate([np.full(P, 10.0 + i), np.full(3 * M, float(i))]))
            time.sleep(0.02)
        time.sleep(0.3)
        del out  # the outlet goes away ...
        time.sleep(0.3)
        out = _outlet(name, P + 3 * M, "ectskin-test-src")  # ... and comes back
        time.sleep(1.0)
        for i in range(3, 5):
            out.push_sample(np.concatenate([np.full(P, 10.0 + i), np.full(3 * M, float(i))]))
            time.sleep(0.02)

    th = threading.Thread(target=produce, daemon=True)
    th.start()
    timer = _safety(src)
    for f in src:
        frames.append(f)
        if len(frames) == 5:
            break
    timer.cancel()
    src.close()
    th.join()
    assert [f.capacitance[0] for f in frames] == [10.0, 11.0, 12.0, 13.0, 14.0]
    np.testing.assert_array_equal(frames[4].markers, np.full((M, 3), 4.0))
    assert all(f.t > 0 for f in frames)  # LSL timestamps
    c = src.counters
    assert c["disconnects"] == 1 and c["reconnects"] == 1


def test_lsl_wrong_channel_count_and_unknown_name():
    import pylsl  # noqa: F401  (a dependency of the live extra: it must be there)
    name = f"ectskin-test-27-{time.monotonic_ns()}"
    out = _outlet(name, 27, "ectskin-test-27")
    with pytest.raises(
        EctskinError, match=rf"lsl:{name}: stream has 27 channels, expected 28 or 43"
    ):
        open_source(f"lsl:{name}")
    del out
    with pytest.raises(EctskinError, match="no LSL stream named 'no-such-ectskin-stream'"):
        open_source("lsl:no-such-ectskin-stream", resolve_timeout_s=0.2)


# ------------------------------------------------------------------ open_source
@pytest.mark.parametrize(
    "spec, fragment",
    [
        ("foo:bar", "Invalid value for 'source kind'"),
        ("replay", "replay needs an argument"),
        ("replay:/no/such/file.h5", "no such recording file"),
        ("sim:3", "'sim' takes no argument"),
        ("tcp:localhost", "expected tcp:HOST:PORT"),
        ("tcp:localhost:99999", "expected tcp:HOST:PORT"),
        ("serial:/dev/ttyUSB0@fast", "BAUD a positive integer, got 'fast'"),
        ("", "Invalid source ''"),
        ("tcp", "tcp needs an argument"),
    ],
)
def test_open_source_rejects_bad_specs(spec, fragment):
    with pytest.raises(EctskinError, match=None) as exc:
        open_source(spec)
    assert fragment in str(exc.value)


def test_frame_defaults():
    f = Frame(seq=1, t=0.5, capacitance=np.zeros(P))
    assert f.markers is None and f.label is None and f.trial is None
    assert abs(f.arrival - time.perf_counter()) < 1.0


def test_real_live_twin_as_source():
    """The lead's LiveTwin behind TwinSource: markers, labels, and a touch that changes the
    readouts far beyond the readout noise."""
    steps = [TwinStep(0.2, (0, 0, 0), None), TwinStep(0.2, (0, 0, 0), 5, 1.5)]
    src = open_source("sim", paced=False, scenario=steps)
    frames = list(src)
    assert len(frames) == 12 and src.provides_markers
    assert [f.label for f in frames] == [0] * 6 + [5] * 6
    assert all(f.markers.shape == (M, 3) and f.capacitance.shape == (P,) for f in frames)
    rest = np.array([f.capacitance for f in frames[:6]])
    touch = np.mean([f.capacitance for f in frames[6:]], axis=0)
    noise = rest.std(axis=0).max()
    assert np.abs(touch - rest.mean(axis=0)).max() > 20 * noise
