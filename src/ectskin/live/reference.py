"""The reference c_0 of paper Eq. 2, captured live, and the checks that it was taken at rest.

Every later frame is calibrated against the reference, so a reference taken while the skin was
touched, inflated or moving poisons every answer after it (a touch model then sees "no change"
during the touch and a large change at rest). :class:`ReferenceCapture` therefore keeps the
frames of its capture window and, when the window is complete, judges them
(:func:`check_window`):

* **contact** – a frame whose label says it is touched (sources that know: replay, sim, a line
  with ``label=``);
* **inflation** – a frame whose inflation is known and not all zero (replay, sim);
* **motion** – a marker whose mean position moved more than :data:`MOTION_MM` between the first
  and the second half of the window (sources with markers);
* **drift** – a channel whose mean changed between the two halves of the window far more than its
  noise allows: more than :data:`DRIFT_SIGMAS` standard errors, the noise taken from the
  frame-to-frame differences (which a slow change barely affects), and more than
  :data:`DRIFT_REL_MIN` of the channel's level. White noise of any size passes; a touch that
  starts or ends, or a skin still settling, does not.

:class:`References` holds the engine's two references and the policy: the touch reference (the
rest state) refuses a window with contact or inflation and captures again, keeping the reference
in use meanwhile; both warn about the rest (motion, drift; contact for tracking, whose reference
is the state at the start of the trajectory and may be inflated).
"""

from __future__ import annotations

import datetime
import logging
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin.io.calibration import REFERENCE_RTOL

logger = logging.getLogger(__name__)

#: A marker "moved" during the capture when its mean position differs by more than this (mm)
#: between the two halves of the window (motion-capture noise is ~0.2 mm per frame).
MOTION_MM = 1.0
#: A channel "drifted" when its half-window means differ by more than this many standard errors…
DRIFT_SIGMAS = 8.0
#: …and by more than this fraction of its level (0.01 %: below any touch's effect).
DRIFT_REL_MIN = 1e-4
#: Windows shorter than this are not judged for drift and motion (too few frames for a noise
#: estimate); contact and inflation are always checked.
MIN_JUDGED_FRAMES = 6
#: Problems of a window (:meth:`WindowCheck.messages` kinds) that make a reference refuse it and
#: capture again; the others are warned about.
REFUSED_BY = {"touch": ("contact", "inflation"), "tracking": ()}
REFERENCE_KINDS = ("both", "touch", "track")


@dataclass
class WindowCheck:
    """The verdict on one capture window (see :func:`check_window`).

    ``contact``: frame numbers with a touch label; ``labels``: the touch labels seen;
    ``inflated``: frame numbers with a non-zero inflation and ``inflation`` the largest one seen;
    ``motion_mm``: the largest marker displacement between the window's halves (None without
    markers); ``drift``: (channel index, relative change) of the drifting channels.
    """

    contact: list[int] = field(default_factory=list)
    labels: list[int] = field(default_factory=list)
    inflated: list[int] = field(default_factory=list)
    inflation: tuple[float, ...] | None = None
    motion_mm: float | None = None
    drift: list[tuple[int, float]] = field(default_factory=list)

    @property
    def moved(self) -> bool:
        return self.motion_mm is not None and self.motion_mm > MOTION_MM

    def messages(self, pair_names: list[str] | tuple[str, ...]) -> dict[str, str]:
        """One message per problem found, by kind (``contact``, ``inflation``, ``motion``,
        ``drift``)."""
        out = {}
        if self.contact:
            out["contact"] = (
                f"{len(self.contact)} frame(s) with contact (label "
                f"{', '.join(map(str, self.labels))}; first frame {self.contact[0]})"
            )
        if self.inflated:
            infl = "/".join(f"{v:g}" for v in self.inflation or ())
            out["inflation"] = (
                f"{len(self.inflated)} frame(s) inflated ({infl} ml; first frame "
                f"{self.inflated[0]})"
            )
        if self.moved:
            out["motion"] = (
                f"markers moved {self.motion_mm:.1f} mm during the capture (more than "
                f"{MOTION_MM:g} mm)"
            )
        if self.drift:
            worst = sorted(self.drift, key=lambda d: -abs(d[1]))[:3]
            names = ", ".join(f"{pair_names[j]} {100 * r:+.2f} %" for j, r in worst)
            out["drift"] = (
                f"{len(self.drift)} channel(s) changed during the capture far beyond their "
                f"noise ({names})"
            )
        return out


def check_window(
    caps: np.ndarray,
    seqs: list[int],
    labels: list[int | None],
    inflations: list[tuple[float, ...] | None],
    markers: list[np.ndarray | None],
) -> WindowCheck:
    """Judge a capture window: ``caps`` (n, n_pairs) pF, and per frame its number, label (None =
    unknown), inflation (None = unknown) and markers ((n_markers, 3) mm or None)."""
    chk = WindowCheck()
    for seq, lab in zip(seqs, labels, strict=True):
        if lab is not None and lab != 0:
            chk.contact.append(seq)
            if lab not in chk.labels:
                chk.labels.append(int(lab))
    peak: tuple[float, ...] | None = None
    for seq, infl in zip(seqs, inflations, strict=True):
        if infl is not None and any(v != 0 for v in infl):
            chk.inflated.append(seq)
            if peak is None or max(infl) > max(peak):
                peak = tuple(float(v) for v in infl)
    chk.inflation = peak
    n = caps.shape[0]
    if n < MIN_JUDGED_FRAMES:
        return chk
    h = n // 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN channels / markers
        # drift: half-window means against the noise of frame-to-frame differences (robust: the
        # median ignores the one large difference of a step)
        m1, m2 = np.nanmean(caps[:h], axis=0), np.nanmean(caps[h:], axis=0)
        sigma = np.nanmedian(np.abs(np.diff(caps, axis=0)), axis=0) / (0.6745 * np.sqrt(2.0))
        stderr = sigma * np.sqrt(1.0 / h + 1.0 / (n - h))
        level = np.abs(np.nanmean(caps, axis=0))
        change = np.abs(m2 - m1)
        bad = (change > DRIFT_SIGMAS * stderr) & (change > DRIFT_REL_MIN * level)
        chk.drift = [(int(j), float((m2[j] - m1[j]) / level[j])) for j in np.flatnonzero(bad)]
        seen = [m for m in markers if m is not None]
        if len(seen) >= MIN_JUDGED_FRAMES:
            ms = np.stack(seen)  # (n_seen, n_markers, 3)
            k = len(seen) // 2
            d = np.linalg.norm(np.nanmean(ms[k:], axis=0) - np.nanmean(ms[:k], axis=0), axis=1)
            chk.motion_mm = float(np.nanmax(d)) if np.isfinite(d).any() else None
    return chk


class ReferenceCapture:
    """One reference (Eq. 2's c_0) captured from a window of raw frames, with its verdict.

    :meth:`start` begins a capture of ``n`` frames; :meth:`add` takes one frame and returns True
    when the window is complete. Then :attr:`last_check` is the window's :class:`WindowCheck`;
    :meth:`accept` makes the window the reference: ``c0`` (n_pairs,) pF, the channel-wise mean
    of the window's finite readouts (the same mean as ``ectskin.io.calibration.touch_reference``
    takes of the rest-state frames), NaN for a channel never finite or whose mean is tiny
    (|c_0| <= ``REFERENCE_RTOL`` × the largest |c_0|, as
    :func:`ectskin.io.calibration.check_reference` judges it), and ``markers`` the (n_markers, 3)
    mm mean marker coordinates (None when no frame carried markers). :meth:`start` again after a
    refused window keeps the reference in use until a new one is accepted.
    """

    def __init__(self, n_pairs: int, n_markers: int):
        self.c0: np.ndarray | None = None  # (n_pairs,) pF, NaN = unusable channel
        self.markers: np.ndarray | None = None  # (n_markers, 3) mm mean over the capture
        self.n_pairs, self.n_markers = n_pairs, n_markers
        self.target = 0  # frames still to take; 0 = not capturing
        self.seqs: list[int] = []
        self.times: list[float] = []
        self.last_check: WindowCheck | None = None
        #: how the reference in use was taken: frames, times, when, warnings (JSON-able)
        self.info: dict[str, Any] | None = None
        self._reset_window()

    def _reset_window(self) -> None:
        self.seqs, self.times = [], []
        self._caps: list[np.ndarray] = []
        self._labels: list[int | None] = []
        self._infl: list[tuple[float, ...] | None] = []
        self._markers: list[np.ndarray | None] = []

    def start(self, n: int) -> None:
        self.target = n
        self._reset_window()

    @property
    def capturing(self) -> bool:
        return self.target > 0

    def add(
        self,
        c: np.ndarray,
        markers: np.ndarray | None,
        seq: int,
        *,
        t: float = float("nan"),
        label: int | None = None,
        inflation: tuple[float, ...] | None = None,
    ) -> bool:
        """Take one frame; returns True when the window just completed (then judge it with
        :attr:`last_check` and :meth:`accept` it, or :meth:`start` again)."""
        self._caps.append(np.asarray(c, dtype=np.float64))
        self._markers.append(markers)
        self._labels.append(label)
        self._infl.append(inflation)
        self.seqs.append(seq)
        self.times.append(float(t))
        self.target -= 1
        if self.target:
            return False
        self.last_check = check_window(
            np.stack(self._caps), self.seqs, self._labels, self._infl, self._markers
        )
        return True

    def accept(self, warnings_: list[str] | None = None) -> None:
        """Make the completed window the reference in use."""
        # (n_pairs, n): each channel's frames contiguous, so its mean is reduced the way
        # touch_reference() reduces the rest-state frames (pairwise, along each channel), and a
        # window over the rest trial gives its reference bit for bit
        per_channel = np.ascontiguousarray(np.stack(self._caps).T)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a channel never finite: NaN
            if np.isfinite(per_channel).all():
                c0 = per_channel.mean(axis=1)
            else:
                c0 = np.nanmean(per_channel, axis=1)
            seen = [m for m in self._markers if m is not None]
            m = np.nanmean(np.stack(seen), axis=0) if seen else None
        scale = np.nanmax(np.abs(c0)) if np.isfinite(c0).any() else 0.0
        bad = ~np.isfinite(c0) | (np.abs(c0) <= REFERENCE_RTOL * scale)
        c0[bad] = np.nan
        self.c0 = c0
        self.markers = m
        self.info = {
            "frames": [int(self.seqs[0]), int(self.seqs[-1])],
            "t": [self.times[0], self.times[-1]],
            "captured_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "warnings": list(warnings_ or []),
        }

    def initial_markers(self, fallback: np.ndarray | None) -> np.ndarray | None:
        """The decoder's initial marker coordinates after a capture: the captured mean, with a
        marker coordinate never seen filled from ``fallback`` (n_markers, 3) mm when given; only
        ``fallback`` when no frame carried markers."""
        m = self.markers
        if m is not None and fallback is not None:
            return np.where(np.isfinite(m), m, fallback)
        if m is None:
            return fallback
        return m


class References:
    """The live engine's two references, ``touch`` and ``tracking`` (:class:`ReferenceCapture`),
    with the policy of :data:`REFUSED_BY` and the account that :meth:`state` gives.

    :meth:`start` begins a capture of ``frames`` frames (``which``: one of
    :data:`REFERENCE_KINDS`); :meth:`add` feeds one frame to the captures in progress and returns
    the references whose window it completed and accepted, each with the line that says how (also
    logged: a warning when something was wrong); a refused window is logged (the first three
    refusals, then every tenth) and captured again.
    """

    def __init__(self, n_pairs: int, n_markers: int, pair_names: Sequence[str]):
        self.touch = ReferenceCapture(n_pairs, n_markers)
        self.tracking = ReferenceCapture(n_pairs, n_markers)
        self.pair_names = list(pair_names)
        self.frames = 0
        self.refusals = {"touch": 0, "tracking": 0}
        self.last_refusal: dict[str, str | None] = {"touch": None, "tracking": None}

    def _named(self) -> tuple[tuple[str, ReferenceCapture], ...]:
        return (("touch", self.touch), ("tracking", self.tracking))

    def start(self, which: str, frames: int) -> None:
        self.frames = frames
        if which in ("both", "touch"):
            self.touch.start(frames)
        if which in ("both", "track"):
            self.tracking.start(frames)

    @property
    def capturing(self) -> bool:
        return self.touch.capturing or self.tracking.capturing

    def add(self, f) -> list[tuple[str, ReferenceCapture, str]]:
        """Feed frame ``f`` (a :class:`~ectskin.live.sources.Frame`) to the captures in progress;
        returns ``(name, reference, text)`` for each reference it completed and accepted."""
        done = []
        for name, ref in self._named():
            if ref.capturing and ref.add(
                f.capacitance, f.markers, f.seq, t=f.t, label=f.label, inflation=f.inflation
            ):
                warned = self._judge(name, ref)
                if warned is not None:
                    done.append((name, ref, self._accepted(name, ref, warned)))
        return done

    def _accepted(self, name: str, ref: ReferenceCapture, warned: list[str]) -> str:
        """Log an accepted reference; returns the line that says how it was taken."""
        bad = np.flatnonzero(np.isnan(ref.c0))
        if bad.size:
            logger.warning(
                "%s reference: %d channel(s) without a usable reference (%s); they calibrate to "
                "NaN and enter the models as 0",
                name,
                bad.size,
                ", ".join(self.pair_names[j] for j in bad[:8]),
            )
        text = f"{name} reference captured from frames {ref.seqs[0]}..{ref.seqs[-1]}"
        if not warned:
            logger.info("%s", text)
            return text
        text += f", but: {'; '.join(warned)}"
        logger.warning(
            "%s. Re-capture it with the skin untouched, uninflated and still (the dashboard's "
            "button, or restart)",
            text,
        )
        return text

    def _judge(self, name: str, ref: ReferenceCapture) -> list[str] | None:
        """Refuse the completed window (returns None, capture restarted) or accept it (returns
        its warnings)."""
        found = ref.last_check.messages(self.pair_names)
        refused = [msg for kind, msg in found.items() if kind in REFUSED_BY[name]]
        warned = [msg for kind, msg in found.items() if kind not in REFUSED_BY[name]]
        if not refused:
            self.last_refusal[name] = None
            ref.accept(warned)
            return warned
        self.refusals[name] += 1
        k = self.refusals[name]
        text = f"{name} reference refused (frames {ref.seqs[0]}..{ref.seqs[-1]}): " + "; ".join(
            refused
        )
        self.last_refusal[name] = text
        if k <= 3 or k % 10 == 0:
            logger.warning(
                "%s. The skin must be untouched and uninflated while the reference is captured; "
                "capturing again from the next %d frames (refusal #%d)",
                text,
                self.frames,
                k,
            )
        ref.start(self.frames)
        return None

    def state(self) -> dict[str, Any]:
        """Both references, JSON-able. Per reference (``touch``, ``tracking``): ``state``
        ("waiting" for frames, "capturing", "retrying" after a refused window, "ready"),
        ``in_use`` (frames, source times, ``captured_utc`` and ``warnings`` of the reference in
        use, or None), ``refusals`` (windows refused so far) and ``last_refusal`` (why the last
        window was refused; None after an accepted one)."""
        out = {}
        for name, ref in self._named():
            if ref.capturing:
                state = "retrying" if self.last_refusal[name] else "capturing"
            else:
                state = "ready" if ref.c0 is not None else "waiting"
            out[name] = {
                "state": state,
                "in_use": ref.info,
                "refusals": self.refusals[name],
                "last_refusal": self.last_refusal[name],
            }
        return out


def reference_line(state: dict[str, Any]) -> str:
    """One line on one reference of :meth:`References.state` (``state["touch"]``), for a run's
    summary: where and when the reference in use was captured and what was wrong with it, or
    why none was."""
    use = state["in_use"]
    if use is None:
        why = f"; last refusal: {state['last_refusal']}" if state["last_refusal"] else ""
        return f"never captured ({state['refusals']} window(s) refused{why})"
    a, b = use["frames"]
    text = f"frames {a}..{b}, captured {use['captured_utc']}"
    if state["refusals"]:
        text += f", after {state['refusals']} refused window(s)"
    if use["warnings"]:
        text += "; WARNING: " + "; ".join(use["warnings"])
    return text
