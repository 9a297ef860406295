"""The live dashboard: a FastAPI app that streams the live engine's outputs to a browser page.

The engine runs in its own thread and hands every :class:`~ectskin.live.engine.Output` to a
:class:`Hub` (``engine.run(on_output=hub.publish)``). The hub keeps only the newest output; each
websocket client is woken when a new one arrives and is sent the newest one at most
``max_rate_hz`` times a second (frames in between are skipped for that client, never queued), so a
slow browser can never slow the engine down.

Routes of :func:`create_app`:

==========================  =====================================================================
``GET /``                   the page (``static/index.html``; scripts and styles under ``/static``)
``GET /api/meta``           layout for drawing: pair names, regions, skins, electrodes, markers
``GET /api/stats``          the engine's counters (``engine.stats``) plus the dashboard's own
``POST /api/reference``     ``engine.capture_reference()``: re-capture the calibration reference
``WS /ws``                  ``meta``, then ``history`` (last ~10 s at ≤ 30 Hz), then ``frame``
                            messages (``Output.to_json_dict()``): always the newest, at most
                            ``max_rate_hz`` per second (:class:`TokenBucket`)
==========================  =====================================================================

Non-finite numbers (NaN for masked channels) are sent as JSON ``null``. There is no
authentication: :func:`serve` binds 127.0.0.1 unless told otherwise, and requests whose
``Origin`` is another site are refused (so a web page cannot trigger a re-capture).
"""

import asyncio
import json
import logging
import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, Self
from urllib.parse import urlsplit

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent / "static"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: Upper bound on messages per second and client (the readout runs at 30 fps).
DEFAULT_MAX_RATE_HZ = 30.0
#: Seconds of readouts replayed to a page that connects mid-run (sampled at ≤ max_rate_hz).
DEFAULT_HISTORY_S = 10.0


# --------------------------------------------------------------------------- JSON helpers
def _sanitize(obj: Any) -> Any:
    """A copy of ``obj`` that ``json.dumps(..., allow_nan=False)`` accepts.

    NumPy arrays and scalars become lists and Python numbers; NaN and ±inf become ``None``.
    """
    if isinstance(obj, dict):
        return {str(k): _sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_sanitize(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _sanitize(obj.tolist())
    if isinstance(obj, np.generic):
        return _sanitize(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    return obj


def to_json_text(obj: Any) -> str:
    """Encode a message as compact, strict JSON (NaN/inf → ``null``, NumPy → lists)."""
    try:
        return json.dumps(obj, allow_nan=False, separators=(",", ":"))
    except (TypeError, ValueError):
        return json.dumps(_sanitize(obj), allow_nan=False, separators=(",", ":"))


def _as_dict(output: Any) -> dict[str, Any]:
    """An engine output as a JSON-able dict (``Output.to_json_dict()``, or a dict as is)."""
    if isinstance(output, dict):
        return output
    to_dict = getattr(output, "to_json_dict", None)
    if to_dict is None:
        raise EctskinError(
            f"dashboard: published outputs must be dicts or have to_json_dict(), "
            f"got {type(output).__name__}"
        )
    return to_dict()


# --------------------------------------------------------------------------- meta
def build_meta(
    layout: SensorLayout, *, reference_markers: Any = None, n_classes: int | None = None
) -> dict[str, Any]:
    """The ``meta`` message: everything the page needs to draw ``layout``.

    Built from :meth:`SensorLayout.to_dict`. Electrodes carry their ``surface``; pairs their two
    surfaces (``pair_surfaces``, (n_pairs, 2)) so the chart can colour same-face and cross-face
    pairs apart. ``reference_markers`` is (n_markers, 3) mm or ``None`` when not known yet (each
    frame carries the engine's current reference anyway).
    """
    d = layout.to_dict()
    skin_surface = {s["name"]: s["surface"] for s in d["skins"]}
    electrodes = [dict(e, surface=skin_surface[e["skin"]]) for e in d["electrodes"]]
    surf = [e["surface"] for e in electrodes]
    if reference_markers is not None:
        reference_markers = np.asarray(reference_markers, dtype=np.float64)
        if reference_markers.shape != (layout.n_markers, 3):
            raise EctskinError(
                f"dashboard: reference_markers must have shape ({layout.n_markers}, 3) for layout "
                f"{layout.name!r}, got {reference_markers.shape}"
            )
    return _sanitize(
        {
            "type": "meta",
            "layout_name": layout.name,
            "n_pairs": layout.n_pairs,
            "pair_names": list(layout.pair_names),
            "pair_surfaces": [[surf[i], surf[j]] for i, j in layout.pairs],
            "n_classes": int(n_classes) if n_classes is not None else layout.n_classes,
            "regions": d["regions"],
            "skins": d["skins"],
            "electrodes": electrodes,
            "marker_names": [m["name"] for m in d["markers"]],
            "markers": d["markers"],
            "reference_markers": reference_markers,
        }
    )


# --------------------------------------------------------------------------- hub
class TokenBucket:
    """Rate limit: ``rate_hz`` messages per second in the long run, bursts of ``burst`` at most.

    ``burst`` a little above 1 (default 1.25) lets a message that was late by up to a quarter
    period go out without delaying the next one: with frames arriving at exactly ``rate_hz``,
    a plain minimum gap would add up to one period of latency that never decays. Any window of
    T seconds holds at most ``floor(burst + rate_hz·T)`` messages.
    """

    def __init__(self, rate_hz: float, burst: float = 1.25) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0 and burst >= 1):
            raise EctskinError(
                f"TokenBucket: need rate_hz > 0 and burst >= 1, got {rate_hz!r}, {burst!r}"
            )
        self.rate_hz = float(rate_hz)
        self.burst = float(burst)
        self._tokens = 1.0
        self._t: float | None = None

    def _refill(self, now: float) -> None:
        if self._t is not None:
            self._tokens = min(self.burst, self._tokens + (now - self._t) * self.rate_hz)
        self._t = now

    def wait_s(self, now: float) -> float:
        """Seconds (≥ 0) until a message may be sent."""
        self._refill(now)
        return max(0.0, (1.0 - self._tokens) / self.rate_hz)

    def take(self, now: float) -> None:
        """Spend one token for a message sent at ``now``."""
        self._refill(now)
        self._tokens -= 1.0


class _Subscriber:
    """One websocket client's wake-up call: an asyncio.Event set from any thread."""

    __slots__ = ("closed", "event", "loop", "pending")

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.event = asyncio.Event()
        self.pending = False  # a set() is already scheduled on the loop
        self.closed = False

    def wake(self) -> None:
        """Schedule ``event.set()`` on the subscriber's loop (thread-safe, coalesced)."""
        if self.pending:
            return
        self.pending = True
        try:
            self.loop.call_soon_threadsafe(self._set)
        except RuntimeError:  # loop closed: the client is gone
            self.closed = True

    def _set(self) -> None:
        self.pending = False
        self.event.set()


class Hub:
    """The meeting point of the engine thread and the web server's asyncio loop.

    ``hub.publish(output)`` (also ``hub(output)``, so ``engine.run(on_output=hub)`` works) is
    thread-safe and O(number of clients): it stores the newest output and wakes the clients;
    JSON encoding happens later, on the server's loop, only for outputs actually sent.

    Parameters
    ----------
    layout : SensorLayout
        Drawn by the page (regions, electrodes, markers).
    engine : object, optional
        The live engine; ``/api/stats`` reads ``engine.stats`` (dict) and ``/api/reference`` calls
        ``engine.capture_reference()``. Without one, stats come from the newest output.
    max_rate_hz : float
        Most messages per second and client (default 30).
    history_s : float
        Seconds of readouts (sampled at ≤ ``max_rate_hz``) sent to a page when it connects.
    reference_markers : array (n_markers, 3) mm, optional
        Sent in ``meta``; by default ``engine.reference_markers`` if the engine has it.
    """

    def __init__(
        self,
        layout: SensorLayout,
        engine: Any = None,
        *,
        max_rate_hz: float = DEFAULT_MAX_RATE_HZ,
        history_s: float = DEFAULT_HISTORY_S,
        reference_markers: Any = None,
    ) -> None:
        if not isinstance(layout, SensorLayout):
            raise EctskinError(
                f"dashboard: layout must be a SensorLayout, got {type(layout).__name__}"
            )
        if not (isinstance(max_rate_hz, (int, float)) and math.isfinite(max_rate_hz)
                and max_rate_hz > 0):
            raise EctskinError(f"dashboard: max_rate_hz must be a number > 0, got {max_rate_hz!r}")
        if not (isinstance(history_s, (int, float)) and math.isfinite(history_s)
                and history_s >= 0):
            raise EctskinError(f"dashboard: history_s must be a number >= 0, got {history_s!r}")
        if engine is not None:
            for attr in ("stats", "capture_reference"):
                if not hasattr(engine, attr):
                    raise EctskinError(
                        f"dashboard: engine {type(engine).__name__} has no {attr!r} "
                        "(expected a LiveEngine)"
                    )
        if reference_markers is not None:
            build_meta(layout, reference_markers=reference_markers)  # checks the shape now
        self.layout = layout
        self.engine = engine
        self.max_rate_hz = float(max_rate_hz)
        self.history_s = float(history_s)
        self._reference_markers = reference_markers
        self._lock = threading.Lock()
        self._latest: Any = None
        self._version = 0
        self._encoded: tuple[int, str] | None = None  # cache, touched on the server loop only
        self._subscribers: set[_Subscriber] = set()
        n_hist = max(1, math.ceil(self.history_s * self.max_rate_hz) + 1)
        self._history: deque[tuple[float, Any]] = deque(maxlen=n_hist)
        self._last_history_t = -math.inf
        self.messages_sent = 0
        self.reference_requests = 0
        self.engine_error: str | None = None
        self.engine_running = False

    # ------------------------------------------------------------- engine side (any thread)
    def publish(self, output: Any) -> None:
        """Store ``output`` (an ``Output`` or a frame dict) as the newest and wake the clients."""
        now = time.monotonic()
        with self._lock:
            self._latest = output
            self._version += 1
            if now - self._last_history_t >= 1.0 / self.max_rate_hz:
                self._history.append((now, output))
                self._last_history_t = now
            subscribers = tuple(self._subscribers)
        for sub in subscribers:
            sub.wake()

    __call__ = publish

    @property
    def n_published(self) -> int:
        """Outputs published so far."""
        return self._version

    @property
    def n_clients(self) -> int:
        """Websocket clients connected now."""
        return len(self._subscribers)

    def latest(self) -> tuple[int, Any]:
        """``(version, output)`` of the newest output (``(0, None)`` before the first)."""
        with self._lock:
            return self._version, self._latest

    # ------------------------------------------------------------- server side
    def meta(self) -> dict[str, Any]:
        """The ``meta`` message (see :func:`build_meta`).

        With an engine that has ``meta()`` (LiveEngine), its current reference markers and its
        extra fields (``touch_model``, ``track_model``, ``policy``) are included.
        """
        ref = self._reference_markers
        extra: dict[str, Any] = {}
        engine_meta = getattr(self.engine, "meta", None) if self.engine is not None else None
        if callable(engine_meta):
            extra = dict(engine_meta())
            if ref is None:
                ref = extra.get("reference_markers")
        if ref is None and self.engine is not None:
            ref = getattr(self.engine, "reference_markers", None)
        meta = build_meta(self.layout, reference_markers=ref)
        for key, value in extra.items():
            meta.setdefault(key, _sanitize(value))
        return meta

    def stats(self) -> dict[str, Any]:
        """The engine's counters plus ``dashboard`` (clients, published, sent, engine state)."""
        if self.engine is not None:
            stats = dict(self.engine.stats)
        else:
            _, out = self.latest()
            stats = dict(_as_dict(out).get("stats") or {}) if out is not None else {}
        stats["dashboard"] = {
            "clients": self.n_clients,
            "published": self.n_published,
            "sent": self.messages_sent,
            "reference_requests": self.reference_requests,
            "engine_running": self.engine_running,
            "engine_error": self.engine_error,
        }
        return _sanitize(stats)

    def capture_reference(self) -> dict[str, Any]:
        """Ask the engine to re-capture its reference from the next frames."""
        if self.engine is None:
            raise EctskinError("dashboard: no live engine attached, nothing to re-capture")
        self.engine.capture_reference()
        self.reference_requests += 1
        logger.info("reference re-capture requested from the dashboard (#%d)",
                    self.reference_requests)
        return {"ok": True, "reference_requests": self.reference_requests}

    def encoded_latest(self) -> tuple[int, str | None]:
        """``(version, JSON text)`` of the newest output, encoded once however many clients."""
        version, out = self.latest()
        if out is None:
            return 0, None
        cached = self._encoded
        if cached is not None and cached[0] == version:
            return cached
        text = to_json_text(_as_dict(out))
        self._encoded = (version, text)
        return version, text

    def history_message(self) -> dict[str, Any]:
        """``{"type": "history", "frames": [{seq, t, raw, calibrated, age_s}, ...]}``, oldest
        first; ``age_s`` is how long ago (s) the frame was published, for the page's time axis."""
        now = time.monotonic()
        with self._lock:
            items = [(t, out) for t, out in self._history if t >= now - self.history_s]
        frames = []
        for t, out in items:
            d = _as_dict(out)
            frame = {k: d.get(k) for k in ("seq", "t", "raw", "calibrated")}
            frame["age_s"] = round(now - t, 4)
            frames.append(frame)
        return {"type": "history", "frames": frames}

    def subscribe(self) -> _Subscriber:
        """Register a client on the running loop; new outputs set its event."""
        sub = _Subscriber(asyncio.get_running_loop())
        with self._lock:
            self._subscribers.add(sub)
            has_output = self._version > 0
        if has_output:
            sub.event.set()
        return sub

    def unsubscribe(self, sub: _Subscriber) -> None:
        sub.closed = True
        with self._lock:
            self._subscribers.discard(sub)

    def close(self) -> None:
        """Wake every client so that its stream ends (server shutdown)."""
        with self._lock:
            subscribers = tuple(self._subscribers)
        for sub in subscribers:
            sub.closed = True
            sub.wake()


# --------------------------------------------------------------------------- app
def _require_fastapi():
    try:
        import fastapi  # noqa: F401
    except ImportError:  # pragma: no cover - depends on the environment
        raise EctskinError(
            "the dashboard needs FastAPI and uvicorn: pip install 'ectskin[live]'"
        ) from None


def _same_origin(origin: str | None, host: str | None) -> bool:
    """True without an ``Origin`` header (not a browser) or when it names the page's own host."""
    if not origin:
        return True
    if origin == "null":
        return False
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    return bool(host) and parts.netloc.lower() == host.lower()


def create_app(hub: Hub):
    """The FastAPI application serving the page, the JSON API and the ``/ws`` stream of ``hub``."""
    _require_fastapi()
    from fastapi import FastAPI, Request, WebSocket
    from fastapi.responses import FileResponse, JSONResponse
    from fastapi.staticfiles import StaticFiles
    from starlette.websockets import WebSocketDisconnect, WebSocketState

    if not isinstance(hub, Hub):
        raise EctskinError(f"create_app: expected a dashboard Hub, got {type(hub).__name__}")
    if not (STATIC_DIR / "index.html").is_file():
        raise EctskinError(f"dashboard: page missing at {STATIC_DIR / 'index.html'} (broken install?)")

    app = FastAPI(title="ectskin live dashboard", docs_url=None, redoc_url=None,
                  openapi_url=None)
    app.state.hub = hub
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    no_store = {"Cache-Control": "no-store"}

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", headers=no_store)

    @app.get("/api/meta")
    async def meta() -> JSONResponse:
        return JSONResponse(hub.meta(), headers=no_store)

    @app.get("/api/stats")
    async def stats() -> JSONResponse:
        return JSONResponse(hub.stats(), headers=no_store)

    @app.post("/api/reference")
    async def reference(request: Request) -> JSONResponse:
        if not _same_origin(request.headers.get("origin"), request.headers.get("host")):
            return JSONResponse({"ok": False, "error": "cross-origin request refused"},
                                status_code=403)
        try:
            result = await asyncio.to_thread(hub.capture_reference)
        except EctskinError as exc:
            return JSONResponse({"ok": False, "error": str(exc)}, status_code=409)
        return JSONResponse(result, headers=no_store)

    @app.websocket("/ws")
    async def stream(ws: WebSocket) -> None:
        if not _same_origin(ws.headers.get("origin"), ws.headers.get("host")):
            await ws.close(code=1008)
            return
        await ws.accept()
        sub = hub.subscribe()

        async def watch_disconnect() -> None:
            # The page sends nothing we act on; reading is how a closed socket is noticed.
            try:
                while True:
                    msg = await ws.receive()
                    if msg["type"] == "websocket.disconnect":
                        break
            except (WebSocketDisconnect, RuntimeError):
                pass
            finally:
                sub.closed = True
                sub.event.set()

        watcher = asyncio.create_task(watch_disconnect())
        bucket = TokenBucket(hub.max_rate_hz)
        loop = asyncio.get_running_loop()
        sent_version = 0
        try:
            await ws.send_text(to_json_text(hub.meta()))
            await ws.send_text(to_json_text(hub.history_message()))
            while not sub.closed:
                await sub.event.wait()
                if sub.closed:
                    break
                wait = bucket.wait_s(loop.time())
                if wait > 0:  # throttle to max_rate_hz; frames published meanwhile are skipped
                    await asyncio.sleep(wait)
                    if sub.closed:
                        break
                sub.event.clear()
                version, text = hub.encoded_latest()
                if text is None or version == sent_version:
                    continue
                bucket.take(loop.time())
                await ws.send_text(text)
                sent_version = version
                hub.messages_sent += 1
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass  # the client went away mid-send
        finally:
            hub.unsubscribe(sub)
            watcher.cancel()
            if ws.application_state == WebSocketState.CONNECTED:
                try:
                    await ws.close()
                except (WebSocketDisconnect, RuntimeError, OSError):
                    pass  # closed from the other side meanwhile

    return app


# --------------------------------------------------------------------------- serving
def _bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (port 0 = any free port), or a clear error."""
    if not isinstance(port, int) or isinstance(port, bool) or not 0 <= port <= 65535:
        raise EctskinError(f"dashboard: port must be an integer 0..65535, got {port!r}")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise EctskinError(f"dashboard: cannot resolve host {host!r}: {exc.strerror}") from None
    family, _, _, _, addr = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(addr)
    except OSError as exc:
        sock.close()
        raise EctskinError(
            f"dashboard: cannot listen on {host}:{port} ({exc.strerror}); is another dashboard "
            "running? choose another port"
        ) from None
    sock.listen(128)
    sock.setblocking(False)
    return sock


class DashboardServer:
    """An engine thread plus a uvicorn server for its dashboard.

    ``start()`` runs both in background threads and returns once the server accepts connections
    (for tests and notebooks; ``url`` tells where). ``serve_forever()`` runs the server in the
    calling thread until Ctrl-C. ``stop()`` stops the engine and the server. The engine runs as
    ``engine.run(on_output=hub.publish, **run_kwargs)``; pass ``engine=None`` to publish into
    ``hub`` yourself.
    """

    def __init__(
        self,
        engine: Any,
        *,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        layout: SensorLayout | None = None,
        hub: Hub | None = None,
        max_rate_hz: float = DEFAULT_MAX_RATE_HZ,
        run_kwargs: dict[str, Any] | None = None,
        log_level: str = "warning",
    ) -> None:
        _require_fastapi()
        if hub is None:
            layout = layout if layout is not None else getattr(engine, "layout", None)
            if layout is None:
                raise EctskinError("dashboard: pass layout= (the engine has no .layout)")
            hub = Hub(layout, engine, max_rate_hz=max_rate_hz)
        self.hub = hub
        self.engine = engine
        self.host = host
        self.run_kwargs = dict(run_kwargs or {})
        self.log_level = log_level
        self._sock = _bind(host, port)
        self.port = int(self._sock.getsockname()[1])
        self._server = None
        self._server_thread: threading.Thread | None = None
        self._engine_thread: threading.Thread | None = None
        self._stopping = False
        if host not in ("127.0.0.1", "localhost", "::1"):
            logger.warning(
                "dashboard listening on %s: anyone who can reach this address can watch the "
                "stream and re-capture the reference (there is no authentication)", host
            )

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def _make_server(self):
        import uvicorn

        config = uvicorn.Config(
            create_app(self.hub), log_level=self.log_level, lifespan="off",
            timeout_graceful_shutdown=2,
        )
        self._server = uvicorn.Server(config)
        return self._server

    def _run_engine(self) -> None:
        self.hub.engine_running = True
        try:
            self.engine.run(on_output=self.hub.publish, **self.run_kwargs)
            if not self._stopping:
                logger.info("live engine finished; the dashboard keeps showing the last frame")
        except Exception as exc:  # shown on the page and in /api/stats, then re-raised in logs
            self.hub.engine_error = f"{type(exc).__name__}: {exc}"
            logger.exception("live engine stopped with an error")
        finally:
            self.hub.engine_running = False

    def _start_engine(self) -> None:
        if self.engine is None or not hasattr(self.engine, "run"):
            return
        self._engine_thread = threading.Thread(
            target=self._run_engine, name="ectskin-engine", daemon=True
        )
        self._engine_thread.start()

    def start(self, timeout_s: float = 10.0) -> "DashboardServer":
        """Start engine and server in background threads; return when the server is up."""
        server = self._make_server()
        self._server_thread = threading.Thread(
            target=server.run, kwargs={"sockets": [self._sock]}, name="ectskin-dashboard",
            daemon=True,
        )
        self._server_thread.start()
        deadline = time.monotonic() + timeout_s
        while not server.started:
            if not self._server_thread.is_alive():
                raise EctskinError(f"dashboard: server on {self.url} failed to start (see log)")
            if time.monotonic() > deadline:
                raise EctskinError(f"dashboard: server on {self.url} not up after {timeout_s} s")
            time.sleep(0.01)
        self._start_engine()
        logger.info("dashboard at %s", self.url)
        return self

    def serve_forever(self) -> None:
        """Run the engine in a thread and the server here until interrupted, then stop both."""
        server = self._make_server()
        self._start_engine()
        logger.info("dashboard at %s (Ctrl-C to stop)", self.url)
        try:
            server.run(sockets=[self._sock])
        finally:
            self.stop()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the engine (``engine.stop()``) and the server; join their threads."""
        self._stopping = True
        if self.engine is not None and hasattr(self.engine, "stop"):
            self.engine.stop()
        self.hub.close()
        if self._server is not None:
            self._server.should_exit = True
        for th in (self._engine_thread, self._server_thread):
            if th is not None and th is not threading.current_thread():
                th.join(timeout_s)
                if th.is_alive():
                    logger.warning("%s did not stop within %.1f s", th.name, timeout_s)
        try:
            self._sock.close()
        except OSError:
            pass

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def serve(
    engine: Any,
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    *,
    layout: SensorLayout | None = None,
    max_rate_hz: float = DEFAULT_MAX_RATE_HZ,
    run_kwargs: dict[str, Any] | None = None,
    log_level: str = "warning",
    on_ready: Callable[[str], None] | None = None,
) -> None:
    """Run ``engine`` and its dashboard on ``http://host:port/`` until Ctrl-C (blocking).

    Binds 127.0.0.1 by default: the dashboard has no authentication. ``layout`` defaults to
    ``engine.layout``; ``run_kwargs`` go to ``engine.run`` (e.g. ``duration_s``); ``on_ready``
    is called with the URL once the port is bound (the CLI prints it). When the engine ends (a
    replay without ``loop``), the page keeps showing the last frame until Ctrl-C. Ctrl-C stops
    engine and server, then re-raises ``KeyboardInterrupt`` (the CLI exits with 130).
    """
    server = DashboardServer(
        engine, host=host, port=port, layout=layout, max_rate_hz=max_rate_hz,
        run_kwargs=run_kwargs, log_level=log_level,
    )
    if on_ready is not None:
        on_ready(server.url)
    server.serve_forever()
