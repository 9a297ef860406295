"""The live engine: source → reference capture → calibration (Eq. 2) → heads → outputs.

Heads (:mod:`ectskin.live.heads`), each optional: touch (TouchMLP, one frame), tracking (C2DT, a
window), contact (ContactNet, a window), the ECT image (every N-th frame) and the physical
inversion (:mod:`ectskin.live.inversion_head`, every N-th frame). The engine keeps the
raw frames and the references; every head is run the same way, on every processed frame whose
reference exists, with the newest frames it reads.

Threads and policy
------------------
A reader thread takes every frame from the source, hands it to the recorder (if any: recording
never drops a frame) and puts it into a bounded queue. The inference loop (the thread that calls
:meth:`LiveEngine.run`) takes what is queued:

``"skip-to-newest"`` (live default)
    every queued frame updates the reference capture and the C2DT window. The newest frame is
    always run through the models; an older queued frame is run only while it is fresh (waited
    less than ``max_lag_ms``, default 50 ms), else it is skipped and counted in
    ``stats["dropped"]``. So a short burst (two frames arriving together) is processed whole, and
    when inference falls behind the engine jumps to the newest frame and the latency stays
    bounded. ``max_lag_ms=0`` processes only the newest frame of each batch. If the inference loop
    stalls so long that the queue fills (``queue_size`` frames), the reader drops the oldest
    queued frame (also counted as dropped) rather than slowing the source down.
``"block"`` (offline, benchmarks)
    every frame is processed; the reader waits when the queue is full (back-pressure).

Reference and calibration
-------------------------
The first ``reference_frames`` frames (and again the next ones after :meth:`capture_reference`)
are averaged channel-wise (NaN-aware) into the reference c_0; frames are calibrated by paper Eq. 2,
c = (c_t − c_0)/c_0. Touch, contact and the ECT image use the touch reference (the paper's rest
state: capture it untouched and uninflated; their models describe the skin against it), tracking
its own reference (the paper's "prior knowledge": the state at the start of the trajectory, with
the marker coordinates of that moment as the decoder's initial coordinates).
``capture_reference(which="both"|"touch"|"track")`` re-captures one or both.

A capture window is judged before use (:mod:`ectskin.live.reference`): the touch reference refuses
one with a touched or inflated frame (when the source knows) and captures again; marker motion and
channel drift far beyond the noise are warned about. :meth:`reference_state` (and
``stats["reference"]``) says where, when and how the references in use were taken. Initial marker
coordinates are the mean markers of the reference frames when the source provides markers, else
``reference_markers`` (e.g. the twin's rest pose). A channel whose reference is missing or zero is
calibrated to NaN (shown as null) and fed to the models as 0 (no change).

Latency is ``perf_counter()`` from the frame's arrival (``Frame.arrival``) to its output. Run
torch single-threaded (``ectskin live`` does, through :func:`ectskin.learn.threads.torch_threads`):
the models are tiny, and extra intra-op threads compete with the reader and recorder threads and
stall inference on a small machine.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array, check_option
from ectskin.io.calibration import relative_change
from ectskin.layout import SensorLayout
from ectskin.live.heads import HEAD_KEYS, Head, ReferenceInUse, build_heads
from ectskin.live.meter import Meter
from ectskin.live.output import Output, json_list
from ectskin.live.reference import REFERENCE_KINDS, ReferenceCapture, References

logger = logging.getLogger(__name__)

POLICIES = ("skip-to-newest", "block")


class LiveEngine:
    """Runs the heads (touch recognition, tracking, contact, ECT image, inversion) on a live
    source.

    Parameters
    ----------
    source
        A :class:`~ectskin.live.sources.FrameSource` (or any iterable of ``Frame`` with
        ``close()`` and optional ``counters``).
    layout
        The sensor layout (default: ``source.layout``); its pair count must match the source's.
    touch, track, contact
        Predictors with the ``TouchPredictor`` / ``TrackPredictor`` / ``ContactPredictor``
        protocol of :mod:`ectskin.learn.predict`, or None; each becomes a head
        (:func:`~ectskin.live.heads.build_heads`).
    imager, ect_every
        An ECT imager (``faces``, ``grid_extent``, ``image(delta_c)``, ``locate(delta_c)``) run
        on every ``ect_every``-th processed frame that has a reference, or None.
    inversion
        An :class:`~ectskin.live.inversion_head.InversionHead` (the physical inversion through
        response fields; it runs after the other heads), or None.
    reference_frames
        Frames averaged into a reference (30 = 1 s at 30 fps).
    policy
        ``"skip-to-newest"`` or ``"block"`` (module docstring).
    recorder
        A :class:`~ectskin.live.recorder.Recorder` that gets every frame, or None.
    reference_markers
        (n_markers, 3) mm initial marker coordinates used when the source provides no markers
        (default: ``source.reference_markers`` if the source has it).
    queue_size
        Frames the reader may queue ahead of the inference loop.
    max_lag_ms
        With ``"skip-to-newest"``: a queued frame older than this is skipped when a newer one
        waits.
    """

    def __init__(
        self,
        source,
        layout: SensorLayout | None = None,
        *,
        touch=None,
        track=None,
        contact=None,
        imager=None,
        ect_every: int = 1,
        inversion=None,
        reference_frames: int = 30,
        policy: str = "skip-to-newest",
        recorder=None,
        reference_markers: Any = None,
        queue_size: int = 256,
        max_lag_ms: float = 50.0,
    ):
        check_option("policy", policy, POLICIES)
        layout = layout if layout is not None else getattr(source, "layout", None)
        if layout is None:
            raise EctskinError("LiveEngine needs a layout (the source has none)")
        if not (isinstance(reference_frames, int) and reference_frames >= 1):
            raise EctskinError(
                f"reference_frames must be an integer >= 1, got {reference_frames!r}"
            )
        if not (isinstance(queue_size, int) and queue_size >= 1):
            raise EctskinError(f"queue_size must be an integer >= 1, got {queue_size!r}")
        self.source, self.layout = source, layout
        self.policy = policy
        self.recorder = recorder
        self.reference_frames = reference_frames
        self.queue_size = queue_size
        if not max_lag_ms >= 0:
            raise EctskinError(f"max_lag_ms must be >= 0, got {max_lag_ms!r}")
        self.max_lag_s = float(max_lag_ms) / 1e3
        n_pairs, n_markers = layout.n_pairs, layout.n_markers
        src_pairs = getattr(source, "n_pairs", n_pairs)
        if src_pairs != n_pairs:
            raise EctskinError(
                f"source {getattr(source, 'name', source)!r} gives {src_pairs} channels, layout "
                f"{layout.name!r} has {n_pairs} pairs"
            )
        self.n_pairs, self.n_markers = n_pairs, n_markers
        #: the heads, in the order they run (:data:`~ectskin.live.heads.HEAD_KEYS`)
        self.heads: tuple[Head, ...] = build_heads(
            layout, touch=touch, track=track, contact=contact, imager=imager, ect_every=ect_every
        )
        if inversion is not None:
            if inversion.layout.n_pairs != n_pairs:
                raise EctskinError(
                    f"the inversion head reads {inversion.layout.n_pairs} pairs, layout "
                    f"{layout.name!r} has {n_pairs}"
                )
            inversion.bind(source)  # a replay visiting a state without a field is refused here
            self.heads += (inversion,)
        by_key = {h.key: h for h in self.heads}
        self.n_classes = getattr(by_key.get("touch"), "n_classes", layout.n_classes)
        self._tracks = any(h.reference == "tracking" for h in self.heads)
        # raw frames kept for the windowed heads, a ring buffer
        self._ring = max((h.window for h in self.heads), default=1)
        if reference_markers is None:
            reference_markers = getattr(source, "reference_markers", None)
        if reference_markers is not None:
            reference_markers = check_array(
                "reference_markers", reference_markers, (n_markers, 3), finite=True
            )
        self._fallback_markers = reference_markers
        if (
            self._tracks
            and reference_markers is None
            and getattr(source, "provides_markers", None) is False
        ):
            raise EctskinError(
                f"tracking needs initial marker coordinates: source "
                f"{getattr(source, 'name', source)!r} gives no markers; pass reference_markers "
                f"(n_markers={n_markers}, 3) in mm"
            )

        # state shared between threads
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._queue: deque = deque()
        self._reader_done = False
        self._stop = threading.Event()
        self._ran = False
        self._pending_capture: str | None = "both"
        self._counts = {"frames": 0, "processed": 0, "dropped": 0, "wrong_channels": 0, "errors": 0}
        self._meter = Meter()
        self._error: str | None = None
        self.latest: Output | None = None
        # inference-loop state
        self._refs = References(n_pairs, n_markers, layout.pair_names)
        self._win = np.zeros((self._ring, n_pairs))
        self._win_pos = 0
        self._win_n = 0
        #: the references the heads are calibrated against, once accepted (the tracking one with
        #: the decoder's initial marker coordinates)
        self._in_use: dict[str, ReferenceInUse | None] = {"touch": None, "tracking": None}
        self._warned: set[str] = set()

    # ------------------------------------------------------------------ public API
    def capture_reference(self, which: str = "both") -> None:
        """Re-capture the reference(s) from the next ``reference_frames`` frames (thread-safe)."""
        check_option("which", which, REFERENCE_KINDS)
        with self._lock:
            self._pending_capture = which

    def stop(self) -> None:
        """Ask :meth:`run` to return soon (thread-safe); closes the source."""
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        self._close_source()

    @property
    def reference_ready(self) -> bool:
        return self._refs.touch.c0 is not None

    def reference_state(self) -> dict[str, Any]:
        """The state of both references, for the dashboard and the final summary (JSON-able;
        :meth:`ectskin.live.reference.References.state`)."""
        return self._refs.state()

    @property
    def stats(self) -> dict[str, Any]:
        """Counters, latency percentiles (ms) and rates (frames/s); the ``stats`` of every output."""
        return self._stats(refresh=True)

    @property
    def reference_markers(self) -> np.ndarray | None:
        """(n_markers, 3) mm initial marker coordinates in use (None until known)."""
        tracking = self._in_use["tracking"]
        if tracking is not None and tracking.markers is not None:
            return tracking.markers
        return self._fallback_markers

    def meta(self) -> dict[str, Any]:
        """The engine's part of the dashboard's ``meta`` message (the dashboard adds the layout:
        ``ectskin.dashboard.build_meta``): per head key (:data:`~ectskin.live.heads.HEAD_KEYS`)
        the head's ``meta()`` or None without that head, and ``touch_model``, ``track_model``,
        ``contact_model`` saying which models run; ``inversion`` the inversion head's
        ``meta()`` or None."""
        by_key = {h.key: h for h in self.heads}
        return {
            "reference_markers": json_list(self.reference_markers),
            "n_classes": self.n_classes,
            "policy": self.policy,
            "reference_frames": self.reference_frames,
            **{f"{key}_model": key in by_key for key in ("touch", "track", "contact")},
            **{key: by_key[key].meta() if key in by_key else None
               for key in (*HEAD_KEYS, "inversion")},
            "source": str(getattr(self.source, "name", type(self.source).__name__)),
        }

    def run(
        self,
        max_frames: int | None = None,
        duration_s: float | None = None,
        on_output: Callable[[Output], None] | None = None,
    ) -> dict[str, Any]:
        """Process frames until the source ends, ``max_frames`` frames have been read,
        ``duration_s`` seconds have passed, or :meth:`stop` is called. Calls ``on_output(output)``
        for every processed frame. Returns the final :attr:`stats`. An engine runs once."""
        if self._ran:
            raise EctskinError("a LiveEngine runs once; build a new one (with a new source)")
        self._ran = True
        if max_frames is not None and not (isinstance(max_frames, int) and max_frames >= 1):
            raise EctskinError(f"max_frames must be an integer >= 1, got {max_frames!r}")
        if duration_s is not None and not duration_s > 0:
            raise EctskinError(f"duration_s must be > 0, got {duration_s!r}")
        self._t_start = time.perf_counter()
        deadline = None if duration_s is None else self._t_start + duration_s
        reader = threading.Thread(
            target=self._read, args=(max_frames,), name="ectskin-reader", daemon=True
        )
        reader.start()
        try:
            while not self._stop.is_set():
                batch, done = self._take(deadline)
                if batch:
                    self._handle(batch, on_output)
                elif done:
                    break
                if deadline is not None and time.perf_counter() >= deadline:
                    break
        finally:
            self._stop.set()
            with self._cond:
                self._cond.notify_all()
            self._close_source()
            reader.join(timeout=10.0)
        if self._error:
            raise EctskinError(self._error)
        return self.stats

    # ------------------------------------------------------------------ reader thread
    def _read(self, max_frames: int | None) -> None:
        n = 0
        try:
            for frame in self.source:
                if self._stop.is_set():
                    break
                c = frame.capacitance
                if getattr(c, "shape", None) != (self.n_pairs,):
                    with self._lock:
                        self._counts["wrong_channels"] += 1
                    self._warn_once(
                        "shape",
                        f"frame {frame.seq}: expected {self.n_pairs} channels,"
                        f" got shape {getattr(c, 'shape', None)}; skipped",
                    )
                    continue
                if self.recorder is not None:
                    try:
                        self.recorder.write(frame)
                    except EctskinError as exc:  # disk full, file removed: stop, say why
                        self._error = str(exc)
                        logger.error("%s", exc)
                        break
                with self._cond:
                    if self.policy == "block":
                        while len(self._queue) >= self.queue_size and not self._stop.is_set():
                            self._cond.wait(0.1)
                    elif len(self._queue) >= self.queue_size:
                        self._queue.popleft()
                        self._counts["dropped"] += 1
                    self._queue.append(frame)
                    self._counts["frames"] += 1
                    self._meter.frame_in(frame.arrival)
                    self._cond.notify_all()
                n += 1
                if max_frames is not None and n >= max_frames:
                    break
        except EctskinError as exc:
            self._error = f"{getattr(self.source, 'name', 'source')}: {exc}"
            logger.error("%s", self._error)
        except Exception as exc:  # a source bug must not leave run() waiting forever
            self._error = (
                f"{getattr(self.source, 'name', 'source')} failed: {type(exc).__name__}: {exc}"
            )
            logger.exception("source failed")
        finally:
            with self._cond:
                self._reader_done = True
                self._cond.notify_all()

    # ------------------------------------------------------------------ inference loop
    def _take(self, deadline: float | None) -> tuple[list, bool]:
        with self._cond:
            while not self._queue and not self._reader_done and not self._stop.is_set():
                timeout = 0.1 if deadline is None else min(0.1, deadline - time.perf_counter())
                if timeout <= 0:
                    break
                self._cond.wait(timeout)
            batch = list(self._queue)
            self._queue.clear()
            done = self._reader_done and not self._queue
            self._cond.notify_all()
        return batch, done

    def _handle(self, batch: list, on_output) -> None:
        skip = self.policy == "skip-to-newest"
        last = len(batch) - 1
        for i, f in enumerate(batch):
            self._ingest(f)
            if skip and i < last and time.perf_counter() - f.arrival > self.max_lag_s:
                with self._lock:
                    self._counts["dropped"] += 1
                continue
            out = self._process(f)
            now = time.perf_counter()
            out.latency_ms = (now - f.arrival) * 1e3
            with self._lock:
                self._counts["processed"] += 1
                self._meter.frame_out(now, out.latency_ms)
            out.stats = self._stats(refresh=False)
            self.latest = out
            if on_output is not None:
                try:
                    on_output(out)
                except Exception:
                    with self._lock:
                        self._counts["errors"] += 1
                    if "callback" not in self._warned:
                        self._warned.add("callback")
                        logger.exception(
                            "on_output callback failed (further failures counted "
                            "in stats['errors'])"
                        )

    def _ingest(self, f) -> None:
        """Update reference captures and the raw window with one frame (every frame)."""
        with self._lock:
            which, self._pending_capture = self._pending_capture, None
        if which is not None:
            self._refs.start(which, self.reference_frames)
            logger.info(
                "capturing the %s reference from the next %d frames",
                "touch and tracking" if which == "both" else which,
                self.reference_frames,
            )
        c = f.capacitance
        if self._win_n == 0:
            self._win[:] = c  # pad: the first frame repeated (as datasets' pad=True)
        self._win[self._win_pos] = c
        self._win_pos = (self._win_pos + 1) % self._ring
        self._win_n += 1
        for name, ref, text in self._refs.add(f):
            self._reference_done(name, ref, f, text)

    def _reference_done(self, name: str, ref: ReferenceCapture, f, text: str) -> None:
        """A reference was accepted (``text`` says how, :meth:`References.add` logged it)."""
        if self.recorder is not None:
            try:
                self.recorder.add_event(text, t_s=f.t)
            except EctskinError as exc:
                logger.error("cannot record the event: %s", exc)
        c0 = ref.c0
        assert c0 is not None  # an accepted reference has its c_0
        if name == "touch":
            self._in_use["touch"] = ReferenceInUse(c0)
        if name == "tracking":
            m = ref.initial_markers(self._fallback_markers)
            if m is not None and not np.isfinite(m).all():
                j = int(np.argwhere(~np.isfinite(m))[0][0])
                self._warn_once(
                    "occluded",
                    f"marker {j} was not visible during the reference capture; its prediction "
                    "is NaN",
                )
            if m is None and self._tracks:
                self._warn_once(
                    "nomarkers",
                    "tracking disabled: the source gave no markers during the reference and no "
                    "reference_markers was passed",
                )
            self._in_use["tracking"] = ReferenceInUse(c0, m)

    def _process(self, f) -> Output:
        raw = f.capacitance
        out = Output(
            seq=f.seq,
            t=f.t,
            raw=raw,
            label=f.label,
            markers_true=f.markers,
            trial=f.trial,
            inflation=f.inflation,
        )
        touch_ref = self._in_use["touch"]
        if touch_ref is not None:
            # Eq. 2; NaN where the reference channel is unusable
            out.calibrated = relative_change(raw, touch_ref.c0)
        for head in self.heads:
            ref = self._in_use[head.reference]
            if ref is None:
                continue
            # the frame itself for a head of one frame (as the source gave it), else the ring's
            frames = raw[None] if head.window == 1 else self._window(head.window)
            try:
                head.step(frames, ref, out)
            except Exception:
                self._model_error(head.what)
        return out

    # ------------------------------------------------------------------ helpers
    def _window(self, k: int) -> np.ndarray:
        """(k, n_pairs) the newest k raw frames, oldest first (k <= the ring's length)."""
        order = (self._win_pos - k + np.arange(k)) % self._ring
        return self._win[order]

    def _close_source(self) -> None:
        try:
            self.source.close()
        except Exception:  # a source that fails to close is being abandoned anyway
            logger.debug("source close failed", exc_info=True)

    def _model_error(self, what: str) -> None:
        with self._lock:
            self._counts["errors"] += 1
        if what not in self._warned:
            self._warned.add(what)
            logger.exception("%s failed (further failures counted in stats['errors'])", what)

    def _warn_once(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            logger.warning("%s", message)

    def _stats(self, refresh: bool) -> dict[str, Any]:
        now = time.perf_counter()
        with self._lock:
            counts = dict(self._counts)
            p50, p99 = self._meter.latency_ms(now, refresh)
            fps_in, fps_out = self._meter.rates(now)
            queued = len(self._queue)
        src = getattr(self.source, "counters", None) or {}
        stats = {
            "frames": counts["frames"],
            "processed": counts["processed"],
            "dropped": counts["dropped"],
            "malformed": int(src.get("malformed", 0)),
            "wrong_channels": int(src.get("wrong_channels", 0)) + counts["wrong_channels"],
            "disconnects": int(src.get("disconnects", 0)),
            "reconnects": int(src.get("reconnects", 0)),
            "seq_gaps": int(src.get("seq_gaps", 0)),
            "errors": counts["errors"],
            "queue": queued,
            "latency_ms_p50": None if math.isnan(p50) else round(p50, 4),
            "latency_ms_p99": None if math.isnan(p99) else round(p99, 4),
            "fps_in": round(fps_in, 2),
            "fps_out": round(fps_out, 2),
            "policy": self.policy,
            "reference_ready": self._refs.touch.c0 is not None,
            "reference_capturing": self._refs.capturing,
            "reference": self.reference_state(),
        }
        if self.recorder is not None:
            stats.update(self.recorder.stats)
        return stats
