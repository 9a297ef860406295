"""The e-skin on the deforming manipulator: geometry → panels → capacitance, and marker positions.

:class:`SensorModel` ties a :class:`~ectskin.layout.SensorLayout` to a
:class:`~ectskin.twin.mechanics.Manipulator`. It builds the rest-state panel corners of every
electrode (wire strips and pads, in surface coordinates) once, and per state maps them through the
deformation, adds the grounded finger (fingertip hemisphere + shaft cylinder) and solves the
method of moments (:mod:`ectskin.electrostatics`). The ECT readout of pair (i, j) is the mutual
capacitance with electrode i excited and every other conductor, the finger included, at 0 V:
C_ij = −K_ij (paper Eq. 1).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError
from ectskin.electrostatics import Panels, cylinder_panels, maxwell_capacitance, sphere_panels
from ectskin.electrostatics.panels import _frame, rectangle_quads, strip_quads
from ectskin.layout import SensorLayout
from ectskin.twin.mechanics import Manipulator, Touch

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Discretisation:
    """Panel sizes of the method of moments.

    Charge crowds at the free edges of strips and pads. Strips are cut into cosine-graded cells
    across and meshed wider by :func:`~ectskin.electrostatics.panels.edge_correction_factor` so
    they carry the true strip's charge; their free ends are refined to ``end_panel_fraction`` of
    the width. Doubling every density from these defaults changes the readout by < 1 %
    (``tests/test_twin.py``).
    """

    wire_panel_length_mm: float = 2.0
    wire_panels_across: int = 2
    end_panel_fraction: float = 0.125  # free-end cell, as a fraction of the wire width
    pad_panels: int = 3
    finger_sphere_n: int = 5
    finger_shaft_around: int = 12
    finger_shaft_along: int = 5

    def refined(self, factor: int = 2) -> "Discretisation":
        """A discretisation with ``factor`` times the panel density (for convergence checks)."""
        return Discretisation(
            self.wire_panel_length_mm / factor,
            self.wire_panels_across * factor,
            self.end_panel_fraction / factor,
            self.pad_panels * factor,
            self.finger_sphere_n * factor,
            self.finger_shaft_around * factor,
            self.finger_shaft_along * factor,
        )


@dataclass(frozen=True)
class Finger:
    """The grounded finger: a fingertip (hemisphere) on a shaft (cylinder), both radius R."""

    radius_mm: float = 8.0  # (assumed) adult fingertip
    shaft_length_mm: float = 50.0
    skin_cover_mm: float = 1.0  # (assumed) sealing layer between the wires and the finger


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
    """

    def __init__(
        self,
        layout: SensorLayout,
        manipulator: Manipulator | None = None,
        discretisation: Discretisation | None = None,
        eps_r: float = 2.0,
        finger: Finger | None = None,
    ):
        self.layout = layout
        self.manipulator = manipulator or Manipulator()
        self.discretisation = discretisation or Discretisation()
        self.eps_r = float(eps_r)
        self.finger = finger or Finger()
        d = self.discretisation
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
    def electrode_panels(self, inflation_ml, touch: Touch | None, forces) -> list[Panels]:
        """Deformed electrode panels, one :class:`Panels` per force value."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        per_force: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in forces]
        for surface, (quads, cond) in self._rest.items():
            xyz = self.manipulator.deform(surface, quads.reshape(-1, 2), inflation_ml, touch, forces)
            xyz = xyz.reshape(forces.size, len(quads), 4, 3)
            for f in range(forces.size):
                per_force[f].append((xyz[f], cond))
        n_cond = self.n_electrodes + 1  # + finger (conductor n_electrodes), absent if no touch
        return [
            Panels.from_quads(
                np.concatenate([q for q, _ in parts]), np.concatenate([c for _, c in parts]), n_cond
            )
            for parts in per_force
        ]

    def finger_panels(
        self, inflation_ml, touch: Touch, forces, *, sphere_n: int | None = None
    ) -> list[Panels]:
        """The grounded finger resting on the deformed skin at each force (conductor n_el)."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        fg, d = self.finger, self.discretisation
        uv = np.asarray([touch.uv_mm])
        pts = self.manipulator.deform(touch.surface, uv, inflation_ml, touch, forces)[:, 0]
        nrm = self.manipulator.surface_normal(touch.surface, uv, inflation_ml, touch, forces)[:, 0]
        out = []
        cond = self.n_electrodes
        # the fingertip: the half of a cubed sphere facing the skin, chosen once in the sphere's
        # own frame (pole along +z) and then rotated onto the surface normal, so that the same
        # panels make the tip at every force (choosing them by the sign of (c − centre)·n in
        # world axes let panels on the equator flip in and out as the normal tilted, a step
        # of ~0.1 % in the readout)
        unit = sphere_panels(np.zeros(3), fg.radius_mm, sphere_n or d.finger_sphere_n, cond)
        keep = unit.centres[:, 2] < -1e-6 * fg.radius_mm
        for p, n in zip(pts, nrm):
            centre = p + n * (fg.radius_mm + fg.skin_cover_mm)
            e1, e2 = _frame(n)
            rot = np.stack([e1, e2, n], axis=1)  # local (x, y, z) -> world, z onto n
            tip = Panels(
                centre + unit.centres[keep] @ rot.T,
                unit.u[keep] @ rot.T,
                unit.v[keep] @ rot.T,
                unit.conductor[keep],
                cond + 1,
            )
            shaft = cylinder_panels(
                centre,
                centre + n * fg.shaft_length_mm,
                fg.radius_mm,
                d.finger_shaft_around,
                d.finger_shaft_along,
                cond,
                caps=False,
            )
            out.append(Panels.concatenate([tip, shaft]))
        return out

    # ------------------------------------------------------------------ readout
    def capacitance(
        self, inflation_ml, touch: Touch | None = None, forces=0.0, *, with_finger: bool = True
    ) -> np.ndarray:
        """(F, n_pairs) ECT readout C_ij = −K_ij in pF for each force value (Eq. 1).

        Without a touch, ``forces`` only sets how many (identical) rows are returned.
        ``with_finger=False`` keeps the touch's mechanics (bending, dimple) but leaves the finger
        out of the electrostatics: the bending-only part of a touch response.
        """
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        if not with_finger and touch is not None:
            out = np.empty((forces.size, len(self._pairs)))
            for f, pe in enumerate(self.electrode_panels(inflation_ml, touch, forces)):
                K = maxwell_capacitance(_without_finger(pe, self.n_electrodes), self.eps_r)
                out[f] = -K[self._pairs[:, 0], self._pairs[:, 1]]
            return out
        if touch is None:
            panels = self.electrode_panels(inflation_ml, None, forces[:1])
            K = maxwell_capacitance(_without_finger(panels[0], self.n_electrodes), self.eps_r)
            row = -K[self._pairs[:, 0], self._pairs[:, 1]]
            return np.repeat(row[None, :], forces.size, axis=0)
        electrodes = self.electrode_panels(inflation_ml, touch, forces)
        fingers = self.finger_panels(inflation_ml, touch, forces)
        out = np.empty((forces.size, len(self._pairs)))
        for f, (pe, pf) in enumerate(zip(electrodes, fingers)):
            try:
                K = maxwell_capacitance(Panels.concatenate([pe, pf]), self.eps_r)
            except EctskinError:
                # a coarse fingertip panel very close to a fine wire-end panel can make the
                # collocation matrix indefinite: refine the fingertip and solve again
                log.debug("refining the fingertip at %s, %s N", touch, forces[f])
                pf = self.finger_panels(
                    inflation_ml, touch, forces[f : f + 1], sphere_n=2 * self.discretisation.finger_sphere_n
                )[0]
                K = maxwell_capacitance(Panels.concatenate([pe, pf]), self.eps_r)
            out[f] = -K[self._pairs[:, 0], self._pairs[:, 1]]
        return out

    def marker_positions(self, inflation_ml, touch: Touch | None = None, forces=0.0) -> np.ndarray:
        """(F, n_markers, 3) marker positions in mm for each force value."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        out = np.empty((forces.size, self.layout.n_markers, 3))
        by_surface: dict[str, list[int]] = {}
        for k, m in enumerate(self.layout.markers):
            by_surface.setdefault(m.surface, []).append(k)
        for surface, idx in by_surface.items():
            uv = np.asarray([self.layout.markers[k].uv_mm for k in idx])
            out[:, idx] = self.manipulator.deform(surface, uv, inflation_ml, touch, forces)
        return out


def _without_finger(panels: Panels, n_electrodes: int) -> Panels:
    """The same panels declared with only the electrode conductors (no finger present)."""
    return Panels(panels.centres, panels.u, panels.v, panels.conductor, n_electrodes)
