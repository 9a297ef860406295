"""Cramér–Rao bounds from a response field: the physical limit at many points at once.

:mod:`ectskin.twin.bound` bounds one point at a time from finite differences of direct
method-of-moments solves (1–2 s a point). Here the Jacobian of the finger's parameters
(u, v, F) comes from a :class:`~ectskin.twin.field.ResponseField` (``jacobian``: its splines'
derivatives, microseconds a point), the noise is ``twin.readout.noise_pf`` at the field's
readout, and the bound of many points is taken in one batched eigen-decomposition
(:func:`crb_many`, the same rule as :func:`~ectskin.twin.bound.crb`: unit-diagonal FIM, clamped
eigenvalues, inf where unresolved).

Nuisance columns, once per state (:func:`state_nuisances`, direct solves of the twin):

* ``push`` (9 columns, no prior): ∂C/∂(each hand load of ``DEFAULT_PUSH_LOADS``) of the
  *untouched* state (``push_columns="untouched"``, the default): the hand bends the whole body,
  the finger rides on it, and the finger's own signal is taken not to change with the push, so
  the columns are taken once per state instead of at every point. Beyond the wire ends that
  makes the bound with the push unknown several times too low (force and push are nearly
  collinear there, and the finger's share of the push's column decides it); with
  ``push_columns="finger"`` the columns are taken with the finger pressing, by direct central
  differences on a grid of nodes per state (a :class:`~ectskin.twin.bound_push.PushTable`),
  interpolated to each point and force;
* ``inflation`` (one column per chamber, prior ±1 ml): ∂C/∂p_k of the untouched state, once per
  state. It leaves out how the finger's signal changes with the bulge under it, which is large
  only over the inflated chamber itself;
* ``finger`` (1 column, prior ±1 mm): ∂C/∂R ≈ κ ΔC, the finger's signal ΔC = C − C_untouched
  scaled by one gain κ (1/mm) per state, fitted by least squares to direct finite differences of
  the fingertip's radius at a few points. A larger fingertip couples more to the wires it is
  near: its signal grows with its size, in the pattern of its signal;
* ``modulus`` (1 column, prior ln 4 / √12 in ln E; on request): ∂C/∂ln E of the fingertip's
  pulp, which no gain model fits (:mod:`ectskin.twin.bound_modulus`): direct central differences
  on a grid of nodes per state (a :class:`~ectskin.twin.bound_modulus.ModulusTable`),
  interpolated to each point and force.

What each shortcut costs against the direct bound (``TwinResponse`` + ``point_bounds``) is
measured at points of a small field by ``tests/twin/test_bound_field.py`` (``docs/bound.md``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout
from ectskin.twin.bound import (
    DEFAULT_PRIOR_SD,
    DEFAULT_PUSH_LOADS,
    FD_STEPS,
    FORCE_THRESHOLD_N,
    NUISANCE_NAMES,
    NUISANCES,
    NULL_SHARE,
    RCOND,
    SCHEMA,
    VERSION,
    TwinResponse,
    cases,
    priors_in_use,
)
from ectskin.twin.bound_modulus import ModulusTable, modulus_table
from ectskin.twin.bound_push import PushTable, push_table
from ectskin.twin.field import ResponseField
from ectskin.twin.mechanics import Handling, Touch
from ectskin.twin.readout import ReadoutConfig, noise_pf
from ectskin.twin.sensor import SensorModel

#: points per batch of :func:`field_bounds` (memory: batch × n_pairs × n_params floats)
BATCH = 4096
#: the spacing (mm) of the maps' cells over each face
MAP_SPACING_MM = 5.0
#: a map cell whose centre lies within this distance (mm) of a wire counts as "near the wires"
NEAR_WIRE_MM = 5.0
#: where the push's columns come from (module docstring): the untouched state, once per state,
#: or a table of direct solves with the finger pressing
PUSH_COLUMNS = ("untouched", "finger")


# ---------------------------------------------------------------------------- the batched bound
def crb_many(
    J: np.ndarray,
    sigma: np.ndarray,
    *,
    n_nuisance: int = 0,
    prior_var: Sequence[float] | np.ndarray | None = None,
    rcond: float = RCOND,
) -> tuple[np.ndarray, np.ndarray]:
    """The bound of many points at once: :func:`~ectskin.twin.bound.crb` over a batch.

    ``J`` (n, n_obs, k): each point's Jacobian, its last ``n_nuisance`` columns nuisances;
    ``sigma`` (n, n_obs) > 0 the readouts' standard deviations; ``prior_var`` (k,) Gaussian
    prior variances per column (inf: none, 0: known). Returns (std (n, k − n_nuisance), inf where
    unresolved; resolved (n, k − n_nuisance)), as ``crb(J[i], sigma[i], ...)`` row by row.
    """
    J = np.asarray(J, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    if J.ndim != 3 or s.shape != J.shape[:2]:
        raise EctskinError(
            f"crb_many: expected J (n, n_obs, k) and sigma (n, n_obs), got shapes {J.shape} "
            f"and {s.shape}"
        )
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(s)) and np.all(s > 0)):
        raise EctskinError("crb_many: J must be finite and sigma finite and > 0")
    n, _, k = J.shape
    if not 0 <= n_nuisance <= k:
        raise EctskinError(f"crb_many: n_nuisance must be 0..{k}, got {n_nuisance}")
    var = np.full(k, np.inf) if prior_var is None else np.asarray(prior_var, dtype=np.float64)
    if var.shape != (k,) or not np.all(var >= 0):  # (NaN fails too)
        raise EctskinError(f"crb_many: prior_var must be {k} variances >= 0, got {var}")
    w = J / s[:, :, None]
    fim = np.einsum("nok,nol->nkl", w, w)
    idx = np.arange(k)
    with np.errstate(divide="ignore"):
        fim[:, idx, idx] += np.where(np.isfinite(var) & (var > 0), 1.0 / var, 0.0)
    keep = np.flatnonzero(var != 0)  # known columns leave the problem (bound 0)
    fim = fim[:, keep][:, :, keep]
    std_all = np.zeros((n, k))
    ok_all = np.ones((n, k), bool)
    if keep.size:
        std_all[:, keep], ok_all[:, keep] = _bound_many(fim, rcond)
    m = k - n_nuisance
    return std_all[:, :m], ok_all[:, :m]


def _bound_many(fim: np.ndarray, rcond: float) -> tuple[np.ndarray, np.ndarray]:
    """(std, resolved) of every column of each FIM (n, k, k), as ``bound._bound_block``."""
    d = np.sqrt(np.maximum(np.einsum("nkk->nk", fim), 0.0))
    live = d > 0  # a column without information has no coupling either (|F_ij| <= d_i d_j)
    dd = np.where(live, d, 1.0)
    scaled = fim / (dd[:, :, None] * dd[:, None, :])
    k = fim.shape[1]
    idx = np.arange(k)
    # a dead column becomes a decoupled unit row: it leaves the others' eigenvalues alone and
    # cannot raise the largest (the unit diagonal's largest eigenvalue is >= 1)
    scaled[:, idx, idx] = np.where(live, scaled[:, idx, idx], 1.0)
    lam, V = np.linalg.eigh(scaled)
    floor = rcond * lam[:, -1:]
    null = lam <= floor
    inv = 1.0 / np.where(null, floor, lam)
    var_s = np.einsum("nij,nj->ni", V**2, inv)
    null_part = np.einsum("nij,nj->ni", V**2, np.where(null, inv, 0.0))
    ok = live & (null_part <= NULL_SHARE * var_s)
    std = np.where(ok, np.sqrt(var_s) / dd, np.inf)
    return std, ok


# ---------------------------------------------------------------------------- nuisances
@dataclass(frozen=True)
class StateNuisances:
    """The nuisance columns of one state (module docstring).

    ``push`` (n_pairs, n_loads) pF/N and ``inflation`` (n_pairs, n_chambers) pF/ml: derivatives
    of the untouched readout; ``finger_gain`` κ (1/mm): ∂C/∂R ≈ κ (C − C_untouched);
    ``finger_fit`` the relative residual of that fit, ‖col − κ ΔC‖ / ‖col‖ over its points;
    ``modulus``: ∂C/∂ln E of the pulp's modulus at nodes of each face (None: not taken);
    ``push_table``: the push's columns with the finger pressing at nodes of each face, used
    instead of ``push`` where given (None: the untouched ``push``).
    """

    inflation_ml: tuple[float, ...]
    push: np.ndarray
    inflation: np.ndarray
    finger_gain: float
    finger_fit: float
    modulus: ModulusTable | None = None
    push_table: PushTable | None = None

    @property
    def sizes(self) -> dict[str, int]:
        return {"push": self.push.shape[1], "inflation": self.inflation.shape[1], "finger": 1,
                **({"modulus": 1} if self.modulus is not None else {})}

    @property
    def push_columns(self) -> str:
        """Where the push's columns come from: "untouched" or "finger" (:data:`PUSH_COLUMNS`)."""
        return "untouched" if self.push_table is None else "finger"

    def columns(self, name: str, delta: np.ndarray, face: str | None = None, uv=None,
                force_n=None) -> np.ndarray:
        """(n, n_pairs, k) columns of nuisance ``name`` at points whose finger's signal is
        ``delta`` (n, n_pairs) pF; ``modulus``, and ``push`` from a table, need the points too:
        ``face``, ``uv`` (n, 2) mm and ``force_n`` (n,)."""
        check_option("nuisance", name, tuple(self.sizes))
        n = delta.shape[0]
        if name == "finger":
            return (self.finger_gain * delta)[:, :, None]
        table = self.modulus if name == "modulus" else self.push_table if name == "push" else None
        if table is not None or name == "modulus":
            if table is None or face is None or uv is None or force_n is None:
                raise EctskinError(f"StateNuisances.columns: {name!r} needs its table, face, uv "
                                   "and force_n")
            col = table.column(face, uv, force_n)
            return col[:, :, None] if col.ndim == 2 else col
        col = self.push if name == "push" else self.inflation
        return np.broadcast_to(col, (n, *col.shape))

    def to_dict(self) -> dict[str, Any]:
        return {
            "inflation_ml": list(self.inflation_ml),
            "finger_gain_per_mm": self.finger_gain,
            "finger_fit_residual": self.finger_fit,
            "n_push_loads": self.push.shape[1],
            "push_columns": self.push_columns,
            **({"modulus": self.modulus.to_dict()} if self.modulus is not None else {}),
            **({"push_table": self.push_table.to_dict()} if self.push_table is not None else {}),
        }


def _central(fn, x0: float, h: float, lo: float) -> np.ndarray:
    """(fn(x0 + h) − fn(x0 − h)) / 2h, forward (fn(x0 + h) − fn(x0)) / h where x0 − h < lo."""
    if x0 - h >= lo:
        return (fn(x0 + h) - fn(x0 - h)) / (2 * h)
    return (fn(x0 + h) - fn(x0)) / h


def state_nuisances(
    sensor: SensorModel,
    inflation_ml,
    *,
    finger_points: Sequence[tuple[str, tuple[float, float], float]] = (),
    push_loads: Sequence[tuple[Touch, tuple[float, float, float]]] = DEFAULT_PUSH_LOADS,
    steps: Mapping[str, float] | None = None,
) -> StateNuisances:
    """The nuisance columns of ``sensor`` at ``inflation_ml`` by direct solves (module doc).

    ``finger_points`` [(face, (u, v) mm, force N)]: where κ is fitted (1 + 2 solves each; none:
    κ = 0, no finger column). Steps: :data:`~ectskin.twin.bound.FD_STEPS` updated by ``steps``.
    Costs 2 solves per push load and per chamber (one where the chamber is empty), untouched.
    """
    st = {**FD_STEPS, **(steps or {})}
    infl = sensor.manipulator.check_inflation(inflation_ml)

    def untouched(p: np.ndarray, handling: Handling | None = None) -> np.ndarray:
        return sensor.capacitance(p, None, 0.0, handling)[0]

    push = []
    for point, direction in push_loads:
        d = np.asarray(direction, dtype=np.float64)
        push.append(_central(
            lambda x, pt=point, d=d: untouched(infl, Handling(push=pt, push_force_n=(x * d)[None])),
            0.0, st["push"], -np.inf,
        ))
    chambers = []
    for k in range(infl.size):
        e = np.eye(infl.size)[k]
        chambers.append(_central(lambda x, e=e: untouched(infl + x * e), 0.0, st["inflation"],
                                 -float(infl[k])))
    gain, fit = 0.0, 0.0
    if finger_points:
        twin = TwinResponse(sensor, infl)  # (no push: its loads stay at 0)
        base = untouched(infl)
        num = den = res = tot = 0.0
        cols, deltas = [], []
        for face, uv, force in finger_points:
            def radius(x: float, face=face, uv=uv, force=force) -> np.ndarray:
                return twin.readout(face, np.array([uv]), np.array([force]), np.zeros(1),
                                    {"finger": np.array([[x]])})[0]
            cols.append(_central(radius, 0.0, st["finger"], -np.inf))
            deltas.append(radius(0.0) - base)
        for col, dc in zip(cols, deltas):
            num += float(dc @ col)
            den += float(dc @ dc)
        gain = num / den if den > 0 else 0.0
        for col, dc in zip(cols, deltas):
            res += float(np.sum((col - gain * dc) ** 2))
            tot += float(np.sum(col**2))
        fit = float(np.sqrt(res / tot)) if tot > 0 else 0.0
    return StateNuisances(
        tuple(float(x) for x in infl),
        np.array(push).T.reshape(sensor.layout.n_pairs, len(push)),
        np.array(chambers).T,
        gain,
        fit,
    )


def default_finger_points(field: ResponseField) -> list[tuple[str, tuple[float, float], float]]:
    """Where :func:`field_nuisances` fits κ: per face two points, at a quarter and three
    quarters of the grid's v extent, at its middle u, at the force range's middle."""
    out = []
    force = float(np.mean(field.spec.force_range_n))
    for face in field.faces:
        (ulo, uhi), (vlo, vhi) = field.spec.extent(face)
        for q in (0.25, 0.75):
            out.append((face, (0.5 * (ulo + uhi), vlo + q * (vhi - vlo)), force))
    return out


def field_nuisances(
    field: ResponseField, *, finger: bool = True, modulus: bool = False,
    push_columns: str = "untouched", push_options: Mapping[str, Any] | None = None,
    steps: Mapping[str, float] | None = None, **table: Any,
) -> StateNuisances:
    """:func:`state_nuisances` of the sensor and state ``field`` was built from (its spec); with
    ``modulus`` also the pulp modulus's :func:`~ectskin.twin.bound_modulus.modulus_table` over
    the field's faces and force range (``table``: its ``spacing_mm``, ``force_nodes``; the
    step is ``steps["modulus"]``, :data:`~ectskin.twin.bound.FD_STEPS`); with ``push_columns``
    "finger" also the push's :func:`~ectskin.twin.bound_push.push_table` over the same
    (``push_options``: its ``spacing_mm``, ``force_nodes``, ``scheme``; the step
    ``steps["push"]``), whose columns then replace the untouched state's."""
    check_option("push_columns", push_columns, PUSH_COLUMNS)
    points = default_finger_points(field) if finger else ()
    sensor = field.spec.sensor()
    out = state_nuisances(sensor, field.spec.inflation_ml, finger_points=points, steps=steps)
    step = {**FD_STEPS, **(steps or {})}
    extents = {face: field.spec.extent(face) for face in field.faces}
    if modulus:
        out = replace(out, modulus=modulus_table(sensor, field.spec.inflation_ml, extents,
                                                 field.spec.force_range_n,
                                                 step=step["modulus"], **table))
    if push_columns == "finger":
        out = replace(out, push_table=push_table(sensor, field.spec.inflation_ml, extents,
                                                 field.spec.force_range_n, step=step["push"],
                                                 **(push_options or {})))
    return out


# ---------------------------------------------------------------------------- many points
def field_bounds(
    field: ResponseField,
    face: str,
    uv,
    force_n,
    *,
    columns: StateNuisances | None = None,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
    readout: ReadoutConfig | None = None,
    rcond: float = RCOND,
    only: Sequence[str] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """{case: {"position_mm" (n,), "force_n" (n,)}} at the points ``uv`` (n, 2) of ``face``
    pressed with ``force_n`` (n,) (broadcast), for each case of
    :func:`~ectskin.twin.bound.cases` (``only``: these of them; inf: unresolved).

    (u, v, F) columns from ``field.jacobian``, the noise ``noise_pf`` at ``field.readout``;
    ``columns`` the state's nuisance columns (required when ``nuisances`` is not empty);
    ``prior_sd`` as :func:`~ectskin.twin.bound.point_bounds` (:data:`DEFAULT_PRIOR_SD` if None).
    The position bound is sqrt(var_u + var_v).
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    n = uv.shape[0]
    force = np.broadcast_to(np.asarray(force_n, dtype=np.float64), (n,))
    nuisances = tuple(nuisances)
    for k in nuisances:
        check_option("nuisance", k, NUISANCE_NAMES)
    if nuisances and columns is None:
        raise EctskinError(f"field_bounds: nuisances {list(nuisances)} need the state's columns")
    if "modulus" in nuisances and columns is not None and columns.modulus is None:
        raise EctskinError("field_bounds: the 'modulus' nuisance needs the state's modulus table "
                           "(field_nuisances(..., modulus=True))")
    prior = DEFAULT_PRIOR_SD if prior_sd is None else prior_sd
    cfg = readout or ReadoutConfig()
    names = cases(nuisances)
    for name in only or ():
        check_option("case", name, names)
    names = [name for name in names if only is None or name in only]
    out = {name: {"position_mm": np.empty(n), "force_n": np.empty(n)} for name in names}
    for lo in range(0, n, BATCH):
        sl = slice(lo, min(n, lo + BATCH))
        u, v, f = uv[sl, 0], uv[sl, 1], force[sl]
        c = field.readout(face, u, v, f)
        J = field.jacobian(face, u, v, f)[:, :, :3]
        sigma = noise_pf(c, cfg)
        extra = {k: columns.columns(k, c - field.untouched, face, uv[sl], f)
                 for k in nuisances} if columns else {}
        for case in names:
            active = list(nuisances) if case == "all" else [] if case == "none" else [case]
            Js = np.concatenate([J] + [extra[k] for k in active], axis=2)
            var = [np.inf] * 3
            for k in active:
                sd = prior.get(k)
                var += [np.inf if sd is None else float(sd) ** 2] * extra[k].shape[2]
            std, _ = crb_many(Js, sigma, n_nuisance=Js.shape[2] - 3, prior_var=var, rcond=rcond)
            out[case]["position_mm"][sl] = np.hypot(std[:, 0], std[:, 1])
            out[case]["force_n"][sl] = std[:, 2]
    return out


def reduce(pos: np.ndarray, force: np.ndarray, threshold_n: float = FORCE_THRESHOLD_N) -> dict:
    """Reductions of position and force bounds over points: ``loc_mm_mean``, ``loc_mm_median``,
    ``loc_mm_p95`` (over points where the position is resolved), ``force_n_mean``,
    ``force_n_median`` (over points where the force is resolved), ``force_observable_share``
    (share of all points with a force bound < ``threshold_n``), ``position_resolved_share``,
    ``force_resolved_share``, ``n_points``; None where nothing is resolved."""
    pos, force = np.asarray(pos, float).ravel(), np.asarray(force, float).ravel()
    p, f = pos[np.isfinite(pos)], force[np.isfinite(force)]
    stat = lambda a, fn: float(fn(a)) if a.size else None  # noqa: E731
    return {
        "loc_mm_mean": stat(p, np.mean),
        "loc_mm_median": stat(p, np.median),
        "loc_mm_p95": stat(p, lambda a: np.percentile(a, 95)),
        "force_n_mean": stat(f, np.mean),
        "force_n_median": stat(f, np.median),
        "force_observable_share": float(np.mean(force < threshold_n)) if force.size else None,
        "position_resolved_share": float(np.mean(np.isfinite(pos))) if pos.size else None,
        "force_resolved_share": float(np.mean(np.isfinite(force))) if force.size else None,
        "n_points": int(pos.size),
    }


def wire_distance(points: np.ndarray, wires: Sequence[Any]) -> np.ndarray:
    """(n,) distance (mm) in (u, v) from each of ``points`` (n, 2) to the nearest segment of the
    ``wires`` (polylines of (u, v) points); inf without wires."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    best = np.full(len(pts), np.inf)
    for wire in wires:
        w = np.asarray(wire, dtype=np.float64).reshape(-1, 2)
        for a, b in zip(w[:-1], w[1:]) if len(w) > 1 else [(w[0], w[0])]:
            ab = b - a
            t = np.clip(((pts - a) @ ab) / max(float(ab @ ab), 1e-300), 0.0, 1.0)
            best = np.minimum(best, np.linalg.norm(pts - (a + t[:, None] * ab), axis=1))
    return best


def map_grid(field: ResponseField, face: str, spacing_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres (u (nu,), v (nv,)) mm of cells about ``spacing_mm`` wide tiling the field's
    extent of ``face`` (the rule of :func:`~ectskin.twin.bound.skin_grid`)."""
    out = []
    for lo, hi in field.spec.extent(face):
        m = max(1, int(round((hi - lo) / spacing_mm)))
        out.append(lo + (np.arange(m) + 0.5) * (hi - lo) / m)
    return out[0], out[1]


def field_bound_maps(
    fields: Mapping[tuple[float, ...], ResponseField],
    columns: Mapping[tuple[float, ...], StateNuisances] | None,
    layout: SensorLayout,
    *,
    spacing_mm: float = MAP_SPACING_MM,
    force_n: float = 1.0,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
    readout: ReadoutConfig | None = None,
    rcond: float = RCOND,
    force_threshold_n: float = FORCE_THRESHOLD_N,
) -> dict[str, Any]:
    """Bound maps of every state's field over its faces, in the shape of
    :func:`~ectskin.twin.bound.bound_maps` (``docs/bound.md``; contact mode only), each
    state × face × case with ``reduce``'s reductions under ``reduction``.

    ``fields``: {inflation (ml per chamber): its field}; ``columns``: {inflation: its nuisance
    columns} (None with no nuisances).
    """
    if not (np.isfinite(spacing_mm) and spacing_mm > 0):
        raise EctskinError(f"spacing_mm must be a finite number > 0, got {spacing_mm!r}")
    if not fields:
        raise EctskinError("field_bound_maps: no fields given")
    nuisances = tuple(nuisances)
    names = cases(nuisances)
    t0 = time.perf_counter()
    faces = list(next(iter(fields.values())).faces)
    states, pooled, n_points = [], {c: [] for c in names}, 0  # type: ignore[var-annotated]
    wires = {
        f: [e.polyline_mm for k, e in enumerate(layout.electrodes) if layout.electrode_surface(k) == f]
        for f in faces
    }
    near: list[np.ndarray] = []
    used = {columns[s].push_columns for s in fields if s in columns} if columns else set()
    if len(used) > 1:
        raise EctskinError(f"field_bound_maps: the states' push columns differ ({sorted(used)}); "
                           "take them alike for every state")
    push_from = used.pop() if used and nuisances else None
    for inflation, field in fields.items():
        if tuple(field.spec.inflation_ml) != tuple(float(x) for x in inflation):
            raise EctskinError(
                f"field_bound_maps: the field under state {tuple(inflation)} was built for "
                f"{field.spec.inflation_ml}"
            )
        if list(field.faces) != faces:
            raise EctskinError(f"field_bound_maps: fields cover different faces ({faces}, "
                               f"{list(field.faces)})")
        lo, hi = field.spec.force_range_n
        if not lo <= force_n <= hi:
            raise EctskinError(f"force_n must lie in the field's force range [{lo}, {hi}] N, "
                               f"got {force_n!r}")
        cols = None
        if nuisances:
            if columns is None or inflation not in columns:
                raise EctskinError(f"field_bound_maps: no nuisance columns for state {inflation}")
            cols = columns[inflation]
        per_face: dict[str, Any] = {}
        for face in faces:
            u, v = map_grid(field, face, spacing_mm)
            U, V = np.meshgrid(u, v)
            res = field_bounds(field, face, np.c_[U.ravel(), V.ravel()], force_n, columns=cols,
                               nuisances=nuisances, prior_sd=prior_sd, readout=readout, rcond=rcond)
            n_points += U.size
            near.append(wire_distance(np.c_[U.ravel(), V.ravel()], wires[face]) <= NEAR_WIRE_MM)
            entry: dict[str, Any] = {"u_mm": u, "v_mm": v, "contact": {}}
            for case in names:
                pos = res[case]["position_mm"].reshape(U.shape)
                thr = res[case]["force_n"].reshape(U.shape)
                pooled[case].append(np.stack([pos.ravel(), thr.ravel()]))
                entry["contact"][case] = {"position_mm": pos, "force_n": thr,
                                          "reduction": reduce(pos, thr, force_threshold_n)}
            per_face[face] = entry
        states.append({"inflation_ml": [float(x) for x in inflation], "faces": per_face})
    summary = {}
    is_near = np.concatenate(near)
    for c, parts in pooled.items():
        a = np.concatenate(parts, axis=1)
        summary[c] = reduce(a[0], a[1], force_threshold_n)
        for key, m in (("near_wires", is_near), ("away_from_wires", ~is_near)):
            summary[c][f"force_observable_share_{key}"] = (
                float(np.mean(a[1][m] < force_threshold_n)) if m.any() else None)
    first = next(iter(fields.values()))
    return {
        "schema": SCHEMA,
        "version": VERSION,
        "layout": layout.name,
        "settings": {
            "source": "response field", "faces": faces, "spacing_mm": spacing_mm,
            "force_n": force_n, "hover_mm": None, "nuisances": list(nuisances),
            "prior_sd": priors_in_use(prior_sd, nuisances), "rcond": rcond,
            "null_share": NULL_SHARE, "force_threshold_n": force_threshold_n,
            "near_wire_mm": NEAR_WIRE_MM,
            "readout": readout or ReadoutConfig(), "position": "sqrt(var_u + var_v)",
            "push_columns": push_from,
            "columns": {"u, v, force": "ResponseField.jacobian",
                        "push": ("direct differences with the finger on, at nodes per state, "
                                 "interpolated" if push_from == "finger"
                                 else "untouched state, once per state"),
                        "inflation": "untouched state, once per state",
                        "finger": "gain x finger's signal, fitted per state",
                        "modulus": "direct differences at nodes per state, interpolated"},
        },
        "cases": names,
        "modes": ["contact"],
        "skins": {f: dict(zip(("u_mm", "v_mm"), first.spec.extent(f))) for f in faces},
        "wires": wires,
        "states": states,
        "nuisance_columns": [columns[s].to_dict() for s in fields] if columns and nuisances else [],
        "summary": {"contact": summary},
        "timing": {"points": n_points, "wall_s": time.perf_counter() - t0},
    }
