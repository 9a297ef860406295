"""The readout of a touch trial read from the state's response field (``Protocol.response="field"``).

:class:`~ectskin.twin.response.TouchResponse` takes about a dozen method-of-moments solves per
dwell, so a trial visits one or two points. Read from the state's
:class:`~ectskin.twin.field.ResponseField` instead, a finger that slides over its region to a new
point every half second costs nothing per point, and a trial visits dozens
(:meth:`ectskin.pipeline.config.ReproduceConfig.contact_protocol`) for about a dozen solves per
trial. A frame's readout is

    c = B(m) + Δ₁ + Δ₂

* **B(m), the body under the hand's push, without a finger**: direct solves of the simulation's
  own sensor (its mesh) at the trial's least and greatest push magnitude m along the push's
  direction, linear in between (one solve without a hand). The untouched readouts are thus the
  twin's own, those of the paper's trials.
* **Δ₁, the first finger in contact**: the field's signal at the frame's point and force,
  ``field.delta(face, u, v, F)`` (beyond the field's force range: linear in F from the range's
  end, with the field's own slope), plus the trial's finger's *difference* from the field's:
  *anchors*, direct solves of the simulation's own sensor (its mesh, with the trial's finger
  and its off-axis push) less its untouched readout, less the field's signal, at a grid over the
  finger's region (``grid_nodes``, 2 × 4) at the trial's median force, bilinear in (u, v), and
  linear in force from two more at the region's centre (the trial's 5th and 95th percentile
  forces). The anchors carry the trial's finger (people differ; the field is built for one
  finger), its tangential force, the field's interpolation error at the nodes, and the
  simulation's mesh where it differs from the field's (a field is solved on a coarser one,
  ``COARSE_FIELD_MESH``): wherever a direct solve anchors the readout it is the twin's own, as
  the paper's trials' are, and the field carries the signal's change between the anchors.
  Their number does not grow with the trial's points.
* **Δ₁, the finger above the skin**: within the field's heights, the field's hover signal
  scaled by a per-trial factor k = ⟨D, Δ⟩ / ⟨Δ, Δ⟩ that matches it to a direct solve's signal D
  with the trial's finger at the hover frames' mean point and median height (a bigger fingertip
  couples more; above the skin that is nearly a common factor). Beyond the field's top (the
  approach from ``approach_height_mm``, lifts of a few centimetres): direct solves at
  ``far_nodes`` heights (Chebyshev-Lobatto in ln h from the field's top to the trial's highest)
  at those frames' mean point, interpolated in ln h; the field's point dependence at the top
  is carried up, shrinking as the signal does.
* **Δ₂, a second finger**: superposed, the field's signal at its point and force. Where both
  fingers press, their coupling (they are one grounded conductor and screen each other: a
  quarter of the signal at the protocol's separation) and the second finger's difference come
  from direct two-finger solves at ``coupling_nodes`` times along those frames, linear in time
  between them. Where the second presses and the first is above the skin, the first still
  screens it, the more the lower it is (at the protocol's separation, largest over the pairs:
  0.8-0.95 times the second finger's signal with the first at 0.5 mm, 0.65-0.85 at 10 mm,
  about a third at 40 mm, 6-7 % at 100 mm): the correction (the two-finger solve less the field's second finger and
  the first finger's :meth:`~FieldTouchResponse.finger_above`) comes from ``screen_nodes``
  two-finger solves at those frames' mean points and the second finger's mean force, the first
  finger at heights spanning those frames' (Chebyshev-Lobatto in ln(h + ``screen_scale_mm``):
  the screening is flat in h below a fingertip's size and falls off in ln h above it),
  interpolated by the polynomial through them (one solve where the heights are all one).

What is neglected: the hand's push times the finger (B is taken without it), the finger's
difference between the anchors (bilinear) and its curvature in force, the finger's point up
high, the coupling's change between its anchors, and, while the second finger presses alone,
its force's and both fingers' points' change over those frames (the anchors take their means).
Each is bounded against direct ``SensorModel.capacitance`` solves in
``tests/twin/test_field_response.py`` and ``tests/twin/test_field_response_second.py``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.polynomial import chebyshev

from ectskin._check import EctskinError
from ectskin.twin.field import ResponseField
from ectskin.twin.mechanics import Handling, Touch
from ectskin.twin.sensor import SensorModel


def lobatto_nodes(lo: float, hi: float, k: int) -> np.ndarray:
    """(k,) Chebyshev-Lobatto nodes on [lo, hi], both ends included, ascending (k >= 2)."""
    x = -np.cos(np.pi * np.arange(k) / (k - 1))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


def _poly(nodes: np.ndarray, values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(len(x), P): the polynomial through ``values`` (K, P) at ``nodes`` (K,), at ``x``."""
    if nodes.size == 1:
        return np.repeat(values[:1], np.size(x), axis=0)
    lo, hi = nodes[0], nodes[-1]
    t = (2 * nodes - (lo + hi)) / (hi - lo)
    coef = chebyshev.chebfit(t, values, nodes.size - 1)
    return chebyshev.chebval((2 * np.asarray(x) - (lo + hi)) / (hi - lo), coef).T


def contact_delta(field: ResponseField, face: str, u, v, force) -> np.ndarray:
    """(n, P) the field's signal of a finger pressing at (u, v) with ``force`` (n,); beyond the
    field's force range linear in F from the range's end (the field's slope there)."""
    u, v, force = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (u, v, force))
    lo, hi = field.spec.force_range_n
    fc = np.clip(force, lo, hi)
    out = field.delta(face, u, v, fc)
    beyond = fc != force
    if beyond.any():
        slope = field.jacobian(face, u[beyond], v[beyond], fc[beyond])[..., 2]
        out[beyond] += slope * (force - fc)[beyond, None]
    return out


def hover_delta(field: ResponseField, face: str, u, v, height) -> np.ndarray:
    """(n, P) the field's signal of a finger hovering at ``height`` (n,) within the field's
    top; below the field's lowest height linear in h from it (the field's slope there)."""
    u, v, height = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (u, v, height))
    lo, hi = field.spec.height_range_mm
    if np.any(height > hi * (1 + 1e-12)):
        raise EctskinError(f"hover_delta: height {height.max():.4g} mm above the field's top {hi}")
    hc = np.clip(height, lo, hi)
    zeros = np.zeros_like(hc)
    out = field.delta(face, u, v, zeros, hc)
    below = hc != height
    if below.any():
        slope = field.jacobian(face, u[below], v[below], zeros[below], hc[below])[..., 3]
        out[below] += slope * (height - hc)[below, None]
    return out


#: the reading's version, in the settings of the steps that simulate with it: 2 = every direct
#: solve of the reading (anchors, hover scale, far solves, two-finger anchors) on the
#: simulation's own sensor (1: those on the field's sensor and mesh)
FIELD_RESPONSE_VERSION = 2


class FieldTouchResponse:
    """The readout of one touch trial from a response field (module docstring).

    Parameters
    ----------
    field : the trial's state's field.
    sensor : the simulation's sensor with the trial's fingers
        (:meth:`SensorModel.with_fingers`), for the body under the hand and the anchors.
    inflation, surface, path, hand, push_dir : as :class:`~ectskin.twin.response.TouchResponse`.
    region : ((u_lo, v_lo), (u_hi, v_hi)) mm, where the first finger's points lie (its
        region's bounds): the anchors' grid spans it.
    surface2, path2 : the second finger, or None.
    """

    #: the anchors' grid over the region (u, v), and the coupling anchors along the frames
    #: with both fingers on
    grid_nodes = (2, 4)
    coupling_nodes = 3
    far_nodes = 4
    #: the screening anchors while the second finger presses alone: heights (Chebyshev-Lobatto
    #: in ln(h + screen_scale_mm), flat in h below the scale, ln h above it)
    screen_nodes = 4
    screen_scale_mm = 10.0

    def __init__(
        self,
        field: ResponseField,
        sensor: SensorModel,
        inflation,
        surface: str,
        path,
        hand: Handling,
        push_dir,
        region,
        surface2: str | None = None,
        path2=None,
    ) -> None:
        for face in (surface, surface2):
            if face is not None and face not in field.faces:
                raise EctskinError(
                    f"response field: the trial touches the {face!r} face, the field covers "
                    f"{list(field.faces)}"
                )
        self.field, self.sensor = field, sensor
        self.p, self.face = tuple(inflation), surface
        self.face2: str = surface2 if surface2 is not None else surface  # (unused without one)
        self.n_solves = 0
        self._base(hand, push_dir)
        #: the sensor's untouched readout (P,): the direct solves' signals are taken from it
        self.u0 = (self.b_nodes[0] if self.push_dir is None
                   else self._solve(self.sensor, None, [0.0])[0])
        self._above(path)
        self._first(path, np.asarray(region, dtype=np.float64))
        self._second(path, path2)

    # ------------------------------------------------------------------ the parts
    def _solve(self, model: SensorModel, touch, forces, handling=None, heights=None) -> np.ndarray:
        out = model.capacitance(self.p, touch, forces, handling, heights_mm=heights)
        self.n_solves += out.shape[0]
        return out

    def _base(self, hand: Handling, push_dir) -> None:
        """B(m): the body without a finger at the least and greatest push of the trial."""
        self.push_dir = None if hand.push_force_n is None or push_dir is None else np.asarray(push_dir)
        if self.push_dir is None:
            self.m_nodes = np.zeros(1)
            self.b_nodes = self._solve(self.sensor, None, [0.0])
            return
        m = np.asarray(hand.push_force_n) @ self.push_dir
        lo, hi = float(m.min()), float(m.max())
        self.m_nodes = np.array([lo, hi]) if hi - lo > 1e-9 else np.array([lo])
        push = self.m_nodes[:, None] * self.push_dir[None, :]
        handling = Handling(push=hand.push, push_force_n=push)
        self.b_nodes = self._solve(self.sensor, None, np.zeros(self.m_nodes.size), handling)

    def _anchor(self, uv, force: float, shear) -> np.ndarray:
        """(P,) the direct solve with the trial's first finger less the field's, at one point."""
        f = self.field
        direct = self._solve(
            self.sensor, Touch(self.face, (float(uv[0]), float(uv[1]))), [force],
            Handling(shear_n=np.asarray(shear, dtype=np.float64)[None]),
        )[0]
        return direct - self.u0 - contact_delta(f, self.face, uv[0], uv[1], force)[0]

    def _first(self, path, region: np.ndarray) -> None:
        """The first finger's anchors: a grid over its region at the trial's median force, and
        the difference's slope in force at the region's centre."""
        on = path.contact
        self.grid = None
        if not on.any():
            return
        forces = path.force_n[on]
        shear_per_n = (path.shear_n[on] / forces[:, None]).mean(axis=0)
        self.f_ref = float(np.median(forces))
        lo, hi = region
        nu, nv = self.grid_nodes
        self.grid_u, self.grid_v = np.linspace(lo[0], hi[0], nu), np.linspace(lo[1], hi[1], nv)
        self.grid = np.stack([
            np.stack([self._anchor((u, v), self.f_ref, self.f_ref * shear_per_n) for v in self.grid_v])
            for u in self.grid_u
        ])  # (nu, nv, P)
        f_lo, f_hi = (float(x) for x in np.percentile(forces, [5, 95]))
        self.f_slope = np.zeros(self.field.n_pairs)
        if f_hi - f_lo > 1e-6:
            c = 0.5 * (lo + hi)
            d_lo = self._anchor(c, f_lo, f_lo * shear_per_n)
            d_hi = self._anchor(c, f_hi, f_hi * shear_per_n)
            self.f_slope = (d_hi - d_lo) / (f_hi - f_lo)

    def first_difference(self, uv: np.ndarray, force: np.ndarray) -> np.ndarray:
        """(n, P) the trial's first finger less the field's, pressing at ``uv`` (n, 2) with
        ``force`` (n,): the grid's anchors bilinear in (u, v), linear in force."""
        if self.grid is None:
            raise EctskinError("FieldTouchResponse: frames in contact, but the model was built "
                               "from a path that never touches the skin")
        u = np.clip(uv[:, 0], self.grid_u[0], self.grid_u[-1])
        v = np.clip(uv[:, 1], self.grid_v[0], self.grid_v[-1])
        out = np.zeros((len(uv), self.field.n_pairs))
        for i in range(self.grid_u.size):
            wu = _hat(self.grid_u, i, u)
            for j in range(self.grid_v.size):
                out += (wu * _hat(self.grid_v, j, v))[:, None] * self.grid[i, j]
        return out + self.f_slope * (np.asarray(force) - self.f_ref)[:, None]

    def _second(self, path, path2) -> None:
        """The second finger's anchors: a few at the first finger's heights while it is above
        the skin (the screening), and a few along the frames with both on (their coupling, in
        time)."""
        f = self.field
        #: the screening anchors: their ln(h + screen_scale_mm) (k,), corrections (k, P) and the
        #: first finger's lowest and highest height over those frames
        self.screen: tuple[np.ndarray, np.ndarray, tuple[float, float]] | None = None
        self.coupling = None
        if path2 is None:
            return
        on1, on2 = path.contact, path2.contact
        alone2 = on2 & ~on1
        if alone2.any():  # the second finger pressing while the first is above the skin
            uv2, f2 = path2.uv_mm[alone2].mean(axis=0), float(path2.force_n[alone2].mean())
            sh2 = path2.shear_n[alone2].mean(axis=0)
            uv1 = path.uv_mm[alone2].mean(axis=0)
            h = path.height_mm[alone2]
            lo, hi = float(h.min()), float(h.max())
            c = self.screen_scale_mm
            k = self.screen_nodes if hi - lo > 1e-6 * hi else 1
            x = lobatto_nodes(np.log(lo + c), np.log(hi + c), k) if k > 1 else np.log([lo + c])
            nodes_h = np.clip(np.exp(x) - c, lo, hi)  # (exp∘log round-off kept inside)
            shear = np.tile(np.stack([np.zeros(2), sh2]), (k, 1, 1))  # (k, 2 fingers, 2)
            direct = self._solve(
                self.sensor, (Touch(self.face, tuple(uv1)), Touch(self.face2, tuple(uv2))),
                np.tile([0.0, f2], (k, 1)), Handling(shear_n=shear),
                heights=np.c_[nodes_h, np.zeros(k)],
            )
            corr = (
                direct - self.u0 - contact_delta(f, self.face2, uv2[0], uv2[1], f2)[0]
                - self.finger_above(np.tile(uv1, (k, 1)), nodes_h)
            )
            self.screen = (x, corr, (lo, hi))
        both = np.flatnonzero(on1 & on2)
        if not both.size:
            return
        frames, values = [], []
        for part in np.array_split(both, min(self.coupling_nodes, both.size)):
            uv1, f1 = path.uv_mm[part].mean(axis=0), float(path.force_n[part].mean())
            uv2, f2 = path2.uv_mm[part].mean(axis=0), float(path2.force_n[part].mean())
            sh = np.stack([path.shear_n[part].mean(axis=0), path2.shear_n[part].mean(axis=0)])
            direct = self._solve(
                self.sensor, (Touch(self.face, tuple(uv1)), Touch(self.face2, tuple(uv2))),
                np.array([[f1, f2]]), Handling(shear_n=sh[None]),
            )[0]
            values.append(
                direct - self.u0 - contact_delta(f, self.face, uv1[0], uv1[1], f1)[0]
                - self.first_difference(uv1[None], np.array([f1]))[0]
                - contact_delta(f, self.face2, uv2[0], uv2[1], f2)[0]
            )
            frames.append(float(part.mean()))
        self.coupling = (np.array(frames), np.stack(values))

    def _above(self, path) -> None:
        """The hover scale k (within the field's heights) and the far solves (beyond them)."""
        f, face = self.field, self.face
        self.k_hover = 1.0
        self.far = None
        off = ~path.contact
        if not off.any():
            return
        h = path.height_mm
        top = f.spec.height_range_mm[1]
        near, far = off & (h <= top), off & (h > top)
        if near.any():
            uv = path.uv_mm[near].mean(axis=0)
            hm = float(np.median(h[near]))
            d = self._solve(self.sensor, Touch(face, tuple(uv)), [0.0], heights=[hm])[0]
            d = d - self.u0
            fd = hover_delta(f, face, uv[0], uv[1], hm)[0]
            self.k_hover = float(d @ fd / max(fd @ fd, 1e-30))
        if far.any():
            hi = float(h[far].max())
            k = self.far_nodes if hi > top * (1 + 1e-6) else 1
            far_h = np.exp(lobatto_nodes(np.log(top), np.log(hi), k)) if k > 1 else np.array([top])
            far_uv = path.uv_mm[far].mean(axis=0)
            z = np.zeros(far_h.size)
            d = self._solve(self.sensor, Touch(face, tuple(far_uv)), z, heights=far_h)
            self.far = (np.log(far_h), d - self.u0)

    # ------------------------------------------------------------------ readout
    def base(self, hand: Handling, n: int) -> np.ndarray:
        """(n, P) B(m) of each frame."""
        if self.push_dir is None or self.m_nodes.size == 1:
            return np.repeat(self.b_nodes[:1], n, axis=0)
        m = np.asarray(hand.push_force_n) @ self.push_dir
        lo, hi = self.m_nodes
        t = ((m - lo) / (hi - lo))[:, None]
        return (1 - t) * self.b_nodes[0] + t * self.b_nodes[1]

    def finger_above(self, uv: np.ndarray, h: np.ndarray) -> np.ndarray:
        """(n, P) the first finger's signal above the skin at ``uv`` (n, 2), ``h`` (n,)."""
        f, face = self.field, self.face
        top = f.spec.height_range_mm[1]
        out = np.empty((h.size, f.n_pairs))
        near = h <= top
        if near.any():
            out[near] = self.k_hover * hover_delta(f, face, uv[near, 0], uv[near, 1], h[near])
        far = ~near
        if far.any():
            if self.far is None:
                raise EctskinError("FieldTouchResponse: frames above the field's top, but the "
                                   "model was built from a path that never goes there")
            x, d = self.far
            at_top = self.k_hover * hover_delta(f, face, uv[far, 0], uv[far, 1], np.full(far.sum(), top))
            dh = _poly(x, d, np.log(h[far]))
            d_top = d[0]
            shrink = np.linalg.norm(dh, axis=1) / max(float(np.linalg.norm(d_top)), 1e-30)
            out[far] = dh + (at_top - d_top) * shrink[:, None]
        return out

    def second_alone(self, h: np.ndarray) -> np.ndarray:
        """(n, P) the correction of the superposed second finger while it presses and the first
        is ``h`` (n,) above the skin: the anchors' polynomial in ln(h + ``screen_scale_mm``)."""
        if self.screen is None:
            raise EctskinError("FieldTouchResponse: the second finger presses alone, but the model "
                               "was built from paths in which it never does")
        x, corr, (lo, hi) = self.screen
        h = np.asarray(h, dtype=np.float64)
        if np.any(h < lo * (1 - 1e-9)) or np.any(h > hi * (1 + 1e-9)):
            raise EctskinError(
                f"FieldTouchResponse: the first finger at {h.min():.4g}-{h.max():.4g} mm, the "
                f"second finger's anchors span {lo:.4g}-{hi:.4g} mm (the paths it was built from)"
            )
        return _poly(x, corr, np.log(h + self.screen_scale_mm))

    def __call__(self, path, hand: Handling, path2=None) -> np.ndarray:
        """(n, n_pairs) readout of every frame of ``path`` (the path the model was built from)."""
        f, face = self.field, self.face
        n = path.force_n.size
        out = self.base(hand, n)
        on1 = path.contact
        on2 = np.zeros_like(on1) if path2 is None else path2.contact
        if on1.any():
            uv, force = path.uv_mm[on1], path.force_n[on1]
            out[on1] += contact_delta(f, face, uv[:, 0], uv[:, 1], force)
            out[on1] += self.first_difference(uv, force)
        if (~on1).any():
            out[~on1] += self.finger_above(path.uv_mm[~on1], path.height_mm[~on1])
        if on2.any():
            uv2 = path2.uv_mm[on2]
            out[on2] += contact_delta(f, self.face2, uv2[:, 0], uv2[:, 1], path2.force_n[on2])
        alone2 = on2 & ~on1
        if alone2.any():
            out[alone2] += self.second_alone(path.height_mm[alone2])
        both = np.flatnonzero(on1 & on2)
        if both.size and self.coupling is not None:
            t, values = self.coupling
            out[both] += np.stack([np.interp(both, t, values[:, k]) for k in range(f.n_pairs)], 1)
        return out


def _hat(nodes: np.ndarray, i: int, x: np.ndarray) -> np.ndarray:
    """(n,) the piecewise-linear basis function of node i of ``nodes`` (ascending) at ``x``."""
    e = np.zeros(nodes.size)
    e[i] = 1.0
    return np.interp(x, nodes, e)


class TrialFields:
    """The response fields of an experiment's states, loaded once per process.

    ``sources``: inflation state (ml per chamber) → a :class:`ResponseField`, or the path of a
    saved field (its ``field.npz`` or its cache folder), read on first use. Worker processes get
    the paths (cheap to send) and each reads a field once (:meth:`get`).
    """

    def __init__(self, sources: Mapping[tuple[float, ...], ResponseField | str | os.PathLike]):
        if not isinstance(sources, Mapping) or not sources:
            raise EctskinError(
                "fields must map inflation states (ml per chamber) to response fields or their "
                f"paths, got {type(sources).__name__}"
            )
        self._sources: dict[tuple[float, ...], ResponseField | str] = {}
        for state, src in sources.items():
            key = _state(state)
            if isinstance(src, ResponseField):
                self._sources[key] = src
            elif isinstance(src, str | os.PathLike):
                self._sources[key] = os.fspath(src)
            else:
                raise EctskinError(
                    f"fields[{key}] must be a ResponseField or a path, got {type(src).__name__}"
                )
        self._loaded: dict[tuple[float, ...], ResponseField] = {}

    @property
    def states(self) -> list[tuple[float, ...]]:
        return list(self._sources)

    def sources(self) -> dict[tuple[float, ...], ResponseField | str]:
        """What to send to a worker process (paths stay paths)."""
        return dict(self._sources)

    def get(self, inflation) -> ResponseField:
        """The field of state ``inflation`` (read once)."""
        key = _state(inflation)
        if key not in self._loaded:
            if key not in self._sources:
                raise EctskinError(
                    f"no response field for the inflation state {list(key)} ml; the fields "
                    f"cover {[list(s) for s in self._sources]}"
                )
            src = self._sources[key]
            field = src if isinstance(src, ResponseField) else _read(src)
            if tuple(field.spec.inflation_ml) != key:
                raise EctskinError(
                    f"the response field given for state {list(key)} ml was built for "
                    f"{list(field.spec.inflation_ml)} ml"
                )
            self._loaded[key] = field
        return self._loaded[key]


def _state(state) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in state)
    except (TypeError, ValueError):
        raise EctskinError(f"fields: a state must be volumes (ml per chamber), got {state!r}") from None


def _read(path: str) -> ResponseField:
    p = Path(path)
    return ResponseField.from_file(p / "field.npz" if p.is_dir() else p)
