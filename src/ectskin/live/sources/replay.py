"""Replay of a recorded HDF5 file (or an in-memory recording) as a live source."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Sequence
from typing import Any

from ectskin._check import EctskinError
from ectskin.io.hdf5 import read_recording
from ectskin.io.recording import Recording
from ectskin.live.sources.base import Frame, FrameSource


class ReplaySource(FrameSource):
    """Replays an HDF5 recording (or an in-memory :class:`~ectskin.io.Recording`).

    ``speed=1.0`` paces frames by their timestamps (real time), ``speed=k`` k times faster,
    ``speed=math.inf`` as fast as possible. Trials play in file order (``trials`` selects names);
    between trials one frame period passes. ``loop=True`` starts again after the last trial
    (``seq`` keeps counting). ``Frame.t`` is the trial's own timestamp, ``Frame.trial`` its name,
    ``Frame.inflation`` its inflation (None when the recording does not say).
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
        if isinstance(recording, Recording):
            rec, self.name = recording, "replay:<memory>"
        else:
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
                inflation = tuple(float(v) for v in trial.inflation) or None
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
                        inflation=inflation,
                    )
                    seq += 1
                virtual += period
            if not self.loop:
                return
