"""The e-skin on the deforming manipulator: geometry → panels → capacitance, and marker positions.

:class:`SensorModel` ties a :class:`~ectskin.layout.SensorLayout` to a
:class:`~ectskin.twin.mechanics.Manipulator`. It builds the rest-state panel corners of every
electrode (wire strips and pads, in surface coordinates) once, and per state maps them through the
deformation, adds the grounded finger (fingertip hemisphere + shaft cylinder) and solves the
method of moments (:mod:`ectskin.electrostatics`). The ECT readout of pair (i, j) is the mutual
capacitance with electrode i excited and every other conductor, the finger included, at 0 V:
C_ij = −K_ij (paper Eq. 1).

Two (or more) fingers: ``touch`` may be a tuple of :class:`~ectskin.twin.mechanics.Touch` with
forces (F, T) (:func:`~ectskin.twin.mechanics.touch_loads`). Every fingertip is grounded and they
are **one conductor**: the fingers belong to one hand and one body, which connects them (the
body's resistance is negligible at the readout's frequencies, and its capacitance to the
surroundings is far larger than the sensor's), so they share one potential (0 V, like the other
electrodes) and one conductor index (``n_electrodes``).

Every fingertip rests on the deformed skin (:mod:`ectskin.twin.finger`: the contact law, the
cover under the pad and the fingertip's shape); :meth:`SensorModel.fingertips` says where, and
its panels follow it (:meth:`SensorModel.finger_panels`). :meth:`SensorModel.with_fingers` gives
a sensor with other fingers (people's differ) cheaply.
"""

from __future__ import annotations

import copy
import functools
import logging
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError
from ectskin.electrostatics import (
    EPS0_PF_PER_MM,
    Panels,
    cylinder_panels,
    dielectric_sensitivity,
    maxwell_capacitance,
    potential_matrix,
    sphere_panels,
)
from ectskin.electrostatics.meshing import orthonormal_frame, rectangle_quads, strip_quads
from ectskin.layout import SensorLayout
from ectskin.twin.finger import Finger, Fingertip, flatten_cap, rest_fingertips
from ectskin.twin.mechanics import Handling, Manipulator, Touch, touch_loads

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Discretisation:
    """Panel sizes of the method of moments.

    Charge crowds at the free edges of strips and pads. Strips are cut into cosine-graded cells
    across and meshed wider by :func:`~ectskin.electrostatics.meshing.edge_correction_factor` so
    they carry the true strip's charge; their free ends are refined to ``end_panel_fraction`` of
    the width. Doubling every density from these defaults changes the readout by < 1 %
    (``tests/twin/test_twin.py``).
    """

    wire_panel_length_mm: float = 2.0
    wire_panels_across: int = 2
    end_panel_fraction: float = 0.125  # free-end cell, as a fraction of the wire width
    pad_panels: int = 3
    finger_sphere_n: int = 5
    finger_shaft_around: int = 12
    finger_shaft_along: int = 5
    cavity_cell_mm: float = 4.0  # chamber cavities: cell size over the footprint
    cavity_layers: int = 3  # ... and Gauss-Legendre nodes across the cavity (face to face)

    def refined(self, factor: int = 2) -> Discretisation:
        """A discretisation with ``factor`` times the panel density (for convergence checks)."""
        return Discretisation(
            self.wire_panel_length_mm / factor,
            self.wire_panels_across * factor,
            self.end_panel_fraction / factor,
            self.pad_panels * factor,
            self.finger_sphere_n * factor,
            self.finger_shaft_around * factor,
            self.finger_shaft_along * factor,
            self.cavity_cell_mm / factor,
            self.cavity_layers * factor,
        )


def _planar(quads3: np.ndarray) -> np.ndarray:
    """Drop the zero third coordinate of quads built in the (u, v, 0) plane."""
    return quads3[..., :2]


def _strip_quads(a, b, width: float, d: Discretisation, free_end: bool) -> np.ndarray:
    """(n, 4, 2) quads of a straight strip from a to b in surface coordinates (u, v).

    Edge-corrected cosine cells across; the wire's free end refined (its start joins the pad or
    the previous segment, so it is not free).
    """
    a3, b3 = np.r_[a, 0.0], np.r_[b, 0.0]
    return _planar(
        strip_quads(
            a3, b3, width, (0.0, 0.0, 1.0),
            n_across=d.wire_panels_across,
            panel_length=d.wire_panel_length_mm,
            end_panel=d.end_panel_fraction * width,
            refine_start=False,
            refine_end=free_end,
        )
    )


def _pad_quads(centre, size, d: Discretisation) -> np.ndarray:
    return _planar(
        rectangle_quads(
            (centre[0], centre[1], 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), size[0], size[1],
            d.pad_panels, d.pad_panels, spacing_u="cosine", spacing_v="cosine", edge_correction=True,
        )
    )


class SensorModel:
    """Capacitance readout and marker positions of a layout on a manipulator.

    Parameters
    ----------
    layout : the e-skin layout (electrodes on the front/back faces).
    manipulator : the body's deformation model.
    discretisation : panel sizes.
    eps_r : effective relative permittivity of silicone and air **(assumed, 2.0)**.
    finger : the grounded finger's geometry.
    chamber_eps_r : relative permittivity inside the chamber cavities (air, 1.0), or None for one
        homogeneous medium. The cavities (the body between the two faces, less a wall of
        ``ManipulatorConfig.chamber_wall_mm`` at each face, over each chamber's footprint; they
        grow as the faces bulge and follow the bending and the dimple) enter to first order, as
        in ECT's linearised sensitivity maps: ``K ← K + ε0 (chamber_eps_r − eps_r) ∫ E_a·E_c dV``
        (:func:`~ectskin.electrostatics.dielectric_sensitivity`, checked against the analytic
        spherical capacitor with a dielectric shell). Air between the faces lowers the
        cross-face pairs most; inflation adds air there.
    """

    def __init__(
        self,
        layout: SensorLayout,
        manipulator: Manipulator | None = None,
        discretisation: Discretisation | None = None,
        eps_r: float = 2.0,
        finger: Finger | None = None,
        chamber_eps_r: float | None = 1.0,
    ):
        self.layout = layout
        self.manipulator = manipulator or Manipulator()
        self.discretisation = discretisation or Discretisation()
        self.eps_r = float(eps_r)
        self.finger = finger or Finger()
        self._more_fingers: tuple[Finger, ...] = ()  # the other touches' (with_fingers)
        if chamber_eps_r is not None and not (np.isfinite(chamber_eps_r) and chamber_eps_r >= 1.0):
            raise EctskinError(
                f"chamber_eps_r must be None (one homogeneous medium) or a relative permittivity "
                f">= 1, got {chamber_eps_r!r}"
            )
        self.chamber_eps_r = None if chamber_eps_r is None else float(chamber_eps_r)
        d = self.discretisation
        c = self.manipulator.config
        if 2 * c.chamber_wall_mm >= c.thickness_mm:
            raise EctskinError(
                f"manipulator: chamber_wall_mm ({c.chamber_wall_mm}) leaves no cavity in a body "
                f"{c.thickness_mm} mm thick"
            )
        self._cavity_uv = _cavity_grid(c, d.cavity_cell_mm)
        # rest-state quads per surface: (uv corners (n, 4, 2), conductor index (n,))
        by_surface: dict[str, tuple[list, list]] = {}
        for k, e in enumerate(layout.electrodes):
            surface = layout.electrode_surface(k)
            segments = list(zip(e.polyline_mm[:-1], e.polyline_mm[1:]))
            quads = [
                _strip_quads(a, b, e.width_mm, d, free_end=k == len(segments) - 1)
                for k, (a, b) in enumerate(segments)
            ]
            quads.append(_pad_quads(e.pad_centre_mm, e.pad_size_mm, d))
            q = np.concatenate(quads)
            entry = by_surface.setdefault(surface, ([], []))
            entry[0].append(q)
            entry[1].append(np.full(len(q), k))
        self._rest = {s: (np.concatenate(q), np.concatenate(c)) for s, (q, c) in by_surface.items()}
        self.n_electrodes = layout.n_electrodes
        self._pairs = layout.pairs

    # ------------------------------------------------------------------ geometry
    def electrode_panels(
        self, inflation_ml, touch: Touch | tuple[Touch, ...] | None, forces,
        handling: Handling | None = None,
    ) -> list[Panels]:
        """Deformed electrode panels, one :class:`Panels` per frame (row of ``forces``)."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        n_f = touch_loads(forces, touch)[1].shape[0]
        per_force: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(n_f)]
        for surface, (quads, cond) in self._rest.items():
            xyz = self.manipulator.deform(
                surface, quads.reshape(-1, 2), inflation_ml, touch, forces, handling,
                keep_rest=True,
            )
            xyz = xyz.reshape(n_f, len(quads), 4, 3)
            for f in range(n_f):
                per_force[f].append((xyz[f], cond))
        n_cond = self.n_electrodes + 1  # + finger (conductor n_electrodes), absent if no touch
        return [
            Panels.from_quads(
                np.concatenate([q for q, _ in parts]), np.concatenate([c for _, c in parts]), n_cond
            )
            for parts in per_force
        ]

    def with_fingers(self, *fingers: Finger) -> SensorModel:
        """This sensor with other fingers, cheaply: a shallow copy sharing the rest-state panels
        and the manipulator (its pose cache too). Touch k of a tuple of touches is
        ``fingers[k]`` (the last one for any beyond); one finger for every touch by default."""
        if not fingers or not all(isinstance(f, Finger) for f in fingers):
            raise EctskinError(
                f"with_fingers: expected one or more Finger, got {fingers!r:.80}"
            )
        out = copy.copy(self)
        out.finger, out._more_fingers = fingers[0], tuple(fingers[1:])
        return out

    def finger_of(self, k: int) -> Finger:
        """The finger of touch ``k`` (:meth:`with_fingers`)."""
        more = self._more_fingers
        return self.finger if k == 0 or not more else more[min(k, len(more)) - 1]

    def fingertips(
        self,
        inflation_ml,
        touch: Touch | tuple[Touch, ...],
        forces,
        handling: Handling | None = None,
        *,
        heights_mm=None,
    ) -> list[Fingertip]:
        """Where each fingertip rests in each frame (one :class:`Fingertip` per touch).

        Every fingertip rests on the skin under its whole pad, as deformed by all the loads
        (:mod:`ectskin.twin.finger`: the contact law); ``heights_mm`` > 0 lifts it that far above.
        """
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        touches, per_touch = touch_loads(forces, touch)
        heights = _heights(heights_mm, per_touch.shape)
        fingers = [self.finger_of(k) for k in range(len(touches))]
        return rest_fingertips(
            self.manipulator, fingers, inflation_ml, touch, forces, per_touch, heights, handling
        )

    def finger_panels(
        self,
        inflation_ml,
        touch: Touch | tuple[Touch, ...],
        forces,
        handling: Handling | None = None,
        *,
        heights_mm=None,
        sphere_n: int | None = None,
    ) -> list[Panels]:
        """The grounded finger resting on (or above) the deformed skin at each force (conductor
        n_el), placed by :meth:`fingertips`.

        In contact (height 0) the fingertip's pulp flattens against the skin: the sphere's cap
        beyond the plane R − δ below its centre is pressed onto that plane (a disc of radius
        √(δ (2R − δ)); :func:`~ectskin.twin.finger.flatten_cap`), δ the Hertz indentation
        (9F² / (16 R E*²))^(1/3) (:attr:`Finger.pulp_modulus_mpa`), so the contact patch grows
        with force. Above the skin (``heights_mm`` > 0, force 0) the round fingertip hovers that
        far above the skin under it.

        With a tuple of T touches (``forces`` and ``heights_mm`` (F, T)) each frame's panels are
        every finger's, all on the one finger conductor (see the module docstring), each placed
        on the skin as deformed by all of them.
        """
        sets = self.finger_sets(
            inflation_ml, touch, forces, handling, heights_mm=heights_mm, sphere_n=sphere_n
        )
        return [panels for panels, _ in sets]

    def finger_sets(
        self, inflation_ml, touch, forces, handling=None, *, heights_mm=None,
        sphere_n: int | None = None,
    ) -> list[tuple[Panels, list[tuple[int, np.ndarray]]]]:
        """:meth:`finger_panels` per frame with each fingertip's own potential block: (panels,
        [(first panel of a fingertip, its block), ...]), the blocks of
        :func:`~ectskin.electrostatics.potential_matrix`'s ``blocks`` (:func:`finger_block`:
        computed once per finger shape, not per touch)."""
        tips = self.fingertips(inflation_ml, touch, forces, handling, heights_mm=heights_mm)
        fingers = [self._tip_panels(tip, sphere_n) for tip in tips]
        if len(fingers) == 1:
            return [(panels, [(0, block)]) for panels, block in fingers[0]]
        out = []
        for parts in zip(*fingers):
            starts = np.cumsum([0] + [p.n_panels for p, _ in parts[:-1]])
            out.append(
                (Panels.concatenate([p for p, _ in parts]),
                 [(int(s), block) for s, (_, block) in zip(starts, parts)])
            )
        return out

    def _tip_panels(self, tip: Fingertip, sphere_n: int | None) -> list[tuple[Panels, np.ndarray]]:
        """Panels of one fingertip and its shaft, per frame, and their own potential block: the
        finger's shape (:func:`finger_shape`) turned onto the axis and moved to the centre."""
        fg, d = tip.finger, self.discretisation
        out: list[tuple[Panels, np.ndarray]] = []
        shape = (fg.radius_mm, fg.shaft_length_mm, sphere_n or d.finger_sphere_n,
                 d.finger_shaft_around, d.finger_shaft_along, self.n_electrodes)
        for f, (n, centre, depth) in enumerate(zip(tip.axis, tip.centre_mm, tip.pad_depth_mm)):
            if f and np.array_equal(n, tip.axis[f - 1]) and depth == tip.pad_depth_mm[f - 1]:
                # the previous frame's finger moved along its axis (a hovering finger at
                # another height): the same panels, translated
                last, block = out[-1]
                shift = centre - tip.centre_mm[f - 1]
                out.append(
                    (Panels(last.centres + shift, last.u, last.v, last.conductor,
                            last.n_conductors), block)
                )
                continue
            local = finger_shape(*shape[:2], float(depth), *shape[2:])
            e1, e2 = orthonormal_frame(n)
            rot = np.stack([e1, e2, n], axis=1)  # local (x, y, z) -> world, z onto n
            panels = Panels(
                centre + local.centres @ rot.T, local.u @ rot.T, local.v @ rot.T,
                local.conductor, local.n_conductors,
            )
            out.append((panels, finger_block(*shape[:2], float(depth), *shape[2:], self.eps_r)))
        return out

    def cavity_cells(
        self, inflation_ml, touch: Touch | tuple[Touch, ...] | None, forces,
        handling: Handling | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Centres (F, M, 3) mm and volumes (F, M) mm³ of the chamber cavities' sample cells.

        Each footprint cell (``cavity_cell_mm``) spans from the deformed front face to the
        deformed back face at the same surface coordinates; the cavity is that segment less a wall
        of ``chamber_wall_mm`` at each end, integrated across with ``cavity_layers`` Gauss-Legendre
        nodes (the footprint with the midpoint rule).
        """
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        n_f = touch_loads(forces, touch)[1].shape[0]
        wall = self.manipulator.config.chamber_wall_mm
        n_t = self.discretisation.cavity_layers
        uv, area = self._cavity_uv
        m = self.manipulator
        front = m.deform("front", uv, inflation_ml, touch, forces, handling, keep_rest=True)
        back = m.deform("back", uv, inflation_ml, touch, forces, handling, keep_rest=True)
        span = back - front
        gap = np.linalg.norm(span, axis=2)  # (F, n)
        inner = np.maximum(gap - 2.0 * wall, 0.0)
        x, w = np.polynomial.legendre.leggauss(n_t)  # Gauss-Legendre across the cavity
        t, w = (x + 1.0) / 2.0, w / 2.0
        frac = (wall + t[:, None, None] * inner[None]) / gap[None]  # (n_t, F, n)
        pts = front[None] + frac[..., None] * span[None]  # (n_t, F, n, 3)
        vol = area * w[:, None, None] * inner[None]  # (n_t, F, n)
        return (
            pts.transpose(1, 0, 2, 3).reshape(n_f, -1, 3),
            vol.transpose(1, 0, 2).reshape(n_f, -1),
        )

    @property
    def _with_cavities(self) -> bool:
        return self.chamber_eps_r is not None and self.chamber_eps_r != self.eps_r

    def _readout(
        self, panels: Panels, cells: tuple[np.ndarray | None, np.ndarray | None],
        blocks: list[tuple[int, np.ndarray]] | None = None,
    ) -> np.ndarray:
        """(n_pairs,) C_ij = −K_ij of one panel set, with the cavities' first-order term;
        ``blocks``: the fingertips' own potential blocks (:meth:`finger_sets`)."""
        if not self._with_cavities:
            K = maxwell_capacitance(panels, self.eps_r, blocks=blocks or ())
        else:
            K, q = maxwell_capacitance(
                panels, self.eps_r, return_charges=True, blocks=blocks or ()
            )
            n = self.n_electrodes
            S = dielectric_sensitivity(panels, q[:, :n], cells[0], cells[1], self.eps_r)
            chamber_eps_r = self.chamber_eps_r
            assert chamber_eps_r is not None  # (_with_cavities says so)
            K = K[:n, :n] + EPS0_PF_PER_MM * (chamber_eps_r - self.eps_r) * S
        return -K[self._pairs[:, 0], self._pairs[:, 1]]

    # ------------------------------------------------------------------ readout
    def capacitance(
        self,
        inflation_ml,
        touch: Touch | tuple[Touch, ...] | None = None,
        forces=0.0,
        handling: Handling | None = None,
        *,
        heights_mm=None,
        with_finger: bool = True,
    ) -> np.ndarray:
        """(F, n_pairs) ECT readout C_ij = −K_ij in pF for each state (Eq. 1).

        One row per value of ``forces`` (the finger's normal force; with ``heights_mm`` > 0 the
        finger hovers that high above ``touch``'s point instead, force 0) and of the per-frame
        ``handling`` loads. Without a touch and handling, ``forces`` only sets how many
        (identical) rows are returned. ``with_finger=False`` keeps the loads' mechanics (bending,
        dimple) but leaves the finger out of the electrostatics: the deformation-only part.

        Several fingers: ``touch`` a tuple of T touches, ``forces`` and ``heights_mm`` (F, T)
        (one row per frame); the fingers are one grounded conductor (module docstring).
        """
        forces, heights_mm, n_rows = self._frame_loads(touch, forces, heights_mm)
        static = touch is None and handling is None
        if static:
            forces = forces[:1]  # one solve: nothing changes from row to row
        n_f = 1 if static else n_rows
        out = np.empty((n_f, len(self._pairs)))
        if touch is None or not with_finger:
            pts, vols = self._cells(inflation_ml, touch, forces, handling, n_f)
            electrodes = self.electrode_panels(inflation_ml, touch, forces, handling)
            for f, pe in enumerate(electrodes):
                out[f] = self._readout(_without_finger(pe, self.n_electrodes), (pts[f], vols[f]))
            return np.repeat(out, n_rows, axis=0) if static else out
        sets = self._solve_sets(inflation_ml, touch, forces, handling, heights_mm)
        for f, (panels, blocks, cells) in enumerate(sets):
            try:
                out[f] = self._readout(panels, cells, blocks)
            except EctskinError:
                out[f] = self.refined_readout(
                    inflation_ml, touch, forces, handling, heights_mm, f, panels, blocks, cells
                )
        return out

    def solve_sets(
        self, inflation_ml, touch: Touch | tuple[Touch, ...], forces=0.0,
        handling: Handling | None = None, *, heights_mm=None,
    ) -> list[tuple[Panels, list[tuple[int, np.ndarray]], tuple[np.ndarray | None, np.ndarray | None]]]:
        """The method-of-moments inputs of :meth:`capacitance`'s rows with a finger, one per row:
        (panels: the electrodes', then the fingers'; the fingertips' own potential blocks as
        (first panel, block); the cavity cells (points, volumes), or (None, None) without
        cavities). A batched solver (:func:`ectskin.electrostatics.batched.readout_batch`) takes
        them as they are; a row it cannot factor goes to :meth:`refined_readout`."""
        forces, heights_mm, _ = self._frame_loads(touch, forces, heights_mm)
        return self._solve_sets(inflation_ml, touch, forces, handling, heights_mm)

    def _frame_loads(self, touch, forces, heights_mm):
        """(forces, heights, rows); with several touches the per-frame (F, T) ones."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        per_touch = touch_loads(forces, touch)[1]
        if not (touch is None or isinstance(touch, Touch)):
            forces = per_touch  # (F, T): one row per frame
            if heights_mm is not None:
                heights_mm = _heights(heights_mm, forces.shape)
        return forces, heights_mm, per_touch.shape[0]

    def _cells(self, inflation_ml, touch, forces, handling, n_f):
        if self._with_cavities:
            return self.cavity_cells(inflation_ml, touch, forces, handling)
        return [None] * n_f, [None] * n_f

    def _solve_sets(self, inflation_ml, touch, forces, handling, heights_mm):
        n_f = touch_loads(forces, touch)[1].shape[0]
        pts, vols = self._cells(inflation_ml, touch, forces, handling, n_f)
        electrodes = self.electrode_panels(inflation_ml, touch, forces, handling)
        fingers = self.finger_sets(inflation_ml, touch, forces, handling, heights_mm=heights_mm)
        return [(Panels.concatenate([pe, pf]), [(pe.n_panels + s, b) for s, b in blocks],
                 (pts[f], vols[f])) for f, (pe, (pf, blocks)) in enumerate(zip(electrodes, fingers))]

    def refined_readout(
        self, inflation_ml, touch, forces, handling, heights_mm, f: int, panels: Panels,
        blocks: list[tuple[int, np.ndarray]], cells,
    ) -> np.ndarray:
        """Row ``f`` of :meth:`solve_sets` solved with a refined fingertip: a coarse fingertip
        panel very close to a fine wire-end panel can make the collocation matrix indefinite."""
        log.debug("refining the fingertip at %s, %s N", touch, forces[f])
        n_e = blocks[0][0]  # the electrodes' panels come first
        pe = Panels(panels.centres[:n_e], panels.u[:n_e], panels.v[:n_e],
                    panels.conductor[:n_e], panels.n_conductors)
        one = None if handling is None else _handling_rows(handling, f)
        h = None if heights_mm is None else np.atleast_1d(heights_mm)[f : f + 1]
        pf, fine = self.finger_sets(
            inflation_ml, touch, forces[f : f + 1], one, heights_mm=h,
            sphere_n=2 * self.discretisation.finger_sphere_n,
        )[0]
        return self._readout(
            Panels.concatenate([pe, pf]), cells, [(pe.n_panels + s, block) for s, block in fine]
        )

    def marker_positions(
        self, inflation_ml, touch: Touch | tuple[Touch, ...] | None = None, forces=0.0,
        handling: Handling | None = None,
    ) -> np.ndarray:
        """(F, n_markers, 3) marker positions in mm for each frame (row of ``forces``)."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        n_f = touch_loads(forces, touch)[1].shape[0]
        out = np.empty((n_f, self.layout.n_markers, 3))
        by_surface: dict[str, list[int]] = {}
        for k, m in enumerate(self.layout.markers):
            by_surface.setdefault(m.surface, []).append(k)
        for surface, idx in by_surface.items():
            uv = np.asarray([self.layout.markers[k].uv_mm for k in idx])
            out[:, idx] = self.manipulator.deform(surface, uv, inflation_ml, touch, forces, handling)
        return out


# ---------------------------------------------------------------------- the finger's shape
#: fingertip shapes kept (and their own potential blocks): a field's force nodes and its hover
#: shape, for a few fingers and meshes
SHAPES_KEPT = 64


@functools.lru_cache(maxsize=SHAPES_KEPT)
def finger_shape(
    radius_mm: float, shaft_length_mm: float, depth_mm: float, sphere_n: int,
    shaft_around: int, shaft_along: int, conductor: int,
) -> Panels:
    """The panels of a fingertip and its shaft in the finger's own frame: the sphere's centre at
    the origin, the shaft along +z, the pad (pressed ``depth_mm`` flat) towards −z; conductor
    ``conductor`` of ``conductor + 1``. They depend on nothing else, so they are built once per
    shape and turned onto each touch's axis (:meth:`SensorModel._tip_panels`).

    The fingertip is the half of a cubed sphere facing the skin, chosen in the sphere's own
    frame, so that the same panels make the tip at every force and axis (choosing them by the
    sign of (c − centre)·n in world axes let panels on the equator flip in and out as the normal
    tilted, a step of ~0.1 % in the readout), its pad flattened (:func:`flatten_cap`)."""
    unit = sphere_panels(np.zeros(3), radius_mm, sphere_n, conductor)
    keep = unit.centres[:, 2] < -1e-6 * radius_mm
    c_loc, u_loc, v_loc = flatten_cap(
        unit.centres[keep], unit.u[keep], unit.v[keep], radius_mm - depth_mm
    )
    tip = Panels(c_loc, u_loc, v_loc, unit.conductor[keep], conductor + 1)
    shaft = cylinder_panels(
        np.zeros(3), np.array([0.0, 0.0, shaft_length_mm]), radius_mm, shaft_around, shaft_along,
        conductor, caps=False,
    )

    # cylinder_panels starts its side on orthonormal_frame(+z) = (−y, +x); a quarter turn about
    # z (exact) starts it on (+x, +y), so that turned onto an axis n by orthonormal_frame(n) it
    # is the shaft that cylinder_panels builds about n
    def quarter(a: np.ndarray) -> np.ndarray:
        return np.stack([-a[:, 1], a[:, 0], a[:, 2]], axis=1)

    shaft = Panels(quarter(shaft.centres), quarter(shaft.u), quarter(shaft.v), shaft.conductor,
                   shaft.n_conductors)
    return Panels.concatenate([tip, shaft])


@functools.lru_cache(maxsize=SHAPES_KEPT)
def finger_block(
    radius_mm: float, shaft_length_mm: float, depth_mm: float, sphere_n: int,
    shaft_around: int, shaft_along: int, conductor: int, eps_r: float,
) -> np.ndarray:
    """(m, m) the potential matrix of :func:`finger_shape` (read-only): the fingertip's own
    block of every solve it takes part in, whatever its point and axis (a rigid motion leaves it
    as it is, to round-off)."""
    shape = finger_shape(
        radius_mm, shaft_length_mm, depth_mm, sphere_n, shaft_around, shaft_along, conductor
    )
    out = potential_matrix(shape, eps_r)
    out.setflags(write=False)
    return out


def _cavity_grid(c, cell_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Rest surface coordinates (n, 2) of the cells covering every chamber footprint, and the
    footprint area of one cell (mm²)."""
    nx = max(1, int(np.ceil(c.chamber_size_x_mm / cell_mm)))
    nz = max(1, int(np.ceil(c.chamber_size_z_mm / cell_mm)))
    hx, hz = c.chamber_size_x_mm / nx, c.chamber_size_z_mm / nz
    xs = -c.chamber_size_x_mm / 2 + (np.arange(nx) + 0.5) * hx
    cells = []
    for zc in c.chamber_centres_z_mm:
        zs = zc - c.chamber_size_z_mm / 2 + (np.arange(nz) + 0.5) * hz
        X, Z = np.meshgrid(xs, zs)
        cells.append(np.c_[X.ravel(), Z.ravel()])
    return np.concatenate(cells), hx * hz


def _heights(heights_mm, shape: tuple[int, int]) -> np.ndarray:
    """Fingertip heights (F, T) in mm from None (all in contact), a scalar, (F,) (one per frame,
    every finger) or (F, T)."""
    if heights_mm is None:
        return np.zeros(shape)
    h = np.asarray(heights_mm, dtype=np.float64)
    if h.ndim == 1 and h.size == shape[0]:
        h = h[:, None]
    try:
        return np.broadcast_to(h, shape)
    except ValueError:
        raise EctskinError(
            f"heights_mm: expected a scalar, (F,) or (F, T) = {shape} fingertip heights (mm), "
            f"got shape {h.shape}"
        ) from None


def _handling_rows(handling: Handling, f: int) -> Handling:
    """The loads of row ``f`` only."""
    def row(a):
        return None if a is None else np.asarray(a)[f : f + 1]

    return Handling(row(handling.shear_n), handling.push, row(handling.push_force_n))


def _without_finger(panels: Panels, n_electrodes: int) -> Panels:
    """The same panels declared with only the electrode conductors (no finger present)."""
    return Panels(panels.centres, panels.u, panels.v, panels.conductor, n_electrodes)
