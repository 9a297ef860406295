"""The hand's push as a nuisance of the bound: its columns with the finger pressing.

The push nuisance (:data:`~ectskin.twin.bound.DEFAULT_PUSH_LOADS`: 9 hand loads) enters the
bound as ∂C/∂(each load). The field-backed bound's shortcut (:mod:`ectskin.twin.bound_field`)
takes these derivatives once per state on the *untouched* skin, as if the finger's own signal
did not change with the push. Beyond the wire ends that is not so: there the finger's signal is
small, force and push bend the body alike, their columns are nearly collinear, and the small
part of the push's column that the finger adds (a few % of it) decides how much force
information is left: with the untouched columns the bound was 3-4 × too low there
(``docs/bound.md``).

Here the columns are taken with the finger pressing: central differences of direct
method-of-moments solves with each load at ± the push step (:func:`push_columns`), at any
points, or once per state on a grid of nodes over each face's extent and forces
(:func:`push_table`, a :class:`PushTable` that interpolates them cubically in (u, v, ln F), as
:class:`~ectskin.twin.bound_modulus.ModulusTable` does the pulp's modulus). The loads that push
at the same point (``DEFAULT_PUSH_LOADS``: two at each right-side point, one at each left-side
one) and every force of a node share one call to
:meth:`~ectskin.twin.sensor.SensorModel.capacitance`: the finger's placement and the body's
deformation are taken for all their rows at once (6 calls, 18 solves per node point and force;
batched, a solve costs about 40 % of one alone). The loads cannot share one placement: the push
moves the skin under the finger, and that is the change this column is for.

Beyond the wire ends the direct differences themselves are uncertain by some 10 % of the bound
(over inflated chambers: the bound there changes by that much between push steps of 0.05, 0.1
and 0.2 N): a table closer to them than that is not better.

One-sided differences from one shared base solve (10 solves instead of 18;
``scheme="forward"``) are on offer for measurements: their O(h) error is about a tenth of the
finger's part of the column, and they put the force bound beyond the wire ends some 5 % lower
than central ones (``docs/bound.md``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.twin.bound import DEFAULT_PUSH_LOADS, FD_STEPS
from ectskin.twin.bound_modulus import interpolate_table, log_forces, tabulate
from ectskin.twin.mechanics import Handling, Touch
from ectskin.twin.sensor import SensorModel

#: the step (N) of each load's difference: the direct bound's (twin.bound.FD_STEPS)
PUSH_STEP = FD_STEPS["push"]
#: the nodes of a :class:`PushTable`: about this spacing (mm) over each face's extent ...
PUSH_SPACING_MM = 5.0
#: ... and this many forces, equally spaced in ln F over the field's force range (the cubic's
#: least): 6 brought the bound at the paper's 5-mm cells no closer to the direct bound
#: (docs/bound.md); 10-mm nodes, about a third of the solves, missed the column twice as much
PUSH_FORCE_NODES = 4
#: the difference schemes of :func:`push_columns`
SCHEMES = ("central", "forward")

PushLoads = Sequence[tuple[Touch, tuple[float, float, float]]]


def _by_point(push_loads: PushLoads) -> dict[Touch, list[tuple[int, np.ndarray]]]:
    """{push point: [(load index, world direction (3,))]}: the loads one call can hold."""
    out: dict[Touch, list[tuple[int, np.ndarray]]] = {}
    for k, (point, direction) in enumerate(push_loads):
        d = np.asarray(direction, dtype=np.float64)
        if not (isinstance(point, Touch) and d.shape == (3,) and np.all(np.isfinite(d))):
            raise EctskinError(f"push_loads: load {k} must be (Touch, (x, y, z) direction), got "
                               f"{(point, direction)!r:.100}")
        out.setdefault(point, []).append((k, d))
    return out


def push_columns(
    sensor: SensorModel,
    inflation_ml,
    face: str,
    uv,
    force_n,
    *,
    push_loads: PushLoads = DEFAULT_PUSH_LOADS,
    step: float = PUSH_STEP,
    scheme: str = "central",
) -> np.ndarray:
    """(n, n_pairs, n_loads) ∂C/∂(each of ``push_loads``) (pF/N) at the points ``uv`` (n, 2) mm
    of ``face`` pressed with ``force_n`` (n,) N (broadcast), by direct solves of ``sensor`` at
    ``inflation_ml``: ``"central"`` (C(+h) − C(−h)) / 2h, ``"forward"`` (C(+h) − C(0)) / h, each
    load of force h = ``step`` along its direction. The rows of one point are solved in one call
    per push point (each call holds its loads' ± rows at every force of the point), and the
    forward scheme's base in one more."""
    check_option("scheme", scheme, SCHEMES)
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    n = uv.shape[0]
    force = np.broadcast_to(np.asarray(force_n, dtype=np.float64), (n,))
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(force)) and np.all(force > 0)):
        raise EctskinError("push_columns: points must be finite and forces finite and > 0")
    if not (math.isfinite(step) and step > 0):
        raise EctskinError(f"push_columns: step must be a finite number > 0, got {step!r}")
    infl = sensor.manipulator.check_inflation(inflation_ml)
    loads = _by_point(push_loads)
    signs = (1.0, -1.0) if scheme == "central" else (1.0,)
    out = np.empty((n, sensor.layout.n_pairs, len(push_loads)))
    groups: dict[tuple[float, float], list[int]] = {}
    for i, p in enumerate(uv):
        groups.setdefault((float(p[0]), float(p[1])), []).append(i)
    for point, rows in groups.items():
        touch, f = Touch(face, point), force[rows]
        m = len(rows)
        base = None if scheme == "central" else sensor.capacitance(infl, touch, f)
        for at, members in loads.items():
            # rows: load j, sign s, force i -> index (j * len(signs) + s) * m + i
            push = np.concatenate([np.broadcast_to(s * step * d, (m, 3))
                                   for _, d in members for s in signs])
            c = sensor.capacitance(infl, touch, np.tile(f, len(members) * len(signs)),
                                   Handling(push=at, push_force_n=push))
            c = c.reshape(len(members), len(signs), m, -1)
            for j, (k, _) in enumerate(members):
                out[rows, :, k] = ((c[j, 0] - c[j, 1]) / (2 * step) if base is None
                                   else (c[j, 0] - base) / step)
    return out


@dataclass(frozen=True)
class PushTable:
    """The push's columns of one state with the finger pressing at the nodes of a grid per face
    (:func:`push_table`), interpolated cubically in (u, v, ln F); points and forces beyond the
    nodes are moved to the nearest node plane.

    ``nodes``: {face: (u (nu,) mm, v (nv,) mm)}; ``forces_n`` (nf,); ``values``: {face:
    (nu, nv, nf, n_pairs, n_loads) pF/N}; ``step``: the loads' difference step (N); ``scheme``:
    ``"central"`` or ``"forward"`` (:func:`push_columns`).
    """

    nodes: Mapping[str, tuple[np.ndarray, np.ndarray]]
    forces_n: np.ndarray
    values: Mapping[str, np.ndarray]
    step: float
    scheme: str = "central"

    @property
    def n_loads(self) -> int:
        return int(next(iter(self.values.values())).shape[-1])

    @property
    def n_solves(self) -> int:
        """Readouts the table solved: per node (u, v, F) 2 per load (central) or 1 per load and
        a base (forward)."""
        per = 2 * self.n_loads if self.scheme == "central" else self.n_loads + 1
        return sum(per * u.size * v.size * self.forces_n.size for u, v in self.nodes.values())

    def column(self, face: str, uv, force_n) -> np.ndarray:
        """(n, n_pairs, n_loads) the push's columns at the points ``uv`` (n, 2) of ``face`` and
        forces (n,)."""
        return interpolate_table(self.nodes, self.forces_n, self.values, face, uv, force_n,
                                 "PushTable")

    def to_dict(self) -> dict[str, Any]:
        """A summary for JSON: the grid and the solves (not the values)."""
        return {
            "nodes": {f: [int(u.size), int(v.size)] for f, (u, v) in self.nodes.items()},
            "forces_n": [float(x) for x in self.forces_n], "step_n": self.step,
            "scheme": self.scheme, "n_loads": self.n_loads, "n_solves": self.n_solves,
        }


def push_table(
    sensor: SensorModel,
    inflation_ml,
    extents: Mapping[str, tuple[tuple[float, float], tuple[float, float]]],
    force_range_n: Sequence[float],
    *,
    spacing_mm: float = PUSH_SPACING_MM,
    force_nodes: int = PUSH_FORCE_NODES,
    push_loads: PushLoads = DEFAULT_PUSH_LOADS,
    step: float = PUSH_STEP,
    scheme: str = "central",
) -> PushTable:
    """The :class:`PushTable` of ``sensor`` at ``inflation_ml``: :func:`push_columns` at the
    nodes of each face's extent ({face: ((u_lo, u_hi), (v_lo, v_hi)) mm},
    :func:`~ectskin.twin.bound_modulus.table_nodes` at ``spacing_mm``) and ``force_nodes``
    (>= 4) forces equally spaced in ln F over ``force_range_n`` (lo, hi) N. Costs 18 readouts
    per node with the 9 default loads (central; 10 forward), in 6 calls (7) per point (u, v)."""
    if not push_loads:
        raise EctskinError("push_table: no push loads given")
    forces = log_forces(force_range_n, force_nodes, "push_table")
    nodes, values = tabulate(
        extents, spacing_mm, forces, "push_table",
        lambda face, pts, f: push_columns(sensor, inflation_ml, face, pts, f,
                                          push_loads=push_loads, step=step, scheme=scheme),
    )
    return PushTable(nodes, forces, values, step, scheme)
