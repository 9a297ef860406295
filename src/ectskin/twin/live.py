"""The digital twin as a live source: inflate and touch while streaming frames.

Each new (inflation, touch point) state costs a few method-of-moments solves (Chebyshev nodes over
the force range, as in :mod:`ectskin.twin.simulate`), cached; every frame after that is an
interpolation plus the readout and motion-capture noise models, far faster than 30 fps.
"""

from __future__ import annotations

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout, default_layout
from ectskin.twin.mechanics import Touch
from ectskin.twin.protocol import Protocol
from ectskin.twin.readout import mocap, readout
from ectskin.twin.response import chebyshev_nodes
from ectskin.twin.sensor import SensorModel

_FORCE_MAX_N = 3.0


class LiveTwin:
    """A streaming twin: ``set_inflation``, ``set_touch``, then ``next_frame()`` at will."""

    def __init__(
        self,
        layout: SensorLayout | None = None,
        *,
        seed: int = 0,
        frame_rate_hz: float = 30.0,
        sensor: SensorModel | None = None,
        protocol: Protocol | None = None,
    ):
        self.layout = layout or default_layout()
        self.sensor = sensor or SensorModel(self.layout)
        self.protocol = protocol or Protocol(frame_rate_hz=frame_rate_hz, seed=seed)
        self.frame_rate_hz = float(frame_rate_hz)
        self._rng = np.random.default_rng([seed, 3])
        self._drift_phase = self._rng.uniform(0, 2 * np.pi, self.layout.n_pairs)
        self._inflation = np.zeros(self.sensor.manipulator.config.n_chambers)
        self._touch: Touch | None = None
        self._region = 0
        self._force_target = 1.0
        self._force = 1.0
        self._cache: dict = {}
        self._frame = 0

    @property
    def n_pairs(self) -> int:
        return self.layout.n_pairs

    @property
    def n_markers(self) -> int:
        return self.layout.n_markers

    def set_inflation(self, p_ml) -> None:
        self._inflation = self.sensor.manipulator.check_inflation(p_ml)

    def set_touch(self, region: int | None, force_n: float = 1.0, uv_mm=None) -> None:
        """Touch ``region`` (at its centre, or at ``uv_mm``) with ``force_n``; None lifts."""
        if region is None or region == 0:
            self._touch, self._region = None, 0
            return
        reg = self.layout.region(int(region))
        if not 0 < force_n <= _FORCE_MAX_N:
            raise EctskinError(f"touch force must be in (0, {_FORCE_MAX_N}] N, got {force_n}")
        uv = tuple(uv_mm) if uv_mm is not None else reg.centre_mm
        self._touch, self._region = Touch(reg.surface, uv), reg.id
        self._force_target = float(force_n)

    def _interpolant(self):
        key = (tuple(self._inflation), self._touch)
        if key not in self._cache:
            p = self._inflation
            if self._touch is None:
                c0 = self.sensor.capacitance(p, None, [0.0])[0]
                self._cache[key] = lambda f: c0
            else:
                k = self.protocol.force_nodes
                lo, hi = 0.05, _FORCE_MAX_N
                nodes = chebyshev_nodes(lo, hi, k)
                c_nodes = self.sensor.capacitance(p, self._touch, nodes)
                coef = np.polynomial.chebyshev.chebfit((2 * nodes - lo - hi) / (hi - lo), c_nodes, k - 1)
                self._cache[key] = lambda f, coef=coef: np.polynomial.chebyshev.chebval(
                    (2 * f - lo - hi) / (hi - lo), coef
                )
            if len(self._cache) > 64:
                self._cache.pop(next(iter(self._cache)))
        return self._cache[key]

    def next_frame(self) -> tuple[np.ndarray, np.ndarray, int]:
        """One frame: capacitance (n_pairs,) pF, markers (n_markers, 3) mm, true label."""
        t = self._frame / self.frame_rate_hz
        self._frame += 1
        if self._touch is not None:  # the finger's force wanders smoothly around its target
            self._force += 0.1 * (self._force_target - self._force) + self._rng.normal(0, 0.01)
            self._force = float(np.clip(self._force, 0.05, _FORCE_MAX_N))
        c_true = np.asarray(self._interpolant()(self._force), dtype=np.float64)[None, :]
        cap = readout(c_true, np.array([t]), self._rng, self.protocol.readout, self._drift_phase)[0]
        force = self._force if self._touch is not None else 0.0
        m_true = self.sensor.marker_positions(self._inflation, self._touch, [force])
        markers = mocap(m_true, self._rng, self.protocol.mocap, 0, False)[0]
        return cap, markers, self._region
