"""What the Motive reader returns: marker trajectories and a report of the occlusions."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: How many line numbers an occlusion report lists per marker.
N_FIRST_LINES = 5


@dataclass
class MarkerOcclusion:
    """Frames in which one marker was occluded (all cells empty) or partly empty (also NaN)."""

    name: str
    n_occluded: int = 0
    n_partial: int = 0
    first_lines: list[int] = field(default_factory=list)

    def add(self, line: int, partial: bool) -> None:
        self.n_occluded += 1
        self.n_partial += int(partial)
        if len(self.first_lines) < N_FIRST_LINES:
            self.first_lines.append(line)


@dataclass
class MocapData:
    """Marker trajectories from one Motive take.

    ==================  ============================  ======================================
    field               shape                         meaning
    ==================  ============================  ======================================
    ``timestamps``      (n_frames,) float64           s, the file's ``Time (Seconds)``
    ``positions``       (n_frames, n_markers, 3) f64  mm, NaN where the marker was occluded
    ``frame_numbers``   (n_frames,) int64             Motive frame number
    ``lines``           (n_frames,) int64             line number (1-based) of each frame
    ==================  ============================  ======================================

    ``units`` is the ``Length Units`` of the file (positions are always mm); ``meta`` holds the
    metadata row (take name, frame rates, ...).
    """

    path: str
    timestamps: np.ndarray
    positions: np.ndarray
    marker_names: tuple[str, ...]
    frame_rate_hz: float
    units: str
    frame_numbers: np.ndarray
    lines: np.ndarray
    meta: dict[str, str] = field(default_factory=dict)
    occlusions: dict[str, MarkerOcclusion] = field(default_factory=dict)
    skipped_rows: list[tuple[int, str]] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_markers(self) -> int:
        return self.positions.shape[1]

    def summary(self) -> str:
        """Human-readable occlusion report, one line per occluded marker."""
        out = []
        for name, o in self.occlusions.items():
            if o.n_occluded:
                part = f" ({o.n_partial} partly empty)" if o.n_partial else ""
                lines = ", ".join(str(n) for n in o.first_lines)
                out.append(
                    f"{name}: occluded in {o.n_occluded} of {self.n_frames} frames{part}, first "
                    f"at line(s) {lines}"
                )
        for line, reason in self.skipped_rows:
            out.append(f"line {line} skipped: {reason}")
        return "\n".join(out) if out else "no occlusions, no skipped rows"
