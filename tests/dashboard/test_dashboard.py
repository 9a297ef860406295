"""The dashboard server (FastAPI app, hub, websocket stream) against a fake engine.

The browser side is tested in ``test_dashboard_browser.py``.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import socket
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

with warnings.catch_warnings():  # starlette 1.x: "use httpx2"; httpx is what CI has
    warnings.filterwarnings("ignore", message=".*httpx2.*")
    from fastapi.testclient import TestClient

from ectskin._check import EctskinError
from ectskin.dashboard import DashboardServer, Hub, build_meta, create_app
from ectskin.dashboard.app import STATIC_DIR
from ectskin.dashboard.hub import TokenBucket
from ectskin.dashboard.messages import encode
from ectskin.layout import default_layout

LAYOUT = default_layout()
REST = np.array([[25.0, 0.0, z] for z in (24, 48, 72, 96, 120)])


def make_output(k: int, layout=LAYOUT, *, nan_channel: int | None = None) -> dict:
    """A frame message as ``Output.to_json_dict()`` gives it."""
    n, c = layout.n_pairs, layout.n_classes
    raw = 1.0 + 0.01 * np.arange(n) + 0.001 * k
    if nan_channel is not None:
        raw[nan_channel] = np.nan
    cls = 1 + k % (c - 1)
    probs = np.full(c, 0.01)
    probs[cls] = 1 - 0.01 * (c - 1)
    pred = REST + np.array([0.0, 0.1 * k, 0.0])
    return {
        "type": "frame", "seq": k, "t": k / 30.0, "raw": raw.tolist(),
        "calibrated": (raw / raw[0] - 1).tolist(),
        "touch": {"cls": cls, "probs": probs.tolist()},
        "markers": {"pred": pred.tolist(), "reference": REST.tolist(), "true": None},
        "label": cls,
        "stats": {"frames": k + 1, "processed": k + 1, "dropped": 0, "malformed": 0},
    }


class FakeOutput:
    """Stands in for ``ectskin.live.engine.Output`` (only ``to_json_dict`` is used)."""

    def __init__(self, k: int):
        self.k = k

    def to_json_dict(self) -> dict:
        return make_output(self.k)


class FakeEngine:
    """The LiveEngine surface the dashboard uses: layout, stats, capture_reference, run, stop."""

    def __init__(self, layout=LAYOUT, n_frames: int = 0, rate_hz: float | None = None,
                 fail: Exception | None = None):
        self.layout = layout
        self.n_frames = n_frames
        self.rate_hz = rate_hz
        self.fail = fail
        self.captures = 0
        self.run_calls: list[dict] = []
        self._stopped = threading.Event()
        self.processed = 0

    @property
    def stats(self) -> dict:
        return {"frames": self.processed + 3, "processed": self.processed, "dropped": 3,
                "malformed": 1, "reconnects": 0, "latency_ms_p50": 0.5,
                "latency_ms_p99": float("nan"), "fps_in": 30.0, "fps_out": 29.0,
                "policy": "skip-to-newest", "reference_ready": self.captures == 0}

    def capture_reference(self) -> None:
        if isinstance(self.fail, EctskinError):
            raise self.fail
        self.captures += 1

    def run(self, max_frames=None, duration_s=None, on_output=None):
        self.run_calls.append({"max_frames": max_frames, "duration_s": duration_s})
        if self.fail is not None and not isinstance(self.fail, EctskinError):
            raise self.fail
        for k in range(self.n_frames):
            if self._stopped.is_set():
                break
            on_output(FakeOutput(k))
            self.processed += 1
            if self.rate_hz:
                time.sleep(1 / self.rate_hz)

    def stop(self) -> None:
        self._stopped.set()


@pytest.fixture
def engine():
    return FakeEngine()


@pytest.fixture
def hub(engine):
    return Hub(LAYOUT, engine)


#: What a browser on this machine sends as Host: TestClient's default "testserver" is not a
#: loopback name, and the dashboard refuses it (DNS rebinding).
BASE = "http://127.0.0.1:8765"
WS = "ws://127.0.0.1:8765/ws"  # TestClient joins a relative websocket URL with ws://testserver


def local_client(app) -> TestClient:
    return TestClient(app, base_url=BASE)


@pytest.fixture
def client(hub):
    with local_client(create_app(hub)) as c:
        yield c


# --------------------------------------------------------------------------- meta
def test_meta_describes_the_layout():
    meta = build_meta(LAYOUT)
    assert meta["type"] == "meta"
    assert meta["n_pairs"] == 28 and len(meta["pair_names"]) == 28
    assert meta["pair_names"][:2] == ["E1-E2", "E1-E3"] and meta["pair_names"][-1] == "E7-E8"
    assert meta["n_classes"] == 19
    assert sorted(r["id"] for r in meta["regions"]) == list(range(1, 19))
    assert {r["surface"] for r in meta["regions"] if r["id"] <= 9} == {"front"}
    assert {r["surface"] for r in meta["regions"] if r["id"] >= 10} == {"back"}
    assert [e["surface"] for e in meta["electrodes"]] == ["front"] * 4 + ["back"] * 4
    assert meta["marker_names"] == ["M1", "M2", "M3", "M4", "M5"]
    assert meta["reference_markers"] is None
    # Same-face pairs: 6 front-front + 6 back-back of 28, as layout.same_surface says.
    same = [a == b for a, b in meta["pair_surfaces"]]
    assert same == LAYOUT.same_surface.tolist() and sum(same) == 12
    json.dumps(meta, allow_nan=False)


def test_meta_reference_markers_are_checked():
    meta = build_meta(LAYOUT, reference_markers=REST)
    assert meta["reference_markers"][4] == [25.0, 0.0, 120.0]
    with pytest.raises(EctskinError, match=r"reference_markers must have shape \(5, 3\).*\(4, 3\)"):
        build_meta(LAYOUT, reference_markers=REST[:4])
    with pytest.raises(EctskinError, match=r"reference_markers must have shape \(5, 3\)"):
        Hub(LAYOUT, reference_markers=REST[:, :2])
    assert Hub(LAYOUT, reference_markers=REST).meta()["reference_markers"][1] == [25.0, 0.0, 48.0]


def test_meta_takes_reference_markers_from_the_engine(engine):
    engine.reference_markers = REST
    assert Hub(LAYOUT, engine).meta()["reference_markers"][0] == [25.0, 0.0, 24.0]


# --------------------------------------------------------------------------- JSON
def test_non_finite_numbers_become_null():
    obj = {"a": np.array([1.0, np.nan, np.inf]), "b": np.float32(2.5), "c": [float("-inf")],
           "d": np.int64(3)}
    assert json.loads(encode(obj)) == {"a": [1.0, None, None], "b": 2.5, "c": [None], "d": 3}
    assert json.loads(encode({"x": (1, np.nan)})) == {"x": [1, None]}
    assert encode({"a": [1.5, None]}) == '{"a":[1.5,null]}'  # compact


# --------------------------------------------------------------------------- rate limit
def _simulate(bucket: TokenBucket, arrivals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Send times and waits when each arrival is sent as soon as the bucket allows, newest
    first (an arrival that comes while a send waits replaces the waiting one)."""
    sends, waits = [], []
    t_free = -np.inf  # time at which the previous send happened
    for k, t in enumerate(arrivals):
        t = max(t, t_free)
        if k + 1 < len(arrivals) and arrivals[k + 1] <= t + bucket.wait_s(t):
            continue  # superseded before it could go out
        w = bucket.wait_s(t)
        bucket.take(t + w)
        sends.append(t + w)
        waits.append(t + w - arrivals[k])
        t_free = t + w
    return np.array(sends), np.array(waits)


def _max_in_window(times: np.ndarray, window_s: float) -> int:
    return max(int(np.searchsorted(times, a + window_s - 1e-12) - i) for i, a in enumerate(times))


def test_token_bucket_caps_a_flood_at_the_rate():
    arrivals = np.arange(0, 10, 1e-3)  # 1000 frames/s for 10 s
    sends, _ = _simulate(TokenBucket(30.0), arrivals)
    assert 10 * 30 - 2 <= len(sends) <= 10 * 30 + 2
    assert _max_in_window(sends, 1.0) <= 31  # floor(1.25 + 30)
    assert np.diff(sends).min() >= 0.75 / 30 - 1e-9  # bursts of 1.25 tokens at most


def test_token_bucket_adds_no_lasting_delay_at_the_source_rate():
    """Frames at exactly the limit with timing jitter go out at once; no phase lag builds up."""
    rng = np.random.default_rng(1)
    period = 1 / 30
    arrivals = np.arange(900) * period + rng.uniform(0, 0.2 * period, 900)
    sends, waits = _simulate(TokenBucket(30.0), arrivals)
    assert len(sends) == 900  # none skipped
    assert waits.mean() < 0.05 * period and waits.max() < 0.25 * period
    # A plain minimum gap (burst = 1) lets the lag grow to a good part of a period.
    _, waits_gap = _simulate(TokenBucket(30.0, burst=1.0), arrivals)
    assert waits_gap.mean() > 2 * waits.mean()


def test_token_bucket_refuses_bad_settings():
    with pytest.raises(EctskinError, match="rate_hz > 0 and burst >= 1, got 30.0, 0.5"):
        TokenBucket(30.0, burst=0.5)


# --------------------------------------------------------------------------- hub checks
def test_hub_refuses_bad_arguments():
    with pytest.raises(EctskinError, match="layout must be a SensorLayout, got dict"):
        Hub({"name": "x"})
    with pytest.raises(EctskinError, match="max_rate_hz must be a number > 0, got 0"):
        Hub(LAYOUT, max_rate_hz=0)
    with pytest.raises(EctskinError, match="engine object has no 'stats'"):
        Hub(LAYOUT, engine=object())
    hub = Hub(LAYOUT)
    hub.publish(42)  # publish stays cheap: garbage is refused when it is read
    with pytest.raises(EctskinError, match="must be dicts or have to_json_dict.*got int"):
        hub.encoded_latest()


def test_publish_keeps_newest_and_counts():
    hub = Hub(LAYOUT)
    assert hub.latest() == (0, None) and hub.encoded_latest() == (0, None)
    for k in range(5):
        hub.publish(FakeOutput(k))
    version, text = hub.encoded_latest()
    assert version == 5 and hub.n_published == 5
    assert json.loads(text)["seq"] == 4
    assert hub.encoded_latest()[1] is text  # encoded once, however many clients


def test_history_is_sampled_at_the_client_rate():
    hub = Hub(LAYOUT, max_rate_hz=10.0, history_s=10.0)
    for k in range(50):  # 50 publishes within a few ms: only the first falls in a new 0.1 s slot
        hub.publish(make_output(k))
    frames = hub.history_message()["frames"]
    assert [f["seq"] for f in frames] == [0]
    assert set(frames[0]) == {"seq", "t", "raw", "calibrated", "trial", "inflation", "age_s"}
    assert 0 <= frames[0]["age_s"] < 1.0
    old = Hub(LAYOUT, history_s=0.05)
    old.publish(make_output(0))
    time.sleep(0.1)
    assert old.history_message()["frames"] == []  # older than history_s


# --------------------------------------------------------------------------- HTTP routes
def test_page_and_static_files_are_served(client):
    r = client.get("/")
    assert r.status_code == 200 and "text/html" in r.headers["content-type"]
    for needed in ('id="strip-chart"', 'id="capture-reference"', 'id="predicted-class"',
                   'id="markers-moved"', 'id="frames-count"', "/static/app.js",
                   'id="marker-errors"', 'id="trial-info"', 'id="reference-detail"',
                   "untouched and uninflated", "estimated (model)", "true (motion capture)"):
        assert needed in r.text
    js = client.get("/static/app.js")
    assert js.status_code == 200 and "WebSocket" in js.text
    assert client.get("/static/style.css").status_code == 200


def test_page_loads_nothing_from_elsewhere():
    """No CDN: the page must work on a machine without internet access."""
    for path in STATIC_DIR.iterdir():
        text = path.read_text(encoding="utf-8")
        urls = set(re.findall(r"(?:https?:)?//[a-zA-Z0-9.-]+\.[a-z]{2,}[^\s\"')]*", text))
        urls.discard("http://www.w3.org/2000/svg")  # the SVG namespace name, not fetched
        assert not urls, f"{path.name} refers to {urls}"


def test_api_meta(client, hub):
    r = client.get("/api/meta")
    assert r.status_code == 200
    assert r.json() == json.loads(encode(hub.meta()))
    assert r.json()["pair_names"] == list(LAYOUT.pair_names)


def test_api_stats_reads_the_engine(client, engine):
    engine.processed = 41
    s = client.get("/api/stats").json()
    assert s["processed"] == 41 and s["frames"] == 44 and s["dropped"] == 3 and s["malformed"] == 1
    assert s["latency_ms_p99"] is None  # NaN from the engine arrives as null, not invalid JSON
    assert s["dashboard"]["clients"] == 0 and s["dashboard"]["reference_requests"] == 0


def test_api_stats_without_engine_uses_the_newest_output():
    hub = Hub(LAYOUT)
    with local_client(create_app(hub)) as c:
        assert c.get("/api/stats").json()["dashboard"]["published"] == 0
        hub.publish(make_output(7))
        s = c.get("/api/stats").json()
    assert s["frames"] == 8 and s["dashboard"]["published"] == 1


def test_reference_post_calls_the_engine(client, engine):
    r = client.post("/api/reference")
    assert r.status_code == 200 and r.json() == {"ok": True, "reference_requests": 1}
    assert engine.captures == 1
    r = client.post("/api/reference", headers={"Origin": BASE})  # same origin
    assert r.status_code == 200 and engine.captures == 2
    assert client.get("/api/stats").json()["dashboard"]["reference_requests"] == 2
    assert client.get("/api/reference").status_code == 405


def test_reference_post_from_another_site_is_refused(client, engine):
    for origin in ("http://evil.example", "null", "http://127.0.0.1.evil.example:8765"):
        r = client.post("/api/reference", headers={"Origin": origin})
        assert r.status_code == 403, origin
    assert engine.captures == 0


# --------------------------------------------------------------------------- DNS rebinding
def test_host_names_and_addresses_are_parsed_and_judged():
    from ectskin.dashboard.security import host_allowed, split_host

    assert split_host("127.0.0.1:8765") == "127.0.0.1"
    assert split_host("[::1]:8765") == "::1" and split_host("::1") == "::1"
    assert split_host("LocalHost.:80") == "localhost" and split_host("rig.lab") == "rig.lab"
    for ok in ("127.0.0.1:8765", "127.3.4.5", "localhost:1", "app.localhost", "[::1]:8765"):
        assert host_allowed(ok), ok
    for bad in ("evil.example:8765", "127.0.0.1.evil.example", "localhost.evil.example", "",
                None, "192.168.1.20:8765", "0.0.0.0:8765"):
        assert not host_allowed(bad), bad
    assert host_allowed("rig.lab:8765", ["rig.lab"]) and host_allowed("RIG.LAB", ["rig.lab:80"])


def test_dns_rebinding_requests_are_refused(client, engine):
    """DNS rebinding: a page from evil.example re-pointed at 127.0.0.1 sends Host and Origin
    evil.example; Origin equals Host, so only the Host check can refuse it."""
    evil = {"Host": "evil.example:8765", "Origin": "http://evil.example:8765"}
    r = client.post("/api/reference", headers=evil)
    assert r.status_code == 403 and r.json() == {"ok": False, "error": "host not allowed"}
    assert engine.captures == 0
    for path in ("/", "/api/stats", "/api/meta", "/static/app.js"):  # nothing leaks either
        assert client.get(path, headers={"Host": "evil.example:8765"}).status_code == 403, path
    from starlette.websockets import WebSocketDisconnect

    with (
        pytest.raises(WebSocketDisconnect) as info,
        client.websocket_connect("ws://evil.example:8765/ws", headers=evil) as ws,
    ):
        ws.receive_json()
    assert info.value.code == 1008
    # a configured name is served
    with local_client(create_app(Hub(LAYOUT, engine), allowed_hosts=["rig.lab"])) as c:
        r = c.post("/api/reference", headers={"Host": "rig.lab:8765",
                                              "Origin": "http://rig.lab:8765"})
    assert r.status_code == 200 and engine.captures == 1


def test_dns_rebinding_reproduction_against_a_real_server():
    """The attack reproduced against a running server: the curl POST and a raw websocket
    handshake with Host and Origin evil.example are refused; the same from 127.0.0.1 works."""
    import httpx

    engine = FakeEngine()
    with DashboardServer(engine, port=0) as server:
        port = server.port
        evil = {"Host": f"evil.example:{port}", "Origin": f"http://evil.example:{port}"}
        r = httpx.post(f"http://127.0.0.1:{port}/api/reference", headers=evil)
        assert r.status_code == 403 and engine.captures == 0

        def handshake(host: str, origin: str) -> str:
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                s.sendall(
                    f"GET /ws HTTP/1.1\r\nHost: {host}\r\nOrigin: {origin}\r\n"
                    "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                    "Sec-WebSocket-Version: 13\r\n\r\n".encode()
                )
                return s.recv(4096).decode("latin-1").split("\r\n")[0]

        assert " 403 " in handshake(f"evil.example:{port}", f"http://evil.example:{port}")
        assert " 101 " in handshake(f"127.0.0.1:{port}", f"http://127.0.0.1:{port}")
        assert httpx.post(f"http://127.0.0.1:{port}/api/reference").status_code == 200
    assert engine.captures == 1


def test_reference_post_errors_are_reported():
    with local_client(create_app(Hub(LAYOUT))) as c:
        r = c.post("/api/reference")
    assert r.status_code == 409 and "no live engine attached" in r.json()["error"]
    eng = FakeEngine(fail=EctskinError("reference: source has no frames yet"))
    with local_client(create_app(Hub(LAYOUT, eng))) as c:
        r = c.post("/api/reference")
    assert r.status_code == 409 and r.json() == {
        "ok": False, "error": "reference: source has no frames yet"}


def test_create_app_refuses_a_non_hub():
    with pytest.raises(EctskinError, match="expected a dashboard Hub, got FakeEngine"):
        create_app(FakeEngine())


# --------------------------------------------------------------------------- websocket
def test_websocket_sends_meta_history_then_frames(client, hub):
    hub.publish(make_output(0))  # before the client connects: becomes history
    with client.websocket_connect(WS) as ws:
        meta = ws.receive_json()
        assert meta["type"] == "meta" and meta["pair_names"] == list(LAYOUT.pair_names)
        history = ws.receive_json()
        assert history["type"] == "history" and [f["seq"] for f in history["frames"]] == [0]
        status = ws.receive_json()
        assert status == {"type": "status", "engine": "waiting", "error": None, "published": 1}
        first = ws.receive_json()  # the newest output at connection time comes at once
        assert first["type"] == "frame" and first["seq"] == 0
        t = threading.Thread(target=lambda: [hub.publish(FakeOutput(k)) for k in (1, 2)])
        t.start()
        t.join()
        seqs = [first["seq"]]
        while seqs[-1] != 2:  # 1 may be skipped (newest wins), 2 must arrive
            msg = ws.receive_json()
            assert msg["type"] == "frame"
            seqs.append(msg["seq"])
        assert seqs == sorted(set(seqs))
        assert msg["touch"]["cls"] == 3 and len(msg["touch"]["probs"]) == 19
        assert hub.n_clients == 1
    deadline = time.monotonic() + 2
    while hub.n_clients and time.monotonic() < deadline:
        time.sleep(0.01)
    assert hub.n_clients == 0


def test_websocket_frames_with_masked_channels_are_valid_json(client, hub):
    hub.publish(make_output(5, nan_channel=3))
    with client.websocket_connect(WS) as ws:
        for kind in ("meta", "history", "status"):
            assert ws.receive_json()["type"] == kind
        text = ws.receive_text()
    msg = json.loads(text)  # strict JSON: a bare NaN would not parse in the browser
    assert "NaN" not in text and msg["raw"][3] is None and msg["raw"][4] == pytest.approx(1.045)


def test_websocket_from_another_site_is_refused(client):
    from starlette.websockets import WebSocketDisconnect

    with (
        pytest.raises(WebSocketDisconnect) as info,
        client.websocket_connect(WS, headers={"Origin": "http://evil.example"}) as ws,
    ):
        ws.receive_json()
    assert info.value.code == 1008


# --------------------------------------------------------------------------- real server
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_stream_is_throttled_and_ends_on_the_newest_frame():
    """A 1000-fps publisher, a 20 msg/s limit: ≤ 20 messages in any second, the last one sent."""
    from websockets.sync.client import connect

    rate = 20.0
    hub = Hub(LAYOUT, max_rate_hz=rate)
    with DashboardServer(None, hub=hub, port=0) as server:
        url = f"ws://127.0.0.1:{server.port}/ws"
        with connect(url) as ws:
            for kind in ("meta", "history", "status"):
                assert json.loads(ws.recv(timeout=5))["type"] == kind
            n_pub = 1500

            def publish():
                for k in range(n_pub):
                    hub.publish(make_output(k))
                    time.sleep(0.001)

            pub = threading.Thread(target=publish)
            pub.start()
            arrivals, seqs = [], []
            deadline = time.monotonic() + 30
            while (not seqs or seqs[-1] != n_pub - 1) and time.monotonic() < deadline:
                msg = json.loads(ws.recv(timeout=5))
                arrivals.append(time.monotonic())
                seqs.append(msg["seq"])
            pub.join()
            publish_s = arrivals[-1] - arrivals[0]
    assert seqs[-1] == n_pub - 1, "the newest frame must be delivered"
    assert all(b > a for a, b in itertools.pairwise(seqs)), "frames arrive in order, never repeated"
    assert len(seqs) < n_pub / 5  # most frames were skipped, not queued
    # At most `rate` messages in any 1-s window (+1 for the window's edge).
    arr = np.array(arrivals)
    per_window = max(np.searchsorted(arr, a + 1.0) - i for i, a in enumerate(arr))
    assert per_window <= rate + 1, f"{per_window} messages within one second"
    assert len(seqs) <= rate * publish_s + 2
    assert len(seqs) >= 0.5 * rate * publish_s  # and it keeps up with the limit
    assert hub.messages_sent == len(seqs)


def test_publishing_is_not_slowed_by_a_client_that_never_reads():
    from websockets.sync.client import connect

    hub = Hub(LAYOUT, max_rate_hz=1000.0)
    big = make_output(0)
    big["raw"] = [1.0] * 20000  # ~200 kB per message: a non-reading client fills its buffers
    with (
        DashboardServer(None, hub=hub, port=0) as server,
        connect(f"ws://127.0.0.1:{server.port}/ws", max_size=None),
    ):
        time.sleep(0.2)
        t0 = time.perf_counter()
        for _ in range(3000):
            hub.publish(big)
        per_call_us = (time.perf_counter() - t0) / 3000 * 1e6
    assert per_call_us < 500, f"publish took {per_call_us:.0f} µs per call"


def test_server_runs_the_engine_and_reports_its_errors():
    import httpx

    engine = FakeEngine(n_frames=20, rate_hz=200)
    with DashboardServer(engine, port=0, run_kwargs={"duration_s": 5}) as server:
        assert server.url == f"http://127.0.0.1:{server.port}/"
        deadline = time.monotonic() + 5
        while server.hub.n_published < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
        s = httpx.get(server.url + "api/stats").json()
        assert httpx.post(server.url + "api/reference").json()["ok"]
    assert engine.run_calls == [{"max_frames": None, "duration_s": 5}]
    assert server.hub.n_published == 20 and s["dashboard"]["published"] == 20
    assert engine.captures == 1

    broken = FakeEngine(fail=RuntimeError("serial port vanished"))
    with DashboardServer(broken, port=0) as server:
        deadline = time.monotonic() + 5
        while server.hub.engine_error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        s = httpx.get(server.url + "api/stats").json()
    assert s["dashboard"]["engine_error"] == "RuntimeError: serial port vanished"
    assert s["dashboard"]["engine_running"] is False


def test_pages_are_told_when_the_engine_ends():
    """The "live" badge once stayed after the source ended. The stream says so: a status
    message "running", then "ended" after the last frame."""
    from websockets.sync.client import connect

    engine = FakeEngine(n_frames=30, rate_hz=30)
    with DashboardServer(engine, port=0) as server, connect(
        f"ws://127.0.0.1:{server.port}/ws"
    ) as ws:
        states, seqs = [], []
        deadline = time.monotonic() + 15
        while "ended" not in states and time.monotonic() < deadline:
            msg = json.loads(ws.recv(timeout=5))
            if msg["type"] == "status":
                states.append(msg["engine"])
            elif msg["type"] == "frame":
                seqs.append(msg["seq"])
        assert states[-1] == "ended" and "running" in states, states
        assert seqs and seqs[-1] == 29  # the last frame came before "ended"
        s = server.hub.stats()["dashboard"]
        assert s["engine_state"] == "ended" and s["engine_running"] is False


def test_serve_returns_when_the_engine_ends_unless_told_to_keep_serving(monkeypatch):
    """`live --dashboard --duration` once kept serving after the duration. serve() returns
    once the engine has ended (and the pages were told); keep_serving waits for Ctrl-C."""
    from ectskin.dashboard import serve
    from ectskin.dashboard import server as server_module

    made = []
    real = server_module.DashboardServer

    def remember(*args, **kwargs):
        made.append(real(*args, **kwargs))
        return made[-1]

    monkeypatch.setattr(server_module, "DashboardServer", remember)

    done = threading.Event()
    engine = FakeEngine(n_frames=5)
    t0 = time.monotonic()
    th = threading.Thread(target=lambda: (serve(engine, port=0), done.set()), daemon=True)
    th.start()
    assert done.wait(15), "serve() kept running after the engine ended"
    assert time.monotonic() - t0 < 10 and engine.processed == 5
    kept = threading.Event()
    th = threading.Thread(
        target=lambda: (serve(FakeEngine(n_frames=5), port=0, keep_serving=True), kept.set()),
        daemon=True,
    )
    th.start()
    assert not kept.wait(2.5)  # still serving the last frame
    made[-1].stop()  # what Ctrl-C does
    assert kept.wait(10)
    with pytest.raises(EctskinError, match="live engine stopped: RuntimeError: port vanished"):
        serve(FakeEngine(fail=RuntimeError("port vanished")), port=0)


def test_server_port_in_use_is_a_clear_error():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(EctskinError, match=rf"cannot listen on 127.0.0.1:{port}.*another port"):
            DashboardServer(FakeEngine(), port=port)
    with pytest.raises(EctskinError, match="port must be an integer 0..65535, got 70000"):
        DashboardServer(FakeEngine(), port=70000)
    with pytest.raises(EctskinError, match="pass layout="):
        DashboardServer(object(), port=_free_port())


def test_serve_runs_until_ctrl_c(tmp_path):
    """``serve()`` (what ``ectskin live`` calls) in a real process: the page is served from a
    replayed recording through the real LiveEngine, and SIGINT stops it promptly."""
    import os
    import signal
    import subprocess
    import sys

    import httpx

    from ectskin.io.hdf5 import RecordingWriter

    path = tmp_path / "rest.h5"
    with RecordingWriter(path, LAYOUT, 30.0) as w:
        w.start_trial("rest", inflation=(0, 0, 0))
        w.append(np.ones((60, LAYOUT.n_pairs)), np.arange(60) / 30.0)
    code = (
        "import sys\n"
        "from ectskin.dashboard import serve\n"
        "from ectskin.live import LiveEngine, open_source\n"
        f"engine = LiveEngine(open_source({'replay:' + str(path)!r}, loop=True))\n"
        "serve(engine, port=0, on_ready=lambda url: print(url, flush=True))\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), (url, proc.stderr.read() if not url else "")
        deadline = time.monotonic() + 10
        while True:
            try:
                stats = httpx.get(url + "api/stats", timeout=2).json()
                if stats["processed"] > 0:
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, "server did not come up with frames"
            time.sleep(0.1)
        assert httpx.get(url + "api/meta").json()["n_pairs"] == 28
        t0 = time.monotonic()
        os.kill(proc.pid, signal.SIGINT)
        proc.wait(timeout=10)
        assert time.monotonic() - t0 < 8
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    with pytest.raises(httpx.TransportError):
        httpx.get(url + "api/stats", timeout=1)


def test_hub_with_the_real_engine():
    """Meta and stats of a real (not yet running) LiveEngine pass through unchanged."""
    from ectskin.io.recording import Recording, Trial
    from ectskin.live import LiveEngine, ReplaySource

    trial = Trial("rest", np.ones((5, LAYOUT.n_pairs)), np.arange(5) / 30.0, np.zeros(5))
    engine = LiveEngine(ReplaySource(Recording(LAYOUT, [trial], 30.0)), reference_markers=REST)
    hub = Hub(LAYOUT, engine)
    with local_client(create_app(hub)) as c:
        meta = c.get("/api/meta").json()
        stats = c.get("/api/stats").json()
        assert c.post("/api/reference").json()["ok"]
    assert meta["touch_model"] is False and meta["track_model"] is False
    assert meta["policy"] == "skip-to-newest"
    assert meta["reference_markers"] == REST.tolist()  # the engine's fallback pose
    assert meta["electrodes"][4]["surface"] == "back"  # the dashboard's own fields win
    assert stats["frames"] == 0 and stats["latency_ms_p50"] is None
    assert stats["reference_ready"] is False


# --------------------------------------------------------------------------- skips never fail CI
REPO = Path(__file__).resolve().parents[2]
BROWSER_TEST = REPO / "tests" / "dashboard" / "test_dashboard_browser.py"


def test_browser_test_fails_in_ci_instead_of_skipping(tmp_path):
    """Without Chromium the browser test once skipped silently, also in CI. With CI set it
    must fail; on a developer's machine it may still skip."""
    import subprocess
    import sys

    env = dict(os.environ, ECTSKIN_CHROMIUM=str(tmp_path / "no-chromium"), CI="true")
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(BROWSER_TEST)]
    r = subprocess.run(argv, env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode != 0, r.stdout
    assert "the dashboard's browser test must run in CI" in r.stdout
    env["CI"] = ""
    r = subprocess.run(argv, env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
    # a module skipped at collection: pytest exits 5 (no tests ran) and reports the skip
    assert r.returncode in (0, 5) and "SKIPPED [1]" in r.stdout, r.stdout


def test_make_browser_fails_loudly_when_chromium_cannot_be_installed(tmp_path):
    """`make browser` once printed a line and succeeded when apt-get failed, so `make test`
    went on and the browser test skipped. Now the target fails."""
    import shutil
    import subprocess

    make = shutil.which("make")
    assert make, "make is needed to run the project's targets"
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "apt-get").write_text('#!/bin/sh\necho "E: Could not resolve host" >&2\nexit 100\n')
    (fake / "apt-get").chmod(0o755)
    argv = [make, "-s", "-C", str(REPO), "browser", f"CHROMIUM={tmp_path / 'no-chromium'}"]
    r = subprocess.run(argv, env=dict(os.environ, PATH=f"{fake}:{os.environ['PATH']}"),
                       capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "could not install chromium with apt-get" in r.stderr, r.stderr
    empty = tmp_path / "empty"  # no apt-get at all
    empty.mkdir()
    r = subprocess.run(argv, env=dict(os.environ, PATH=str(empty)), capture_output=True,
                       text=True, timeout=60)
    assert r.returncode != 0 and "apt-get is not available" in r.stderr, r.stderr
    # with the browser there it succeeds and installs nothing
    chromium = tmp_path / "chromium"
    chromium.write_text("#!/bin/sh\n")
    chromium.chmod(0o755)
    argv[-1] = f"CHROMIUM={chromium}"
    r = subprocess.run(argv, env=dict(os.environ, PATH=str(empty)), capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
