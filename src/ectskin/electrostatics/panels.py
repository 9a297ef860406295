"""Flat parallelogram panels, the surface elements of the method of moments.

A conductor surface is cut into flat panels; panel ``k`` is the parallelogram spanned by
``centres[k] ± u[k]/2 ± v[k]/2`` (mm) and belongs to conductor ``conductor[k]``. The solver in
:mod:`ectskin.electrostatics.mom` puts a uniform charge on each panel. The builders of plates,
strips (wires), spheres and cylinders are in :mod:`ectskin.electrostatics.meshing`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError, check_array

logger = logging.getLogger(__name__)



@dataclass(frozen=True, eq=False)
class Panels:
    """Flat parallelogram panels: panel k spans ``centres[k] ± u[k]/2 ± v[k]/2``.

    Attributes
    ----------
    centres : (N, 3) float, mm
        Panel centres (the collocation points of the method of moments).
    u, v : (N, 3) float, mm
        Full edge vectors; the panel normal is ``u × v / |u × v|``.
    conductor : (N,) int
        Conductor index of each panel, ``0 .. n_conductors - 1``.
    n_conductors : int
        Number of conductors (a conductor may not be left without panels when solving).

    The arrays are checked once, here, and stored read-only.
    """

    centres: np.ndarray
    u: np.ndarray
    v: np.ndarray
    conductor: np.ndarray
    n_conductors: int

    def __post_init__(self) -> None:
        centres = _rows3("Panels.centres", self.centres, None)
        n = centres.shape[0]
        u = _rows3("Panels.u", self.u, n)
        v = _rows3("Panels.v", self.v, n)
        conductor = conductor_array(self.conductor, n, "Panels.conductor")
        if isinstance(self.n_conductors, bool) or not isinstance(
            self.n_conductors, (int, np.integer)
        ):
            raise EctskinError(
                f"Panels.n_conductors must be int, got {type(self.n_conductors).__name__} "
                f"({self.n_conductors!r:.60})"
            )
        n_conductors = int(self.n_conductors)
        if n_conductors < 1:
            raise EctskinError(f"Panels.n_conductors must be >= 1, got {n_conductors}")
        if n and (conductor.min() < 0 or conductor.max() >= n_conductors):
            bad = int(np.flatnonzero((conductor < 0) | (conductor >= n_conductors))[0])
            raise EctskinError(
                f"Panels.conductor[{bad}] must be in 0..{n_conductors - 1} "
                f"(n_conductors={n_conductors}), got {int(conductor[bad])}"
            )
        cross = cross3(u, v)
        areas = _norms(cross)
        # A panel is degenerate when its area is negligible against its edge lengths squared.
        scale = _norms(u) * _norms(v)
        degenerate = ~(areas > 1e-9 * scale) | ~(scale > 0)
        if np.any(degenerate):
            bad = int(np.flatnonzero(degenerate)[0])
            raise EctskinError(
                f"Panels: panel {bad} is degenerate (edge vectors u={u[bad].tolist()} mm, "
                f"v={v[bad].tolist()} mm span zero area); expected two non-parallel, non-zero "
                "edges"
            )
        for name, arr in (("centres", centres), ("u", u), ("v", v), ("conductor", conductor)):
            arr = np.array(arr)  # own copy, then freeze it
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "n_conductors", n_conductors)
        areas.setflags(write=False)
        object.__setattr__(self, "_areas", areas)
        normals = cross / np.where(areas > 0, areas, 1.0)[:, None]
        normals.setflags(write=False)
        object.__setattr__(self, "_normals", normals)

    def __repr__(self) -> str:
        return f"Panels(n_panels={self.n_panels}, n_conductors={self.n_conductors})"

    # ------------------------------------------------------------------ derived quantities
    @property
    def n_panels(self) -> int:
        """Number of panels N."""
        return int(self.centres.shape[0])

    @property
    def areas(self) -> np.ndarray:
        """(N,) panel areas ``|u × v|``, mm²."""
        return self._areas  # type: ignore[attr-defined]

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) unit normals ``u × v / |u × v|``."""
        return self._normals  # type: ignore[attr-defined]

    @property
    def sizes(self) -> np.ndarray:
        """(N,) characteristic size: the longer diagonal ``max(|u + v|, |u − v|)``, mm.

        It bounds the distance between any two points of the panel, which is what decides
        whether a point sees the panel as a point charge (see :func:`~.mom.potential_matrix`).
        """
        sizes = self.__dict__.get("_sizes")
        if sizes is None:  # (computed once: the arrays are read-only)
            sizes = np.maximum(_norms(self.u + self.v), _norms(self.u - self.v))
            sizes.setflags(write=False)
            object.__setattr__(self, "_sizes", sizes)
        return sizes

    def corners(self) -> np.ndarray:
        """(N, 4, 3) parallelogram corners ``c0..c3`` in order around each panel, mm.

        ``c0 = centre − u/2 − v/2``, ``c1 = centre + u/2 − v/2``, ``c2 = centre + u/2 + v/2``,
        ``c3 = centre − u/2 + v/2``; the order is counter-clockwise seen from the normal.
        """
        hu = 0.5 * self.u[:, None, :]
        hv = 0.5 * self.v[:, None, :]
        signs_u = np.array([-1.0, 1.0, 1.0, -1.0])[None, :, None]
        signs_v = np.array([-1.0, -1.0, 1.0, 1.0])[None, :, None]
        return self.centres[:, None, :] + signs_u * hu + signs_v * hv

    def conductor_areas(self) -> np.ndarray:
        """(n_conductors,) total panel area of each conductor, mm²."""
        return np.bincount(self.conductor, weights=self.areas, minlength=self.n_conductors)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_quads(
        cls,
        corners: np.ndarray,
        conductor: int | np.ndarray,
        n_conductors: int | None = None,
    ) -> Panels:
        """Panels from quads given by their corners (possibly non-planar, non-parallelogram).

        Parameters
        ----------
        corners : (N, 4, 3) mm
            Corners ``c0, c1, c2, c3`` in order around each quad.
        conductor : int or (N,) int
            Conductor index of every quad (an int applies to all).
        n_conductors : int, optional
            Number of conductors; default ``max(conductor) + 1``.

        Each quad is replaced by the parallelogram with ``centre = mean(corners)``,
        ``u = ((c1 − c0) + (c2 − c3)) / 2`` and ``v = ((c3 − c0) + (c2 − c1)) / 2`` (the mean
        opposite edges). This is exact for a parallelogram and first-order accurate for a
        slightly deformed one, which is how the digital twin deforms panels.
        """
        c = check_array("corners", corners, (None, 4, 3), finite=True)
        n = c.shape[0]
        cond = conductor_array(conductor, n, "conductor")
        if n_conductors is None:
            n_conductors = int(cond.max()) + 1 if n else 1
        centres = c.mean(axis=1)
        u = 0.5 * ((c[:, 1] - c[:, 0]) + (c[:, 2] - c[:, 3]))
        v = 0.5 * ((c[:, 3] - c[:, 0]) + (c[:, 2] - c[:, 1]))
        return cls(centres=centres, u=u, v=v, conductor=cond, n_conductors=n_conductors)

    @staticmethod
    def concatenate(parts: Sequence[Panels]) -> Panels:
        """Join panel sets; conductor ids are kept, ``n_conductors`` is the largest of the parts."""
        parts = list(parts)
        if not parts:
            raise EctskinError("Panels.concatenate needs at least one Panels, got none")
        for k, p in enumerate(parts):
            if not isinstance(p, Panels):
                raise EctskinError(
                    f"Panels.concatenate: parts[{k}] must be Panels, got {type(p).__name__}"
                )
        # the parts were checked when they were made, and every derived quantity is row-wise:
        # joined, not computed again (the same numbers)
        out = object.__new__(Panels)
        for name in ("centres", "u", "v", "conductor", "_areas", "_normals"):
            arr = np.concatenate([getattr(p, name) for p in parts])
            arr.setflags(write=False)
            object.__setattr__(out, name, arr)
        object.__setattr__(out, "n_conductors", max(p.n_conductors for p in parts))
        return out

    def with_conductor(
        self, conductor: int | np.ndarray, n_conductors: int | None = None
    ) -> Panels:
        """A copy with new conductor ids (an int applies to all panels); ``n_conductors``
        defaults to ``max(conductor) + 1``."""
        cond = conductor_array(conductor, self.n_panels, "conductor")
        if n_conductors is None:
            n_conductors = int(cond.max()) + 1 if cond.size else 1
        return Panels(self.centres, self.u, self.v, cond, n_conductors)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 3) row-wise cross products a × b of (n, 3) arrays: ``np.cross``'s arithmetic (the
    same products and differences), without its general-axis overhead."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def _rows3(name: str, value, n: int | None) -> np.ndarray:
    """``value`` as a finite float (n, 3) array (any n when None), or an EctskinError naming
    ``name`` (:func:`~ectskin._check.check_array`; a float64 array of that shape is taken as
    it is)."""
    if (
        isinstance(value, np.ndarray)
        and value.dtype == np.float64
        and value.ndim == 2
        and value.shape[1] == 3
        and (n is None or value.shape[0] == n)
        and np.isfinite(value).all()
    ):
        return value
    return check_array(name, value, (n, 3), finite=True)


def _norms(a: np.ndarray) -> np.ndarray:
    """(n,) Euclidean norms of the rows of an (n, 3) array (as ``np.linalg.norm(a, axis=1)``)."""
    return np.sqrt(np.add.reduce(a * a, axis=1))


def conductor_array(conductor, n: int, name: str) -> np.ndarray:
    """Broadcast an int (or check an (n,) array) of conductor ids to an (n,) int64 array."""
    if isinstance(conductor, (bool, np.bool_)):
        raise EctskinError(f"{name} must be an int or an (n,) int array, got a bool")
    if isinstance(conductor, (int, np.integer)):
        return np.full(n, int(conductor), dtype=np.int64)
    arr = np.asarray(conductor)
    if arr.dtype.kind not in "iu" and not (arr.size == 0 and arr.dtype.kind == "f"):
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise EctskinError(f"{name} must hold integer conductor ids, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if arr.shape != (n,):
        raise EctskinError(f"{name} must have shape ({n},), got {arr.shape}")
    return arr
