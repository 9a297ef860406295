"""The dashboard's web app: a FastAPI application that serves the page, a JSON API and the stream.

Routes of :func:`create_app`:

==========================  =====================================================================
``GET /``                   the page (``static/index.html``; scripts and styles under ``/static``)
``GET /api/meta``           layout for drawing: pair names, regions, skins, electrodes, markers
``GET /api/stats``          the engine's counters (``engine.stats``) plus the dashboard's own
``POST /api/reference``     ``engine.capture_reference()``: re-capture the calibration reference
``WS /ws``                  ``meta``, then ``history`` (last ~10 s at ≤ 30 Hz), then ``status``
                            (the engine is running, has ended, or failed) and ``frame`` messages
                            (``Output.to_json_dict()``): always the newest, at most
                            ``max_rate_hz`` per second (:class:`~ectskin.dashboard.hub.TokenBucket`);
                            a new ``status`` whenever the engine's state changes
==========================  =====================================================================

Non-finite numbers (NaN for masked channels) are sent as JSON ``null``
(:mod:`ectskin.dashboard.messages`). There is no authentication: every request must be addressed
to a loopback host or one of ``allowed_hosts`` (DNS rebinding), and requests whose ``Origin`` is
another site are refused (:mod:`ectskin.dashboard.security`).

FastAPI is optional (the ``live`` extra): it is imported when an app is built. No
``from __future__ import annotations`` here: FastAPI reads the route functions' annotations
(``Request``, ``WebSocket``), which are imported inside :func:`create_app`.
"""

import asyncio
from collections.abc import Iterable
from pathlib import Path

from ectskin._check import EctskinError
from ectskin.dashboard.hub import Hub, TokenBucket
from ectskin.dashboard.messages import encode
from ectskin.dashboard.security import HostCheck, same_origin

STATIC_DIR = Path(__file__).resolve().parent / "static"


def require_fastapi() -> None:
    """Raise a clear error when FastAPI is not installed."""
    try:
        import fastapi  # noqa: F401
    except ImportError:  # pragma: no cover - depends on the environment
        raise EctskinError(
            "the dashboard needs FastAPI and uvicorn: pip install 'ectskin[live]'"
        ) from None


def create_app(hub: Hub, allowed_hosts: Iterable[str] = ()):
    """The FastAPI application serving the page, the JSON API and the ``/ws`` stream of ``hub``.

    Requests are answered only when addressed to a loopback host (``127.0.0.1``, ``localhost``,
    ``::1``…) or one of ``allowed_hosts`` (:class:`~ectskin.dashboard.security.HostCheck`)."""
    require_fastapi()
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
    app.add_middleware(HostCheck, allowed=tuple(allowed_hosts))
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
        if not same_origin(request.headers.get("origin"), request.headers.get("host")):
            return JSONResponse({"ok": False, "error": "cross-origin request refused"},
                                status_code=403)
        try:
            result = await asyncio.to_thread(hub.capture_reference)
        except EctskinError as exc:
            return JSONResponse({"ok": False, "error": str(exc)}, status_code=409)
        return JSONResponse(result, headers=no_store)

    @app.websocket("/ws")
    async def stream(ws: WebSocket) -> None:
        if not same_origin(ws.headers.get("origin"), ws.headers.get("host")):
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
            await ws.send_text(encode(hub.meta()))
            await ws.send_text(encode(hub.history_message()))
            status_version, status = hub.status()
            await ws.send_text(encode(status))
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
                version, status = hub.status()
                if version != status_version:
                    await ws.send_text(encode(status))
                    status_version = version
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
