"""The reference c_0 of paper Eq. 2, captured live: a NaN-aware running mean of raw frames."""

from __future__ import annotations

import numpy as np

from ectskin.io.calibration import REFERENCE_RTOL


class ReferenceCapture:
    """NaN-aware running mean of raw frames (and markers) for one reference (Eq. 2's c_0).

    :meth:`start` begins a capture of ``n`` frames; :meth:`add` takes one frame and returns True
    when the capture completes. Then ``c0`` is (n_pairs,) pF with NaN for a channel that was never
    finite or whose mean is tiny (|c_0| <= ``REFERENCE_RTOL`` × the largest |c_0|, as
    :func:`ectskin.io.calibration.check_reference` judges it), and ``markers`` the (n_markers, 3)
    mm mean marker coordinates (None when no frame carried markers).
    """

    def __init__(self, n_pairs: int, n_markers: int):
        self.c0: np.ndarray | None = None  # (n_pairs,) pF, NaN = unusable channel
        self.markers: np.ndarray | None = None  # (n_markers, 3) mm mean over the capture
        self.n_pairs, self.n_markers = n_pairs, n_markers
        self.target = 0  # frames still to take; 0 = not capturing
        self.seqs: list[int] = []

    def start(self, n: int) -> None:
        self.target = n
        self.seqs = []
        self._sum = np.zeros(self.n_pairs)
        self._cnt = np.zeros(self.n_pairs)
        self._msum = np.zeros((self.n_markers, 3))
        self._mcnt = np.zeros((self.n_markers, 3))

    @property
    def capturing(self) -> bool:
        return self.target > 0

    def add(self, c: np.ndarray, markers: np.ndarray | None, seq: int) -> bool:
        """Take one frame; returns True when the capture just completed."""
        ok = np.isfinite(c)
        self._sum[ok] += c[ok]
        self._cnt += ok
        if markers is not None:
            okm = np.isfinite(markers)
            self._msum[okm] += markers[okm]
            self._mcnt += okm
        self.seqs.append(seq)
        self.target -= 1
        if self.target:
            return False
        with np.errstate(invalid="ignore", divide="ignore"):
            c0 = self._sum / self._cnt
            m = self._msum / self._mcnt if self._mcnt.any() else None
        scale = np.nanmax(np.abs(c0)) if np.isfinite(c0).any() else 0.0
        bad = ~np.isfinite(c0) | (np.abs(c0) <= REFERENCE_RTOL * scale)
        c0[bad] = np.nan
        self.c0 = c0
        self.markers = m
        return True

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
