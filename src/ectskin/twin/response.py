"""The readout of a touch trial as a smooth function of the frame's state (the response models).

A touch trial's frames differ in the finger's force, its small slide around the dwell point, its
height above the skin and the hand's push. :class:`TouchResponse` solves the method of moments at
a few Chebyshev nodes in force (plus a slide, a push and a hover solve) and interpolates between
them per frame; :class:`SecondFingerResponse` adds a second finger's effect to it. The trials that
use these models are built in :mod:`ectskin.twin.simulate`.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev

from ectskin._check import EctskinError
from ectskin.twin.mechanics import Handling, Touch


def chebyshev_nodes(lo: float, hi: float, k: int) -> np.ndarray:
    """(k,) Chebyshev nodes of the first kind on [lo, hi] (the interpolation nodes in force)."""
    x = np.cos(np.pi * (2 * np.arange(k) + 1) / (2 * k))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


def _cheb_fit(x_lo: float, x_hi: float, nodes: np.ndarray, values: np.ndarray, x: np.ndarray):
    """Evaluate at ``x`` the Chebyshev interpolant of ``values`` (K, P) given at ``nodes``."""
    if x_hi - x_lo < 1e-12:
        return np.repeat(values[:1], np.size(x), axis=0)
    xn = (2 * nodes - (x_lo + x_hi)) / (x_hi - x_lo)
    coef = chebyshev.chebfit(xn, values, nodes.size - 1)
    return chebyshev.chebval((2 * np.asarray(x) - (x_lo + x_hi)) / (x_hi - x_lo), coef).T


class TouchResponse:
    """The readout of one touch trial as a smooth function of the frame's state.

    The finger's state moves along a few smooth coordinates within a trial, so the trial needs a
    handful of method-of-moments solves, not one per frame:

    * the force F (contact) or the height h (above the skin): a Chebyshev interpolant at the
      trial's mean point, over the trial's force range (``force_nodes`` solves) and over log h
      (``force_nodes`` + 2 solves, only if the finger leaves the skin). The finger's off-axis
      push is a fixed fraction of F, so it rides along;
    * the point (u, v) on the skin: a quadratic in (u − ū, v − v̄) from a 5-point stencil and
      one diagonal point, ``slide_step_mm`` apart, at the middle force (5 solves; the middle
      Chebyshev node is the stencil's centre), added to the frames in contact;
    * the hand's push m (fixed direction, varying magnitude): a slope at the middle force
      (1 solve), added to every frame.

    The model's error against direct solves is bounded in the tests.
    """

    slide_step_mm = 1.0

    def __init__(self, sensor, inflation, surface, path, handling, push_dir, protocol):
        self.sensor, self.p, self.surface = sensor, inflation, surface
        self.n_solves = 0  # method-of-moments solves this trial took
        self.shear_per_n = np.zeros(2)
        on = path.contact
        if on.any():
            self.shear_per_n = (path.shear_n[on] / path.force_n[on, None]).mean(axis=0)
        self.push_dir = push_dir
        self.push_point = handling.push
        self.uv0 = path.uv_mm[on].mean(axis=0) if on.any() else path.uv_mm.mean(axis=0)
        mags = self._push_magnitude(handling)
        self.m0 = float(mags.mean()) if mags is not None else 0.0
        dm = float(np.ptp(mags)) / 2 if mags is not None else 0.0
        k = protocol.force_nodes | 1  # odd: the middle node is the range's centre
        self.f_lo = self.f_hi = 0.0
        if on.any():
            self.f_lo, self.f_hi = float(path.force_n[on].min()), float(path.force_n[on].max())
        self.f_nodes = chebyshev_nodes(self.f_lo, self.f_hi, k)
        c_nodes = self._solve(self.f_nodes) if on.any() else None
        self.c_nodes = c_nodes
        f_mid = np.array([0.5 * (self.f_lo + self.f_hi)])
        # the finger never lands: the stencil is taken at the lowest height
        centre = None if c_nodes is None else c_nodes[k // 2]
        off = ~on
        if off.any():
            h = np.log(path.height_mm[off])
            self.h_lo, self.h_hi = float(h.min()), float(h.max())
            self.h_nodes = chebyshev_nodes(self.h_lo, self.h_hi, k + 2)
            self.c_hover = self._solve(np.zeros(k + 2), heights=np.exp(self.h_nodes))
        heights = None if on.any() else np.exp([self.h_lo])
        forces = f_mid if on.any() else np.zeros(1)
        if centre is None:
            centre = self._solve(forces, heights=heights)[0]
        # the reference state the other terms are taken at (the second finger's too)
        self.ref_forces, self.ref_heights, self.centre = forces, heights, centre
        d = self.slide_step_mm
        stencil = np.stack(
            [self._solve(forces, du=du, heights=heights)[0] for du in ((d, 0), (-d, 0), (0, d), (0, -d), (d, d))]
        )
        self.g_u = (stencil[0] - stencil[1]) / (2 * d)
        self.g_v = (stencil[2] - stencil[3]) / (2 * d)
        self.g_uu = (stencil[0] - 2 * centre + stencil[1]) / d**2
        self.g_vv = (stencil[2] - 2 * centre + stencil[3]) / d**2
        # C(d, d) = C + d(g_u + g_v) + d²(g_uu + g_vv)/2 + d² g_uv
        self.g_uv = (
            stencil[4] - centre - d * (self.g_u + self.g_v) - 0.5 * d**2 * (self.g_uu + self.g_vv)
        ) / d**2
        self.h_slope = None
        if dm > 0:
            self.h_slope = (self._solve(forces, dm=dm, heights=heights)[0] - centre) / dm

    def _push_magnitude(self, handling):
        if handling.push_force_n is None or self.push_dir is None:
            return None
        return np.asarray(handling.push_force_n) @ self.push_dir

    def _handling(self, forces, m, second=None):
        forces = np.atleast_1d(forces)
        shear = forces[:, None] * self.shear_per_n[None, :]
        if second is not None:  # (F, 2 fingers, 2)
            shear = np.stack([shear, second[1][:, None] * second[2][None, :]], axis=1)
        push = None
        if self.push_point is not None:
            push = np.repeat((m * self.push_dir)[None, :], forces.size, axis=0)
        return Handling(shear_n=shear, push=self.push_point, push_force_n=push)

    def _solve(self, forces, *, du=(0.0, 0.0), dm=0.0, heights=None, second=None):
        """MoM solves at ``forces`` (K,) of this finger at its mean point + ``du``; ``second``:
        (Touch, forces (K,), shear per N (2,)) of a second finger pressing as well."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        self.n_solves += forces.size
        touch = Touch(self.surface, (float(self.uv0[0] + du[0]), float(self.uv0[1] + du[1])))
        handling = self._handling(forces, self.m0 + dm, second)
        if second is None:
            return self.sensor.capacitance(self.p, touch, forces, handling, heights_mm=heights)
        both = np.column_stack([forces, second[1]])
        h = None if heights is None else np.column_stack([heights, np.zeros(forces.size)])
        return self.sensor.capacitance(self.p, (touch, second[0]), both, handling, heights_mm=h)

    def __call__(self, path, handling) -> np.ndarray:
        """(n, n_pairs) readout of every frame of ``path``."""
        n = path.force_n.size
        out = np.empty((n, self.sensor.layout.n_pairs))
        on = path.contact
        if on.any():
            if self.c_nodes is None:
                raise EctskinError("TouchResponse: frames in contact, but the model was built "
                                   "from a path that never touches the skin")
            out[on] = _cheb_fit(self.f_lo, self.f_hi, self.f_nodes, self.c_nodes, path.force_n[on])
        off = ~on
        if off.any():
            out[off] = _cheb_fit(
                self.h_lo, self.h_hi, self.h_nodes, self.c_hover, np.log(path.height_mm[off])
            )
        # the point's quadratic applies in contact (above the skin the finger's point matters far
        # less, and hover frames are taken at the trial's mean point), or everywhere if the
        # finger never lands (then the stencil was taken at the lowest height)
        where = on if on.any() else np.ones(n, dtype=bool)
        du = path.uv_mm[where] - self.uv0
        u, v = du[:, :1], du[:, 1:]
        out[where] += (
            self.g_u * u + self.g_v * v + 0.5 * self.g_uu * u**2 + 0.5 * self.g_vv * v**2
            + self.g_uv * u * v
        )
        mags = self._push_magnitude(handling)
        if self.h_slope is not None and mags is not None:
            out += self.h_slope * (mags - self.m0)[:, None]
        return out


class SecondFingerResponse:
    """What a second finger adds to a :class:`TouchResponse`, in the frames where it presses.

    Taken around the first model's reference state (its middle force, or its lowest height if
    the first finger never lands) and the second finger's mean point ū₂ and middle force F̄₂:

    * Δ(F₁): the change the second finger at (ū₂, F̄₂) makes, as a Chebyshev interpolant over the
      first finger's force nodes (``force_nodes`` solves with both fingers, the single-finger
      values at the same nodes already known): the two fingers' coupling through the body and
      the field, as the first finger's force varies. Frames where the first finger is off the
      skin take Δ at the reference state;
    * B(F₂) − B(F̄₂): the second finger's own force, a Chebyshev interpolant over
      ``second_nodes`` forces at the reference state (the middle node is shared, so
      ``second_nodes`` − 1 solves);
    * a slope in the second finger's point (u₂, v₂) − ū₂: forward differences, ``slide_step_mm``
      apart (2 solves; the pad rolls and slides a millimetre or so).

    The first finger's point and the hand's push enter through the first model, unchanged by the
    second finger. The model's error against direct solves is bounded in the tests.
    """

    second_nodes = 3
    slide_step_mm = 1.0

    def __init__(self, first: TouchResponse, path1, surface2: str, path2):
        self.first = first
        on2 = path2.contact
        if not on2.any():
            raise EctskinError("second finger: its path never touches the skin")
        n0 = first.n_solves
        self.shear2 = (path2.shear_n[on2] / path2.force_n[on2, None]).mean(axis=0)
        self.uv2 = path2.uv_mm[on2].mean(axis=0)
        self.surface2 = surface2
        self.f2_lo, self.f2_hi = float(path2.force_n[on2].min()), float(path2.force_n[on2].max())
        k2 = self.second_nodes | 1
        self.f2_nodes = chebyshev_nodes(self.f2_lo, self.f2_hi, k2)
        f2_mid = self.f2_nodes[k2 // 2]
        ref_f, ref_h = first.ref_forces, first.ref_heights
        self.on1 = path1.contact.any()
        if self.on1:  # the coupling over the first finger's force nodes
            both = self._solve(first.f_nodes, np.full(first.f_nodes.size, f2_mid))
            self.delta_nodes = both - first.c_nodes
            ref_two = both[first.f_nodes.size // 2]
        else:
            ref_two = self._solve(ref_f, [f2_mid], heights=ref_h)[0]
        self.delta_ref = ref_two - first.centre
        others = np.delete(self.f2_nodes, k2 // 2)
        c2 = self._solve(np.repeat(ref_f, others.size), others, heights=_rep(ref_h, others.size))
        self.c2_nodes = np.insert(c2, k2 // 2, ref_two, axis=0)
        d = self.slide_step_mm
        steps = self._solve(
            np.repeat(ref_f, 2), [f2_mid] * 2, heights=_rep(ref_h, 2), du2=((d, 0.0), (0.0, d))
        )
        self.g2 = (steps - ref_two) / d  # (2, P): d C / d u2, d C / d v2
        self.ref_two = ref_two
        self.n_solves = first.n_solves - n0

    def _solve(self, forces1, forces2, *, heights=None, du2=None):
        forces2 = np.asarray(forces2, dtype=np.float64)
        if du2 is None:
            t2 = Touch(self.surface2, (float(self.uv2[0]), float(self.uv2[1])))
            return self.first._solve(forces1, heights=heights, second=(t2, forces2, self.shear2))
        rows = []
        for k, (du, dv) in enumerate(du2):  # one solve per displaced point
            t2 = Touch(self.surface2, (float(self.uv2[0] + du), float(self.uv2[1] + dv)))
            one = None if heights is None else heights[k : k + 1]
            second = (t2, forces2[k : k + 1], self.shear2)
            rows.append(
                self.first._solve(np.atleast_1d(forces1)[k : k + 1], heights=one, second=second)[0]
            )
        return np.stack(rows)

    def __call__(self, path1, path2) -> np.ndarray:
        """(n, n_pairs) change of the readout the second finger makes (0 where it is away)."""
        out = np.zeros((path2.force_n.size, self.ref_two.size))
        on2 = path2.contact
        on = on2 & path1.contact if self.on1 else np.zeros_like(on2)
        f = self.first
        if on.any():
            out[on] = _cheb_fit(f.f_lo, f.f_hi, f.f_nodes, self.delta_nodes, path1.force_n[on])
        off = on2 & ~on
        out[off] = self.delta_ref
        b = _cheb_fit(self.f2_lo, self.f2_hi, self.f2_nodes, self.c2_nodes, path2.force_n[on2])
        du = path2.uv_mm[on2] - self.uv2
        out[on2] += b - self.ref_two + du @ self.g2
        return out


def _rep(heights, n: int):
    """``heights`` (1,) repeated n times (None stays None)."""
    return None if heights is None else np.repeat(heights, n)
