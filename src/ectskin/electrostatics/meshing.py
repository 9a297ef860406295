"""Meshing for the method of moments: builders of flat panels for plates, strips, spheres, cylinders.

The panels themselves are :class:`~ectskin.electrostatics.panels.Panels`.

Builders come in two flavours:

* ``*_quads`` return corner arrays ``(n, 4, 3)`` (mm, corners ``c0, c1, c2, c3`` in order around
  the quad). This is what the digital twin deforms: it maps rest-state corners through a
  deformation map and rebuilds the panels with :meth:`Panels.from_quads`.
* ``*_panels`` return :class:`Panels` directly (rigid bodies such as the finger).

Discretisation advice (checked in ``tests/electrostatics/test_electrostatics.py``):

* Uniformly charged panels cannot hold the charge crowding at a free edge, so a coarse strip or
  plate behaves like a narrower one. :func:`edge_correction_factor` gives, from the 2-D
  cross-section problem, how much wider to mesh it so that it carries the true charge; with it a
  1-mm wire needs only 2 panels across (:data:`STRIP_PANELS_ACROSS`).
* Along a wire, panels may be long (:data:`STRIP_PANEL_LENGTH_MM` = 2 mm) if the last ones at a
  free end are refined to about w/8 (:func:`graded_nodes`).
* With both, two coplanar 1 × 60 mm strips 10 mm apart change their mutual capacitance by
  < 0.1 % when every panel dimension is halved, and agree with an uncorrected 8-across mesh to
  < 1 %. Pads: 3 × 3 cosine panels with ``edge_correction=True`` are within about 2 %.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ectskin._check import EctskinError, check_array, check_option
from ectskin.electrostatics.panels import Panels, cross3

SPACINGS = ("uniform", "cosine")

#: Recommended number of panels across a strip (with the edge correction).
STRIP_PANELS_ACROSS = 2
#: Recommended panel length along a 1-mm-wide strip away from its free ends, mm.
STRIP_PANEL_LENGTH_MM = 2.0

def grid_1d(n: int, spacing: str = "uniform") -> np.ndarray:
    """(n + 1,) node positions on ``[-1/2, 1/2]`` for ``n`` cells.

    ``"uniform"`` gives equal cells; ``"cosine"`` gives Chebyshev–Lobatto nodes
    ``−cos(π k / n) / 2``, cells shrinking toward both ends like the ``1/√(edge distance)``
    charge density at a strip's edges.
    """
    check_option("spacing", spacing, SPACINGS)
    n = _positive_int("n", n)
    k = np.arange(n + 1, dtype=np.float64)
    if spacing == "uniform":
        return k / n - 0.5
    return -0.5 * np.cos(np.pi * k / n)


@lru_cache(maxsize=64)
def edge_correction_factor(n: int, spacing: str = "cosine") -> float:
    """Factor (≥ 1) by which to widen a strip cut into ``n`` cells across so that it carries the
    charge of the true strip.

    Uniformly charged panels with collocation at their centres cannot hold the
    ``1/√(edge distance)`` charge crowding at a free edge, so a discretised strip behaves like a
    narrower one. For a long strip this is a two-dimensional property of the cross-section alone:
    the exact strip of width w is equivalent to a round wire of radius ``w / 4`` (conformal
    mapping), and solving the same pulse/collocation scheme in 2-D (kernel ``−ln|x − x'|``, whose
    cell integral is ``F(x) = x − x ln|x|``) gives the equivalent radius ``a_n`` of the discretised
    one: for a conductor at 1 V carrying total charge Q (in units of 2π ε), ``a_n = exp(−1/Q)``.
    The factor is ``(w / 4) / a_n``: 1.359 for 1 cell, 1.192 for 2, 1.053 for 4 cosine cells.
    It depends only on ``n`` and ``spacing`` (scale-free), so a deformed strip keeps it.
    """
    check_option("spacing", spacing, SPACINGS)
    g = grid_1d(n, spacing)
    a, b = g[:-1], g[1:]
    x = 0.5 * (a + b)

    def antiderivative(t):  # ∫ −ln|t| dt = t − t ln|t|
        at = np.abs(t)
        return t - np.where(at > 0, t * np.log(np.where(at > 0, at, 1.0)), 0.0)

    # potential at centre i of unit charge on cell j (per unit length, in units of 1/(2π ε))
    P = (antiderivative(x[:, None] - a[None, :]) - antiderivative(x[:, None] - b[None, :])) / (
        b - a
    )[None, :]
    q = np.linalg.solve(0.5 * (P + P.T), np.ones(len(x)))
    a_eq = float(np.exp(-1.0 / q.sum()))  # width 1 strip: exact a_eq = 1/4
    return 0.25 / a_eq


def graded_nodes(
    length: float,
    panel_length: float,
    end_panel: float,
    growth: float = 2.0,
    *,
    refine_start: bool = True,
    refine_end: bool = True,
) -> np.ndarray:
    """(n + 1,) node positions on ``[0, length]`` (mm): cells ``panel_length`` long, refined to
    ``end_panel`` at the refined ends and growing by ``growth`` per cell toward the middle.

    The end of a strip carries a charge peak that uniform cells miss (a 60-mm strip pair loses
    0.8 % of its mutual capacitance with 2-mm cells); refining the last cells to about a eighth
    of the strip width recovers it, while the middle cells may stay long.
    """
    length = _positive_float("length", length)
    panel_length = _positive_float("panel_length", panel_length)
    end_panel = _positive_float("end_panel", end_panel)
    growth = float(growth)
    if not (np.isfinite(growth) and growth > 1.0):
        raise EctskinError(f"growth must be a finite number > 1, got {growth}")
    n_ends = int(bool(refine_start)) + int(bool(refine_end))
    ramp: list[float] = []
    if n_ends:
        s = end_panel
        while s < panel_length and n_ends * (sum(ramp) + s) <= length:
            ramp.append(s)
            s *= growth
    rest = length - n_ends * sum(ramp)
    while ramp and 1e-12 * length < rest < ramp[-1]:  # no middle cell smaller than the ramp
        ramp.pop()
        rest = length - n_ends * sum(ramp)
    n_mid = int(np.ceil(rest / panel_length - 1e-9)) if rest > 1e-12 * length else 0
    cells = (ramp if refine_start else []) + [rest / max(n_mid, 1)] * n_mid
    cells += ramp[::-1] if refine_end else []
    nodes = np.concatenate([[0.0], np.cumsum(cells)])
    nodes[-1] = length
    return nodes


def grid_quads(centre, u_axis, v_axis, nodes_u, nodes_v) -> np.ndarray:
    """Corners of a flat tensor-product grid, (n_u * n_v, 4, 3) mm.

    ``nodes_u`` (n_u + 1,) and ``nodes_v`` (n_v + 1,) are increasing node offsets (mm) from
    ``centre`` along the perpendicular directions ``u_axis`` and ``v_axis`` (normalised here).
    Quad ``i * n_v + j`` has corners ``c0 = (u_i, v_j)``, ``c1 = (u_i+1, v_j)``,
    ``c2 = (u_i+1, v_j+1)``, ``c3 = (u_i, v_j+1)``; its normal is ``u_axis × v_axis``.
    """
    c = check_array("centre", centre, (3,), finite=True)
    eu = _unit("u_axis", u_axis)
    ev = _unit("v_axis", v_axis)
    if abs(float(eu @ ev)) > 1e-6:
        raise EctskinError(
            f"u_axis and v_axis must be perpendicular, got cos(angle) = {float(eu @ ev):.3g}"
        )
    gu = check_array("nodes_u", nodes_u, (None,), finite=True)
    gv = check_array("nodes_v", nodes_v, (None,), finite=True)
    for name, g in (("nodes_u", gu), ("nodes_v", gv)):
        if g.size < 2 or np.any(np.diff(g) <= 0):
            raise EctskinError(f"{name} must hold at least 2 strictly increasing values, got {g}")
    i, j = np.indices((gu.size - 1, gv.size - 1)).reshape(2, -1)  # the cells, i-major
    cu = np.stack([gu[i], gu[i + 1], gu[i + 1], gu[i]], axis=1)  # (n, 4)
    cv = np.stack([gv[j], gv[j], gv[j + 1], gv[j + 1]], axis=1)
    return c + cu[..., None] * eu + cv[..., None] * ev


def rectangle_quads(
    centre,
    u_axis,
    v_axis,
    size_u: float,
    size_v: float,
    n_u: int,
    n_v: int,
    *,
    spacing_u: str = "uniform",
    spacing_v: str = "uniform",
    edge_correction: bool = False,
) -> np.ndarray:
    """Corners of a flat rectangle cut into ``n_u × n_v`` quads, (n_u * n_v, 4, 3) mm.

    Parameters
    ----------
    centre : (3,) mm
    u_axis, v_axis : (3,)
        Directions of the two sides (normalised here; they must be perpendicular). The panel
        normals are ``u_axis × v_axis``.
    size_u, size_v : float, mm
        Side lengths.
    n_u, n_v : int
        Panels along each side.
    spacing_u, spacing_v : {"uniform", "cosine"}
        Node spacing along each side (see :func:`grid_1d`); ``"cosine"`` refines toward the edges.
    edge_correction : bool
        Widen each side by :func:`edge_correction_factor` so the coarse plate carries the edge
        charge of the true one (recommended for pads; measured in the tests).

    Quads are ordered with the v index fastest: quad ``i * n_v + j``. For wires prefer
    :func:`strip_quads` (edge correction across, refined ends along).
    """
    su = _positive_float("size_u", size_u)
    sv = _positive_float("size_v", size_v)
    if edge_correction:
        su *= edge_correction_factor(_positive_int("n_u", n_u), spacing_u)
        sv *= edge_correction_factor(_positive_int("n_v", n_v), spacing_v)
    return grid_quads(
        centre, u_axis, v_axis, grid_1d(n_u, spacing_u) * su, grid_1d(n_v, spacing_v) * sv
    )


def rectangle_panels(
    centre,
    u_axis,
    v_axis,
    size_u: float,
    size_v: float,
    n_u: int,
    n_v: int,
    conductor: int,
    *,
    n_conductors: int | None = None,
    spacing_u: str = "uniform",
    spacing_v: str = "uniform",
    edge_correction: bool = False,
) -> Panels:
    """:func:`rectangle_quads` as :class:`Panels` of one conductor."""
    q = rectangle_quads(
        centre,
        u_axis,
        v_axis,
        size_u,
        size_v,
        n_u,
        n_v,
        spacing_u=spacing_u,
        spacing_v=spacing_v,
        edge_correction=edge_correction,
    )
    return Panels.from_quads(q, conductor, n_conductors)


def strip_quads(
    p0,
    p1,
    width: float,
    normal,
    *,
    n_across: int = STRIP_PANELS_ACROSS,
    panel_length: float = STRIP_PANEL_LENGTH_MM,
    end_panel: float | None = None,
    growth: float = 2.0,
    spacing: str = "cosine",
    edge_correction: bool = True,
    refine_start: bool = True,
    refine_end: bool = True,
) -> np.ndarray:
    """Corners of a straight flat strip (wire) from ``p0`` to ``p1`` (mm), (n, 4, 3) mm.

    Parameters
    ----------
    p0, p1 : (3,) mm
        Ends of the strip's centre line.
    width : float, mm
        Physical strip width.
    normal : (3,)
        The strip's normal (its component along the strip axis is removed).
    n_across : int
        Panels across the width (``spacing`` grid).
    panel_length : float, mm
        Panel length in the middle of the strip.
    end_panel : float, mm, optional
        Length of the last panel at each refined end; default ``width / 8``.
    growth : float
        Growth of panel length from the ends inward (see :func:`graded_nodes`).
    edge_correction : bool
        Mesh the strip ``edge_correction_factor(n_across, spacing)`` times wider than ``width``
        so that its capacitance is that of the true strip (see :func:`edge_correction_factor`).
    refine_start, refine_end : bool
        Refine the panels at ``p0`` / ``p1`` (a free end; an end joined to a pad need not be).

    Quads are ordered along the strip, the across index fastest; the normals of the panels are
    ``axis × across`` = ``normal``. Defaults are the recommended discretisation for the 1-mm
    wires (< 1 % change in mutual capacitance when every panel dimension is halved).
    """
    a = check_array("p0", p0, (3,), finite=True)
    b = check_array("p1", p1, (3,), finite=True)
    length = float(np.linalg.norm(b - a))
    if not length > 0:
        raise EctskinError(f"strip: p0 and p1 must differ, both are {a.tolist()}")
    axis = (b - a) / length
    nrm = _unit("normal", normal)
    across = np.cross(nrm, axis)
    if not np.linalg.norm(across) > 1e-9:
        raise EctskinError("strip: normal must not be parallel to the strip axis p1 - p0")
    across /= np.linalg.norm(across)
    w = _positive_float("width", width)
    n_across = _positive_int("n_across", n_across)
    w_mesh = w * edge_correction_factor(n_across, spacing) if edge_correction else w
    end = w / 8.0 if end_panel is None else end_panel
    nodes_u = graded_nodes(
        length, panel_length, end, growth, refine_start=refine_start, refine_end=refine_end
    )
    return grid_quads(
        0.5 * (a + b), axis, across, nodes_u - 0.5 * length, grid_1d(n_across, spacing) * w_mesh
    )


def strip_panels(
    p0, p1, width: float, normal, conductor: int, *, n_conductors=None, **kwargs
) -> Panels:
    """:func:`strip_quads` as :class:`Panels` of one conductor (keyword options as there)."""
    return Panels.from_quads(strip_quads(p0, p1, width, normal, **kwargs), conductor, n_conductors)


# ---------------------------------------------------------------------- sphere
_CUBE_FACES = (
    # (normal, a, b): face points are normal + x a + y b, with a × b = normal (outward)
    (np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])),
    (np.array([-1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0])),
    (np.array([0, 1.0, 0]), np.array([0, 0, 1.0]), np.array([1.0, 0, 0])),
    (np.array([0, -1.0, 0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
    (np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),
    (np.array([0, 0, -1.0]), np.array([0, 1.0, 0]), np.array([1.0, 0, 0])),
)


def sphere_quads(centre, radius: float, n: int) -> np.ndarray:
    """Corners of an equiangular cubed sphere, (6 n², 4, 3) mm, all on the sphere.

    Each cube face is cut into ``n × n`` cells of equal angle (``tan`` mapping), then projected
    radially; cells are nearly square and none is degenerate. Corners run counter-clockwise
    seen from outside, so panel normals point outward.
    """
    c = check_array("centre", centre, (3,), finite=True)
    r = _positive_float("radius", radius)
    n = _positive_int("n", n)
    t = np.tan(0.25 * np.pi * np.linspace(-1.0, 1.0, n + 1))
    i, j = np.indices((n, n)).reshape(2, -1)  # the cells, i-major
    x = np.stack([t[i], t[i + 1], t[i + 1], t[i]], axis=1)  # (n², 4)
    y = np.stack([t[j], t[j], t[j + 1], t[j + 1]], axis=1)
    out = []
    for nrm, a, b in _CUBE_FACES:
        p = nrm + x[..., None] * a + y[..., None] * b  # (n², 4, 3)
        out.append(p / np.linalg.norm(p, axis=-1, keepdims=True))
    return c + r * np.concatenate(out)


def _spherical_quad_areas(unit_corners: np.ndarray) -> np.ndarray:
    """(n,) areas of spherical quads with great-circle edges on the unit sphere (sr).

    Two triangles (c0, c1, c2) and (c0, c2, c3), each by the Van Oosterom–Strackee formula
    tan(E/2) = |a · (b × c)| / (1 + a·b + b·c + c·a).
    """

    def tri(a, b, c):
        num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
        den = 1.0 + np.einsum("ij,ij->i", a, b) + np.einsum("ij,ij->i", b, c)
        den += np.einsum("ij,ij->i", c, a)
        return 2.0 * np.arctan2(num, den)

    q = unit_corners
    return tri(q[:, 0], q[:, 1], q[:, 2]) + tri(q[:, 0], q[:, 2], q[:, 3])


def sphere_panels(
    centre,
    radius: float,
    n: int,
    conductor: int,
    *,
    n_conductors: int | None = None,
    true_area: bool = True,
) -> Panels:
    """A sphere as ``6 n²`` cubed-sphere panels (see :func:`sphere_quads`).

    With ``true_area=True`` (default) each flat panel is moved out so its centre lies on the
    sphere and scaled so its area equals the spherical cell it stands for (the cell edges are
    great circles, so the exact area is the spherical excess). Flat inscribed panels otherwise
    shrink the sphere; with the correction the isolated-sphere capacitance is within about 0.2 % of
    4π ε0 R already at n = 6 (216 panels).
    """
    c = check_array("centre", centre, (3,), finite=True)
    if not c.any() and isinstance(conductor, (int, np.integer)):  # (a fingertip's own frame)
        return _sphere_at_origin(
            _positive_float("radius", radius), _positive_int("n", n), int(conductor),
            n_conductors, bool(true_area),
        )
    return _sphere_panels(c, radius, n, conductor, n_conductors, true_area)


@lru_cache(maxsize=16)
def _sphere_at_origin(
    radius: float, n: int, conductor: int, n_conductors: int | None, true_area: bool
) -> Panels:
    """:func:`sphere_panels` about the origin, kept (the panels are read-only)."""
    return _sphere_panels(np.zeros(3), radius, n, conductor, n_conductors, true_area)


def _sphere_panels(centre, radius, n, conductor, n_conductors, true_area) -> Panels:
    q = sphere_quads(centre, radius, n)
    p = Panels.from_quads(q, conductor, n_conductors)
    if not true_area:
        return p
    c = np.asarray(centre, dtype=np.float64)
    r = float(radius)
    unit = (q - c) / r
    target = _spherical_quad_areas(unit) * r * r
    d = p.centres - c
    centres = c + r * d / np.linalg.norm(d, axis=1, keepdims=True)
    s = np.sqrt(target / p.areas)[:, None]
    return Panels(centres, p.u * s, p.v * s, p.conductor, p.n_conductors)


# ---------------------------------------------------------------------- cylinder
def orthonormal_frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors e1, e2 with (e1, e2, axis) right-handed and orthonormal."""
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = cross3(helper, axis)
    e1 /= np.linalg.norm(e1)
    e2 = cross3(axis, e1)
    return e1, e2


def _disc_grid(m: int) -> tuple[np.ndarray, np.ndarray]:
    """(m+1, m+1) unit-disc coordinates from the square [-1, 1]² (elliptical grid mapping)."""
    s = np.linspace(-1.0, 1.0, m + 1)
    a, b = np.meshgrid(s, s, indexing="ij")
    x = a * np.sqrt(1.0 - 0.5 * b * b)
    y = b * np.sqrt(1.0 - 0.5 * a * a)
    return x, y


def cylinder_quads(
    p0, p1, radius: float, n_around: int, n_along: int, caps: bool = False
) -> np.ndarray:
    """Corners of a circular cylinder surface (axis p0 → p1), (n, 4, 3) mm.

    The side is ``n_around × n_along`` rectangles with corners on the circle (normals point
    outward); with ``caps=True`` two flat end discs are added, each an ``m × m`` grid
    (``m = max(2, n_around // 4)``) mapped from a square onto the disc (normals point outward).
    """
    a = check_array("p0", p0, (3,), finite=True)
    b = check_array("p1", p1, (3,), finite=True)
    r = _positive_float("radius", radius)
    n_around = _positive_int("n_around", n_around, minimum=3)
    n_along = _positive_int("n_along", n_along)
    length = float(np.linalg.norm(b - a))
    if not length > 0:
        raise EctskinError(f"cylinder: p0 and p1 must differ, both are {a.tolist()}")
    axis = (b - a) / length
    e1, e2 = orthonormal_frame(axis)
    phi = np.linspace(0.0, 2.0 * np.pi, n_around + 1)
    z = np.linspace(0.0, length, n_along + 1)
    i, j = np.indices((n_around, n_along)).reshape(2, -1)  # the cells, i-major
    # corners in order (phi_i, z_j), (phi_i+1, z_j), (phi_i+1, z_j+1), (phi_i, z_j+1):
    # u runs around, v along the axis, and u × v = (d/dphi) × axis points outward.
    pi_ = np.stack([phi[i], phi[i + 1], phi[i + 1], phi[i]], axis=1)
    zj = np.stack([z[j], z[j], z[j + 1], z[j + 1]], axis=1)
    radial = np.cos(pi_)[..., None] * e1 + np.sin(pi_)[..., None] * e2
    side = a + r * radial + zj[..., None] * axis
    if not caps:
        return side
    m = max(2, n_around // 4)
    x, y = _disc_grid(m)
    ii, jj = np.indices((m, m)).reshape(2, -1)  # the cells, ii-major
    cx = np.stack([x[ii, jj], x[ii + 1, jj], x[ii + 1, jj + 1], x[ii, jj + 1]], axis=1)
    cy = np.stack([y[ii, jj], y[ii + 1, jj], y[ii + 1, jj + 1], y[ii, jj + 1]], axis=1)
    disc = r * (cx[..., None] * e1 + cy[..., None] * e2)  # counter-clockwise about +axis
    top = b + disc
    bottom = a + disc[:, ::-1]  # reversed order: normal −axis
    return np.concatenate([side, top, bottom])


def cylinder_panels(
    p0,
    p1,
    radius: float,
    n_around: int,
    n_along: int,
    conductor: int,
    caps: bool = False,
    *,
    n_conductors: int | None = None,
    true_area: bool = True,
) -> Panels:
    """A circular cylinder (axis p0 → p1, mm) as panels, optional flat end caps.

    With ``true_area=True`` (default) each side panel is moved out to the true surface and
    widened to the arc length ``2π r / n_around`` (the inscribed polygon otherwise makes the
    cylinder thinner); cap panels are scaled so each cap's area is ``π r²``.
    """
    q = cylinder_quads(p0, p1, radius, n_around, n_along, caps)
    p = Panels.from_quads(q, conductor, n_conductors)
    if not true_area:
        return p
    a = np.asarray(p0, dtype=np.float64)
    b = np.asarray(p1, dtype=np.float64)
    r = float(radius)
    axis = (b - a) / np.linalg.norm(b - a)
    n_side = int(n_around) * int(n_along)
    centres = np.array(p.centres)
    u = np.array(p.u)
    v = np.array(p.v)
    d = centres[:n_side] - a
    rad = d - np.outer(d @ axis, axis)
    centres[:n_side] = (
        a + np.outer(d @ axis, axis) + r * rad / np.linalg.norm(rad, axis=1, keepdims=True)
    )
    # side quads: u runs around, v along the axis; stretch u to the arc length
    arc = 2.0 * np.pi * r / int(n_around)
    u[:n_side] *= arc / np.linalg.norm(u[:n_side], axis=1, keepdims=True)
    if caps:
        n_cap = (len(centres) - n_side) // 2
        for start in (n_side, n_side + n_cap):
            sl = slice(start, start + n_cap)
            s = np.sqrt(np.pi * r * r / p.areas[sl].sum())
            c0 = b if start == n_side else a
            centres[sl] = c0 + (centres[sl] - c0) * s
            u[sl] *= s
            v[sl] *= s
    return Panels(centres, u, v, p.conductor, p.n_conductors)


# ---------------------------------------------------------------------- small checks
def _unit(name: str, vec) -> np.ndarray:
    a = check_array(name, vec, (3,), finite=True)
    nrm = float(np.linalg.norm(a))
    if not nrm > 0:
        raise EctskinError(f"{name} must be a non-zero 3-vector, got {a.tolist()}")
    return a / nrm


def _positive_float(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise EctskinError(f"{name} must be a positive number (mm), got {value!r:.60}") from None
    if not (np.isfinite(x) and x > 0):
        raise EctskinError(f"{name} must be a positive finite number (mm), got {x}")
    return x


def _positive_int(name: str, value, minimum: int = 1) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise EctskinError(f"{name} must be an int >= {minimum}, got {value!r:.60}")
    if int(value) < minimum:
        raise EctskinError(f"{name} must be an int >= {minimum}, got {int(value)}")
    return int(value)
