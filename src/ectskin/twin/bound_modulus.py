"""The fingertip pulp's modulus as a nuisance of the bound: a column from direct solves.

People's fingers differ in their pulp's stiffness (the twin draws it per trial, 0.05-0.2 MPa,
:func:`ectskin.twin.human.trial_fingers`). A softer pulp spreads the pad as a larger force does
(Hertz: the pad's radius a = (3 F R / 4 E)^(1/3), :meth:`~ectskin.twin.finger.Finger.
indentation_mm`), so the pad's part of the finger's signal cannot tell force from modulus; the
body's own deformation under the finger (the dimple and the bending, which follow the force
alone) and the cover's compression (which follows the pressure) can. How much of the force's
information that leaves is what this column lets the bound say.

The parameter is the logarithm of the modulus, x = ln(E / E0) (E0: the field's finger): the
effect is multiplicative (a ∝ E^(−1/3)), so one derivative holds over the whole range of
people's fingers, where ∂C/∂E changes fourfold between 0.05 and 0.2 MPa. Its prior
(:data:`MODULUS_PRIOR_SD`) is the twin's own spread: E uniform on [0.05, 0.2] MPa is ln E
uniform over a width ln 4, of standard deviation ln 4 / √12 = 0.40.

The column ∂C/∂x is not a gain times the finger's signal (as the radius's is,
:mod:`ectskin.twin.bound_field`): over an inflated chamber it changes sign from point to point,
and what decides the bound is the part of it along the force's own column, which such a gain
leaves out (``docs/bound.md``). It is therefore taken by central differences of direct
method-of-moments solves (:func:`modulus_column`, a finger of modulus E0 e^(±h)), at any
points, or once per state on a grid of nodes over each face's extent and forces
(:func:`modulus_table`, a :class:`ModulusTable` that interpolates it cubically in (u, v, ln F)).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse.linalg
from scipy.interpolate import RegularGridInterpolator

from ectskin._check import EctskinError
from ectskin.twin.mechanics import Touch
from ectskin.twin.sensor import SensorModel

#: the step of the central difference in x = ln(E / E0) (a 10 % softer and stiffer pulp)
MODULUS_STEP = 0.1
#: the prior's standard deviation of ln E: the twin's spread of people's pulp (uniform on
#: [0.05, 0.2] MPa: ln E uniform over a width ln 4), ln 4 / √12
MODULUS_PRIOR_SD = math.log(4.0) / math.sqrt(12.0)
#: the nodes of a :class:`ModulusTable`: about this spacing (mm) over each face's extent ...
TABLE_SPACING_MM = 5.0
#: ... and this many forces, equally spaced in ln F over the field's force range: the column
#: changes quickly with the force as the pad spreads over the skin's panels, and fewer nodes
#: miss it between them (tests/twin/test_bound_field.py); the cubic needs at least 4
TABLE_FORCE_NODES = 6


def _finger_sensor(sensor: SensorModel, x: float) -> SensorModel:
    """``sensor`` with its finger's pulp modulus E0 e^x (the rest shared)."""
    f = sensor.finger
    return sensor.with_fingers(replace(f, pulp_modulus_mpa=f.pulp_modulus_mpa * math.exp(x)))


def modulus_column(
    sensor: SensorModel,
    inflation_ml,
    face: str,
    uv,
    force_n,
    *,
    step: float = MODULUS_STEP,
) -> np.ndarray:
    """(n, n_pairs) ∂C/∂ln E (pF per unit of ln E) at the points ``uv`` (n, 2) mm of ``face``
    pressed with ``force_n`` (n,) N (broadcast): (C(E0 e^h) − C(E0 e^−h)) / 2h, h = ``step``,
    by direct solves of ``sensor`` at ``inflation_ml``; the rows at one point are solved in one
    call per modulus (2 calls a point)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    n = uv.shape[0]
    force = np.broadcast_to(np.asarray(force_n, dtype=np.float64), (n,))
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(force)) and np.all(force > 0)):
        raise EctskinError("modulus_column: points must be finite and forces finite and > 0")
    if not (math.isfinite(step) and step > 0):
        raise EctskinError(f"modulus_column: step must be a finite number > 0, got {step!r}")
    infl = sensor.manipulator.check_inflation(inflation_ml)
    soft, stiff = _finger_sensor(sensor, -step), _finger_sensor(sensor, step)
    out = np.empty((n, sensor.layout.n_pairs))
    groups: dict[tuple[float, float], list[int]] = {}
    for i, p in enumerate(uv):
        groups.setdefault((float(p[0]), float(p[1])), []).append(i)
    for point, rows in groups.items():
        touch = Touch(face, point)
        out[rows] = (stiff.capacitance(infl, touch, force[rows])
                     - soft.capacitance(infl, touch, force[rows])) / (2 * step)
    return out


@dataclass(frozen=True)
class ModulusTable:
    """∂C/∂ln E of one state at the nodes of a grid per face (:func:`modulus_table`),
    interpolated cubically in (u, v, ln F); points and forces beyond the nodes are moved to the
    nearest node plane.

    ``nodes``: {face: (u (nu,) mm, v (nv,) mm)}; ``forces_n`` (nf,); ``values``: {face:
    (nu, nv, nf, n_pairs) pF}; ``step``: the difference's step in ln E.
    """

    nodes: Mapping[str, tuple[np.ndarray, np.ndarray]]
    forces_n: np.ndarray
    values: Mapping[str, np.ndarray]
    step: float

    @property
    def n_solves(self) -> int:
        """Readouts the table solved: 2 per node (u, v, F), in 2 calls per node point (u, v)."""
        return sum(2 * u.size * v.size * self.forces_n.size for u, v in self.nodes.values())

    def column(self, face: str, uv, force_n) -> np.ndarray:
        """(n, n_pairs) ∂C/∂ln E at the points ``uv`` (n, 2) of ``face`` and forces (n,)."""
        return interpolate_table(self.nodes, self.forces_n, self.values, face, uv, force_n,
                                 "ModulusTable")

    def to_dict(self) -> dict[str, Any]:
        """A summary for JSON: the grid and the solves (not the values)."""
        return {
            "nodes": {f: [int(u.size), int(v.size)] for f, (u, v) in self.nodes.items()},
            "forces_n": [float(x) for x in self.forces_n], "step_ln": self.step,
            "n_solves": self.n_solves,
        }


def log_forces(force_range_n, force_nodes: int, who: str) -> np.ndarray:
    """A table's ``force_nodes`` (>= 4, for cubic interpolation) forces equally spaced in ln F
    over ``force_range_n`` (lo, hi) N; ``who`` names the caller in the errors."""
    if not (isinstance(force_nodes, int) and force_nodes >= 4):
        raise EctskinError(f"{who}: force_nodes must be an integer >= 4 (cubic interpolation), "
                           f"got {force_nodes!r}")
    lo, hi = (float(x) for x in force_range_n)
    if not 0 < lo < hi < math.inf:
        raise EctskinError(f"{who}: force_range_n must be 0 < lo < hi, got "
                           f"{tuple(force_range_n)!r}")
    return np.exp(np.linspace(math.log(lo), math.log(hi), force_nodes))


def table_nodes(lo: float, hi: float, spacing_mm: float) -> np.ndarray:
    """At least 4 equally spaced nodes from ``lo`` to ``hi``, about ``spacing_mm`` apart."""
    return np.linspace(lo, hi, max(4, int(round((hi - lo) / spacing_mm)) + 1))


def interpolate_table(nodes: Mapping[str, tuple[np.ndarray, np.ndarray]], forces_n: np.ndarray,
                      values: Mapping[str, np.ndarray], face: str, uv, force_n,
                      who: str) -> np.ndarray:
    """(n, ...) a table's ``values`` ({face: (nu, nv, nf, ...)} at its ``nodes`` {face: (u, v)}
    and ``forces_n``) at the points ``uv`` (n, 2) of ``face`` and forces (n,): a cubic spline
    in (u, v, ln F), points and forces beyond the nodes moved to the nearest node plane."""
    if face not in values:
        raise EctskinError(f"{who}: no nodes on face {face!r} (faces {sorted(values)})")
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    force = np.broadcast_to(np.asarray(force_n, dtype=np.float64), (uv.shape[0],))
    u, v = nodes[face]
    lf = np.log(forces_n)
    q = np.c_[np.clip(uv[:, 0], u[0], u[-1]), np.clip(uv[:, 1], v[0], v[-1]),
              np.clip(np.log(np.maximum(force, 1e-300)), lf[0], lf[-1])]
    vals = values[face]
    # the cubic spline's system solved exactly (scipy's default iterative solver is off by up
    # to ~1e-3 relative here)
    interp = RegularGridInterpolator((u, v, lf), vals.reshape(*vals.shape[:3], -1),
                                     method="cubic", solver=scipy.sparse.linalg.spsolve)
    return interp(q).reshape(len(q), *vals.shape[3:])


def tabulate(
    extents: Mapping[str, tuple[tuple[float, float], tuple[float, float]]], spacing_mm: float,
    forces: np.ndarray, who: str, column: Callable[[str, np.ndarray, np.ndarray], np.ndarray],
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict[str, np.ndarray]]:
    """(nodes, values) of a table: ``column(face, points (m, 2), forces (m,))`` -> (m, ...) at
    the nodes of each face's extent ({face: ((u_lo, u_hi), (v_lo, v_hi)) mm},
    :func:`table_nodes` at ``spacing_mm``) times ``forces``; values {face: (nu, nv, nf, ...)}."""
    if not (math.isfinite(spacing_mm) and spacing_mm > 0):
        raise EctskinError(f"{who}: spacing_mm must be a finite number > 0, got {spacing_mm!r}")
    nodes, values = {}, {}
    for face, ((ulo, uhi), (vlo, vhi)) in extents.items():
        u, v = table_nodes(ulo, uhi, spacing_mm), table_nodes(vlo, vhi, spacing_mm)
        U, V = np.meshgrid(u, v, indexing="ij")
        pts = np.repeat(np.c_[U.ravel(), V.ravel()], forces.size, axis=0)
        col = column(face, pts, np.tile(forces, U.size))
        nodes[face] = (u, v)
        values[face] = col.reshape(u.size, v.size, forces.size, *col.shape[1:])
    return nodes, values


def modulus_table(
    sensor: SensorModel,
    inflation_ml,
    extents: Mapping[str, tuple[tuple[float, float], tuple[float, float]]],
    force_range_n: Sequence[float],
    *,
    spacing_mm: float = TABLE_SPACING_MM,
    force_nodes: int = TABLE_FORCE_NODES,
    step: float = MODULUS_STEP,
) -> ModulusTable:
    """The :class:`ModulusTable` of ``sensor`` at ``inflation_ml``: :func:`modulus_column` at
    the nodes of each face's extent ({face: ((u_lo, u_hi), (v_lo, v_hi)) mm}, :func:`table_nodes`
    at ``spacing_mm``) and ``force_nodes`` (>= 4) forces equally spaced in ln F over
    ``force_range_n`` (lo, hi) N. Costs 2 readouts per node, in 2 calls per point (u, v)."""
    forces = log_forces(force_range_n, force_nodes, "modulus_table")
    nodes, values = tabulate(
        extents, spacing_mm, forces, "modulus_table",
        lambda face, pts, f: modulus_column(sensor, inflation_ml, face, pts, f, step=step),
    )
    return ModulusTable(nodes, forces, values, step)
