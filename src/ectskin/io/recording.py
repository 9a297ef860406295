"""In-memory recordings: a :class:`Recording` holds a layout and a list of :class:`Trial`.

A trial is one contiguous group of frames (30 s in the paper's protocol). Arrays and their
metadata are checked against each other when a trial is built, so downstream code can trust
shapes and units:

================  =============================  ======================================
field             shape                          meaning
================  =============================  ======================================
``capacitance``   (n_frames, n_pairs) float64    raw readout per pair, pF (NaN = masked)
``timestamps``    (n_frames,) float64            seconds from the start of the trial
``labels``        (n_frames,) int16              touch class per frame, 0 = no touch
``markers``       (n_frames, n_markers, 3) f64   marker positions, mm, NaN where occluded
``force``         (n_frames,) float64            touch force, N (NaN where unknown)
================  =============================  ======================================

``markers`` and ``force`` may be ``None`` (not recorded). ``inflation`` is the chamber volume
vector p in ml, ``region`` the trial's touched region (0 for none).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array
from ectskin.layout import SensorLayout


@dataclass
class Trial:
    """One trial of frames with its labels; validated on construction."""

    name: str
    capacitance: np.ndarray
    timestamps: np.ndarray
    labels: np.ndarray
    inflation: tuple[float, ...] = ()
    region: int = 0
    markers: np.ndarray | None = None
    force: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        src = f"trial {self.name!r}"
        self.capacitance = check_array("capacitance", self.capacitance, (None, None), source=src)
        n = self.capacitance.shape[0]
        self.timestamps = check_array("timestamps", self.timestamps, (n,), finite=True, source=src)
        self.labels = check_array("labels", self.labels, (n,), dtype=np.int16, source=src)
        if self.markers is not None:
            self.markers = check_array("markers", self.markers, (n, None, 3), source=src)
        if self.force is not None:
            self.force = check_array("force", self.force, (n,), source=src)
        self.inflation = tuple(float(v) for v in self.inflation)
        self.region = int(self.region)
        if n and np.any(np.diff(self.timestamps) <= 0):
            k = int(np.argmax(np.diff(self.timestamps) <= 0)) + 1
            raise EctskinError(
                f"{src}: timestamps must increase; frame {k} has {self.timestamps[k]} after "
                f"{self.timestamps[k - 1]}"
            )

    @property
    def n_frames(self) -> int:
        return self.capacitance.shape[0]

    @property
    def n_pairs(self) -> int:
        return self.capacitance.shape[1]

    @property
    def n_markers(self) -> int:
        return 0 if self.markers is None else self.markers.shape[1]

    @property
    def has_occlusion(self) -> bool:
        return self.markers is not None and bool(np.isnan(self.markers).any())


@dataclass
class Recording:
    """A layout plus trials of frames at ``frame_rate_hz``; checks that all of them agree."""

    layout: SensorLayout
    trials: list[Trial]
    frame_rate_hz: float
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.frame_rate_hz) and self.frame_rate_hz > 0):
            raise EctskinError(f"frame_rate_hz must be > 0, got {self.frame_rate_hz!r}")
        names = set()
        for t in self.trials:
            if t.name in names:
                raise EctskinError(f"recording: duplicate trial name {t.name!r}")
            names.add(t.name)
            if t.n_pairs != self.layout.n_pairs:
                raise EctskinError(
                    f"trial {t.name!r}: capacitance has {t.n_pairs} channels, but layout "
                    f"{self.layout.name!r} has {self.layout.n_electrodes} electrodes = "
                    f"{self.layout.n_pairs} pairs"
                )
            if t.markers is not None and t.n_markers != self.layout.n_markers:
                raise EctskinError(
                    f"trial {t.name!r}: markers has {t.n_markers} markers, layout has "
                    f"{self.layout.n_markers}"
                )
            bad = (t.labels < 0) | (t.labels > self.layout.n_regions)
            if bad.any():
                k = int(np.argmax(bad))
                raise EctskinError(
                    f"trial {t.name!r}: frame {k} has label {t.labels[k]}, expected 0.."
                    f"{self.layout.n_regions}"
                )

    @property
    def n_trials(self) -> int:
        return len(self.trials)

    @property
    def n_pairs(self) -> int:
        return self.layout.n_pairs

    @property
    def n_markers(self) -> int:
        return self.layout.n_markers

    @property
    def n_frames(self) -> int:
        return sum(t.n_frames for t in self.trials)

    def trial(self, name: str) -> Trial:
        for t in self.trials:
            if t.name == name:
                return t
        raise EctskinError(f"recording has no trial {name!r}")
