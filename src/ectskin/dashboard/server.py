"""Serving the dashboard: the listening socket, the engine thread and the uvicorn server.

:class:`DashboardServer` runs an engine and the app of :mod:`ectskin.dashboard.app` for it, in
background threads (``start()``, for tests and notebooks) or with the server in the calling thread
(``serve_forever()``); :func:`serve` is the blocking call ``ectskin live --dashboard`` makes: it
returns when the engine ends (the source ended, ``duration_s`` passed), after telling the pages,
unless asked to keep serving until Ctrl-C. It binds 127.0.0.1 unless told otherwise
(:func:`~ectskin.dashboard.security.warn_if_public`) and answers only requests addressed to a
loopback name or a configured one (:func:`~ectskin.dashboard.security.host_allowed`).
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Self

from ectskin._check import EctskinError
from ectskin.dashboard.app import create_app, require_fastapi
from ectskin.dashboard.hub import DEFAULT_MAX_RATE_HZ, Hub
from ectskin.dashboard.security import warn_if_public
from ectskin.layout import SensorLayout

if TYPE_CHECKING:
    import uvicorn  # optional (the `live` extra): imported at run time by _make_server

logger = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: Seconds the server keeps running after the engine ended (``stop_when_done``), so that every
#: page hears that the stream has ended before the server goes away.
END_GRACE_S = 1.0
_WILDCARD_HOSTS = ("", "0.0.0.0", "::")


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
    calling thread until Ctrl-C, or, with ``stop_when_done``, until the engine has ended (plus
    :data:`END_GRACE_S`). ``stop()`` stops the engine and the server. The engine runs as
    ``engine.run(on_output=hub.publish, **run_kwargs)`` (``on_output``, if given, gets every
    output as well); pass ``engine=None`` to publish into ``hub`` yourself. Requests must be
    addressed to a loopback host, ``host`` itself (unless a wildcard) or one of
    ``allowed_hosts``. ``engine_exception`` keeps what the engine raised, if anything.
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
        allowed_hosts: Iterable[str] = (),
        on_output: Callable[[Any], None] | None = None,
        stop_when_done: bool = False,
    ) -> None:
        require_fastapi()
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
        self.allowed_hosts = tuple(allowed_hosts) + (() if host in _WILDCARD_HOSTS else (host,))
        self.on_output = on_output
        self.stop_when_done = bool(stop_when_done)
        self.engine_exception: BaseException | None = None
        self._done = threading.Event()  # set by stop(): ends the grace wait early
        self._sock = _bind(host, port)
        self.port = int(self._sock.getsockname()[1])
        self._server: uvicorn.Server | None = None
        self._server_thread: threading.Thread | None = None
        self._engine_thread: threading.Thread | None = None
        self._stopping = False
        warn_if_public(host)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def _make_server(self) -> uvicorn.Server:
        import uvicorn  # optional (the `live` extra), like FastAPI

        config = uvicorn.Config(
            create_app(self.hub, allowed_hosts=self.allowed_hosts),
            log_level=self.log_level,
            lifespan="off",
            timeout_graceful_shutdown=2,
        )
        self._server = uvicorn.Server(config)
        return self._server

    def _publish(self, output: Any) -> None:
        self.hub.publish(output)
        if self.on_output is not None:
            self.on_output(output)

    def _run_engine(self) -> None:
        self.hub.set_engine_state("running")
        try:
            self.engine.run(on_output=self._publish, **self.run_kwargs)
        except Exception as exc:  # shown on the page and in /api/stats
            self.engine_exception = exc
            self.hub.set_engine_state("error", f"{type(exc).__name__}: {exc}")
            if isinstance(exc, EctskinError):
                logger.error("live engine stopped: %s", exc)
            else:
                logger.exception("live engine stopped with an error")
        else:
            self.hub.set_engine_state("ended")
            if not self._stopping:
                logger.info(
                    "live engine finished; %s",
                    "stopping the dashboard"
                    if self.stop_when_done
                    else "the dashboard keeps showing the last frame",
                )
        if self.stop_when_done and not self._stopping:
            self._done.wait(END_GRACE_S)  # the pages hear "ended" before the server goes
            if self._server is not None:
                self._server.should_exit = True

    def _start_engine(self) -> None:
        if self.engine is None or not hasattr(self.engine, "run"):
            return
        self._engine_thread = threading.Thread(
            target=self._run_engine, name="ectskin-engine", daemon=True
        )
        self._engine_thread.start()

    def start(self, timeout_s: float = 10.0) -> Self:
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
        self._done.set()
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
    on_output: Callable[[Any], None] | None = None,
    keep_serving: bool = False,
    allowed_hosts: Iterable[str] = (),
) -> None:
    """Run ``engine`` and its dashboard on ``http://host:port/`` (blocking).

    Binds 127.0.0.1 by default: the dashboard has no authentication; requests must name a
    loopback host or one of ``allowed_hosts``. ``layout`` defaults to ``engine.layout``;
    ``run_kwargs`` go to ``engine.run`` (e.g. ``duration_s``); ``on_output`` gets every output
    too (e.g. a JSON-lines writer); ``on_ready`` is called with the URL once the port is bound
    (the CLI prints it). When the engine ends (its source ended, ``duration_s`` passed) the pages
    are told, and ``serve`` returns :data:`END_GRACE_S` later; with ``keep_serving`` the page
    keeps showing the last frame until Ctrl-C instead. An engine that failed is raised as an
    :class:`EctskinError` (without ``keep_serving``). Ctrl-C stops engine and server, then
    re-raises ``KeyboardInterrupt`` (the CLI exits with 130).
    """
    server = DashboardServer(
        engine,
        host=host,
        port=port,
        layout=layout,
        max_rate_hz=max_rate_hz,
        run_kwargs=run_kwargs,
        log_level=log_level,
        allowed_hosts=allowed_hosts,
        on_output=on_output,
        stop_when_done=not keep_serving,
    )
    if on_ready is not None:
        on_ready(server.url)
    server.serve_forever()
    exc = server.engine_exception
    if exc is not None and not keep_serving:
        if isinstance(exc, EctskinError):
            raise exc
        raise EctskinError(f"live engine stopped: {type(exc).__name__}: {exc}") from exc
