"""Frame times of a capacitance-meter export: time stamps out of order, and resampling.

Real exports carry time stamps that repeat or step back (``1.455`` then ``1.377``) in the middle
of a file, between irregular intervals. The policy (``time_order``) says what the reader does:

* ``"file"`` (default): the rows stay in the file's order, and each row whose time stamp is not
  later than every stamp before it (a repeat, or a step back) gets a new time:
  :func:`monotone_times` spaces such rows evenly, by row, between the nearest rows around them
  whose stamps are new maxima; rows after the last new maximum continue at the median of the
  positive intervals. Every other row keeps its stamp, so the frames follow the file's clock and
  no offset builds up after a step back;
* ``"sort"``: the rows are sorted by time stamp (a stable sort: rows with one stamp keep their
  order); a stamp that then repeats is spaced as in ``"file"``;
* ``"strict"``: a time that does not increase makes the row malformed (an error; with
  ``strict=False`` the row is skipped).

:func:`resample` puts the frames onto a uniform grid (``resample_hz``), each channel linearly
interpolated.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError

log = logging.getLogger(__name__)

#: The policies for time stamps that repeat or step back.
TIME_ORDERS = ("file", "sort", "strict")
#: How many line numbers the record of out-of-order stamps lists.
N_FIRST_LINES = 5


@dataclass
class TimeRepair:
    """What :func:`order_frames` did to the time stamps of one file.

    ``steps_back`` and ``repeats`` count the rows (in file order) whose stamp is before, or equal
    to, the stamp of the row above; ``first_lines`` are the first of those rows' line numbers;
    ``retimed`` counts the frames given a new time.
    """

    policy: str
    steps_back: int
    repeats: int
    first_lines: list[int] = field(default_factory=list)
    retimed: int = 0

    def note(self, src: str) -> str:
        lines = ", ".join(str(v) for v in self.first_lines)
        how = (
            "kept in the file's order"
            if self.policy == "file"
            else "rows sorted by time stamp"
        )
        return (
            f"{src}: time stamps out of order: {self.steps_back} step(s) back and {self.repeats} "
            f"repeat(s), first at line(s) {lines}; {how}, {self.retimed} frame time(s) "
            f"re-derived (time_order={self.policy!r}; docs/instrument-import.md)"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "time_order": self.policy,
            "steps_back": self.steps_back,
            "repeats": self.repeats,
            "first_lines": list(self.first_lines),
            "retimed": self.retimed,
        }


def monotone_times(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strictly increasing times for frames whose stamps ``t`` (n,) may repeat or step back.

    A frame whose stamp is later than every stamp before it (the first frame included) keeps it;
    the frames between two such frames a < b get ``t[a] + (t[b] - t[a]) * (k - a) / (b - a)``,
    and the frames after the last one continue at the median positive interval of ``t``.
    Returns the times and which frames were given a new one. Needs a positive interval when a
    frame after the last new maximum is to be placed (the caller checks).
    """
    n = len(t)
    keep = np.ones(n, dtype=bool)
    if n > 1:
        keep[1:] = t[1:] > np.maximum.accumulate(t)[:-1]
    if keep.all():
        return t, ~keep
    anchors = np.flatnonzero(keep)
    out = np.interp(np.arange(n), anchors, t[anchors])
    last = anchors[-1]
    if last < n - 1:
        steps = np.diff(t)
        dt = float(np.median(steps[steps > 0]))
        out[last + 1 :] = t[last] + dt * np.arange(1, n - last)
    out[anchors] = t[anchors]
    return out, ~keep


def order_frames(
    t: np.ndarray, lines: np.ndarray, policy: str, src: str, time_name: str
) -> tuple[np.ndarray | None, np.ndarray, TimeRepair | None]:
    """The frames' order and times under ``policy`` (see the module): ``(order, times, repair)``.

    ``order`` indexes the rows (None: the file's order), ``times`` are the frames' times in that
    order, strictly increasing; ``repair`` is None when every stamp already increases.
    """
    steps = np.diff(t)
    back, same = steps < 0, steps == 0
    if not (back.any() or same.any()) or policy == "strict":
        return None, t, None
    repair = TimeRepair(
        policy,
        int(back.sum()),
        int(same.sum()),
        [int(v) for v in lines[1:][back | same][:N_FIRST_LINES]],
    )
    order = None
    if policy == "sort":
        order = np.argsort(t, kind="stable")
        t = t[order]
    if not (np.diff(t) > 0).any():
        raise EctskinError(
            f"{src}: time column {time_name!r}: the time stamp never increases (lines "
            f"{lines[0]} to {lines[-1]}); no frame times can be derived"
        )
    times, retimed = monotone_times(t)
    repair.retimed = int(retimed.sum())
    log.warning("%s", repair.note(src))
    return order, times, repair


def resample(
    t: np.ndarray, values: np.ndarray, lines: np.ndarray, hz: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames on the uniform grid ``t[0] + k / hz`` (k = 0, 1, ... up to ``t[-1]``).

    Each channel of ``values`` (n, m) is interpolated linearly between the two frames around a
    grid time (increasing ``t``); a grid time on a frame takes that frame. A grid value is NaN
    where a frame it is drawn from is NaN (a masked cell is not bridged). Each grid frame's line
    is the line of the frame at or before it. Returns (times, values, lines).
    """
    n_new = int(np.floor((t[-1] - t[0]) * hz + 1e-9)) + 1
    grid = t[0] + np.arange(n_new) / hz
    if len(t) < 2:
        return grid, values[:n_new].copy(), lines[:n_new].copy()
    i = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 2)
    w = np.clip((grid - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0)[:, None]
    out = values[i] * (1.0 - w) + values[i + 1] * w
    on_left, on_right = w[:, 0] == 0.0, w[:, 0] == 1.0
    out[on_left] = values[i[on_left]]
    out[on_right] = values[i[on_right] + 1]
    return grid, out, np.where(on_right, lines[i + 1], lines[i])
