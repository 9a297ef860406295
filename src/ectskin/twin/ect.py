"""Training-free ECT images of touch on the twin's e-skin: the voxel grid, the sensitivity, the live imager.

The sensitivity (Jacobian) of the 28 pair readouts to the relative permittivity of voxels over
both skins is computed from one method-of-moments solve of the current deformation (inflation,
optionally a handling load): ``J[p, m] = −ε0 (E_i · E_j)(r_m) V_m``
(:func:`~ectskin.electrostatics.dielectric.permittivity_jacobian`). The images are reconstructed
by :mod:`ectskin.electrostatics.reconstruct` (LBP, Tikhonov, projected Landweber) from
``−Δc = −(c − c_0)`` (a grounded finger lowers the readouts), summed over the voxel layers into one
2-D image per face, and the touch is located at its peak or intensity-weighted centroid.

The voxel grid (:func:`ect_grid`) is laid out in *rest* surface coordinates (u, v) = (x, z) mm of
each skin, pixels of ``pixel_mm``, and layers between ``heights_mm`` edges above the surface;
for a state the voxel centres are mapped through the deformation and pushed out along the
deformed surface normal. Locations are reported in rest coordinates, as the recordings' truth.
The localisation error of these images over a recording is :mod:`ectskin.twin.ect_metrics`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.electrostatics import maxwell_capacitance
from ectskin.electrostatics.dielectric import conductor_jacobian, permittivity_jacobian
from ectskin.electrostatics.reconstruct import (
    DEFAULT_ITERATIONS,
    DEFAULT_LAMBDA,
    DEFAULT_RELAXATION,
    Reconstructor,
    centroid_location,
    collapse_layers,
    layer_sum_matrix,
    peak_location,
)
from ectskin.layout import SensorLayout
from ectskin.twin.mechanics import Handling
from ectskin.twin.sensor import SensorModel

log = logging.getLogger(__name__)

#: default pixel size on the skin, mm (assumed: the wire pitch is 10 mm, the fingertip 16 mm wide)
DEFAULT_PIXEL_MM = 4.0
#: default layer edges above the skin, mm (assumed: the finger sits >= 1 mm above the wires and
#: its field-line shadow reaches a few mm up)
DEFAULT_HEIGHTS_MM = (0.5, 2.5, 5.0, 10.0)
LOCALISATIONS = ("peak", "centroid")
#: what a voxel stands for: a permittivity change, or a small grounded conductor (a finger)
SENSITIVITY_KINDS = ("permittivity", "conductor")


@dataclass(frozen=True, eq=False)
class EctGrid:
    """Voxels over the skins: per voxel its face, rest (u, v), height and pixel.

    Attributes (n_vox voxels, n_pix pixels = (face, u, v) cells)
    ----------
    faces : skin surfaces, in layout order (``face`` indexes them).
    face, pixel : (n_vox,) int.
    uv : (n_vox, 2) rest surface coordinates, mm; height, thickness : (n_vox,) mm.
    pixel_face : (n_pix,) int; pixel_uv : (n_pix, 2) mm.
    shapes : per face (n_v, n_u) of its pixel image; extents : per face (u0, u1, v0, v1) mm.
    pixel_mm : the pixel's nominal size (its true size fits the skin evenly).
    """

    faces: tuple[str, ...]
    face: np.ndarray
    uv: np.ndarray
    height: np.ndarray
    thickness: np.ndarray
    pixel: np.ndarray
    pixel_face: np.ndarray
    pixel_uv: np.ndarray
    pixel_area: np.ndarray  # (n_pix,) rest area, mm²
    shapes: tuple[tuple[int, int], ...]
    extents: tuple[tuple[float, float, float, float], ...]
    pixel_mm: float

    @property
    def n_voxels(self) -> int:
        return int(self.face.size)

    @property
    def n_pixels(self) -> int:
        return int(self.pixel_face.size)

    def face_images(self, pixel_image) -> dict[str, np.ndarray]:
        """Per face a (n_v, n_u) image (v down the rows, u along the columns) of (n_pix,) values."""
        y = np.asarray(pixel_image, dtype=np.float64)
        out, start = {}, 0
        for name, (nv, nu) in zip(self.faces, self.shapes):
            out[name] = y[start : start + nv * nu].reshape(nv, nu)
            start += nv * nu
        return out


def ect_grid(
    layout: SensorLayout, *, pixel_mm: float = DEFAULT_PIXEL_MM, heights_mm=DEFAULT_HEIGHTS_MM
) -> EctGrid:
    """The voxel grid over every skin of ``layout``: pixels of about ``pixel_mm`` (each skin cut
    evenly) in layers between consecutive ``heights_mm`` edges above the surface (voxel centre at
    the layer's middle)."""
    if not isinstance(layout, SensorLayout):
        raise EctskinError(f"layout must be a SensorLayout, got {type(layout).__name__}")
    if not (np.isfinite(pixel_mm) and pixel_mm > 0):
        raise EctskinError(f"pixel_mm must be a positive number of mm, got {pixel_mm!r}")
    edges = np.asarray(heights_mm, dtype=np.float64)
    if edges.ndim != 1 or edges.size < 2 or edges[0] < 0 or np.any(np.diff(edges) <= 0):
        raise EctskinError(
            f"heights_mm must be at least two increasing layer edges >= 0 mm, got {heights_mm!r}"
        )
    faces = [s.surface for s in layout.skins]
    if len(set(faces)) != len(faces):
        raise EctskinError(f"ect_grid needs one skin per surface, got surfaces {faces}")
    centres, thick = (edges[:-1] + edges[1:]) / 2, np.diff(edges)
    pf, puv, parea, shapes, extents = [], [], [], [], []
    for k, s in enumerate(layout.skins):
        nu = max(1, int(round((s.u_mm[1] - s.u_mm[0]) / pixel_mm)))
        nv = max(1, int(round((s.v_mm[1] - s.v_mm[0]) / pixel_mm)))
        du, dv = (s.u_mm[1] - s.u_mm[0]) / nu, (s.v_mm[1] - s.v_mm[0]) / nv
        u = s.u_mm[0] + (np.arange(nu) + 0.5) * du
        v = s.v_mm[0] + (np.arange(nv) + 0.5) * dv
        V, U = np.meshgrid(v, u, indexing="ij")  # rows v, columns u
        puv.append(np.c_[U.ravel(), V.ravel()])
        pf.append(np.full(nu * nv, k))
        parea.append(np.full(nu * nv, du * dv))
        shapes.append((nv, nu))
        extents.append((float(s.u_mm[0]), float(s.u_mm[1]), float(s.v_mm[0]), float(s.v_mm[1])))
    pixel_face, pixel_uv = np.concatenate(pf), np.concatenate(puv)
    n_pix, n_l = pixel_face.size, centres.size
    pixel = np.tile(np.arange(n_pix), n_l)
    return EctGrid(
        faces=tuple(faces),
        face=pixel_face[pixel],
        uv=pixel_uv[pixel],
        height=np.repeat(centres, n_pix),
        thickness=np.repeat(thick, n_pix),
        pixel=pixel,
        pixel_face=pixel_face,
        pixel_uv=pixel_uv,
        pixel_area=np.concatenate(parea),
        shapes=tuple(shapes),
        extents=tuple(extents),
        pixel_mm=float(pixel_mm),
    )


class Sensitivity(NamedTuple):
    """The Jacobian of one deformation state."""

    jacobian: np.ndarray  # (n_pairs, n_vox) pF per unit relative permittivity
    xyz: np.ndarray  # (n_vox, 3) deformed voxel centres, mm
    volumes: np.ndarray  # (n_vox,) mm³
    readout: np.ndarray  # (n_pairs,) the state's homogeneous-medium readout C_ij, pF
    kind: str  # "permittivity" (pF per unit ε_r) or "conductor" (pF per mm of grounded sphere)

    @property
    def response_sign(self) -> float:
        """s with a touch's ``Δc ≈ s J x``, x ≥ 0: a finger lowers the readouts."""
        return -1.0 if self.kind == "permittivity" else 1.0


def sensitivity(
    sensor: SensorModel,
    grid: EctGrid,
    inflation_ml,
    handling: Handling | None = None,
    *,
    kind: str = "permittivity",
) -> Sensitivity:
    """``∂C_ij/∂ε_r`` of every voxel at one deformation state (one method-of-moments solve).

    The electrodes are deformed (no finger), solved in the sensor's homogeneous medium
    (``sensor.eps_r``; the chamber cavities' first-order term is left out of the fields), and
    the voxels are placed at their layer height along the deformed normal. A voxel's volume is
    its deformed pixel area (from the surface's tangent vectors) times its layer thickness.
    ``handling`` must hold one frame's loads.

    ``kind="permittivity"``: ``J = ∂C_ij/∂ε_r`` of each voxel, ``−ε0 (E_i·E_j) V``
    (:func:`~ectskin.electrostatics.dielectric.permittivity_jacobian`), pF per unit ε_r.
    ``kind="conductor"``: the change of C_ij when a grounded sphere of 1 mm radius sits at the
    voxel centre, ``−4π ε0 ε_r φ_i φ_j`` (:func:`~ectskin.electrostatics.dielectric.conductor_jacobian`),
    pF per mm: the first-order response to what a finger is, a grounded conductor.
    """
    if not isinstance(grid, EctGrid):
        raise EctskinError(f"grid must be an EctGrid, got {type(grid).__name__}")
    check_option("kind", kind, SENSITIVITY_KINDS)
    if handling is not None and handling.n_frames() not in (None, 1):
        raise EctskinError(f"handling must hold one frame's loads, got {handling.n_frames()}")
    n_el = sensor.n_electrodes
    pe = sensor.electrode_panels(inflation_ml, None, [0.0], handling)[0]
    panels = pe.with_conductor(pe.conductor, n_el)
    K, q = maxwell_capacitance(panels, sensor.eps_r, return_charges=True)
    man = sensor.manipulator
    xyz = np.empty((grid.n_voxels, 3))
    vol = np.empty(grid.n_voxels)
    h = 0.25 * grid.pixel_mm
    for k, face in enumerate(grid.faces):
        sel = np.flatnonzero(grid.face == k)
        uv = grid.uv[sel]
        pts = man.deform(face, uv, inflation_ml, None, [0.0], handling)[0]
        nrm = man.surface_normal(face, uv, inflation_ml, None, [0.0], handling)[0]
        xyz[sel] = pts + grid.height[sel, None] * nrm
        step = np.array([[h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]])
        d = man.deform(
            face, (uv[None] + step[:, None]).reshape(-1, 2), inflation_ml, None, [0.0], handling
        )[0].reshape(4, -1, 3)
        stretch = np.linalg.norm(np.cross(d[0] - d[1], d[2] - d[3]), axis=1) / (4 * h * h)
        vol[sel] = grid.pixel_area[grid.pixel[sel]] * stretch * grid.thickness[sel]
    pairs = sensor.layout.pairs
    if kind == "permittivity":
        J = permittivity_jacobian(panels, q, xyz, vol, pairs, eps_r=sensor.eps_r)
    else:
        J = conductor_jacobian(panels, q, xyz, pairs, eps_r=sensor.eps_r)
    return Sensitivity(J, xyz, vol, -K[pairs[:, 0], pairs[:, 1]], kind)


def locate(image_pix, grid: EctGrid, localisation: str = "centroid", *, radius_mm=None):
    """``(face index, (u, v) mm, peak)`` of a (n_pix,) image: the peak pixel, or the weighted
    centroid of the pixels >= half the peak within ``radius_mm`` (default 2 pixels) of it."""
    check_option("localisation", localisation, LOCALISATIONS)
    if localisation == "peak":
        return peak_location(image_pix, grid.pixel_face, grid.pixel_uv)
    r = 2.0 * grid.pixel_mm if radius_mm is None else radius_mm
    return centroid_location(image_pix, grid.pixel_face, grid.pixel_uv, radius_mm=r)


class EctImager:
    """Live ECT imaging: J and the reconstruction precomputed at one reference state.

    ``image(delta_c)`` → per face (n_v, n_u) images; ``locate(delta_c)`` → (face, u, v, peak).
    ``delta_c = c − c_0`` in pF (n_pairs,), ``c_0`` the untouched readout at the reference state.
    Row scale: the state's model readout (see :mod:`~ectskin.electrostatics.reconstruct`).
    ``kind``: the voxel sensitivity, "conductor" (default: the finger is a grounded conductor)
    or "permittivity" (the classic ECT sensitivity map); see :func:`sensitivity`.
    """

    def __init__(
        self,
        layout: SensorLayout,
        inflation_ml,
        *,
        sensor: SensorModel | None = None,
        grid: EctGrid | None = None,
        method: str = "tikhonov",
        localisation: str = "centroid",
        lam: float = DEFAULT_LAMBDA,
        iterations: int = DEFAULT_ITERATIONS,
        relaxation: float = DEFAULT_RELAXATION,
        row_scale=None,
        kind: str = "conductor",
    ):
        check_option("localisation", localisation, LOCALISATIONS)
        self.sensor = sensor or SensorModel(layout)
        self.grid = grid or ect_grid(layout)
        self.localisation = localisation
        t0 = time.perf_counter()
        self.sensitivity = sensitivity(self.sensor, self.grid, inflation_ml, kind=kind)
        self.jacobian_s = time.perf_counter() - t0
        scale = self.sensitivity.readout if row_scale is None else row_scale
        self.reconstructor = Reconstructor.build(
            self.sensitivity.jacobian,
            method,
            row_scale=scale,
            lam=lam,
            iterations=iterations,
            relaxation=relaxation,
            response_sign=self.sensitivity.response_sign,
        )
        m = self.reconstructor.matrix
        self._pixel_matrix = (
            None if m is None else layer_sum_matrix(self.grid.pixel, self.grid.n_pixels) @ m
        )

    @property
    def faces(self) -> list[str]:
        """The faces the images cover, in the order of :meth:`image`."""
        return list(self.grid.faces)

    @property
    def grid_extent(self) -> dict[str, list[list[float]]]:
        """{face: [[u_lo, u_hi], [v_lo, v_hi]]} mm that each face's image spans (row 0 at the
        lowest v)."""
        return {
            f: [[e[0], e[1]], [e[2], e[3]]] for f, e in zip(self.grid.faces, self.grid.extents)
        }

    def pixel_image(self, delta_c) -> np.ndarray:
        """(n_pix,) or (F, n_pix) image summed over layers."""
        if self._pixel_matrix is not None:
            dc = np.asarray(delta_c, dtype=np.float64)
            if dc.shape[-1] != self._pixel_matrix.shape[1]:
                raise EctskinError(
                    f"delta_c must have {self._pixel_matrix.shape[1]} pair readouts, got {dc.shape}"
                )
            return dc @ self._pixel_matrix.T
        return collapse_layers(
            self.reconstructor.image(delta_c), self.grid.pixel, self.grid.n_pixels
        )

    def image(self, delta_c) -> dict[str, np.ndarray]:
        """Per face name a (n_v, n_u) image of one frame's ``Δc`` (n_pairs,) pF."""
        return self.grid.face_images(self.pixel_image(delta_c))

    def locate(self, delta_c) -> tuple[str, float, float, float]:
        """``(face, u mm, v mm, peak value)`` of one frame's touch."""
        f, uv, peak = locate(self.pixel_image(delta_c), self.grid, self.localisation)
        return self.grid.faces[f], float(uv[0]), float(uv[1]), peak
