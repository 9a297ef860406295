"""The fingertip's pulp modulus and radius as fitted nuisances of each pressing finger (opt-in).

People's fingers differ in their pulp's stiffness and their fingertip's size, and a softer
pulp spreads the pad as a larger force does: through a field built for one finger (modulus E0,
radius R0), another finger's force comes out biased. :class:`~ectskin.inversion.Inversion`
with ``modulus={state: table}`` fits x = ln(E / E0) per pressing finger, and with
``radius={state: table}`` r = ln(R / R0), its signal

    Δ(u, v, F) + x M_E(u, v, F) + r M_R(u, v, F),   M_E = ∂C/∂ln E, M_R = ∂C/∂ln R,

the columns at the field's finger from a table of the state: for the modulus a
:class:`~ectskin.twin.bound_modulus.ModulusTable` (direct solves of a softer and a stiffer pulp
at the nodes of a grid, :func:`~ectskin.twin.bound_modulus.modulus_table`), for the radius
:func:`radius_table` (the same grid and interpolant, a smaller and a bigger fingertip). Each
has a Gaussian prior (``modulus_prior_sd``, ``radius_prior_sd``) truncated at
``FINGER_BOUND_SD`` sd (a penalised fit; each counts as a parameter of the BIC). The columns
are not a gain times Δ (the modulus's changes sign over an inflated chamber), so the finger
scale of ``finger_scale_sd`` cannot stand in for them; both can be fitted with it
((1 + a) Δ + x M_E + r M_R).

:class:`TableColumns` evaluates a table as the table does (a cubic spline, not-a-knot, in u,
v and ln F, beyond the nodes the nearest node plane) with its slopes, so that the fit's
Jacobian holds x ∂M/∂(u, v, F) too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.interpolate import make_interp_spline

from ectskin._check import EctskinError
from ectskin.inversion.model import FingerColumn, StateModel
from ectskin.inversion.spline import AxisBasis, axis_basis
from ectskin.twin.bound_modulus import (
    MODULUS_PRIOR_SD,
    TABLE_FORCE_NODES,
    TABLE_SPACING_MM,
    ModulusTable,
    log_forces,
    table_nodes,
)
from ectskin.twin.field_finger import RADIUS_STEP
from ectskin.twin.mechanics import Touch

__all__ = ["FINGER_BOUND_SD", "FINGER_NUISANCES", "MODULUS_PRIOR_SD", "RADIUS_PRIOR_SD", "TableColumns",
           "finger_column", "finger_columns", "finger_prior", "nuisance_fingers", "radius_table"]

#: the finger nuisances, in the fit's order
FINGER_NUISANCES = ("modulus", "radius")
#: the finger nuisances' range: this many prior sd either side of 0 (a truncated Gaussian prior)
FINGER_BOUND_SD = 3.0
#: the radius prior's sd in ln R: the twin's fingertips, uniform on 7-10 mm
#: (:func:`ectskin.twin.human.trial_fingers`), ln(10 / 7) / √12
RADIUS_PRIOR_SD = math.log(10.0 / 7.0) / math.sqrt(12.0)


class TableColumns:
    """M = ∂C/∂ln E of one state and its slopes, from a table with ``nodes`` {face: (u, v)}
    mm, ``forces_n`` (nf,) N and ``values`` {face: (nu, nv, nf, n_pairs)} pF
    (:class:`~ectskin.twin.bound_modulus.ModulusTable`): the table's own cubic interpolant in
    (u, v, ln F), the point and force moved to the nearest node plane beyond the nodes."""

    def __init__(self, table: Any, n_pairs: int, faces: tuple[str, ...], where: str) -> None:
        try:
            forces = np.asarray(table.forces_n, dtype=np.float64)
            nodes, values = dict(table.nodes), dict(table.values)
        except (AttributeError, TypeError, ValueError):
            raise EctskinError(f"{where}: must be a ModulusTable (nodes, forces_n, values), "
                               f"got {type(table).__name__}") from None
        if not (forces.ndim == 1 and forces.size >= 4 and np.all(forces > 0)
                and np.all(np.diff(forces) > 0)):
            raise EctskinError(f"{where}: forces_n must be >= 4 increasing forces > 0 N, got "
                               f"{forces.tolist()}")
        missing = [f for f in faces if f not in values or f not in nodes]
        if missing:
            raise EctskinError(f"{where}: no nodes on the field's face(s) {missing} (the table "
                               f"has {sorted(values)})")
        self._faces: dict[str, tuple[list[AxisBasis], np.ndarray, list[tuple[float, float]]]] = {}
        lf = np.log(forces)
        for face in faces:
            u, v = (np.asarray(a, dtype=np.float64) for a in nodes[face])
            val = np.asarray(values[face], dtype=np.float64)
            if val.shape != (u.size, v.size, forces.size, n_pairs) or not np.all(np.isfinite(val)):
                raise EctskinError(
                    f"{where}: values[{face!r}] must be finite with shape ({u.size}, {v.size}, "
                    f"{forces.size}, {n_pairs}), got shape {val.shape}")
            if min(u.size, v.size) < 4:
                raise EctskinError(f"{where}: face {face!r} needs >= 4 nodes in u and v (cubic), "
                                   f"got {u.size} x {v.size}")
            c, bases = val, []
            for ax, x in enumerate((u, v, lf)):
                s = make_interp_spline(x, c, k=3, axis=ax)
                c = np.moveaxis(s.c, 0, ax)
                bases.append(axis_basis(s.t, 3))
            ends = [(float(x[0]), float(x[-1])) for x in (u, v, lf)]
            self._faces[face] = (bases, np.ascontiguousarray(c), ends)

    def __call__(self, face: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """M (n_pairs,) and ∂M/∂(u, v, F) (n_pairs, 3) at x = (u, v, F) on ``face``."""
        bases, coef, ends = self._faces[face]
        q = (float(x[0]), float(x[1]), math.log(max(float(x[2]), 1e-300)))
        spans, rows = [], []
        for ax in range(3):
            lo, hi = ends[ax]
            i, b, d = bases[ax](q[ax])  # clamped into [lo, hi]
            if not lo <= q[ax] <= hi:  # the nearest node plane: flat beyond it
                d = [0.0] * 4
            spans.append(i)
            rows.append((b, d))
        (iu, iv, i_f) = spans
        block = coef[iu - 3: iu + 1, iv - 3: iv + 1, i_f - 3: i_f + 1]  # (4, 4, 4, n_pairs)
        (bu, du), (bv, dv), (bf, df) = rows
        wu, wv = np.array([bu, du, bu, bu]), np.array([bv, bv, dv, bv])
        wf = np.array([bf, bf, bf, df])
        w = (wu[:, :, None, None] * wv[:, None, :, None] * wf[:, None, None, :]).reshape(4, -1)
        z = w @ block.reshape(w.shape[1], -1)
        return z[0], np.stack([z[1], z[2], z[3] / math.exp(q[2])], axis=-1)


def finger_columns(tables: Mapping[str, tuple[Mapping[Any, Any] | None, float]],
                   state: tuple[float, ...], same: Any, n_pairs: int, faces: tuple[str, ...]
                   ) -> dict[str, tuple[FingerColumn, float]]:
    """{name: (the columns of ``state``, 1/prior sd)} of the finger nuisances ``tables`` {name:
    ({state: table} or None, prior sd)} that have a table for ``state`` (``same(key, state)``
    matches the keys), in the order of ``tables``."""
    out: dict[str, tuple[FingerColumn, float]] = {}
    for name, (by_state, sd) in tables.items():
        if not (isinstance(sd, int | float) and 0 < sd < math.inf):
            raise EctskinError(f"Inversion: {name}_prior_sd must be > 0, got {sd!r}")
        if by_state is None:
            continue
        if not isinstance(by_state, Mapping):
            raise EctskinError(f"Inversion: {name} must be a mapping {{state: ModulusTable}} or "
                               f"None, got {type(by_state).__name__}")
        table = next((v for k, v in by_state.items() if same(k, state)), None)
        if table is not None:
            out[name] = (TableColumns(table, n_pairs, faces, f"Inversion: {name}[{list(state)}]"),
                         1.0 / float(sd))
    return out


def nuisance_fingers(m: StateModel, keys: list[tuple[str, str]]) -> list[int]:
    """The fingers (positions in ``keys``) that carry the finger nuisances (pulp modulus,
    radius): the pressing ones, where the state has their columns."""
    if not m.finger_columns:
        return []
    return [j for j, key in enumerate(keys) if key[1] == "contact"]


def finger_column(m: StateModel, name: str, face: str, x: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The column of nuisance ``name`` and its slopes ∂/∂(u, v, F) on ``m``'s channels."""
    M, dM = m.finger_columns[name][0](face, x)
    if M.shape[0] != m.n_pairs:  # a masked copy
        M, dM = M[m.channels], dM[m.channels]
    return M, dM


def radius_table(sensor: Any, inflation_ml: Any,
                 extents: Mapping[str, tuple[tuple[float, float], tuple[float, float]]],
                 force_range_n: Sequence[float], *, spacing_mm: float = TABLE_SPACING_MM,
                 force_nodes: int = TABLE_FORCE_NODES, step: float = RADIUS_STEP) -> ModulusTable:
    """∂C/∂ln R of ``sensor``'s finger at ``inflation_ml`` on the grid of
    :func:`~ectskin.twin.bound_modulus.modulus_table` (the same nodes and forces): central
    differences of direct solves with the fingertip's radius R0 e^(±``step``), in a
    :class:`~ectskin.twin.bound_modulus.ModulusTable` (its ``step`` in ln R)."""
    if not (math.isfinite(spacing_mm) and spacing_mm > 0 and math.isfinite(step) and step > 0):
        raise EctskinError(f"radius_table: spacing_mm and step must be finite numbers > 0, got "
                           f"{spacing_mm!r}, {step!r}")
    forces = log_forces(force_range_n, force_nodes, "radius_table")
    f0 = sensor.finger
    small, big = (sensor.with_fingers(replace(f0, radius_mm=f0.radius_mm * math.exp(s)))
                  for s in (-step, step))
    nodes, values = {}, {}
    for face, ((ulo, uhi), (vlo, vhi)) in extents.items():
        u, v = table_nodes(ulo, uhi, spacing_mm), table_nodes(vlo, vhi, spacing_mm)
        val = np.empty((u.size, v.size, forces.size, sensor.layout.n_pairs))
        for i, a in enumerate(u):
            for j, b in enumerate(v):
                touch = Touch(face, (float(a), float(b)))
                val[i, j] = (big.capacitance(inflation_ml, touch, forces)
                             - small.capacitance(inflation_ml, touch, forces)) / (2 * step)
        nodes[face], values[face] = (u, v), val
    return ModulusTable(nodes, forces, values, step)


def finger_prior(finger: Any) -> dict[str, tuple[float, float]]:
    """``finger`` of :meth:`Inversion.fit` checked: {name: (centre, sd)}."""
    if finger is None:
        return {}
    if not isinstance(finger, Mapping):
        raise EctskinError(f"Inversion: finger must be a mapping {{'modulus' | 'radius': (centre, "
                           f"sd)}} or None, got {type(finger).__name__}")
    out = {}
    for name, value in finger.items():
        try:
            centre, sd = (float(x) for x in value)
        except (TypeError, ValueError):
            centre = sd = math.nan
        if name not in FINGER_NUISANCES or not (math.isfinite(centre) and 0 < sd < math.inf):
            raise EctskinError(f"Inversion: finger[{name!r}] must be (centre, sd > 0) of one of "
                               f"{list(FINGER_NUISANCES)}, got {value!r}")
        out[name] = (centre, sd)
    return out
