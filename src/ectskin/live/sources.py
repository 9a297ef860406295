"""Live frame sources: one interface over replayed files, the digital twin, LSL, serial and TCP.

Every source is an iterator of :class:`Frame` with ``close()`` and a ``counters`` dict:

==================  ==========================================================================
counter             meaning
==================  ==========================================================================
``frames``          valid frames handed out
``malformed``       input that could not be parsed (bad number, unknown field, over-long line,
                    line cut by a disconnect, non-finite value other than ``nan``)
``wrong_channels``  input with the wrong number of channel values (or marker coordinates)
``disconnects``     connections lost (TCP server gone, serial device unplugged, LSL outlet lost)
``reconnects``      connections re-established after a disconnect
``seq_gaps``        frames missing according to the sequence numbers (lost upstream)
==================  ==========================================================================

Bad input is never raised into the consumer: it is counted, logged (rate-limited) and described in
``source.problems`` (the last 50 messages, each naming the source, the line or frame and the
channel). Only configuration errors found when a source is opened (a missing file, an unknown
stream name, a refused connection) raise :class:`~ectskin._check.EctskinError`.

``open_source(spec)`` builds a source from a short string: ``replay:FILE``, ``sim``,
``lsl:NAME``, ``serial:PORT[@BAUD]`` or ``tcp:HOST:PORT``. The serial/TCP line protocol is
documented in ``docs/serial-protocol.md`` and implemented by :func:`parse_line`.
"""

from __future__ import annotations

import logging
import math
import re
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout, default_layout

logger = logging.getLogger(__name__)

COUNTERS = ("frames", "malformed", "wrong_channels", "disconnects", "reconnects", "seq_gaps")
SOURCE_SPECS = "replay:FILE, sim, lsl:NAME, serial:PORT[@BAUD], tcp:HOST:PORT"
MAX_LINE_BYTES = 65536


@dataclass(frozen=True, eq=False)
class Frame:
    """One readout of all pairs, as delivered by a source.

    ``seq`` is the source's running frame number (gaps = frames lost upstream); ``t`` is in
    seconds on the source clock (the device timestamp if given, else arrival time since the source
    opened); ``capacitance`` is (n_pairs,) float64 pF with NaN for masked channels; ``markers`` is
    (n_markers, 3) mm or None; ``label`` the ground-truth class when the source knows it.
    ``trial`` names the trial the frame belongs to when the source knows it (replay), and
    ``arrival`` is the ``time.perf_counter()`` at which the frame entered the program (the start of
    the engine's latency measurement).
    """

    seq: int
    t: float
    capacitance: np.ndarray
    markers: np.ndarray | None = None
    label: int | None = None
    trial: str | None = None
    arrival: float = field(default_factory=time.perf_counter)


class LineError(EctskinError):
    """One line of the line protocol could not be used; ``kind`` is the counter it belongs to."""

    def __init__(self, message: str, kind: str = "malformed"):
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class ParsedLine:
    """The content of one data line (see :func:`parse_line`)."""

    capacitance: np.ndarray  # (n_pairs,) float64 pF, NaN = masked
    t: float | None = None
    seq: int | None = None
    label: int | None = None
    markers: np.ndarray | None = None  # (n_markers, 3) mm


_KEYS = ("t", "seq", "label", "markers")


def parse_line(
    text: str, n_pairs: int, n_markers: int = 0, where: str = "line"
) -> ParsedLine | None:
    """Parse one line of the serial/TCP line protocol (``docs/serial-protocol.md``).

    ``[key=value;]* v1,v2,...,vN [# comment]`` with keys ``t`` (s), ``seq`` (int), ``label`` (int)
    and ``markers`` (3 × n_markers comma-separated mm). Returns None for a blank or comment-only
    line. Raises :class:`LineError` naming ``where`` (e.g. ``"tcp:host:5000 line 17"``) and the
    offending channel; its ``kind`` is ``"wrong_channels"`` for a count mismatch, else
    ``"malformed"``.
    """
    body = text.split("#", 1)[0].strip()
    if not body:
        return None
    parts = [p.strip() for p in body.split(";")]
    if parts and parts[-1] == "" and len(parts) > 1:  # a trailing ';' after the values
        parts = parts[:-1]
    values_text: str | None = None
    info: dict[str, Any] = {}
    for part in parts:
        key, eq, value = part.partition("=")
        key = key.strip()
        if not eq:
            if values_text is not None:
                raise LineError(f"{where}: two value lists ({values_text[:20]!r}…, {part[:20]!r}…)")
            values_text = part
            continue
        if key not in _KEYS:
            raise LineError(
                f"{where}: unknown field {key!r}; allowed fields are {', '.join(_KEYS)}"
            )
        if key in info:
            raise LineError(f"{where}: field {key!r} given twice")
        value = value.strip()
        if key == "t":
            try:
                info["t"] = float(value)
            except ValueError:
                raise LineError(
                    f"{where}: field 't' must be a number of seconds, got {value!r}"
                ) from None
            if not math.isfinite(info["t"]):
                raise LineError(f"{where}: field 't' must be finite, got {value!r}")
        elif key in ("seq", "label"):
            try:
                info[key] = int(value)
            except ValueError:
                raise LineError(
                    f"{where}: field {key!r} must be an integer, got {value!r}"
                ) from None
            if info[key] < 0:
                raise LineError(f"{where}: field {key!r} must be >= 0, got {value!r}")
        else:  # markers
            m = _parse_values(
                value, 3 * n_markers, f"{where}: field 'markers'", "coordinate", allow_nan=True
            )
            info["markers"] = m.reshape(n_markers, 3)
    if values_text is None:
        raise LineError(f"{where}: no channel values (expected {n_pairs} comma-separated numbers)")
    cap = _parse_values(values_text, n_pairs, where, "channel", allow_nan=True)
    return ParsedLine(capacitance=cap, **info)


def _parse_values(text: str, n: int, where: str, what: str, *, allow_nan: bool) -> np.ndarray:
    """Comma-separated floats, exactly ``n`` of them (one trailing comma tolerated)."""
    tokens = text.split(",")
    if len(tokens) > 1 and tokens[-1].strip() == "":
        tokens = tokens[:-1]
    if len(tokens) != n:
        raise LineError(f"{where}: expected {n} {what} values, got {len(tokens)}", "wrong_channels")
    try:
        arr = np.array([float(tok) for tok in tokens], dtype=np.float64)
    except ValueError:
        for k, tok in enumerate(tokens):
            try:
                float(tok)
            except ValueError:
                raise LineError(
                    f"{where}: {what} {k + 1} of {n}: {tok.strip()!r} is not a number"
                ) from None
        raise  # pragma: no cover - float() failed on the whole list but on no token
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if bad.any():
        k = int(np.argmax(bad))
        raise LineError(
            f"{where}: {what} {k + 1} of {n}: {tokens[k].strip()!r} is not finite "
            f"(write 'nan' for a masked {what})"
        )
    return arr


class FrameSource:
    """Base class: an iterator of :class:`Frame` with counters, ``problems`` and ``close()``.

    Subclasses implement :meth:`_frames`; iteration stops when the source is exhausted (a replay
    reaches its end) or :meth:`close` is called (from any thread).
    """

    #: short description used in messages, e.g. ``"tcp:127.0.0.1:5000"``
    name: str = "source"
    #: nominal frame rate (Hz) if known, else None
    frame_rate_hz: float | None = None
    #: True / False when it is known whether frames carry markers, None when unknown
    provides_markers: bool | None = None

    def __init__(self, layout: SensorLayout):
        self.layout = layout
        self.n_pairs = layout.n_pairs
        self.n_markers = layout.n_markers
        self._counts = {k: 0 for k in COUNTERS}
        self._count_lock = threading.Lock()
        self._closed = threading.Event()
        self.problems: deque[str] = deque(maxlen=50)
        self._iterating = False

    # ------------------------------------------------------------------ interface
    @property
    def counters(self) -> dict[str, int]:
        """A snapshot of the counters (see the module docstring)."""
        with self._count_lock:
            return dict(self._counts)

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def close(self) -> None:
        """Stop the source (idempotent, callable from another thread).

        A source being iterated stops within its read timeout and frees its handles then; one
        that was never iterated frees them now.
        """
        self._closed.set()
        if not self._iterating:
            self._release()

    def __iter__(self) -> Iterator[Frame]:
        if self._iterating:
            raise EctskinError(f"{self.name}: a source can be iterated only once")
        self._iterating = True
        return self._counted(self._frames())

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ helpers
    def _frames(self) -> Iterator[Frame]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _counted(self, frames: Iterator[Frame]) -> Iterator[Frame]:
        try:
            for f in frames:
                self._count("frames")
                yield f
                if self._closed.is_set():
                    break
        finally:
            self._release()

    def _release(self) -> None:
        """Free handles (sockets, ports, inlets) when iteration ends."""

    def _count(self, kind: str, n: int = 1) -> None:
        with self._count_lock:
            self._counts[kind] += n

    def _problem(self, kind: str, message: str) -> None:
        """Count a problem of counter ``kind`` and keep/log its message (rate-limited)."""
        self._count(kind)
        self.problems.append(message)
        n = self._counts[kind]
        if n <= 10 or n % 100 == 0:
            logger.warning("%s (%s #%d)", message, kind, n)

    def _sleep(self, seconds: float) -> bool:
        """Sleep unless closed meanwhile; returns True if the source was closed."""
        return self._closed.wait(max(seconds, 0.0))


# =============================================================================== replay
class ReplaySource(FrameSource):
    """Replays an HDF5 recording (or an in-memory :class:`~ectskin.io.Recording`).

    ``speed=1.0`` paces frames by their timestamps (real time), ``speed=k`` k times faster,
    ``speed=math.inf`` as fast as possible. Trials play in file order (``trials`` selects names);
    between trials one frame period passes. ``loop=True`` starts again after the last trial
    (``seq`` keeps counting). ``Frame.t`` is the trial's own timestamp, ``Frame.trial`` its name.
    """

    def __init__(
        self,
        recording,
        *,
        speed: float = 1.0,
        loop: bool = False,
        trials: Sequence[str] | None = None,
        allow_partial: bool = False,
    ):
        from ectskin.io.recording import Recording

        if isinstance(recording, Recording):
            rec, self.name = recording, "replay:<memory>"
        else:
            from ectskin.io.hdf5 import read_recording

            rec = read_recording(recording, allow_partial=allow_partial)
            self.name = f"replay:{recording}"
        super().__init__(rec.layout)
        speed = float(speed)
        if not speed > 0:
            raise EctskinError(
                f"{self.name}: speed must be > 0 (inf = as fast as possible), got {speed}"
            )
        self.speed = speed
        self.loop = bool(loop)
        self.recording = rec
        self.frame_rate_hz = rec.frame_rate_hz
        if trials is None:
            self.trials = list(rec.trials)
        else:
            self.trials = [rec.trial(n) for n in trials]
        if not any(t.n_frames for t in self.trials):
            raise EctskinError(f"{self.name}: the recording holds no frames to replay")
        self.provides_markers = any(t.markers is not None for t in self.trials)

    def trial_info(self, name: str) -> dict[str, Any]:
        """Inflation (ml), region and meta of trial ``name`` (for the recorder)."""
        t = self.recording.trial(name)
        return {"inflation": t.inflation, "region": t.region, "meta": dict(t.meta)}

    def _frames(self) -> Iterator[Frame]:
        period = 1.0 / self.frame_rate_hz
        paced = math.isfinite(self.speed)
        start = time.perf_counter()
        virtual = 0.0  # seconds of recording time since the replay started
        seq = 0
        while True:
            for trial in self.trials:
                ts = trial.timestamps
                cap = trial.capacitance
                labels = trial.labels
                markers = trial.markers
                for i in range(trial.n_frames):
                    if self._closed.is_set():
                        return
                    if i:
                        virtual += ts[i] - ts[i - 1]
                    if paced:
                        delay = start + virtual / self.speed - time.perf_counter()
                        if delay > 0 and self._sleep(delay):
                            return
                    yield Frame(
                        seq=seq,
                        t=float(ts[i]),
                        capacitance=cap[i],
                        markers=None if markers is None else markers[i],
                        label=int(labels[i]),
                        trial=trial.name,
                    )
                    seq += 1
                virtual += period
            if not self.loop:
                return


# =============================================================================== twin
@dataclass(frozen=True)
class TwinStep:
    """One step of a twin scenario: hold ``inflation_ml`` and touch ``region`` (None = no touch)."""

    duration_s: float
    inflation_ml: tuple[float, float, float] = (0.0, 0.0, 0.0)
    region: int | None = None
    force_n: float = 1.0


def demo_scenario(
    layout: SensorLayout,
    *,
    seed: int = 0,
    step_s: float = 3.0,
    levels_ml: Sequence[float] = (0.0, 10.0, 20.0),
) -> Iterator[TwinStep]:
    """An endless random scenario: a new touch (or a lift) every ``step_s`` s, a new inflation
    state every third step; forces 0.5–2 N. Seeded, so a run is reproducible."""
    rng = np.random.default_rng(seed)
    infl = (0.0, 0.0, 0.0)
    k = 0
    while True:
        if k % 3 == 0 and k:
            infl = tuple(float(v) for v in rng.choice(levels_ml, size=3))
        region = None if rng.random() < 0.25 else int(rng.integers(1, layout.n_regions + 1))
        yield TwinStep(step_s, infl, region, float(rng.uniform(0.5, 2.0)))
        k += 1


class TwinSource(FrameSource):
    """The digital twin as a live source: wraps an object with the ``LiveTwin`` protocol
    (``set_inflation``, ``set_touch``, ``next_frame() -> (capacitance, markers, label)``).

    ``scenario`` is an iterable of :class:`TwinStep` (default :func:`demo_scenario`); when it ends,
    the source ends. ``paced=True`` delivers frames at the twin's frame rate, else as fast as the
    twin computes them. ``Frame.t = seq / frame_rate_hz`` (the twin's clock). A new
    (inflation, touch) state costs the twin some solves (~0.6 s for the paper's layout, then
    cached); a paced twin then resumes at its frame rate instead of bursting to catch up.
    """

    name = "sim"

    def __init__(
        self,
        twin=None,
        *,
        paced: bool = True,
        scenario: Iterable[TwinStep] | None = None,
        seed: int = 0,
        layout: SensorLayout | None = None,
        frame_rate_hz: float = 30.0,
    ):
        if twin is None:
            try:
                from ectskin.twin.live import LiveTwin
            except ImportError as exc:
                raise EctskinError(f"sim: the digital twin is not available ({exc})") from None
            twin = LiveTwin(layout, seed=seed, frame_rate_hz=frame_rate_hz)
        super().__init__(twin.layout)
        self.twin = twin
        self.frame_rate_hz = float(getattr(twin, "frame_rate_hz", frame_rate_hz))
        self.provides_markers = True
        self.paced = bool(paced)
        self.scenario = (
            iter(scenario) if scenario is not None else demo_scenario(self.layout, seed=seed)
        )

    def _frames(self) -> Iterator[Frame]:
        period = 1.0 / self.frame_rate_hz
        start = time.perf_counter()
        seq = 0
        for step in self.scenario:
            self.twin.set_inflation(tuple(step.inflation_ml))
            self.twin.set_touch(step.region, step.force_n)
            for _ in range(max(1, int(round(step.duration_s * self.frame_rate_hz)))):
                if self._closed.is_set():
                    return
                if self.paced:
                    delay = start + seq * period - time.perf_counter()
                    if delay < -2 * period:
                        # the twin was busy solving a new state: carry on from now, like a
                        # device that paused, rather than bursting frames to catch up
                        start -= delay
                    elif delay > 0 and self._sleep(delay):
                        return
                cap, markers, label = self.twin.next_frame()
                yield Frame(
                    seq=seq,
                    t=seq * period,
                    capacitance=np.asarray(cap, dtype=np.float64),
                    markers=None if markers is None else np.asarray(markers, dtype=np.float64),
                    label=None if label is None else int(label),
                )
                seq += 1


# =============================================================================== line sources
class _LineSource(FrameSource):
    """Shared parsing for sources that deliver the line protocol as bytes."""

    def __init__(self, layout: SensorLayout):
        super().__init__(layout)
        self._buf = bytearray()
        self._line_no = 0  # lines received (any kind), 1-based in messages
        self._data_no = 0  # data lines (valid or not): the implicit frame number
        self._last_seq: int | None = None
        self._skip_to_newline = False  # inside the rest of an over-long line
        self._t0 = time.perf_counter()

    def _feed(self, data: bytes) -> Iterator[Frame]:
        """Split ``data`` into lines and parse the complete ones."""
        self._buf += data
        while True:
            nl = self._buf.find(b"\n")
            if nl < 0:
                if len(self._buf) > MAX_LINE_BYTES:
                    self._line_no += 1
                    self._data_no += 1
                    self._problem(
                        "malformed",
                        f"{self.name} line {self._line_no}: longer than {MAX_LINE_BYTES} bytes; "
                        "discarded",
                    )
                    self._buf.clear()
                    self._skip_to_newline = True
                return
            raw = bytes(self._buf[:nl])
            del self._buf[: nl + 1]
            if self._skip_to_newline:
                self._skip_to_newline = False
                continue
            if nl > MAX_LINE_BYTES:
                self._line_no += 1
                self._data_no += 1
                self._problem(
                    "malformed",
                    f"{self.name} line {self._line_no}: longer than "
                    f"{MAX_LINE_BYTES} bytes; discarded",
                )
                continue
            frame = self._parse(raw)
            if frame is not None:
                yield frame

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


class SerialSource(_LineSource):
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
            try:
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


class TcpSource(_LineSource):
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


# =============================================================================== LSL
class LslSource(FrameSource):
    """Frames from a Lab Streaming Layer stream, resolved by name (pylsl).

    The stream must have ``n_pairs`` channels (capacitance, pF) or ``n_pairs + 3 * n_markers``
    (capacitance then marker x, y, z per marker, mm). ``Frame.t`` is the LSL timestamp. When the
    outlet disappears the source counts a disconnect, resolves the name again with backoff and
    counts a reconnect when a stream with the right channel count is back.
    """

    def __init__(
        self,
        stream_name: str,
        *,
        layout: SensorLayout | None = None,
        resolve_timeout_s: float = 5.0,
        backoff_s: tuple[float, float] = (0.1, 2.0),
    ):
        super().__init__(layout or default_layout())
        try:
            import pylsl
        except ImportError:
            raise EctskinError("lsl sources need pylsl: pip install 'ectskin[live]'") from None
        self._lsl = pylsl
        try:
            from pylsl.util import LostError
        except ImportError:  # older pylsl exposes it at the top level
            LostError = getattr(pylsl, "LostError", RuntimeError)
        self._lost_error = LostError
        self.stream_name = stream_name
        self.name = f"lsl:{stream_name}"
        self.backoff_s = backoff_s
        self._inlet = None
        info = self._resolve(resolve_timeout_s)
        if info is None:
            found = sorted({s.name() for s in pylsl.resolve_streams(wait_time=0.5)})
            raise EctskinError(
                f"{self.name}: no LSL stream named {stream_name!r} found within "
                f"{resolve_timeout_s:g} s; streams seen: {', '.join(found) or 'none'}"
            )
        err = self._check_channels(info)
        if err:
            raise EctskinError(err)
        self._open(info)

    def _resolve(self, timeout: float):
        res = self._lsl.resolve_byprop("name", self.stream_name, minimum=1, timeout=timeout)
        return res[0] if res else None

    def _check_channels(self, info) -> str | None:
        n = info.channel_count()
        ok = (
            (self.n_pairs, self.n_pairs + 3 * self.n_markers) if self.n_markers else (self.n_pairs,)
        )
        if n not in ok:
            want = " or ".join(str(k) for k in ok)
            return (
                f"{self.name}: stream has {n} channels, expected {want} "
                f"({self.n_pairs} pairs of layout {self.layout.name!r}"
                + (f" + 3 x {self.n_markers} marker coordinates)" if self.n_markers else ")")
            )
        return None

    def _open(self, info) -> None:
        self.frame_rate_hz = info.nominal_srate() or None
        self._with_markers = info.channel_count() > self.n_pairs
        self.provides_markers = self._with_markers
        # recover=False: a lost outlet raises LostError, which we count and handle ourselves.
        inlet = self._lsl.StreamInlet(info, max_buflen=60, recover=False)
        inlet.open_stream(timeout=5.0)
        self._inlet = inlet

    def _frames(self) -> Iterator[Frame]:
        seq = 0
        delay = self.backoff_s[0]
        while not self._closed.is_set():
            if self._inlet is None:
                info = self._resolve(min(delay, 1.0))
                if info is not None:
                    err = self._check_channels(info)
                    if err:
                        self._problem("wrong_channels", err + "; not reconnecting to it")
                    else:
                        try:
                            self._open(info)
                        except Exception as exc:  # pylsl raises TimeoutError / LostError
                            logger.debug("%s: reopen failed: %s", self.name, exc)
                        else:
                            self._count("reconnects")
                            logger.info("%s: reconnected", self.name)
                            delay = self.backoff_s[0]
                            continue
                if self._sleep(delay):
                    return
                delay = min(delay * 2, self.backoff_s[1])
                continue
            try:
                sample, ts = self._inlet.pull_sample(timeout=0.2)
                if sample is None:
                    continue
                samples, stamps = [sample], [ts]
                more, more_ts = self._inlet.pull_chunk(timeout=0.0, max_samples=1024)
                samples += more
                stamps += more_ts
            except self._lost_error:
                self._problem("disconnects", f"{self.name}: stream lost; resolving it again")
                self._close_inlet()
                continue
            arrival = time.perf_counter()
            for sample, ts in zip(samples, stamps, strict=True):
                v = np.asarray(sample, dtype=np.float64)
                cap = v[: self.n_pairs]
                if np.isinf(cap).any():
                    k = int(np.argmax(np.isinf(cap)))
                    self._problem(
                        "malformed", f"{self.name} frame {seq}: channel {k + 1} is {cap[k]}"
                    )
                    seq += 1
                    continue
                markers = (
                    v[self.n_pairs :].reshape(self.n_markers, 3) if self._with_markers else None
                )
                yield Frame(seq=seq, t=float(ts), capacitance=cap, markers=markers, arrival=arrival)
                seq += 1

    def _close_inlet(self) -> None:
        inlet, self._inlet = self._inlet, None
        if inlet is not None:
            try:
                inlet.close_stream()
            except Exception:  # a lost stream may refuse to close; it is dropped anyway
                pass

    def _release(self) -> None:
        self._close_inlet()


# =============================================================================== factory
_SPEC = re.compile(r"^(?P<kind>[a-z]+)(?::(?P<rest>.*))?$", re.DOTALL)


def open_source(
    spec: str,
    *,
    layout: SensorLayout | None = None,
    speed: float = 1.0,
    loop: bool = False,
    paced: bool = True,
    seed: int = 0,
    **kwargs: Any,
) -> FrameSource:
    """Open a source from a spec string.

    ``replay:FILE`` (``speed``, ``loop``), ``sim`` (the digital twin; ``paced``, ``seed``),
    ``lsl:NAME``, ``serial:PORT[@BAUD]`` (default 115200 baud), ``tcp:HOST:PORT``. ``layout``
    gives the channel count for lsl/serial/tcp (default: the paper's layout); a replay uses the
    recording's own layout. Extra keyword arguments go to the source class.
    """
    if not isinstance(spec, str) or not (m := _SPEC.match(spec.strip())):
        raise EctskinError(f"Invalid source {spec!r}: expected one of {SOURCE_SPECS}")
    kind, rest = m.group("kind"), m.group("rest")
    check_option("source kind", kind, ("replay", "sim", "lsl", "serial", "tcp"))
    if kind == "sim":
        if rest:
            raise EctskinError(f"Invalid source {spec!r}: 'sim' takes no argument")
        return TwinSource(layout=layout, paced=paced, seed=seed, **kwargs)
    if not rest:
        raise EctskinError(f"Invalid source {spec!r}: {kind} needs an argument ({SOURCE_SPECS})")
    if kind == "replay":
        path = Path(rest)
        if not path.is_file():
            raise EctskinError(f"source {spec!r}: no such recording file {str(path)!r}")
        return ReplaySource(path, speed=speed, loop=loop, **kwargs)
    if kind == "lsl":
        return LslSource(rest, layout=layout, **kwargs)
    if kind == "serial":
        port, baud = rest, 115200
        if "@" in rest:
            port, _, b = rest.rpartition("@")
            if not b.isdigit() or int(b) <= 0 or not port:
                raise EctskinError(
                    f"Invalid source {spec!r}: expected serial:PORT[@BAUD] with BAUD a positive "
                    f"integer, got {b!r}"
                )
            baud = int(b)
        return SerialSource(port, baud, layout=layout, **kwargs)
    host, _, port_s = rest.rpartition(":")
    host = host.strip("[]")  # [::1]:5000
    if not host or not port_s.isdigit() or not 0 < int(port_s) < 65536:
        raise EctskinError(f"Invalid source {spec!r}: expected tcp:HOST:PORT with PORT in 1..65535")
    return TcpSource(host, int(port_s), layout=layout, **kwargs)
