"""Frames from a TCP server speaking the line protocol (``tcp:HOST:PORT``; ectskin is the client)."""

from __future__ import annotations

import logging
import socket
import time
from collections.abc import Iterator

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout, default_layout
from ectskin.live.sources.base import Frame
from ectskin.live.sources.lines import LineSource

logger = logging.getLogger(__name__)


class TcpSource(LineSource):
    """Frames from a TCP server speaking the line protocol (ectskin is the client).

    The first connection must succeed within ``connect_timeout_s`` (retrying with backoff), else
    :class:`EctskinError`. When the server goes away later, the source counts a disconnect and
    reconnects with exponential backoff (``backoff_s`` = first, max delay) until it succeeds (a
    reconnect) or the source is closed. A line cut by the disconnect counts as malformed.
    """

    def __init__(
        self,
        host: str,
        port: int,
        *,
        layout: SensorLayout | None = None,
        connect_timeout_s: float = 10.0,
        backoff_s: tuple[float, float] = (0.05, 2.0),
        read_timeout_s: float = 0.2,
    ):
        super().__init__(layout or default_layout())
        self.host, self.port = host, int(port)
        self.name = f"tcp:{host}:{port}"
        self.backoff_s = backoff_s
        self.read_timeout_s = read_timeout_s
        self._sock: socket.socket | None = None
        deadline = time.monotonic() + connect_timeout_s
        delay = backoff_s[0]
        while True:
            err = self._connect()
            if err is None:
                break
            if time.monotonic() + delay > deadline:
                raise EctskinError(
                    f"{self.name}: cannot connect ({err}); tried for {connect_timeout_s:g} s"
                )
            time.sleep(delay)
            delay = min(delay * 2, backoff_s[1])

    def _connect(self) -> str | None:
        try:
            s = socket.create_connection((self.host, self.port), timeout=2.0)
        except OSError as exc:
            return exc.strerror or str(exc)
        s.settimeout(self.read_timeout_s)
        self._sock = s
        return None

    def _frames(self) -> Iterator[Frame]:
        delay = self.backoff_s[0]
        while not self._closed.is_set():
            if self._sock is None:
                if self._sleep(delay):
                    return
                err = self._connect()
                if err is None:
                    self._count("reconnects")
                    logger.info("%s: reconnected", self.name)
                    delay = self.backoff_s[0]
                else:
                    logger.debug(
                        "%s: reconnect failed (%s); next try in %.2f s", self.name, err, delay
                    )
                    delay = min(delay * 2, self.backoff_s[1])
                continue
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError as exc:
                data, why = b"", str(exc)
            else:
                why = "server closed the connection"
            if not data:
                self._problem("disconnects", f"{self.name}: disconnected ({why}); reconnecting")
                self._drop_partial("a disconnect")
                self._close_sock()
                continue
            yield from self._feed(data)

    def _close_sock(self) -> None:
        s, self._sock = self._sock, None
        if s is not None:
            try:
                s.close()
            except OSError:
                pass

    def _release(self) -> None:
        self._close_sock()
