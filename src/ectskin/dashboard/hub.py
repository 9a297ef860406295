"""The meeting point of the engine thread and the web server: :class:`Hub` and its rate limit.

The engine runs in its own thread and hands every :class:`~ectskin.live.output.Output` to the hub
(``engine.run(on_output=hub.publish)``). The hub keeps only the newest output; each websocket
client is woken when a new one arrives and is sent the newest one at most ``max_rate_hz`` times a
second (:class:`TokenBucket`; frames in between are skipped for that client, never queued), so a
slow browser can never slow the engine down. JSON encoding happens on the server's loop, once per
output sent, whatever the number of clients. Since frames are skipped, the hub also keeps the
newest output that carries a physical-inversion fit (``--inversion-every N`` fits every N-th
frame, the others carry ``inversion: null``): a frame sent without a fit of its own carries that
one as ``inversion_fit`` (``{"seq", "inversion"}``), so the page can show the fit its frame
stands for even when the frame that carried it was skipped. The hub also holds the engine's state (running,
ended, error: :meth:`Hub.set_engine_state`), which every client is told at once, so that a page
never calls a stream "live" after it has stopped.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from collections import deque
from typing import Any

from ectskin._check import EctskinError
from ectskin._files import to_jsonable
from ectskin.dashboard.messages import build_meta, encode, frame_dict
from ectskin.layout import SensorLayout

logger = logging.getLogger(__name__)

#: Upper bound on messages per second and client (the readout runs at 30 fps).
DEFAULT_MAX_RATE_HZ = 30.0
#: Seconds of readouts replayed to a page that connects mid-run (sampled at ≤ max_rate_hz).
DEFAULT_HISTORY_S = 10.0
#: What the engine is doing, as the page's badge shows it.
ENGINE_STATES = ("waiting", "running", "ended", "error")


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
        if not (
            isinstance(max_rate_hz, (int, float)) and math.isfinite(max_rate_hz) and max_rate_hz > 0
        ):
            raise EctskinError(f"dashboard: max_rate_hz must be a number > 0, got {max_rate_hz!r}")
        if not (
            isinstance(history_s, (int, float)) and math.isfinite(history_s) and history_s >= 0
        ):
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
        self._fit: Any = None  # the newest output with an inversion fit
        self._fit_dict: tuple[Any, dict[str, Any]] | None = None  # (that output, its dict)
        self._version = 0
        self._encoded: tuple[int, str] | None = None  # cache, touched on the server loop only
        self._subscribers: set[_Subscriber] = set()
        n_hist = max(1, math.ceil(self.history_s * self.max_rate_hz) + 1)
        self._history: deque[tuple[float, Any]] = deque(maxlen=n_hist)
        self._last_history_t = -math.inf
        self.messages_sent = 0
        self.reference_requests = 0
        self._engine_state = "waiting"
        self._engine_error: str | None = None
        self._status_version = 0

    # ------------------------------------------------------------- engine side (any thread)
    def publish(self, output: Any) -> None:
        """Store ``output`` (an ``Output`` or a frame dict) as the newest and wake the clients."""
        now = time.monotonic()
        fitted = (
            output.get("inversion") if isinstance(output, dict) else getattr(output, "inversion", None)
        ) is not None
        with self._lock:
            self._latest = output
            if fitted:
                self._fit = output
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

    def set_engine_state(self, state: str, error: str | None = None) -> None:
        """The engine is ``"running"``, has ``"ended"`` (its source ended, or its duration
        passed) or stopped with an ``"error"``; clients are told at once (a ``status`` message),
        so a page never shows "live" for a stream that has stopped."""
        if state not in ENGINE_STATES:
            raise EctskinError(
                f"dashboard: engine state must be one of {ENGINE_STATES}, got {state!r}"
            )
        with self._lock:
            self._engine_state, self._engine_error = state, error
            self._status_version += 1
            subscribers = tuple(self._subscribers)
        for sub in subscribers:
            sub.wake()

    @property
    def engine_state(self) -> str:
        return self._engine_state

    @property
    def engine_running(self) -> bool:
        return self._engine_state == "running"

    @property
    def engine_error(self) -> str | None:
        return self._engine_error

    def status(self) -> tuple[int, dict[str, Any]]:
        """``(version, {"type": "status", "engine": state, "error": ..., "published": n})``."""
        with self._lock:
            return self._status_version, {
                "type": "status",
                "engine": self._engine_state,
                "error": self._engine_error,
                "published": self._version,
            }

    # ------------------------------------------------------------- server side
    def meta(self) -> dict[str, Any]:
        """The ``meta`` message (see :func:`build_meta`).

        With an engine that has ``meta()`` (LiveEngine), its current reference markers and its
        extra fields (``touch_model``, ``track_model``, ``policy``, and ``contact`` and ``ect``:
        the faces and extents the Contact panel draws, see ``docs/live.md``) are included.
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
            meta.setdefault(key, to_jsonable(value))
        return meta

    def stats(self) -> dict[str, Any]:
        """The engine's counters plus ``dashboard`` (clients, published, sent, engine state)."""
        if self.engine is not None:
            stats = dict(self.engine.stats)
        else:
            _, out = self.latest()
            stats = dict(frame_dict(out).get("stats") or {}) if out is not None else {}
        stats["dashboard"] = {
            "clients": self.n_clients,
            "published": self.n_published,
            "sent": self.messages_sent,
            "reference_requests": self.reference_requests,
            "engine_running": self.engine_running,
            "engine_state": self.engine_state,
            "engine_error": self.engine_error,
        }
        return to_jsonable(stats)

    def capture_reference(self) -> dict[str, Any]:
        """Ask the engine to re-capture its reference from the next frames."""
        if self.engine is None:
            raise EctskinError("dashboard: no live engine attached, nothing to re-capture")
        self.engine.capture_reference()
        self.reference_requests += 1
        logger.info(
            "reference re-capture requested from the dashboard (#%d)", self.reference_requests
        )
        return {"ok": True, "reference_requests": self.reference_requests}

    def encoded_latest(self) -> tuple[int, str | None]:
        """``(version, JSON text)`` of the newest output, encoded once however many clients."""
        with self._lock:
            version, out, fit = self._version, self._latest, self._fit
        if out is None:
            return 0, None
        cached = self._encoded
        if cached is not None and cached[0] == version:
            return cached
        d = frame_dict(out)
        if fit is not None and fit is not out and d.get("inversion") is None:
            if self._fit_dict is None or self._fit_dict[0] is not fit:  # converted once per fit
                self._fit_dict = (fit, frame_dict(fit))
            f = self._fit_dict[1]
            seq, fit_seq = d.get("seq"), f.get("seq")
            if isinstance(seq, int) and isinstance(fit_seq, int) and fit_seq < seq:
                d = {**d, "inversion_fit": {"seq": fit_seq, "inversion": f["inversion"]}}
        text = encode(d)
        self._encoded = (version, text)
        return version, text

    def history_message(self) -> dict[str, Any]:
        """``{"type": "history", "frames": [{seq, t, raw, calibrated, trial, inflation, age_s},
        ...]}``, oldest first; ``age_s`` is how long ago (s) the frame was published, for the
        page's time axis."""
        now = time.monotonic()
        with self._lock:
            items = [(t, out) for t, out in self._history if t >= now - self.history_s]
        frames = []
        for t, out in items:
            d = frame_dict(out)
            frame = {k: d.get(k) for k in ("seq", "t", "raw", "calibrated", "trial", "inflation")}
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
