"""What the capacitance-meter reader returns: the data, and a report of what it masked."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: How many line numbers a report lists per channel.
N_FIRST_LINES = 5


@dataclass
class ChannelMask:
    """Masked cells of one channel: how many, which markers, and the first line numbers (1-based).

    ``relative_mismatch`` counts rows whose relative-change column disagrees with the value column
    (see :func:`~ectskin.io.capmeter.read_capmeter_csv`); ``relative_checked`` is False when there
    was nothing to check.
    """

    channel: str
    column: int
    n_masked: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    first_lines: list[int] = field(default_factory=list)
    relative_checked: bool = False
    relative_mismatch: int = 0
    relative_first_lines: list[int] = field(default_factory=list)

    def add(self, marker: str, line: int) -> None:
        self.n_masked += 1
        self.counts[marker] = self.counts.get(marker, 0) + 1
        if len(self.first_lines) < N_FIRST_LINES:
            self.first_lines.append(line)


@dataclass
class MaskReport:
    """What the reader masked or skipped: per-channel masks, skipped rows (line, reason), and
    notes on what it did with the file's layout (e.g. relative-change columns ignored)."""

    path: str
    channels: dict[str, ChannelMask]
    skipped_rows: list[tuple[int, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def n_masked(self) -> int:
        return sum(c.n_masked for c in self.channels.values())

    @property
    def masked_channels(self) -> list[str]:
        return [name for name, c in self.channels.items() if c.n_masked]

    def summary(self) -> str:
        """Human-readable lines, e.g. ``C13: 3 masked (OL: 2, empty: 1), first at lines 9, 14``."""
        out = []
        for name, c in self.channels.items():
            if c.n_masked:
                kinds = ", ".join(f"{k}: {v}" for k, v in c.counts.items())
                lines = ", ".join(str(n) for n in c.first_lines)
                out.append(f"{name}: {c.n_masked} masked ({kinds}), first at line(s) {lines}")
            if c.relative_mismatch:
                lines = ", ".join(str(n) for n in c.relative_first_lines)
                out.append(
                    f"{name}: relative-change column disagrees with the value on "
                    f"{c.relative_mismatch} row(s), first at line(s) {lines}"
                )
        for line, reason in self.skipped_rows:
            out.append(f"line {line} skipped: {reason}")
        out.extend(f"note: {n}" for n in self.notes)
        return "\n".join(out) if out else "no masked cells, no skipped rows"

    def to_dict(self) -> dict:
        """Plain JSON-able summary (for ``Trial.meta``)."""
        return {
            "masked": {
                name: {
                    "n": c.n_masked,
                    "counts": dict(c.counts),
                    "first_lines": list(c.first_lines),
                }
                for name, c in self.channels.items()
                if c.n_masked
            },
            "relative_mismatch": {
                name: c.relative_mismatch
                for name, c in self.channels.items()
                if c.relative_mismatch
            },
            "skipped_rows": [[line, reason] for line, reason in self.skipped_rows],
            "notes": list(self.notes),
        }


@dataclass
class CapmeterData:
    """One capacitance-meter export, converted to the units ectskin uses.

    ================  =============================  ==========================================
    field             shape                          meaning
    ================  =============================  ==========================================
    ``timestamps``    (n_frames,) float64            s, strictly increasing; clock times are
                                                     counted from the first row
    ``values``        (n_frames, n_channels) f64     capacitance, pF, NaN where masked
    ``channels``      n_channels names               channel names without unit (``C12``)
    ``units``         n_channels strings             the unit each channel had in the file
    ``lines``         (n_frames,) int64              line number (1-based) of each frame
    ``pairs``         (n_channels, 2) int or None    electrode numbers (1-based) when every
                                                     channel name reads as a pair, e.g. ``C12``
    ================  =============================  ==========================================

    ``timing`` records what was done to the time stamps (empty when nothing was): stamps that
    repeated or stepped back (``time_order``, ``steps_back``, ``repeats``, ``first_lines``,
    ``retimed``; :mod:`~ectskin.io.capmeter.timing`) and ``resampled_hz`` when the frames were
    resampled onto a uniform grid (then ``lines`` holds the line of the row at or before each
    frame).
    """

    path: str
    timestamps: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...]
    lines: np.ndarray
    mask_report: MaskReport
    time_unit: str
    pairs: np.ndarray | None = None
    meta: dict[str, str] = field(default_factory=dict)
    timing: dict[str, Any] = field(default_factory=dict)
    resampled_hz: float | None = None

    @property
    def n_frames(self) -> int:
        return self.values.shape[0]

    @property
    def n_channels(self) -> int:
        return self.values.shape[1]

    @property
    def frame_rate_hz(self) -> float:
        """The resampling rate, else 1 / median frame interval (NaN with fewer than 2 frames)."""
        if self.resampled_hz is not None:
            return float(self.resampled_hz)
        if self.n_frames < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.timestamps)))
