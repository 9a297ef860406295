"""The digital twin as a live source (``sim``): a scripted or random scenario of touches and
inflations played through an object with the ``LiveTwin`` protocol (:mod:`ectskin.twin.live`).

Every step of the scenario is a trial of its own (``Frame.trial`` = ``sim_0000``, ``sim_0001``…),
and :meth:`TwinSource.trial_info` tells the recorder its inflation and region, so a recorded
trial's metadata matches its frames' labels. The default scenario starts at rest (no touch, no
inflation) for :data:`REST_S` seconds: the state the live engine's touch reference must be
captured in (paper Eq. 2).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout
from ectskin.live.sources.base import Frame, FrameSource

#: Seconds the default scenario rests (untouched, uninflated) before its first touch: enough for
#: the live engine's default reference capture (30 frames = 1 s) with room to spare.
REST_S = 2.0
#: Steps whose trial info the source remembers (the recorder asks shortly after a step starts).
_KEEP_STEPS = 1024


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
    rest_s: float = REST_S,
) -> Iterator[TwinStep]:
    """An endless random scenario: first ``rest_s`` s at rest (no touch, no inflation: the state
    the live reference is captured in), then a new touch (or a lift) every ``step_s`` s and a new
    inflation state every third step; forces 0.5–2 N. Seeded, so a run is reproducible."""
    rng = np.random.default_rng(seed)
    infl = (0.0, 0.0, 0.0)
    if rest_s > 0:
        yield TwinStep(rest_s, infl, None)
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
    twin computes them. A new (inflation, touch) state costs the twin some method-of-moments
    solves (then cached); a paced twin then resumes at its frame rate instead of bursting to catch
    up, and ``Frame.t`` (seconds since the source started) shows the pause as a gap, as a
    device's clock would, so the timestamps say how many frames per second were really
    delivered. Unpaced, ``Frame.t = seq / frame_rate_hz``. Each step is a trial
    (``Frame.trial``, described by :meth:`trial_info`) and frames carry its inflation.
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
            # Lazy: the twin pulls in scipy and the method of moments, which every other source
            # (and every `ectskin` command, through the spec list) would otherwise pay for.
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
        self._steps: OrderedDict[str, TwinStep] = OrderedDict()

    def trial_info(self, name: str) -> dict[str, Any]:
        """Inflation (ml), region and meta of the step that trial ``name`` plays (for the
        recorder): region 0 and ``kind`` "no_contact" for a step without touch."""
        step = self._steps.get(name)
        if step is None:
            raise EctskinError(f"{self.name}: no step named {name!r} (only the last ones are kept)")
        touch = step.region is not None and step.region != 0
        meta: dict[str, Any] = {"kind": "touch" if touch else "no_contact", "source": "sim"}
        if touch:
            meta["force_n"] = float(step.force_n)
        return {
            "inflation": tuple(step.inflation_ml),
            "region": int(step.region or 0),
            "meta": meta,
        }

    def _frames(self) -> Iterator[Frame]:
        period = 1.0 / self.frame_rate_hz
        start = start0 = time.perf_counter()
        seq = 0
        for k, step in enumerate(self.scenario):
            trial = f"sim_{k:04d}"
            self._steps[trial] = step
            if len(self._steps) > _KEEP_STEPS:
                self._steps.popitem(last=False)
            inflation = tuple(float(v) for v in step.inflation_ml)
            self.twin.set_inflation(inflation)
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
                    t=(start - start0) + seq * period,
                    capacitance=np.asarray(cap, dtype=np.float64),
                    markers=None if markers is None else np.asarray(markers, dtype=np.float64),
                    label=None if label is None else int(label),
                    trial=trial,
                    inflation=inflation,
                )
                seq += 1
