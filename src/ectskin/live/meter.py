"""Sliding-window latency percentiles and frame rates of the live engine."""

from __future__ import annotations

import math
from collections import deque

import numpy as np

LATENCY_WINDOW = 1000  # processed frames over which p50/p99 are computed
FPS_WINDOW_S = 2.0  # seconds over which fps_in / fps_out are computed
STATS_REFRESH_S = 0.25  # latency percentiles are recomputed at most this often


class Meter:
    """Latency p50/p99 over the last :data:`LATENCY_WINDOW` outputs and input/output frame rates
    over the last :data:`FPS_WINDOW_S` seconds (``perf_counter`` times).

    Not thread-safe on its own: the engine calls it under its lock.
    """

    def __init__(self) -> None:
        self._lat: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self._in_times: deque[float] = deque()
        self._out_times: deque[float] = deque()
        self._lat_cache = (math.nan, math.nan)
        self._lat_cache_t = -math.inf

    def frame_in(self, t: float) -> None:
        """A frame arrived at ``t``."""
        _tick(self._in_times, t)

    def frame_out(self, t: float, latency_ms: float) -> None:
        """An output left at ``t``, ``latency_ms`` after its frame arrived."""
        self._lat.append(latency_ms)
        _tick(self._out_times, t)

    def latency_ms(self, now: float, refresh: bool) -> tuple[float, float]:
        """(p50, p99) in ms, NaN before the first output; recomputed when ``refresh`` or at most
        every :data:`STATS_REFRESH_S` seconds."""
        if refresh or now - self._lat_cache_t > STATS_REFRESH_S:
            if self._lat:
                p50, p99 = np.percentile(np.fromiter(self._lat, float), [50, 99])
                self._lat_cache = (float(p50), float(p99))
            self._lat_cache_t = now
        return self._lat_cache

    def rates(self, now: float) -> tuple[float, float]:
        """(fps_in, fps_out): frames per second in and out (0 when idle)."""
        return _rate(self._in_times, now), _rate(self._out_times, now)


def _tick(times: deque, t: float) -> None:
    """Append ``t`` and forget times older than the fps window."""
    times.append(t)
    while times and t - times[0] > FPS_WINDOW_S:
        times.popleft()


def _rate(times: deque, now: float) -> float:
    """Events per second over the last ``FPS_WINDOW_S`` seconds (0 when idle)."""
    while times and now - times[0] > FPS_WINDOW_S:
        times.popleft()
    if len(times) < 2:
        return 0.0
    span = max(now - times[0], times[-1] - times[0])
    return (len(times) - 1) / span if span > 0 else 0.0
