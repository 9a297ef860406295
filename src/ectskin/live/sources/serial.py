"""Frames from a serial port (pyserial) speaking the line protocol (``serial:PORT[@BAUD]``)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout, default_layout
from ectskin.live.sources.base import Frame
from ectskin.live.sources.lines import LineSource

logger = logging.getLogger(__name__)


class SerialSource(LineSource):
    """Frames from a serial port (pyserial) speaking the line protocol.

    ``port`` is a device (``/dev/ttyACM0``, ``COM3``) or any pyserial URL (``loop://``,
    ``socket://host:port``). A read error (device unplugged) counts a disconnect; the port is then
    reopened with backoff until it works again (a reconnect) or the source is closed.
    ``opener(port, baud, timeout)`` replaces ``serial.serial_for_url`` (tests).
    """

    def __init__(
        self,
        port: str,
        baud: int = 115200,
        *,
        layout: SensorLayout | None = None,
        timeout_s: float = 0.1,
        backoff_s: tuple[float, float] = (0.05, 2.0),
        opener: Callable[..., Any] | None = None,
    ):
        super().__init__(layout or default_layout())
        self.name = f"serial:{port}@{baud}"
        self.port, self.baud, self.timeout_s = port, int(baud), float(timeout_s)
        self.backoff_s = backoff_s
        if opener is None:
            try:  # pyserial is optional (the `live` extra): imported when a port is opened
                import serial
            except ImportError:
                raise EctskinError(
                    "serial sources need pyserial: pip install 'ectskin[live]'"
                ) from None

            def opener(port: str, baud: int, timeout: float):
                return serial.serial_for_url(port, baudrate=baud, timeout=timeout)

        self._opener = opener
        self._ser = self._open(first=True)

    def _open(self, first: bool = False):
        try:
            return self._opener(self.port, self.baud, self.timeout_s)
        except Exception as exc:  # pyserial raises SerialException / OSError / ValueError
            if first:
                raise EctskinError(f"{self.name}: cannot open the serial port: {exc}") from None
            return None

    def _frames(self) -> Iterator[Frame]:
        delay = self.backoff_s[0]
        while not self._closed.is_set():
            if self._ser is None:
                if self._sleep(delay):
                    return
                delay = min(delay * 2, self.backoff_s[1])
                self._ser = self._open()
                if self._ser is not None:
                    self._count("reconnects")
                    logger.info("%s: reconnected", self.name)
                continue
            try:
                data = self._ser.read(max(1, getattr(self._ser, "in_waiting", 0) or 1))
            except Exception as exc:  # SerialException, OSError: device gone
                self._problem("disconnects", f"{self.name}: read failed ({exc}); reopening")
                self._drop_partial("a disconnect")
                self._close_port()
                delay = self.backoff_s[0]
                continue
            if data:
                yield from self._feed(data)
                delay = self.backoff_s[0]

    def _close_port(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # closing a dead port may fail; nothing left to do
                pass

    def _release(self) -> None:
        self._close_port()
