"""Crash-safe recording of live frames into the HDF5 recording format.

:class:`Recorder` takes every :class:`~ectskin.live.sources.Frame` (plus events) and writes it
through :class:`ectskin.io.hdf5.RecordingWriter` from a background thread:

* ``write(frame)`` only enqueues (an unbounded queue), so acquisition is never slowed down by the
  disk and no frame is ever dropped; a backlog is logged if the disk cannot keep up.
* The writer thread wakes every ``flush_interval_s`` (default 0.25 s), appends what is queued
  and flushes the file, so a process killed with SIGKILL loses at most the frames of the last
  ``flush_interval_s`` plus one write (well under one second); the file it leaves opens with
  ``read_recording(path, allow_partial=True)``.
* Trials: frames that name their trial (a replay) go into a trial of that name (with the
  inflation/region/meta given by ``trial_info``); other frames go into ``live_0000``,
  ``live_0001``… A new trial also starts when the source clock goes backwards (a device reset),
  because a trial's timestamps must increase. Timestamps are stored as given (the source clock).
* Frames without a label are stored with label 0 and the trial's meta says ``labels: "unknown"``.
"""

from __future__ import annotations

import datetime
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.hdf5 import RecordingWriter
from ectskin.layout import SensorLayout
from ectskin.live.sources import check_not_input, open_source

logger = logging.getLogger(__name__)

_BACKLOG_WARN = 3000  # frames queued before the recorder warns that the disk is too slow


class Recorder:
    """Records frames and events to ``path`` (HDF5, see ``docs/recording-format.md``).

    Parameters
    ----------
    path, layout, frame_rate_hz, meta, overwrite
        As for :class:`ectskin.io.hdf5.RecordingWriter`.
    flush_interval_s
        Longest time a frame stays in memory before it is appended and flushed to disk.
    trial_prefix
        Name prefix of trials for frames that carry no trial name.
    trial_info
        ``trial_info(name) -> {"inflation": ..., "region": ..., "meta": ...}`` for named trials
        (``ReplaySource.trial_info``).
    """

    def __init__(
        self,
        path: str | Path,
        layout: SensorLayout,
        frame_rate_hz: float,
        *,
        meta: dict[str, Any] | None = None,
        overwrite: bool = False,
        flush_interval_s: float = 0.25,
        trial_prefix: str = "live",
        trial_info: Callable[[str], dict[str, Any]] | None = None,
    ):
        if not flush_interval_s > 0:
            raise EctskinError(f"flush_interval_s must be > 0, got {flush_interval_s!r}")
        self.path = Path(path)
        self.layout = layout
        self.flush_interval_s = float(flush_interval_s)
        self.trial_prefix = trial_prefix
        self.trial_info = trial_info
        meta = dict(meta or {})
        meta.setdefault("recorded_utc", datetime.datetime.now(datetime.UTC).isoformat())
        self._writer = RecordingWriter(
            self.path,
            layout,
            frame_rate_hz,
            meta=meta,
            overwrite=overwrite,
            flush_interval_s=self.flush_interval_s,
        )
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._wake = threading.Event()  # set by flush() / close() to write now
        self._lock = threading.Lock()
        self._error: BaseException | None = None
        self._closed = False
        # writer-thread state
        self._trial: str | None = None  # name of the open trial in the file
        self._trial_key: str | None = None  # Frame.trial that opened it (None for live trials)
        self._trial_markers = False
        self._names: set[str] = set()
        self._n_live = 0
        self._last_t = -math.inf
        self._dropped_marker_warned = False
        self._clock_back: tuple[int, float, float] | None = None
        self.frames_written = 0
        self.frames_queued = 0
        self.trials: list[str] = []
        self._thread = threading.Thread(target=self._run, name="ectskin-recorder", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ producer side
    def write(self, frame) -> None:
        """Queue one frame for writing (never blocks, never drops)."""
        self._check_usable()
        self.frames_queued += 1
        self._queue.put(("frame", frame))

    def add_event(self, text: str, t_s: float | None = None) -> None:
        """Queue an event (e.g. "reference captured") at source time ``t_s`` (default: the last
        frame's time)."""
        self._check_usable()
        self._queue.put(("event", t_s, str(text)))

    def new_trial(
        self,
        name: str | None = None,
        *,
        inflation=(),
        region: int = 0,
        meta: dict[str, Any] | None = None,
    ) -> None:
        """Start a new trial for the following frames (e.g. when the operator changes the state)."""
        self._check_usable()
        self._queue.put(
            (
                "trial",
                name,
                {"inflation": tuple(inflation), "region": int(region), "meta": dict(meta or {})},
            )
        )

    def flush(self, timeout_s: float = 30.0) -> None:
        """Block until everything queued so far is on disk."""
        self._check_usable()
        done = threading.Event()
        self._queue.put(("sync", done))
        self._wake.set()
        if not done.wait(timeout_s):
            raise EctskinError(f"{self.path}: recorder flush did not finish within {timeout_s} s")
        self._raise_error()

    def close(self) -> None:
        """Write everything queued, mark the file complete and close it (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._queue.put(("close",))
        self._wake.set()
        self._thread.join()
        self._raise_error()

    @property
    def backlog(self) -> int:
        """Frames queued but not yet written."""
        return self.frames_queued - self.frames_written

    @property
    def stats(self) -> dict[str, Any]:
        return {
            "recorded": self.frames_written,
            "record_backlog": self.backlog,
            "record_trials": len(self.trials),
        }

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_usable(self) -> None:
        if self._closed:
            raise EctskinError(f"{self.path}: the recorder is closed")
        self._raise_error()

    def _raise_error(self) -> None:
        if self._error is not None:
            err = self._error
            if isinstance(err, EctskinError):  # the writer's message names the file already
                raise EctskinError(f"recording failed: {err}") from None
            raise EctskinError(
                f"{self.path}: recording failed: {type(err).__name__}: {err}"
            ) from None

    # ------------------------------------------------------------------ writer thread
    def _run(self) -> None:
        # Wake once per flush interval (or when flush()/close() asks), not once per frame: a
        # thread woken at the frame rate competes with the reader and inference threads for the
        # GIL and delays inference.
        closing = False
        while not closing:
            self._wake.wait(self.flush_interval_s)
            self._wake.clear()
            items = []
            try:
                while True:
                    items.append(self._queue.get_nowait())
            except queue.Empty:
                pass
            syncs = [it[1] for it in items if it[0] == "sync"]
            closing = any(it[0] == "close" for it in items)
            if self._error is None and items:
                try:
                    self._write_items(items)
                    self._writer.flush()
                except BaseException as exc:  # keep the error for the producer; stop writing
                    logger.debug("%s: recording failed: %s", self.path, exc)  # raised to the producer
                    self._error = exc
            if self.backlog > _BACKLOG_WARN:
                logger.warning(
                    "%s: %d frames waiting to be written (disk too slow?)", self.path, self.backlog
                )
            for ev in syncs:
                ev.set()
        try:
            self._writer.close()
        except BaseException as exc:
            if self._error is None:
                self._error = exc

    def _write_items(self, items: list) -> None:
        run: list = []  # consecutive frames of one trial
        for it in items:
            kind = it[0]
            if kind == "frame":
                f = it[1]
                if self._needs_new_trial(f):
                    self._append(run)
                    run = []
                    self._start_for(f)
                run.append(f)
                self._last_t = f.t
            else:
                self._append(run)
                run = []
                if kind == "event":
                    t = (
                        it[1]
                        if it[1] is not None
                        else (self._last_t if math.isfinite(self._last_t) else 0.0)
                    )
                    self._writer.add_event(float(t), it[2])
                elif kind == "trial":
                    self._start(it[1], None, it[2])
        self._append(run)

    def _needs_new_trial(self, f) -> bool:
        if self._trial is None:
            return True
        if f.trial is not None and f.trial != self._trial_key:
            return True
        if f.t <= self._last_t:
            if f.trial is None:  # a live device restarted its clock
                logger.warning(
                    "%s: source clock went back (%.6f s after %.6f s) at frame %d; "
                    "starting a new trial",
                    self.path,
                    f.t,
                    self._last_t,
                    f.seq,
                )
                self._clock_back = (f.seq, f.t, self._last_t)
            return True  # (a named trial replayed again, loop=True: a new trial, no warning)
        return False

    def _start_for(self, f) -> None:
        info: dict[str, Any] = {}
        if f.trial is not None and self.trial_info is not None:
            try:
                info = dict(self.trial_info(f.trial))
            except EctskinError:
                info = {}
        meta = dict(info.get("meta") or {})
        if f.label is None:
            meta["labels"] = "unknown"
        info["meta"] = meta
        self._trial_markers = f.markers is not None
        name = f.trial if f.trial is not None else None
        self._start(name, f.trial, info)
        back = self._clock_back
        if back is not None:
            self._clock_back = None
            self._writer.add_event(
                float(f.t),
                f"source clock went back from {back[2]} s to "
                f"{back[1]} s at frame {back[0]}; new trial",
            )

    def _start(self, name: str | None, key: str | None, info: dict[str, Any]) -> None:
        if name is None:
            while f"{self.trial_prefix}_{self._n_live:04d}" in self._names:
                self._n_live += 1
            name = f"{self.trial_prefix}_{self._n_live:04d}"
        base, k = name, 1
        while name in self._names:  # a replayed trial seen again (loop) or a clock reset
            name = f"{base}~{k}"
            k += 1
        self._names.add(name)
        self._writer.start_trial(
            name,
            inflation=tuple(info.get("inflation", ())),
            region=int(info.get("region", 0)),
            meta=info.get("meta") or {},
        )
        self._trial, self._trial_key = name, key
        self._last_t = -math.inf
        self.trials.append(name)

    def _append(self, run: list) -> None:
        if not run:
            return
        n = len(run)
        cap = np.stack([f.capacitance for f in run]).astype(np.float64, copy=False)
        ts = np.fromiter((f.t for f in run), dtype=np.float64, count=n)
        labels = np.fromiter(
            (0 if f.label is None else f.label for f in run), dtype=np.int16, count=n
        )
        markers = None
        if self._trial_markers:
            nm = self.layout.n_markers
            markers = np.full((n, nm, 3), np.nan)
            for i, f in enumerate(run):
                if f.markers is not None:
                    markers[i] = f.markers
        elif not self._dropped_marker_warned and any(f.markers is not None for f in run):
            self._dropped_marker_warned = True
            logger.warning(
                "%s: trial %s began without markers; later markers are not recorded",
                self.path,
                self._trial,
            )
        self._writer.append(cap, ts, labels=labels, markers=markers)
        self.frames_written += n


class ClockStats:
    """What a stream's timestamps say: how much source time it spans and at what frame rate.

    ``add(t, arrival)`` per frame. The source clock may restart (a device reset, a replayed
    trial): each run of increasing timestamps is a *segment*, and the span is the sum of the
    segments' spans. ``rate_hz`` = frame intervals / span (NaN with fewer than two frames in a
    segment); ``delivered_hz`` the same over the arrival times (``perf_counter``).
    """

    def __init__(self) -> None:
        self.frames = 0
        self.segments = 0
        self._done_s = 0.0  # span of the closed segments
        self._first: float | None = None  # first and last timestamp of the open segment
        self._last: float | None = None
        self.first_arrival: float | None = None
        self.last_arrival: float | None = None

    def add(self, t: float, arrival: float) -> None:
        if self._last is None or not t > self._last:  # the first frame, or the clock restarted
            if self._last is not None:
                self._done_s += self._last - self._first
            self._first = t
            self.segments += 1
        self._last = t
        self.frames += 1
        if self.first_arrival is None:
            self.first_arrival = arrival
        self.last_arrival = arrival

    @property
    def span_s(self) -> float:
        """Seconds of source time the timestamps cover."""
        return self._done_s + (0.0 if self._last is None else self._last - self._first)

    @property
    def rate_hz(self) -> float:
        """Frames per second according to the timestamps."""
        span = self.span_s
        return (self.frames - self.segments) / span if span > 0 else math.nan

    @property
    def delivered_hz(self) -> float:
        """Frames per second as they arrived (wall clock)."""
        if self.first_arrival is None or self.last_arrival <= self.first_arrival:
            return math.nan
        return (self.frames - 1) / (self.last_arrival - self.first_arrival)


#: ``record_stream`` warns when the timestamps show fewer than this fraction of the nominal rate.
LOW_RATE_FRACTION = 0.9


def record_stream(
    source_spec: str,
    out_path: str | Path,
    duration_s: float | None = None,
    *,
    layout: SensorLayout | None = None,
    overwrite: bool = False,
    speed: float = 1.0,
    loop: bool = False,
    frame_rate_hz: float | None = None,
    flush_interval_s: float = 0.25,
    on_frame: Callable[[Any], None] | None = None,
) -> dict[str, Any]:
    """Record from ``source_spec`` (see :func:`~ectskin.live.sources.open_source`) into
    ``out_path`` for ``duration_s`` seconds (None: until the source ends or Ctrl-C).

    Returns a summary: ``frames`` recorded, ``trials``, ``seconds`` (wall clock), what the
    timestamps say (``timestamps_s`` spanned, ``rate_hz``; :class:`ClockStats`), the
    ``nominal_hz`` stored in the file, ``delivered_hz`` (arrivals), the source's ``counters``
    and whether it was ``interrupted``. Warns when the timestamps show fewer frames per second
    than nominal (:data:`LOW_RATE_FRACTION`): a source that could not keep up, or frames lost
    upstream. ``on_frame(frame)`` is called after each frame is queued (progress).

    Never writes onto the file it replays, even with ``overwrite``.
    """
    if duration_s is not None and not duration_s > 0:
        raise EctskinError(f"duration must be > 0 seconds, got {duration_s!r}")
    out_path = Path(out_path)
    check_not_input(out_path, source_spec, "the output")
    if out_path.exists() and not overwrite:
        raise EctskinError(f"{out_path} exists; refusing to replace it without overwrite")
    source = open_source(source_spec, layout=layout, speed=speed, loop=loop)
    rate = frame_rate_hz or source.frame_rate_hz or 30.0
    recorder = Recorder(
        out_path,
        source.layout,
        rate,
        overwrite=overwrite,
        flush_interval_s=flush_interval_s,
        meta={"source": source_spec},
        trial_info=getattr(source, "trial_info", None),
    )
    timer = None
    if duration_s is not None:
        timer = threading.Timer(duration_s, source.close)
        timer.daemon = True
    interrupted = False
    clock = ClockStats()
    t0 = time.perf_counter()
    logger.info(
        "recording %s -> %s%s",
        source_spec,
        out_path,
        f" for {duration_s:g} s" if duration_s else " (Ctrl-C stops)",
    )
    try:
        if timer is not None:
            timer.start()
        for frame in source:
            recorder.write(frame)
            clock.add(frame.t, frame.arrival)
            if on_frame is not None:
                on_frame(frame)
    except KeyboardInterrupt:
        interrupted = True
        logger.info("interrupted; closing %s", out_path)
    finally:
        if timer is not None:
            timer.cancel()
        source.close()
        recorder.close()
    summary = {
        "path": str(out_path),
        "frames": recorder.frames_written,
        "trials": list(recorder.trials),
        "seconds": time.perf_counter() - t0,
        "timestamps_s": clock.span_s,
        "rate_hz": clock.rate_hz,
        "delivered_hz": clock.delivered_hz,
        "nominal_hz": float(rate),
        "counters": source.counters,
        "interrupted": interrupted,
    }
    logger.info(
        "recorded %d frames in %d trial(s) to %s",
        summary["frames"],
        len(summary["trials"]),
        out_path,
    )
    if clock.rate_hz < LOW_RATE_FRACTION * rate:
        expected = round(clock.span_s * rate) + clock.segments
        logger.warning(
            "the source delivered %.1f frames per second, fewer than its nominal %g: %d frames "
            "over the %.1f s its timestamps span, where %d were due (a source too slow for real "
            "time, or frames lost upstream)",
            clock.rate_hz,
            rate,
            clock.frames,
            clock.span_s,
            expected,
        )
    return summary
