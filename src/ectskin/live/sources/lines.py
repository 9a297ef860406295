"""The shared base of the sources that receive the line protocol as bytes (serial, TCP).

:class:`LineSource` buffers the bytes, splits them into lines (discarding over-long ones and lines
cut by a disconnect), parses each line with :func:`~ectskin.live.sources.protocol.parse_line`,
numbers frames (the ``seq`` field, else the data-line count) and counts sequence gaps.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

from ectskin.layout import SensorLayout
from ectskin.live.sources.base import Frame, FrameSource
from ectskin.live.sources.protocol import MAX_LINE_BYTES, LineError, parse_line


class LineSource(FrameSource):
    """Shared parsing for sources that deliver the line protocol as bytes.

    Subclasses read bytes and pass them to :meth:`_feed` (which yields the complete frames), and
    call :meth:`_drop_partial` when a connection ends in the middle of a line.
    """

    def __init__(self, layout: SensorLayout):
        super().__init__(layout)
        self._buf = bytearray()
        self._line_no = 0  # lines received (any kind), 1-based in messages
        self._data_no = 0  # data lines (valid or not): the implicit frame number
        self._last_seq: int | None = None
        self._skip_to_newline = False  # inside the rest of an over-long line
        self._t0 = time.perf_counter()

    def _feed(self, data: bytes) -> Iterator[Frame]:
        """Split ``data`` into lines and parse the complete ones.

        An over-long line is one problem whatever its length: it is counted (and numbered) once,
        when the buffer first exceeds :data:`MAX_LINE_BYTES`; the rest of it, up to its newline,
        is discarded without being buffered.
        """
        if self._skip_to_newline:  # inside the rest of an over-long line
            nl = data.find(b"\n")
            if nl < 0:
                return
            data = data[nl + 1 :]
            self._skip_to_newline = False
        self._buf += data
        while True:
            nl = self._buf.find(b"\n")
            if nl < 0:
                if len(self._buf) > MAX_LINE_BYTES:
                    self._overlong()
                    self._buf.clear()
                    self._skip_to_newline = True
                return
            if nl > MAX_LINE_BYTES:
                self._overlong()
                del self._buf[: nl + 1]
                continue
            raw = bytes(self._buf[:nl])
            del self._buf[: nl + 1]
            frame = self._parse(raw)
            if frame is not None:
                yield frame

    def _overlong(self) -> None:
        """Count one over-long line (a data line: it takes a frame number)."""
        self._line_no += 1
        self._data_no += 1
        self._problem(
            "malformed",
            f"{self.name} line {self._line_no}: longer than {MAX_LINE_BYTES} bytes; discarded",
        )

    def _drop_partial(self, why: str) -> None:
        """A connection ended in the middle of a line: that line is lost (counted malformed)."""
        if self._buf.strip():
            self._line_no += 1
            self._data_no += 1
            self._problem("malformed", f"{self.name} line {self._line_no}: cut by {why}; discarded")
        self._buf.clear()
        self._skip_to_newline = False

    def _parse(self, raw: bytes) -> Frame | None:
        arrival = time.perf_counter()
        self._line_no += 1
        where = f"{self.name} line {self._line_no}"
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            self._data_no += 1
            self._problem("malformed", f"{where}: not UTF-8 text (byte {exc.start})")
            return None
        try:
            parsed = parse_line(text, self.n_pairs, self.n_markers, where)
        except LineError as exc:
            self._data_no += 1
            self._problem(exc.kind, str(exc))
            return None
        if parsed is None:
            return None
        self._data_no += 1
        if parsed.label is not None and parsed.label > self.layout.n_regions:
            self._problem(
                "malformed",
                f"{where}: field 'label' is {parsed.label}, expected "
                f"0..{self.layout.n_regions} (layout {self.layout.name!r})",
            )
            return None
        seq = parsed.seq if parsed.seq is not None else self._data_no - 1
        if self._last_seq is not None and seq > self._last_seq + 1:
            self._count("seq_gaps", seq - self._last_seq - 1)
        self._last_seq = seq
        return Frame(
            seq=seq,
            t=parsed.t if parsed.t is not None else arrival - self._t0,
            capacitance=parsed.capacitance,
            markers=parsed.markers,
            label=parsed.label,
            arrival=arrival,
        )
