"""The surface map of :meth:`~ectskin.twin.mechanics.Manipulator.deform` under one set of loads,
as a function of the rest points (:meth:`~ectskin.twin.mechanics.Manipulator.surface_map`): what
does not depend on the points (the state's tables, the dimples' depths, the pose) is found once,
so points mapped many times under the same loads (a fingertip's placement maps its skin samples
a dozen times) pay only for their own part. ``deform`` itself is one such map, used once."""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.twin.mechanics_tables import kept_arrays, on_axis


class SurfaceMap:
    """``(uv_mm, keep_rest=False) -> (F, n, 3)``: :meth:`Manipulator.deform
    <ectskin.twin.mechanics.Manipulator.deform>` of one surface under one set of loads (see
    there for the points' shapes and ``keep_rest``).

    Made by :meth:`~ectskin.twin.mechanics.Manipulator.surface_map` (``manipulator``: that
    :class:`~ectskin.twin.mechanics.Manipulator`, not imported here: it imports this module):
    ``side`` the face's sign (front +1, back −1; None on the sides), ``p`` the checked
    inflation, ``n_f`` the frames,
    ``dents`` each finger's (rest point, dimple depth (F,)) on this face, ``state`` the state's
    tables (:meth:`~ectskin.twin.mechanics.Manipulator._rest_part`), ``zs`` the stretched axial
    grid and ``axis`` the pose's :func:`~ectskin.twin.mechanics_tables.axis_table`."""

    def __init__(
        self, manipulator: Any, surface: str, side: float | None, p: np.ndarray,
        n_f: int, dents: list[tuple[tuple[float, float], np.ndarray]],
        state: tuple[np.ndarray, Any], zs: np.ndarray, axis: np.ndarray,
    ) -> None:
        self.manipulator, self.surface, self.side, self.p = manipulator, surface, side, p
        self.n_f, self.dents, self.state, self.zs, self.axis = n_f, dents, state, zs, axis

    def __call__(self, uv_mm, keep_rest: bool = False) -> np.ndarray:
        m, surface, p, n_f = self.manipulator, self.surface, self.p, self.n_f
        c = m.config
        uv = np.asarray(uv_mm, dtype=np.float64)
        per_frame = uv.ndim == 3  # (F, n, 2): x, z below are (F, n), else (n,)
        if per_frame and (uv.shape[0] != n_f or uv.shape[2] != 2):
            raise EctskinError(
                f"deform: per-frame points must be (F, n, 2) with F = {n_f} frames, got shape "
                f"{uv.shape}"
            )
        if not per_frame:
            uv = uv.reshape(-1, 2)
        n_pts = uv.shape[-2]
        if keep_rest and not per_frame:
            key = (surface, uv.shape, uv.tobytes(), p.tobytes())
            x, z, offset, zq = kept_arrays(
                m._rests, key, lambda: m._rest_part(surface, uv, p, self.state)
            )
        else:
            x, z, offset, zq = m._rest_part(surface, uv, p, self.state)
        if self.side is not None:
            offset = np.broadcast_to(offset, (n_f, n_pts)).copy()
            for (u0, v0), depth in self.dents:  # each finger's dimple on this face
                r2 = (x - u0) ** 2 + (z - v0) ** 2
                bump = np.exp(-r2 / (2 * c.dimple_sigma_mm**2))
                offset -= depth[:, None] * (bump if per_frame else bump[None, :])
            yprime = self.side * offset
            xs = np.broadcast_to(x, yprime.shape)
        else:
            x0 = c.width_mm / 2 * (1.0 if surface == "right" else -1.0)
            yprime = np.broadcast_to(uv[..., 0], (n_f, n_pts))
            xs = np.full(yprime.shape, x0)
        # the axis and the section frame at each point's stretched axial position (per frame)
        return on_axis(self.zs, self.axis, zq, xs, yprime)
