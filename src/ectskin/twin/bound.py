"""The physical limit: Cramér–Rao bounds of a finger's contact parameters from one frame.

One frame holds the n_pairs readouts C(θ) with independent Gaussian noise of standard deviation
σ per pair (:func:`~ectskin.twin.readout.noise_pf` at the frame's capacitance). The parameters θ
are the finger's point (u, v) on the face (mm) and its force F (N), or its height h above the
skin (mm) for a hovering finger. With the Jacobian J = ∂C/∂θ (n_pairs, n_params) the Fisher
information is FIM = Jᵀ Σ⁻¹ J, Σ = diag(σ²), and no unbiased estimator has a variance below
diag(FIM⁻¹) (the Cramér–Rao bound). The position bound is sqrt(var_u + var_v) mm: a lower bound
of the root-mean-square distance between the estimated and the true point.

Nuisances are parameters the user does not know but that move the readouts too (the hand's
push, the inflation, the person's finger): extra columns of J, estimated alongside. The bound of
the parameters of interest is then their block of the inverse of the full FIM (the Schur
complement removes the nuisances' share of the information); a Gaussian prior of variance s² on
a column adds 1/s² to its diagonal (s = 0: the column is known, as if it were absent).

Unobservable directions (force beyond the wire ends, where it and the hand's push bend the body
alike) make the FIM singular. :func:`crb` scales the FIM to unit diagonal (the units drop out),
takes its eigen-decomposition and clamps eigenvalues below ``rcond`` × the largest at that floor
(:data:`RCOND`). Clamping adds information, so what it returns is still a lower bound; where the
clamped directions hold more than :data:`NULL_SHARE` of a parameter's variance the parameter is
*unresolved*: its bound is reported as inf and its flag is False, never a finite number made up
by the pseudo-inverse.

Readouts come from a response provider (:class:`ResponseProvider`): :class:`TwinResponse` solves
the method of moments directly (:meth:`~ectskin.twin.sensor.SensorModel.capacitance`); a
precomputed response field with the same ``readout`` and ``nuisance_sizes`` plugs in unchanged. Jacobians are central
finite differences with the steps of :data:`FD_STEPS` (one-sided where a nuisance's limit, such
as an empty chamber, forbids a step below).

A fit that leaves something out (:mod:`ectskin.twin.bound_fit`, the maps' ``fit`` case): a
field inversion models the person's finger only as a scale on its signal, not its radius and
pulp, which move the readouts all the same; its error is the bound plus what its model omits.

The maps (:func:`bound_maps`) evaluate the bound over a grid of points of each skin, per
inflation state, with and without each nuisance; ``docs/bound.md`` lists the keys.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout
from ectskin.twin.mechanics import Handling, Touch
from ectskin.twin.readout import ReadoutConfig, noise_pf
from ectskin.twin.sensor import Discretisation, SensorModel

log = logging.getLogger(__name__)

#: eigenvalues of the unit-diagonal FIM below this fraction of the largest are clamped (a
#: singular value of the whitened, column-normalised Jacobian below 1e-5 of the largest, far
#: below what the finite differences resolve): a floor against round-off, not a judgement of
#: observability; a practically unobservable parameter shows as a large finite bound
RCOND = 1e-10
#: a parameter is unresolved when the clamped directions hold more than this share of its variance
NULL_SHARE = 1e-3
#: finite-difference steps, in each parameter's unit (central differences; error O(step²))
FD_STEPS = {
    "u": 0.25,  # mm
    "v": 0.25,  # mm
    "force": 0.05,  # N
    "height": 0.25,  # mm
    "push": 0.1,  # N, each of the hand's loads
    "inflation": 0.5,  # ml, each chamber
    "finger": 0.25,  # mm, the fingertip's radius
    "modulus": 0.1,  # ln of the pulp's modulus (twin.bound_modulus)
}
#: nuisances of :class:`TwinResponse`, in the order their columns are appended; by default the
#: first three (:data:`NUISANCES`), the pulp's modulus on request (docs/bound.md)
NUISANCE_NAMES = ("push", "inflation", "finger", "modulus")
NUISANCES = NUISANCE_NAMES[:3]
#: (assumed) prior SDs: the inflation to ±1 ml per chamber, the fingertip's radius to ±1 mm (adult
#: fingertips), ln of the pulp's modulus to ln 4 / √12 (twin.bound_modulus); the push: none
DEFAULT_PRIOR_SD: dict[str, float] = {"inflation": 1.0, "finger": 1.0,
                                       "modulus": float(np.log(4.0) / np.sqrt(12.0))}
#: (assumed) how the hand may push: at z = 60, 87.5 and 115 mm (the ends and middle of the distal
#: half, where :func:`~ectskin.twin.human.hand_push` pushes; its point is unknown too, and loads at
#: these heights span the bending a push between them makes) a force along x and one along y on
#: the right side (x = +width/2) and one along y on the left: together any push across the axis
#: at that height, from any side (a force (Fx, Fy) and the twist Mz it makes about the axis).
#: Each is (point, world direction) of one nuisance column.
DEFAULT_PUSH_LOADS = tuple(
    (Touch(side, (0.0, z)), axis)
    for z in (60.0, 87.5, 115.0)
    for side, axis in (("right", (1.0, 0.0, 0.0)), ("right", (0.0, 1.0, 0.0)), ("left", (0.0, 1.0, 0.0)))
)
#: a mesh about 4× coarser than the default (readouts within a few %): quick maps
COARSE = Discretisation(
    wire_panel_length_mm=5.0, wire_panels_across=1, pad_panels=2, finger_sphere_n=4,
    finger_shaft_around=8, finger_shaft_along=3, cavity_cell_mm=8.0, cavity_layers=2,
)
#: force bounds below this (N) count as "force observable" in the maps' summaries
FORCE_THRESHOLD_N = 0.1
SCHEMA, VERSION = "ectskin.bound", 1


# ---------------------------------------------------------------------------- the bound
def fisher_information(J: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """FIM = Jᵀ Σ⁻¹ J (n_params, n_params) of readouts with Jacobian ``J`` (n_obs, n_params) and
    independent Gaussian noise of standard deviations ``sigma`` (n_obs,) > 0."""
    J = np.asarray(J, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    if J.ndim != 2 or s.shape != (J.shape[0],):
        raise EctskinError(
            f"fisher_information: expected J (n_obs, n_params) and sigma (n_obs,), got shapes "
            f"{J.shape} and {s.shape}"
        )
    if not (np.all(np.isfinite(s)) and np.all(s > 0) and np.all(np.isfinite(J))):
        raise EctskinError("fisher_information: J must be finite and sigma finite and > 0")
    w = J / s[:, None]
    return w.T @ w


@dataclass(frozen=True)
class Bound:
    """The Cramér–Rao bound of the parameters of interest (k of them, in column order).

    ``std`` (k,): the bound of each (its unit), inf where unresolved; ``cov`` (k, k): their CRB
    block, NaN in unresolved rows and columns; ``resolved`` (k,); ``retained`` (k,): the share of
    each parameter's own information left once the nuisances are estimated, 1 / (FIM_ii var_i),
    0 where unresolved; ``condition``: largest / smallest eigenvalue of the unit-diagonal FIM.
    """

    std: np.ndarray
    cov: np.ndarray
    resolved: np.ndarray
    retained: np.ndarray
    condition: float


def crb(
    J: np.ndarray,
    sigma: np.ndarray,
    *,
    nuisance_cols: Sequence[int] = (),
    prior_var: Mapping[int, float] | None = None,
    rcond: float = RCOND,
) -> Bound:
    """The bound of the columns of ``J`` not in ``nuisance_cols``, the nuisances unknown.

    ``prior_var``: {column: variance} of Gaussian priors (1/variance joins the FIM's diagonal;
    0 makes the column known, inf leaves it without prior). See the module docstring for the
    unresolved case and ``rcond``.
    """
    fim = fisher_information(J, sigma)
    n = fim.shape[0]
    nuis = {int(c) for c in nuisance_cols}
    if not nuis <= set(range(n)):
        raise EctskinError(f"crb: nuisance_cols must be columns 0..{n - 1}, got {list(nuisance_cols)}")
    known = []
    for c, var in (prior_var or {}).items():
        if not 0 <= int(c) < n or not var >= 0:  # (NaN fails too)
            raise EctskinError(f"crb: prior_var needs columns 0..{n - 1} and variances >= 0, got {c}: {var}")
        if var == 0:
            known.append(int(c))
        elif np.isfinite(var):
            fim[c, c] += 1.0 / var
    if known:
        keep = [c for c in range(n) if c not in known]
        std, cov, ok, ret = np.zeros(n), np.zeros((n, n)), np.ones(n, bool), np.ones(n)  # known: 0
        std[keep], cov[np.ix_(keep, keep)], ok[keep], ret[keep], cond = _bound_block(
            fim[np.ix_(keep, keep)], rcond
        )
    else:  # (the same without the indexing: every frame of the live inversion comes here)
        std, cov, ok, ret, cond = _bound_block(fim, rcond)
    i = [c for c in range(n) if c not in nuis]
    return Bound(std[i], cov[np.ix_(i, i)], ok[i], ret[i], cond)


def _bound_block(fim: np.ndarray, rcond: float):
    """(std, cov, resolved, retained, condition) of every column of ``fim`` (module docstring)."""
    n = fim.shape[0]
    if n == 0:
        return np.zeros(0), np.zeros((0, 0)), np.ones(0, bool), np.ones(0), 1.0
    diag = np.diag(fim).copy()
    d = np.sqrt(np.maximum(diag, 0.0))
    live = d > 0  # a column without information has no coupling either (|F_ij| <= d_i d_j)
    std, retained = np.full(n, np.inf), np.zeros(n)
    cov = np.full((n, n), np.nan)
    resolved = np.zeros(n, bool)
    if not live.any():
        return std, cov, resolved, retained, np.inf
    idx = np.flatnonzero(live)
    dl = d[idx]
    lam, V = np.linalg.eigh((fim if live.all() else fim[np.ix_(idx, idx)]) / np.outer(dl, dl))
    floor = rcond * lam[-1]
    null = lam <= floor
    inv = 1.0 / np.where(null, floor, lam)
    cov_s = (V * inv) @ V.T
    var_s = np.diag(cov_s)
    null_part = (V[:, null] ** 2) @ inv[null]
    ok = null_part <= NULL_SHARE * var_s
    cond = float(lam[-1] / lam[0]) if lam[0] > 0 else np.inf
    good = idx[ok]
    sub = np.flatnonzero(ok)
    if good.size == n:  # (every column resolved: the same without the indexing)
        cov = cov_s / np.outer(dl, dl)
    else:
        cov[np.ix_(good, good)] = cov_s[np.ix_(sub, sub)] / np.outer(dl[sub], dl[sub])
    std[good] = np.sqrt(var_s[sub]) / dl[sub]
    retained[good] = 1.0 / var_s[sub]  # 1 / (F_ii var_i) in scaled units
    resolved[good] = True
    return std, cov, resolved, retained, cond


# ---------------------------------------------------------------------------- providers
class ResponseProvider(Protocol):
    """Anything that gives a finger's readouts at one inflation state.

    ``readout(face, uv (n, 2) mm, force (n,) N, height (n,) mm, nuisances)`` → (n, n_pairs) pF.
    A row with height > 0 hovers (force 0). ``nuisances``: {name: (n, k) offsets from the
    nominal state}, names and k from ``nuisance_sizes`` (a provider without nuisances has {}).
    An optional ``nuisance_limits(name) -> (low (k,), high (k,))`` bounds the offsets.
    """

    @property
    def nuisance_sizes(self) -> Mapping[str, int]: ...

    def readout(
        self,
        face: str,
        uv: np.ndarray,
        force: np.ndarray,
        height: np.ndarray,
        nuisances: Mapping[str, np.ndarray] | None = None,
    ) -> np.ndarray: ...


class TwinResponse:
    """:class:`ResponseProvider` over direct method-of-moments solves of ``sensor`` at one state.

    Nuisance offsets: ``push`` (n, P): the hand's force (N) of each of the P ``push_loads``
    (point, world direction) (a :class:`~ectskin.twin.mechanics.Handling` load; a Handling holds
    one point, so a row may load one of them); ``inflation`` (n, n_chambers) ml added to
    ``inflation_ml``; ``finger`` (n, 1) mm added to the fingertip's radius and ``modulus`` (n, 1)
    to the log of its pulp's modulus (E0 e^x) (a sensor with the replaced
    :class:`~ectskin.twin.sensor.Finger`, sharing the manipulator). Rows that share a point,
    inflation, finger and push load are solved in one call.
    """

    def __init__(
        self,
        sensor: SensorModel,
        inflation_ml,
        push_loads: Sequence[tuple[Touch, tuple[float, float, float]]] = DEFAULT_PUSH_LOADS,
    ):
        self.sensor = sensor
        self.inflation_ml = sensor.manipulator.check_inflation(inflation_ml)
        self.push_loads = tuple((t, np.asarray(d, dtype=np.float64)) for t, d in push_loads)
        self.nuisance_sizes = {"push": len(self.push_loads), "inflation": self.inflation_ml.size,
                               "finger": 1, "modulus": 1}
        self._fingers: dict[tuple[float, float], SensorModel] = {(0.0, 0.0): sensor}
        self._untouched: np.ndarray | None = None

    def nuisance_limits(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        check_option("nuisance", name, tuple(self.nuisance_sizes))
        if name == "inflation":
            cap = self.sensor.manipulator.config.max_volume_ml
            return -self.inflation_ml, cap - self.inflation_ml
        if name == "finger":
            return np.array([-0.5 * self.sensor.finger.radius_mm]), np.array([np.inf])
        m = self.nuisance_sizes[name]
        return np.full(m, -np.inf), np.full(m, np.inf)

    def untouched(self) -> np.ndarray:
        """(n_pairs,) the readout at this state without a finger or a push (cached)."""
        if self._untouched is None:
            self._untouched = self.sensor.capacitance(self.inflation_ml, None)[0]
        return self._untouched

    def _with_finger(self, offset_mm: float, log_modulus: float) -> SensorModel:
        key = (offset_mm, log_modulus)
        if key not in self._fingers:
            s, f = self.sensor, self.sensor.finger
            finger = replace(f, radius_mm=f.radius_mm + offset_mm,
                             pulp_modulus_mpa=f.pulp_modulus_mpa * float(np.exp(log_modulus)))
            self._fingers[key] = SensorModel(
                s.layout, s.manipulator, s.discretisation, s.eps_r, finger, s.chamber_eps_r)
        return self._fingers[key]

    def readout(self, face, uv, force, height, nuisances=None) -> np.ndarray:
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        n = uv.shape[0]
        force = np.broadcast_to(np.asarray(force, dtype=np.float64), (n,))
        height = np.broadcast_to(np.asarray(height, dtype=np.float64), (n,))
        if np.any((height > 0) & (force != 0)):
            raise EctskinError("readout: a hovering row (height > 0) must have force 0")
        nuis = {k: np.zeros((n, m)) for k, m in self.nuisance_sizes.items()}
        for k, v in (nuisances or {}).items():
            check_option("nuisance", k, tuple(self.nuisance_sizes))
            nuis[k] = np.broadcast_to(np.asarray(v, dtype=np.float64), (n, self.nuisance_sizes[k]))
        push = nuis["push"]
        loaded = push != 0  # (n, P)
        if np.any(loaded.sum(axis=1) > 1):
            raise EctskinError("readout: a row may load one of the push loads only")
        at = np.where(loaded.any(axis=1), loaded.argmax(axis=1), 0)
        groups: dict[tuple, list[int]] = {}
        for i in range(n):
            key = (*uv[i], *nuis["inflation"][i], nuis["finger"][i, 0], nuis["modulus"][i, 0],
                   at[i])
            groups.setdefault(key, []).append(i)
        out = np.empty((n, self.sensor.layout.n_pairs))
        for key, rows in groups.items():
            p = int(key[-1])
            handling = None
            if self.push_loads:
                point, direction = self.push_loads[p]
                force_n = push[rows, p][:, None] * direction[None, :]
                handling = Handling(push=point, push_force_n=force_n)
            out[rows] = self._with_finger(float(key[-3]), float(key[-2])).capacitance(
                self.inflation_ml + np.asarray(key[2:-3]),
                Touch(face, (float(key[0]), float(key[1]))),
                force[rows],
                handling,
                heights_mm=height[rows],
            )
        return out


# ---------------------------------------------------------------------------- the Jacobian
def _columns(provider: ResponseProvider, nuisances: Sequence[str]) -> dict[str, slice]:
    """Each nuisance's columns of J, after u, v and force (or height)."""
    out, start = {}, 3
    for k in nuisances:
        check_option("nuisance", k, tuple(provider.nuisance_sizes))
        out[k] = slice(start, start + provider.nuisance_sizes[k])
        start = out[k].stop
    return out


def param_names(provider: ResponseProvider, nuisances: Sequence[str], hover: bool) -> list[str]:
    """Column names: u, v, force (or height), then each nuisance's components (push_1 …)."""
    names = ["u", "v", "height" if hover else "force"]
    for k, sl in _columns(provider, nuisances).items():
        m = sl.stop - sl.start
        names += [k] if m == 1 else [f"{k}_{i + 1}" for i in range(m)]
    return names


def _stencil(x0: float, h: float, lo: float, hi: float) -> tuple[float, float]:
    """Offsets (a, b) of a first derivative (C(x0 + a) − C(x0 + b)) / (a − b) with step ``h``
    inside [lo, hi]: central (h, −h), else forward (h, 0) or backward (0, −h) (error O(h))."""
    if x0 - h >= lo and x0 + h <= hi:
        return h, -h
    if x0 + h <= hi:
        return h, 0.0
    if x0 - h >= lo:
        return 0.0, -h
    raise EctskinError(f"finite differences: no room for a step of {h} in [{lo}, {hi}] at {x0}")


def finite_difference_jacobian(
    provider: ResponseProvider,
    face: str,
    uv,
    *,
    force_n: float = 1.0,
    height_mm: float = 0.0,
    nuisances: Sequence[str] = (),
    steps: Mapping[str, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Readout C (n_pairs,), Jacobian J (n_pairs, n_params) and column names at one point.

    Parameters (u, v, then force for a contact or height for ``height_mm`` > 0, then each
    nuisance's components), differentiated by the stencils of :func:`_stencil` with ``steps``
    (:data:`FD_STEPS` by default); every row is asked of ``provider.readout`` in one call.
    """
    st = {**FD_STEPS, **(steps or {})}
    hover = height_mm > 0
    cols = _columns(provider, nuisances)
    n = 3 + sum(sl.stop - sl.start for sl in cols.values())
    base = np.zeros(n)
    base[:3] = *np.asarray(uv, float), (height_mm if hover else force_n)
    step = np.empty(n)
    step[:3] = st["u"], st["v"], st["height" if hover else "force"]
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    lo[2] = 1e-6 if hover else 0.0  # a hovering row at height 0 would be a contact
    for k, sl in cols.items():
        step[sl] = st[k]
        if hasattr(provider, "nuisance_limits"):
            lo[sl], hi[sl] = provider.nuisance_limits(k)
    rows, pairs = [base], []
    for j in range(n):
        ends = []
        for o in _stencil(base[j], step[j], lo[j], hi[j]):
            ends.append(len(rows) if o else 0)  # a zero offset is the base row
            if o:
                rows.append(base + o * np.eye(n)[j])
        pairs.append(ends)
    x = np.array(rows)
    zero = np.zeros(len(x))
    c = provider.readout(
        face, x[:, :2], zero if hover else x[:, 2], x[:, 2] if hover else zero,
        {k: x[:, sl] for k, sl in cols.items()},
    )
    J = np.empty((c.shape[1], n))
    for j, (a, b) in enumerate(pairs):
        J[:, j] = (c[a] - c[b]) / (x[a, j] - x[b, j])
    return c[0], J, param_names(provider, nuisances, hover)


# ---------------------------------------------------------------------------- one point
class FitLike(Protocol):
    """A fit whose error the maps' ``fit`` case reports (:class:`ectskin.twin.bound_fit.FitModel`):
    the nuisances its Jacobian needs beyond ``nuisances``, and its error at one point."""

    def jacobian_nuisances(self, nuisances: Sequence[str]) -> list[str]: ...

    def settings(self) -> dict[str, Any]: ...

    def error(self, provider: ResponseProvider, c: np.ndarray, J: np.ndarray,
              cols: Mapping[str, slice], sigma: np.ndarray, prior: Mapping[str, float | None],
              rcond: float = ...) -> tuple[float, float]: ...


def priors_in_use(prior_sd: Mapping[str, float] | None, nuisances: Sequence[str]) -> dict:
    """The prior SDs (``prior_sd``, else :data:`DEFAULT_PRIOR_SD`) of ``nuisances`` only."""
    return {k: v for k, v in (DEFAULT_PRIOR_SD if prior_sd is None else prior_sd).items()
            if k in nuisances}


def cases(nuisances: Sequence[str], fit: FitLike | None = None) -> list[str]:
    """The bound's cases: no nuisance, each alone, all together (with two or more), then ``fit``
    (the error of that fit, :class:`FitLike`) when one is given."""
    return ["none", *nuisances] + (["all"] if len(nuisances) > 1 else []) + (["fit"] if fit else [])


def point_bounds(
    provider: ResponseProvider,
    face: str,
    uv,
    *,
    force_n: float = 1.0,
    height_mm: float = 0.0,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
    readout: ReadoutConfig | None = None,
    steps: Mapping[str, float] | None = None,
    rcond: float = RCOND,
    jacobian: Callable[..., tuple[np.ndarray, np.ndarray, list[str]]] | None = None,
    fit: FitLike | None = None,
) -> dict[str, tuple[float, float]]:
    """{case: (position bound sqrt(var_u + var_v) mm, force bound N or height bound mm)} at one
    point, for each case of :func:`cases` (inf: unresolved); with ``fit``, its ``fit`` case is
    the error of that fit (``fit.error``) from the same Jacobian.

    One Jacobian with every nuisance's columns (``jacobian``: a function with the signature of
    :func:`finite_difference_jacobian`, which is the default); a case estimates its nuisances
    (with ``prior_sd``: {nuisance: prior standard deviation in its unit}, :data:`DEFAULT_PRIOR_SD`
    when None) and holds the others known. The noise is ``noise_pf`` at the point's readout.
    """
    every = list(nuisances) if fit is None else fit.jacobian_nuisances(nuisances)
    cols = _columns(provider, every)
    prior = DEFAULT_PRIOR_SD if prior_sd is None else prior_sd
    c, J, _ = (jacobian or finite_difference_jacobian)(
        provider, face, uv, force_n=force_n, height_mm=height_mm, nuisances=every, steps=steps
    )
    sigma = noise_pf(c, readout or ReadoutConfig())
    out = {}
    if fit is not None:
        out["fit"] = fit.error(provider, c, J, cols, sigma, prior, rcond)
    for case in cases(nuisances):
        active = list(nuisances) if case == "all" else [] if case == "none" else [case]
        use = [0, 1, 2] + [i for k in active for i in range(cols[k].start, cols[k].stop)]
        var = {
            use.index(i): float(prior[k]) ** 2 for k in active if prior.get(k) is not None
            for i in range(cols[k].start, cols[k].stop)
        }
        b = crb(J[:, use], sigma, nuisance_cols=range(3, len(use)), prior_var=var, rcond=rcond)
        out[case] = (float(np.hypot(b.std[0], b.std[1])), float(b.std[2]))
    return {case: out[case] for case in cases(nuisances, fit)}


def _map_task(key, provider, face: str, points: np.ndarray, options: dict) -> tuple:
    """Bounds (m, n_cases, 2) at ``points`` (m, 2), and the task's seconds (one BLAS thread)."""
    t0 = time.perf_counter()
    with threadpool_limits(1):
        res = [point_bounds(provider, face, p, **options) for p in points]
    names = cases(options["nuisances"], options.get("fit"))
    return np.array([[r[c] for c in names] for r in res]), time.perf_counter() - t0


# ---------------------------------------------------------------------------- the maps
def skin_grid(layout: SensorLayout, face: str, spacing_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres (u (nu,), v (nv,)) mm of cells about ``spacing_mm`` wide tiling ``face``'s skin."""
    skin = next((s for s in layout.skins if s.surface == face), None)
    if skin is None:
        raise EctskinError(
            f"face {face!r}: the layout has no skin there (skins on "
            f"{sorted({s.surface for s in layout.skins})})"
        )
    out = []
    for lo, hi in (skin.u_mm, skin.v_mm):
        m = max(1, int(round((hi - lo) / spacing_mm)))
        out.append(lo + (np.arange(m) + 0.5) * (hi - lo) / m)
    return out[0], out[1]


def _stats(x: np.ndarray) -> dict[str, float]:
    """mean (inf if any point is unresolved), median and 95th percentile."""
    big = 1e300
    finite = np.isfinite(x)
    q = np.percentile(np.where(finite, x, big), [50, 95])
    # a quantile between the largest finite bound and an unresolved point is unresolved too (the
    # interpolation would give a huge finite number: 8.5e299 mm was seen)
    top = x[finite].max() if finite.any() else -np.inf
    q = np.where(q > top, np.inf, q)
    return {"mean": float(np.mean(x)), "median": float(q[0]), "p95": float(q[1])}


def _summary(pos: np.ndarray, third: np.ndarray, mode: str, threshold: float) -> dict[str, Any]:
    name = "force_n" if mode == "contact" else "height_mm"
    out: dict[str, Any] = {"position_mm": _stats(pos), name: _stats(third)}
    if mode == "contact":
        out["force_observable_share"] = float(np.mean(third < threshold))
    out["resolved_share"] = float(np.mean(np.isfinite(pos) & np.isfinite(third)))
    return out


def bound_maps(
    states: Mapping[tuple[float, ...], ResponseProvider],
    layout: SensorLayout,
    *,
    faces: Sequence[str] | None = None,
    spacing_mm: float = 10.0,
    force_n: float = 1.0,
    hover_mm: float | None = None,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
    readout: ReadoutConfig | None = None,
    steps: Mapping[str, float] | None = None,
    rcond: float = RCOND,
    force_threshold_n: float = FORCE_THRESHOLD_N,
    jacobian: Callable[..., tuple[np.ndarray, np.ndarray, list[str]]] | None = None,
    runner: Any = None,
    points_per_task: int = 4,
    progress: bool = False,
    fit: FitLike | None = None,
) -> dict[str, Any]:
    """Bound maps over a grid of each face's skin (:func:`skin_grid`), per inflation state.

    ``states``: {inflation (ml per chamber): its provider}. Per state, face, mode ("contact" at
    ``force_n``; "hover" at ``hover_mm`` if given) and case (:func:`cases`): the position bound
    (mm) and the force (N) or height (mm) bound at every grid point, and their summary.
    ``runner``: anything with ``stream(fn, next_job)`` (:mod:`ectskin.design.cluster`'s runners);
    None runs here, in order. Returns a JSON-ready dict (``docs/bound.md``; inf → null when
    written); the plot is :func:`ectskin.viz.bound.plot_bound_maps`.
    """
    if not (np.isfinite(spacing_mm) and spacing_mm > 0):
        raise EctskinError(f"spacing_mm must be a finite number > 0, got {spacing_mm!r}")
    if not force_n > FD_STEPS["force"]:
        raise EctskinError(f"force_n must be > {FD_STEPS['force']} N, got {force_n!r}")
    if hover_mm is not None and not hover_mm > FD_STEPS["height"]:
        raise EctskinError(f"hover_mm must be > {FD_STEPS['height']} mm, got {hover_mm!r}")
    faces = list(faces) if faces is not None else list(dict.fromkeys(s.surface for s in layout.skins))
    modes = {"contact": (force_n, 0.0)} | ({} if hover_mm is None else {"hover": (0.0, hover_mm)})
    every = list(nuisances) if fit is None else fit.jacobian_nuisances(nuisances)
    for provider in states.values():
        _columns(provider, every)  # unknown nuisances fail here, not in the workers
    names = cases(nuisances, fit)
    grids = {f: skin_grid(layout, f, spacing_mm) for f in faces}
    base = dict(nuisances=tuple(nuisances), prior_sd=prior_sd, readout=readout, steps=steps,
                rcond=rcond, jacobian=jacobian, fit=fit)
    results: dict[tuple, np.ndarray] = {}
    jobs = []
    for si, provider in enumerate(states.values()):
        for face, (u, v) in grids.items():
            U, V = np.meshgrid(u, v)
            pts = np.c_[U.ravel(), V.ravel()]
            for mode, (f, h) in modes.items():
                results[(si, face, mode)] = np.empty((len(pts), len(names), 2))
                opts = dict(base, force_n=f, height_mm=h)
                for lo in range(0, len(pts), points_per_task):
                    key = (si, face, mode, lo)
                    jobs.append((key, provider, face, pts[lo : lo + points_per_task], opts))
    n_points = sum(len(r) for r in results.values())
    log.info("bound maps: %d points in %d tasks", n_points, len(jobs))
    t0, busy = time.perf_counter(), 0.0
    it = iter(jobs)
    if runner is None:
        stream: Any = ((job, _map_task(*job)) for job in jobs)
    else:
        stream = runner.stream(_map_task, lambda: next(it, None))
    with tqdm(total=len(jobs), desc="bound", unit="task", disable=not progress) as bar:
        for job, (res, seconds) in stream:
            si, face, mode, lo = job[0]
            results[(si, face, mode)][lo : lo + len(res)] = res
            busy += seconds
            bar.update(1)
    wall = time.perf_counter() - t0
    out_states = []
    pooled: dict[tuple, list[np.ndarray]] = {}
    for si, inflation in enumerate(states):
        per_face: dict[str, Any] = {}
        for face, (u, v) in grids.items():
            entry: dict[str, Any] = {"u_mm": u, "v_mm": v}
            for mode in modes:
                third = "force_n" if mode == "contact" else "height_mm"
                r = results[(si, face, mode)].reshape(len(v), len(u), len(names), 2)
                entry[mode] = {}
                for ci, case in enumerate(names):
                    pos, thr = r[:, :, ci, 0], r[:, :, ci, 1]
                    pooled.setdefault((mode, case), []).append(np.stack([pos.ravel(), thr.ravel()]))
                    entry[mode][case] = {
                        "position_mm": pos, third: thr,
                        "summary": _summary(pos, thr, mode, force_threshold_n),
                    }
            per_face[face] = entry
        out_states.append({"inflation_ml": [float(x) for x in inflation], "faces": per_face})
    summary: dict[str, Any] = {m: {} for m in modes}
    for (mode, case), parts in pooled.items():
        a = np.concatenate(parts, axis=1)
        summary[mode][case] = _summary(a[0], a[1], mode, force_threshold_n)
    return {
        "schema": SCHEMA,
        "version": VERSION,
        "layout": layout.name,
        "settings": {
            "faces": faces, "spacing_mm": spacing_mm, "force_n": force_n, "hover_mm": hover_mm,
            "nuisances": list(nuisances),
            "prior_sd": priors_in_use(prior_sd, every),
            "fit": None if fit is None else fit.settings(),
            "steps": {**FD_STEPS, **(steps or {})}, "rcond": rcond, "null_share": NULL_SHARE,
            "force_threshold_n": force_threshold_n,
            "readout": readout or ReadoutConfig(),
            "position": "sqrt(var_u + var_v)",
        },
        "cases": names,
        "modes": list(modes),
        "skins": {s.surface: {"u_mm": s.u_mm, "v_mm": s.v_mm} for s in layout.skins},
        "wires": {
            f: [e.polyline_mm for k, e in enumerate(layout.electrodes)
                if layout.electrode_surface(k) == f]
            for f in faces
        },
        "states": out_states,
        "summary": summary,
        "timing": {"points": n_points, "wall_s": wall, "task_s_per_point": busy / max(n_points, 1)},
    }
