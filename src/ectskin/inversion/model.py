"""The forward model of the inversion: one frame's readouts as a function of the fingers.

For one sensor state (an inflation vector) a frame's n_pairs readouts y (pF) are modelled as

    y = c_u + Σ_k Δ(face_k, mode_k; u_k, v_k, s_k) + N β + e,   e ~ N(0, diag σ²)

* c_u (n_pairs,): the untouched readout of the state (``field.untouched``, or the skin's own
  measured untouched readout of the state where one is given: the twin's or a real skin's body
  differs from the field's mesh by far more than the noise, and Δ stays the field's);
* Δ: one finger's signal, the response field's readout less c_u. ``mode`` is "contact" (the
  finger presses, s = its force F in N) or "hover" (force 0, s = ln h of its height h in mm: the
  field interpolates in ln h, so the fit does too; above the field's top height the top's
  pattern shrinking at its own rate, :mod:`ectskin.inversion.far`). Two fingers add their
  signals and a coupling (:mod:`ectskin.inversion.coupling`: the twin's two fingers are one
  grounded conductor);
* N (n_pairs, m): linear nuisance columns, β their unknown coefficients: the hand's push (a
  per-state basis from direct solves, :func:`push_basis`) and the readout's drift, a common
  gain (the column c_u: the excitation, the amplifier's gain and the permittivity's temperature
  coefficient scale every channel alike) and a common offset (a column of ones: a stray
  capacitance shared through the readout's ground path);
* σ: the readout noise per pair (:func:`ectskin.twin.readout.noise_pf`), divided by √w for a
  window of w frames averaged.

:class:`StateModel` holds this for one state: Δ and ∂Δ/∂(u, v, s) of each face and mode, the
nuisance columns and the node table of the coarse search (every node's Δ, whitened by the
untouched state's σ and projected off the nuisance columns, so that the distance of a frame to
every node is one matrix-vector product).

Fields: a :class:`~ectskin.twin.field.ResponseField` is evaluated through tensor-product
B-splines built from its public node values with the field's own construction
(:mod:`ectskin.inversion.spline`: identical values, checked by the tests, without the field's
per-call checks, which cost more than the evaluation); any other object with the field's interface
(:class:`~ectskin.inversion.field_like.FieldLike`) through its ``readout`` and ``jacobian``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError
from ectskin.inversion.coupling import correction, electrode_pairs, rank_one
from ectskin.inversion.far import HOVER_REACH, far_factor, far_nodes, far_signal
from ectskin.inversion.field_like import FieldLike
from ectskin.inversion.spline import Signal, tensor_spline
from ectskin.twin.bound import DEFAULT_PUSH_LOADS
from ectskin.twin.field import ResponseField
from ectskin.twin.mechanics import Handling, Touch
from ectskin.twin.readout import ReadoutConfig, noise_pf

#: the modes of one finger: pressing (s = force, N) or hovering (s = ln height, ln mm)
MODES = ("contact", "hover")
#: about how many nodes the two-finger coarse search pairs (every pair of them: a Gram matrix of
#: this size squared, precomputed per state)
PAIR_NODES = 300
#: the two-finger coarse search scales each node's signal by its best factor (:meth:`NodeTable.
#: pairs`): the least factor of a finger, and the ridge (whitened units², one noise variance)
#: that keeps the factor of a signal too small to tell near 1
PAIR_SCALE_MIN = 0.3
PAIR_SCALE_RIDGE = 1.0
#: the drift columns there are
DRIFT_TERMS = ("gain", "offset")


# ---------------------------------------------------------------------------- one finger's signal
#: a pressing finger's nuisance column (:mod:`ectskin.inversion.finger_nuisance`): face, (u, v, F)
#: → (M (n_pairs,), ∂M/∂(u, v, F) (n_pairs, 3))
FingerColumn = Callable[[str, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _restricted(signal: Signal, ok: np.ndarray) -> Signal:
    """``signal`` on the channels where ``ok``."""

    def sub(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, J = signal(p)
        return d[ok], J[ok]

    return sub


def field_axes(field: FieldLike, face: str, mode: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """The node axes of ``field`` on ``face`` in ``mode``: u, v, s (forces, or ln heights) and
    the range [lo, hi] of s."""
    u, v = field.grid(face)
    if mode == "contact":
        lo, hi = (float(a) for a in field.spec.force_range_n)
        return u, v, np.asarray(field.forces_n, dtype=np.float64), lo, hi
    lo, hi = (float(a) for a in np.log(field.spec.height_range_mm))
    return u, v, np.log(np.asarray(field.heights_mm, dtype=np.float64)), lo, hi


def spline_signal(field: ResponseField, face: str, mode: str) -> Signal:
    """Δ of ``field`` on ``face`` in ``mode`` by the field's interpolant, rebuilt from its node
    values: cubic not-a-knot in u and v, the polynomial through the force (ln height) nodes."""
    u, v, x, lo, hi = field_axes(field, face, mode)
    values = np.asarray(field.node_values(face, mode), dtype=np.float64) - field.untouched
    return tensor_spline(u, v, x, lo, hi, values)


def generic_signal(field: FieldLike, face: str, mode: str) -> Signal:
    """Δ of any :class:`FieldLike` through its ``readout`` and ``jacobian`` (hovering, the
    height column times h is the derivative in ln h)."""
    c_u = np.asarray(field.untouched, dtype=np.float64)

    def signal(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u, v, s = (float(a) for a in p)
        if mode == "contact":
            d = np.asarray(field.readout(face, u, v, s, 0.0)) - c_u
            J = np.asarray(field.jacobian(face, u, v, s, 0.0))[:, :3]
        else:
            h = float(np.exp(s))
            d = np.asarray(field.readout(face, u, v, 0.0, h)) - c_u
            J4 = np.asarray(field.jacobian(face, u, v, 0.0, h))
            J = np.stack([J4[:, 0], J4[:, 1], J4[:, 3] * h], axis=-1)
        return d, J

    return signal


# ---------------------------------------------------------------------------- nuisances
def push_basis(
    field: ResponseField,
    loads: Sequence[tuple[Touch, tuple[float, float, float]]] = DEFAULT_PUSH_LOADS,
    *,
    step_n: float = 0.2,
    rank: int | None = 3,
    noise: ReadoutConfig | None = None,
) -> np.ndarray:
    """(n_pairs, r) columns that span how the hand's push moves the untouched readouts.

    One direct solve pair per load (``SensorModel.capacitance`` with a
    :class:`~ectskin.twin.mechanics.Handling` push of ±``step_n`` N along the load's direction,
    :data:`~ectskin.twin.bound.DEFAULT_PUSH_LOADS` by default): central differences, pF per N.
    The push bends the whole body, so its effect on the readouts has few independent directions:
    ``rank`` keeps the leading ``rank`` left singular vectors of the noise-whitened columns (scaled
    back to pF, each carrying its singular value), ``None`` keeps every load's column.
    """
    if not (np.isfinite(step_n) and step_n > 0):
        raise EctskinError(f"push_basis: step_n must be a force > 0 N, got {step_n!r}")
    spec = field.spec
    sensor = spec.sensor()
    cols = []
    for point, direction in loads:
        d = np.asarray(direction, dtype=np.float64)
        h = Handling(push=point, push_force_n=np.stack([step_n * d, -step_n * d]))
        c = sensor.capacitance(spec.inflation_ml, None, np.zeros(2), h)
        cols.append((c[0] - c[1]) / (2 * step_n))
    P = np.stack(cols, axis=1)
    if rank is None:
        return P
    if not (isinstance(rank, int) and 1 <= rank <= P.shape[1]):
        raise EctskinError(f"push_basis: rank must be 1..{P.shape[1]} or None, got {rank!r}")
    sigma = noise_pf(field.untouched, noise or ReadoutConfig())
    U, S, _ = np.linalg.svd(P / sigma[:, None], full_matrices=False)
    return (U[:, :rank] * S[:rank]) * sigma[:, None]


def nuisance_columns(
    untouched: np.ndarray, drift: Sequence[str], extra: np.ndarray | None
) -> tuple[np.ndarray, list[str]]:
    """(n_pairs, m) nuisance columns and their names: ``extra`` (push_1 …), then the drift's."""
    p = untouched.size
    cols, names = [], []
    if extra is not None:
        for i in range(extra.shape[1]):
            cols.append(extra[:, i])
            names.append(f"push_{i + 1}")
    for term in drift:
        if term not in DRIFT_TERMS:
            raise EctskinError(
                f"Invalid value for 'drift': allowed terms are {list(DRIFT_TERMS)}; got {term!r}"
            )
        cols.append(untouched.copy() if term == "gain" else np.ones(p))
        names.append(term)
    N = np.stack(cols, axis=1) if cols else np.zeros((p, 0))
    return N, names


# ---------------------------------------------------------------------------- one state
@dataclass
class NodeTable:
    """The coarse search's table of one state: every node's whitened, projected Δ.

    ``D`` (n_nodes, n_pairs): P⊥ (Δ_node / σ_u); ``norm2`` (n_nodes,): its squared norms;
    ``face`` / ``mode`` (n_nodes,) int: indices into the state's faces and :data:`MODES`;
    ``x`` (n_nodes, 3): the node's (u, v, s); ``Q`` (n_pairs, r): an orthonormal basis of the
    whitened nuisance columns (P⊥ = I − Q Qᵀ); ``sigma`` (n_pairs,): σ_u, the untouched noise;
    ``groups``: the (start, stop) rows of each (face, mode);
    ``pair_rows`` (n_sub,): the nodes of the two-finger search (the middle s of every
    ``stride``-th grid point, at most about :data:`PAIR_NODES`); ``gram`` (n_sub, n_sub):
    2 d_i·d_j of those for i < j, +inf elsewhere; ``pair_solve``: the scaled search's 2 × 2
    inverses (:meth:`pairs`), built at its first use.
    """

    D: np.ndarray
    norm2: np.ndarray
    face: np.ndarray
    mode: np.ndarray
    x: np.ndarray
    Q: np.ndarray
    sigma: np.ndarray
    groups: list[tuple[int, int]]
    pair_rows: np.ndarray
    gram: np.ndarray
    pair_solve: tuple[np.ndarray, ...] | None = None

    def project(self, z: np.ndarray) -> np.ndarray:
        return z - self.Q @ (self.Q.T @ z)

    def cost(self, target: np.ndarray, scale_w: float = 0.0) -> np.ndarray:
        """(n_nodes,) the squared whitened, projected distance of ``target`` (n_pairs,) pF (a
        finger's signal: the untouched readout and any known fingers taken off) to every node,
        less the constant ||P⊥ target / σ||².

        ``scale_w`` > 0 (1/sd of the finger scale's prior): each node's signal d is scaled by
        its best g, min over g of ||z − g d||² + w² (g − 1)², g = (d·z + w²) / (||d||² + w²)."""
        z = self.project(target / self.sigma)
        dz = self.D @ z
        if scale_w <= 0:
            return self.norm2 - 2.0 * dz
        w2 = scale_w**2
        g = (dz + w2) / (self.norm2 + w2)
        return g * g * self.norm2 - 2.0 * g * dz + w2 * (g - 1.0) ** 2

    def pairs(self, target: np.ndarray, n: int, scaled: bool = False) -> list[tuple[int, int]]:
        """The ``n`` best pairs of nodes (i, j) for a frame of two fingers, best first, searched
        over every pair of the pair subset (``pair_rows``):
        ||z − d_i − d_j||² = ||z||² + a_i + a_j + 2 d_i·d_j with a_i = ||d_i||² − 2 d_i·z, the
        products d_i·d_j precomputed (``gram``).

        ``scaled``: each node's signal scaled by its best factor instead, min over (a, b) of
        ||z − a d_i − b d_j||² + w² ((a − 1)² + (b − 1)²), w² = :data:`PAIR_SCALE_RIDGE`: a
        2 × 2 linear solve per pair from the same products. The subset holds one force (height)
        per point, the middle one, and two fingers screen each other (each one's signal is less
        than alone), so the size of each node's signal is left to the fit; a pair whose best
        factor is below :data:`PAIR_SCALE_MIN` is not a pair of fingers (one of them is not
        there) and is left out."""
        z = self.project(target / self.sigma)
        rows = self.pair_rows
        p = self.D[rows] @ z
        if not scaled:
            a = self.norm2[rows] - 2.0 * p
            cost = a[:, None] + a[None, :] + self.gram  # the lower triangle is +inf in ``gram``
            flat = np.argpartition(cost, n - 1, axis=None)[:n]
            flat = flat[np.argsort(cost.ravel()[flat])]
            m = cost.shape[1]
            return [(int(rows[f // m]), int(rows[f % m])) for f in flat]
        i, j, h11, h12, h22 = self._pair_solve()
        p = p + PAIR_SCALE_RIDGE
        pi, pj = p[i], p[j]
        fa = h11 * pi + h12 * pj  # the factors (a, b): the 2 × 2 inverse times (p_i, p_j) + w²
        fb = h12 * pi + h22 * pj
        ok = (fa >= PAIR_SCALE_MIN) & (fb >= PAIR_SCALE_MIN)
        cost = np.where(ok, -(fa * pi + fb * pj), np.inf)  # less ||z||² + 2 w²
        n = min(n, int(ok.sum())) or 1
        flat = np.argpartition(cost, n - 1)[:n]
        flat = flat[np.argsort(cost[flat])]
        return [(int(rows[i[f]]), int(rows[j[f]])) for f in flat]

    def _pair_solve(self) -> tuple[np.ndarray, ...]:
        """Each pair i < j of the subset (positions in ``pair_rows``, only pairs whose 2 × 2
        system is regular) and the inverse of its matrix [[g_i, c], [c, g_j]] (g: ||d||² + w²,
        c = d_i·d_j): built at the first scaled search, it does not depend on the frame."""
        if self.pair_solve is None:
            g = self.norm2[self.pair_rows] + PAIR_SCALE_RIDGE
            i, j = np.triu_indices(len(self.pair_rows), 1)
            c = 0.5 * self.gram[i, j]
            det = g[i] * g[j] - c * c
            ok = det > 0
            i, j, c, det = i[ok], j[ok], c[ok], det[ok]
            self.pair_solve = (i, j, g[j] / det, -c / det, g[i] / det)
        return self.pair_solve

    def starts(self, target: np.ndarray, n: int, scale_w: float = 0.0) -> list[int]:
        """The nearest node of each (face, mode) group, best first, at most ``n`` of them
        (``scale_w``: as :meth:`cost`)."""
        cost = self.cost(target, scale_w)
        best = [lo + int(np.argmin(cost[lo:hi])) for lo, hi in self.groups]
        best.sort(key=lambda i: cost[i])
        return best[:n]


class StateModel:
    """The forward model of one state (module docstring) and its coarse-search table.

    Parameters
    ----------
    field : the state's response field (or any :class:`FieldLike`).
    nuisance : (n_pairs, m) extra nuisance columns (the push basis) or None.
    drift : drift terms among :data:`DRIFT_TERMS`.
    noise : the readout's noise model.
    untouched : (n_pairs,) pF, the state's untouched readout as measured (c_u, and the gain's
        column), or None: the field's. The fingers' signals Δ are the field's either way.
    """

    def __init__(
        self,
        field: FieldLike,
        nuisance: np.ndarray | None,
        drift: Sequence[str],
        noise: ReadoutConfig,
        untouched: np.ndarray | None = None,
    ) -> None:
        self.field = field
        self.faces: tuple[str, ...] = tuple(field.faces)
        self.n_pairs = int(field.n_pairs)
        #: the field's channels this model covers (all; fewer in a :meth:`masked` copy)
        self.channels = np.arange(self.n_pairs)
        self._masked: dict[bytes, StateModel] = {}
        #: the field's own untouched readout: the base of its signals Δ
        self.field_untouched = np.asarray(field.untouched, dtype=np.float64)
        #: c_u: the untouched readout the frames are compared with
        self.untouched = (self.field_untouched.copy() if untouched is None
                          else np.asarray(untouched, dtype=np.float64).copy())
        self.noise = noise
        self.N, self.nuisance_names = nuisance_columns(self.untouched, drift, nuisance)
        #: 1/sd of a Gaussian prior on each nuisance coefficient, 0 for none (set by Inversion)
        self.prior_w = np.zeros(self.N.shape[1])
        #: 1/sd of the prior on each finger's relative signal scale, 0 for no scale (set by
        #: Inversion: ``finger_scale_sd``)
        self.scale_w = 0.0
        #: {name: (its column (face, (u, v, F)) -> (M, ∂M/∂(u, v, F)), its prior's 1/sd)} of the
        #: pressing fingers' nuisances, "modulus" and "radius" (set by Inversion; none: {};
        #: :mod:`ectskin.inversion.finger_nuisance`)
        self.finger_columns: dict[str, tuple[FingerColumn, float]] = {}
        #: {name: the centre of its prior} of the finger nuisances (absent: 0, the field's
        #: finger; :meth:`with_finger_prior`)
        self.finger_centre: dict[str, float] = {}
        spec = field.spec
        self.modes: tuple[str, ...] = ("contact", "hover") if np.size(field.heights_mm) else ("contact",)
        lo_f, hi_f = (float(a) for a in spec.force_range_n)
        self.bounds: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
        self._signals: dict[tuple[str, str], Signal] = {}
        self.hover_top = math.inf  # ln of the field's top height (none: no hover part)
        for face in self.faces:
            (ulo, uhi), (vlo, vhi) = spec.extent(face)
            for mode in self.modes:
                if mode == "contact":
                    slo, shi = lo_f, hi_f
                else:  # above the field's top too (:mod:`ectskin.inversion.far`)
                    slo, shi = (float(a) for a in np.log(spec.height_range_mm))
                    self.hover_top, shi = shi, shi + math.log(HOVER_REACH)
                self.bounds[(face, mode)] = (np.array([ulo, vlo, slo]), np.array([uhi, vhi, shi]))
                make = spline_signal if isinstance(field, ResponseField) else generic_signal
                self._signals[(face, mode)] = make(field, face, mode)  # type: ignore[arg-type]
        self.table = self._table(noise_pf(self.untouched, noise))
        # the rank-one factors of the node signals, per (face, mode), built at first use
        # (two fingers, coupled): full pairs, shared with the masked copies
        self._factors: dict[tuple[str, str], Signal] = {}
        try:
            self.pairs: tuple[np.ndarray, np.ndarray] | None = electrode_pairs(self.n_pairs)
        except EctskinError:
            self.pairs = None  # not an electrode set's pairs: no coupled two-finger model

    def factor(self, face: str, mode: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """g (n_e,) and ∂g/∂(u, v, s) (n_e, 3): one finger's rank-one factor at ``x``
        (:mod:`ectskin.inversion.coupling`)."""
        key = (face, mode)
        if self.pairs is None:
            raise EctskinError(
                f"coupling: {self.n_pairs} channels are not the pairs of a set of electrodes; "
                "use two_fingers='superposition'"
            )
        if key not in self._factors:
            u, v, s, lo, hi = field_axes(self.field, face, mode)
            delta = np.asarray(self.field.node_values(face, mode), dtype=np.float64)
            g = rank_one(delta - np.asarray(self.field.untouched, dtype=np.float64), self.pairs)
            self._factors[key] = tensor_spline(u, v, s, lo, hi, g)
        if mode == "hover" and x[2] > self.hover_top:
            return far_factor(self._factors[key], self._signals[key], self.hover_top, x)
        return self._factors[key](x)

    def coupling(self, keys: list[tuple[str, str]], xs: list[np.ndarray], rho: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The coupling's share of two fingers' signal on this model's channels, and its
        derivatives along each finger's (u, v, s) and ρ (:func:`coupling.correction`)."""
        ga, dga = self.factor(*keys[0], xs[0])
        gb, dgb = self.factor(*keys[1], xs[1])
        pairs = self.pairs
        if pairs is None:  # never: factor() refuses first
            raise RuntimeError("coupling: no electrode pairs")
        c, da, db, drho = correction(ga, dga, gb, dgb, rho, pairs)
        ch = self.channels
        return c[ch], da[ch], db[ch], drho[ch]

    def signal(self, face: str, mode: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Δ (n_pairs,) and ∂Δ/∂(u, v, s) (n_pairs, 3) of one finger at ``x`` = (u, v, s)."""
        if mode == "hover" and x[2] > self.hover_top:
            return far_signal(self._signals[(face, mode)], self.hover_top, x)
        return self._signals[(face, mode)](x)

    def masked(self, ok: np.ndarray) -> StateModel:
        """This model on the channels where ``ok`` (n_pairs,) bool holds (the others are masked
        in the frame), its node table rebuilt for them; cached per mask."""
        key = np.asarray(ok, bool).tobytes()
        if key not in self._masked:
            sub = copy.copy(self)
            sub.channels = self.channels[ok]
            sub.n_pairs = int(sub.channels.size)
            sub.untouched = self.untouched[ok]
            sub.field_untouched = self.field_untouched[ok]
            sub.N = self.N[ok]
            sub._masked = {}
            sub._signals = {k: _restricted(sig, ok) for k, sig in self._signals.items()}
            sub.table = sub._table(noise_pf(sub.untouched, self.noise))
            self._masked[key] = sub
        return self._masked[key]

    def with_finger_prior(self, prior: Mapping[str, tuple[float, float]]) -> StateModel:
        """This model with the prior of its finger nuisances set to ``prior`` {name: (centre,
        sd)} (ln(E / E0), ln(R / R0)): what is already known of the person's finger
        (:func:`~ectskin.inversion.pool_fingers`); a name the model has no column of is
        ignored, one not in ``prior`` keeps its prior."""
        sub = copy.copy(self)
        sub.finger_columns = dict(self.finger_columns)
        sub.finger_centre = dict(self.finger_centre)
        for name, (centre, sd) in prior.items():
            if name in sub.finger_columns:
                sub.finger_columns[name] = (sub.finger_columns[name][0], 1.0 / float(sd))
                sub.finger_centre[name] = float(centre)
        return sub

    def sigma(self, readout: np.ndarray, n_frames: int = 1) -> np.ndarray:
        """σ (n_pairs,) of a readout averaged over ``n_frames`` frames."""
        return noise_pf(readout, self.noise) / np.sqrt(n_frames)

    def _table(self, sigma: np.ndarray) -> NodeTable:
        Nw = self.N / sigma[:, None]
        Q = np.linalg.qr(Nw)[0] if Nw.shape[1] else np.zeros((self.n_pairs, 0))
        D, face_i, mode_i, xs, n_ss, shapes = [], [], [], [], [], []
        for fi, face in enumerate(self.faces):
            u, v = self.field.grid(face)
            for mi, mode in enumerate(self.modes):
                vals = np.asarray(self.field.node_values(face, mode), dtype=np.float64)
                d = vals[..., self.channels] - self.field_untouched
                s = (np.asarray(self.field.forces_n) if mode == "contact"
                     else np.log(np.asarray(self.field.heights_mm)))
                if mode == "hover":  # and nodes above the field's top
                    d, s = far_nodes(d, s, *np.log(self.field.spec.height_range_mm))
                U, V, S = np.meshgrid(u, v, s, indexing="ij")  # s fastest: a point's nodes in a row
                n_ss.append(s.size)
                shapes.append((u.size, v.size))
                d = d.reshape(-1, self.n_pairs) / sigma
                D.append(d - (d @ Q) @ Q.T)
                xs.append(np.c_[U.ravel(), V.ravel(), S.ravel()])
                face_i.append(np.full(U.size, fi))
                mode_i.append(np.full(U.size, mi))
        Dm = np.concatenate(D)
        stops = np.cumsum([len(d) for d in D])
        groups = [(int(a), int(b)) for a, b in zip(np.r_[0, stops[:-1]], stops)]
        n_points = sum(len(d) // n_s for d, n_s in zip(D, n_ss))
        stride = max(1, int(np.ceil(np.sqrt(n_points / PAIR_NODES))))
        rows = []
        for (lo, _), shape, n_s in zip(groups, shapes, n_ss):
            iu, iv = np.meshgrid(np.arange(0, shape[0], stride), np.arange(0, shape[1], stride),
                                 indexing="ij")
            rows.append(lo + (iu.ravel() * shape[1] + iv.ravel()) * n_s + n_s // 2)
        pair_rows = np.concatenate(rows)
        sub = Dm[pair_rows]
        gram = 2.0 * (sub @ sub.T)
        gram[np.tril_indices(len(pair_rows))] = np.inf
        return NodeTable(
            D=np.ascontiguousarray(Dm), norm2=np.einsum("ij,ij->i", Dm, Dm),
            face=np.concatenate(face_i), mode=np.concatenate(mode_i), x=np.concatenate(xs),
            Q=Q, sigma=sigma, groups=groups,
            pair_rows=pair_rows, gram=gram,
        )
