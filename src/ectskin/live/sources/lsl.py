"""Frames from a Lab Streaming Layer stream resolved by name (``lsl:NAME``, pylsl)."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout, default_layout
from ectskin.live.sources.base import Frame, FrameSource

logger = logging.getLogger(__name__)


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
        try:  # pylsl is optional (the `live` extra): imported when a stream is opened
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

    def _reopen(self, delay: float) -> bool:
        """One attempt to resolve the stream again and reopen it; True when it is back."""
        info = self._resolve(min(delay, 1.0))
        if info is None:
            return False
        err = self._check_channels(info)
        if err:
            self._problem("wrong_channels", err + "; not reconnecting to it")
            return False
        try:
            self._open(info)
        except Exception as exc:  # pylsl raises TimeoutError / LostError
            logger.debug("%s: reopen failed: %s", self.name, exc)
            return False
        self._count("reconnects")
        logger.info("%s: reconnected", self.name)
        return True

    def _frames(self) -> Iterator[Frame]:
        seq = 0
        delay = self.backoff_s[0]
        while not self._closed.is_set():
            if self._inlet is None:
                if self._reopen(delay):
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
