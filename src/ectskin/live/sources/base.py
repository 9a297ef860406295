"""The frame and the source interface every live source implements.

:class:`Frame` is one readout of all pairs; :class:`FrameSource` is the base class of the sources:
an iterator of frames with ``close()``, a ``counters`` dict (see :data:`COUNTERS` and the package
docstring) and ``problems``, the last 50 messages about bad input.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

COUNTERS = ("frames", "malformed", "wrong_channels", "disconnects", "reconnects", "seq_gaps")


@dataclass(frozen=True, eq=False)
class Frame:
    """One readout of all pairs, as delivered by a source.

    ``seq`` is the source's running frame number (gaps = frames lost upstream); ``t`` is in
    seconds on the source clock (the device timestamp if given, else arrival time since the source
    opened); ``capacitance`` is (n_pairs,) float64 pF with NaN for masked channels; ``markers`` is
    (n_markers, 3) mm or None; ``label`` the ground-truth class when the source knows it.
    ``trial`` names the trial the frame belongs to when the source knows it (replay, sim), and
    ``inflation`` the chambers' inflation (ml) when the source knows it (replay, sim; None when
    unknown). ``arrival`` is the ``time.perf_counter()`` at which the frame entered the program
    (the start of the engine's latency measurement).
    """

    seq: int
    t: float
    capacitance: np.ndarray
    markers: np.ndarray | None = None
    label: int | None = None
    trial: str | None = None
    arrival: float = field(default_factory=time.perf_counter)
    inflation: tuple[float, ...] | None = None


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
        """A snapshot of the counters (see :data:`COUNTERS`)."""
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
