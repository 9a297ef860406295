"""Inflation-referenced calibration: paper Eq. 2 against the rest readout *at the trial's own
inflation*, c = (c_t − c_0(p)) / c_0(p).

The paper calibrates every touch frame against one reference, the uninflated, untouched
manipulator (``"rest"`` in :mod:`ectskin.io.calibration`). Inflation moves the readouts by up
to about 40 %, touch by a few per cent, so a classifier fed frames calibrated that way must
separate touch from inflation on its own. The inflation is known (the pump sets it), and every
state of the paper's protocol starts with 30 s without contact (stage 1), so the reference can
follow the inflation:

``"state"``      c_0(p) = the mean readout of the no-contact trial(s) of the trial's own state
                 (the same inflation vector) in the same recording (:func:`state_reference`).
                 A state without a no-contact trial is an error naming it. A recording without
                 inflation values at all (every ``trial.inflation == ()``, a non-inflatable
                 skin) is one state: its no-contact trials are the reference, as for ``"rest"``.
``"inflation"``  c_0(p) predicted from the inflation vector by an :class:`InflationModel`, a
                 smooth model of each channel's rest readout fitted by least squares on the
                 rest readouts (no-contact trial means) of the recording's states. It predicts
                 at inflations where no rest was recorded (unseen levels); a trained run stores
                 it (plain arrays, :meth:`InflationModel.to_json`) so evaluation applies the
                 training recording's model to other data.

``"state-offset"``, ``"inflation-offset"``  the same rest readout c_0(p) subtracted, but divided
                 by the rest state's readout c_0(0) (0 ml in every chamber; for the model, its
                 prediction there): c = (c_t − c_0(p)) / c_0(0), the paper's Eq. 2 frame minus
                 that of the trial's own state at rest. On the twin the touch-induced change
                 c_t − c_0(p) varies less with inflation than c_0(p) does, so this divides out
                 less of the touch signal's dependence on inflation (measured in the report).

The model (:class:`InflationModel`): per channel j, c_0,j(p) = Σ_k a_kj m_k(p / s), the
monomials m_k of the chamber volumes of total degree <= ``degree`` (default 2: 1, p_i, p_i²,
p_i p_j; 10 terms for 3 chambers), s = ``scale_ml`` (the largest volume fitted) to keep the
least-squares system well conditioned. Each state's rest mean counts once. Fewer states than
terms, or states that do not determine them (two levels per chamber cannot fix a p_i² term),
is an error naming the counts.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial

log = logging.getLogger(__name__)

#: ``InflationModel.to_json()["format"]``
MODEL_FORMAT = "ectskin.inflation_reference"
MODEL_VERSION = 1
#: what an inflation-referenced Eq. 2 divides by: the state's own rest readout, or the rest
#: state's (0 ml)
DIVISORS = ("own", "rest")


def _is_no_contact(trial: Trial) -> bool:
    # as ectskin.io.calibration.is_no_contact (which imports this module)
    kind = trial.meta.get("kind")
    if kind is not None:
        return kind == "no_contact"
    return trial.region == 0 and not np.any(trial.labels)


def state_label(state: Sequence[float]) -> str:
    """A state for messages: "(0, 10, 20) ml"; "no inflation" for ()."""
    if not len(state):
        return "no inflation"
    return "(" + ", ".join(f"{v:g}" for v in state) + ") ml"


def recording_states(rec: Recording, *, need_values: bool = False) -> list[tuple[float, ...]]:
    """The inflation states of ``rec`` (distinct ``trial.inflation`` vectors, first seen first).

    Every trial must give as many chamber volumes as the others (or none at all, a
    non-inflatable skin); ``need_values``: a recording without inflation values is an error."""
    lengths = {len(t.inflation) for t in rec.trials}
    if len(lengths) > 1:
        odd = next(t for t in rec.trials if len(t.inflation) != len(rec.trials[0].inflation))
        raise EctskinError(
            f"trial {odd.name!r}: inflation {list(odd.inflation)} has {len(odd.inflation)} "
            f"chamber volume(s), trial {rec.trials[0].name!r} {len(rec.trials[0].inflation)}; "
            "an inflation-referenced calibration needs every trial's inflation vector (ml)"
        )
    if need_values and lengths <= {0}:
        raise EctskinError(
            f"{rec.source or 'recording'}: has no inflation values (every trial's inflation "
            "is empty); the 'inflation' reference predicts the rest readout from the chamber "
            "volumes (ml): import them (docs/import-format.md), or use reference 'rest' or "
            "'state'"
        )
    return list(dict.fromkeys(tuple(t.inflation) for t in rec.trials))


def state_rest_means(
    rec: Recording, channels: np.ndarray | None = None
) -> dict[tuple[float, ...], np.ndarray]:
    """The mean readout (pF, per channel over its finite values) of the no-contact trials of
    each inflation state of ``rec`` that has some: state → (n_kept,) float64. ``channels``:
    the measured channel indices (default all)."""
    keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
    recording_states(rec)
    frames: dict[tuple[float, ...], list[np.ndarray]] = {}
    for t in rec.trials:
        if _is_no_contact(t):
            frames.setdefault(tuple(t.inflation), []).append(t.capacitance[:, keep])
    out = {}
    for state, parts in frames.items():
        x = np.concatenate(parts, axis=0)
        count = np.isfinite(x).sum(axis=0)
        if (count == 0).any():
            j = int(keep[np.argmax(count == 0)])
            raise EctskinError(
                f"no-contact trial(s) of state {state_label(state)}: channel {j} "
                f"({rec.layout.pair_names[j]!r}) has no finite readout to use as reference"
            )
        out[state] = np.nanmean(x, axis=0) if (count < x.shape[0]).any() else x.mean(axis=0)
    return out


def state_reference(rec: Recording, channels: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The ``"state"`` reference of every trial: trial name → the mean no-contact readout of its
    own inflation state (:func:`state_rest_means`), (n_kept,) pF. A state with trials but no
    no-contact trial is an error naming the state and a trial of it."""
    means = state_rest_means(rec, channels)
    out = {}
    for t in rec.trials:
        state = tuple(t.inflation)
        if state not in means:
            raise EctskinError(
                f"trial {t.name!r}: its inflation state {state_label(state)} has no no-contact "
                "trial to calibrate against (reference 'state' needs one per state, the paper's "
                "30 s without contact); record one, or use reference 'inflation' (a model of "
                "the rest readout over inflation) or 'rest'"
            )
        out[t.name] = means[state]
    return out


# --------------------------------------------------------------------------- the model
def monomials(n_chambers: int, degree: int) -> list[tuple[int, ...]]:
    """The exponent tuples of the monomials of ``n_chambers`` variables of total degree <=
    ``degree``, constant first, then by degree (e.g. 3 chambers, degree 2: 10 terms)."""
    out: list[tuple[int, ...]] = []
    for d in range(degree + 1):
        for combo in itertools.combinations_with_replacement(range(n_chambers), d):
            e = [0] * n_chambers
            for i in combo:
                e[i] += 1
            out.append(tuple(e))
    return out


def design_matrix(inflation: np.ndarray, terms: Sequence[Sequence[int]], scale_ml: float):
    """(n, n_terms) float64: the monomials ``terms`` of ``inflation / scale_ml`` ((n, chambers))."""
    q = np.asarray(inflation, dtype=np.float64) / scale_ml
    e = np.asarray(terms, dtype=np.int64)  # (T, K)
    return np.prod(q[:, None, :] ** e[None, :, :], axis=2)


@dataclass(frozen=True)
class InflationModel:
    """c_0(p): each channel's rest readout as a polynomial of the chamber volumes (module
    docstring). ``coef`` (n_terms, n_pairs) pF for the monomials ``terms`` of p / ``scale_ml``,
    over the layout's ``pair_names`` (NaN column: a channel not measured when fitted);
    ``states`` the inflation states fitted (ml), ``residual_rel`` (n_pairs,) the RMS of the fit
    residual over those states relative to the channel's mean rest readout. ``divisor``: what
    Eq. 2 divides by, "own" (c_0(p), reference "inflation") or "rest" (c_0 at 0 ml,
    "inflation-offset")."""

    coef: np.ndarray
    terms: tuple[tuple[int, ...], ...]
    scale_ml: float
    pair_names: tuple[str, ...]
    states: tuple[tuple[float, ...], ...]
    residual_rel: np.ndarray
    divisor: str = "own"

    @property
    def mode(self) -> str:
        """The reference mode the model calibrates with: "inflation" or "inflation-offset"."""
        return "inflation" if self.divisor == "own" else "inflation-offset"

    def rest_readout(self) -> np.ndarray:
        """c_0 at 0 ml in every chamber, (n_pairs,) pF (the divisor of "inflation-offset")."""
        return self.predict(np.zeros(self.n_chambers))

    @property
    def n_chambers(self) -> int:
        return len(self.terms[0])

    @property
    def degree(self) -> int:
        return max(sum(e) for e in self.terms)

    @classmethod
    def fit(
        cls,
        rec: Recording,
        channels: np.ndarray | None = None,
        *,
        degree: int = 2,
        divisor: str = "own",
    ) -> InflationModel:
        """Fit the model on the rest means of ``rec``'s states (:func:`state_rest_means`), on
        the measured ``channels`` (others NaN); errors: no inflation values, too few states."""
        if divisor not in DIVISORS:
            raise EctskinError(
                f"inflation model: divisor must be one of {DIVISORS}, got {divisor!r}"
            )
        if isinstance(degree, bool) or not isinstance(degree, int) or degree < 1:
            raise EctskinError(f"inflation model: degree must be an integer >= 1, got {degree!r}")
        keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
        recording_states(rec, need_values=True)
        means = state_rest_means(rec, keep)
        states = list(means)
        n_chambers = len(rec.trials[0].inflation)
        terms = monomials(n_chambers, degree)
        p = np.array(states, dtype=np.float64).reshape(len(states), n_chambers)
        scale = float(p.max()) if p.size and p.max() > 0 else 1.0
        a = design_matrix(p, terms, scale)
        rank = np.linalg.matrix_rank(a) if len(states) else 0
        if len(states) < len(terms) or rank < len(terms):
            raise EctskinError(
                f"inflation model: {len(states)} state(s) with a no-contact trial "
                f"({', '.join(state_label(s) for s in states[:4])}"
                f"{', ...' if len(states) > 4 else ''}) determine {rank} of the {len(terms)} "
                f"terms of a degree-{degree} polynomial in {n_chambers} chamber volume(s); "
                "record no-contact trials at more states (at least 3 levels per chamber for "
                "degree 2), lower the degree, or use reference 'state'"
            )
        y = np.stack([means[s] for s in states])  # (S, n_kept)
        sol, *_ = np.linalg.lstsq(a, y, rcond=None)  # (T, n_kept)
        coef = np.full((len(terms), rec.n_pairs), np.nan)
        coef[:, keep] = sol
        resid = np.full(rec.n_pairs, np.nan)
        rms = np.sqrt(np.mean((a @ sol - y) ** 2, axis=0))
        resid[keep] = rms / np.abs(y.mean(axis=0))
        log.info(
            "inflation reference: degree-%d model of %d channels on %d states, residual up to "
            "%.2g %% of the rest readout",
            degree,
            keep.size,
            len(states),
            100 * float(np.nanmax(resid)) if keep.size else 0.0,
        )
        return cls(
            coef=coef,
            terms=tuple(terms),
            scale_ml=scale,
            pair_names=tuple(rec.layout.pair_names),
            states=tuple(states),
            residual_rel=resid,
            divisor=divisor,
        )

    def predict(self, inflation: Any) -> np.ndarray:
        """c_0 at ``inflation`` ((n_chambers,) → (n_pairs,); (n, n_chambers) → (n, n_pairs)),
        pF. A volume outside the fitted range of its chamber is predicted (extrapolated) with a
        logged warning."""
        p = np.asarray(inflation, dtype=np.float64)
        single = p.ndim == 1
        p = p.reshape(-1, p.shape[-1]) if p.ndim else p.reshape(1, 0)
        if p.shape[1] != self.n_chambers:
            raise EctskinError(
                f"inflation model: fitted on {self.n_chambers} chamber volume(s), got an "
                f"inflation of {p.shape[1]} ({p[0].tolist() if len(p) else []})"
            )
        fitted = np.array(self.states, dtype=np.float64)
        lo, hi = fitted.min(axis=0), fitted.max(axis=0)
        outside = (p < lo - 1e-9) | (p > hi + 1e-9)
        if outside.any():
            i = int(np.argmax(outside.any(axis=1)))
            log.warning(
                "inflation reference: %s is outside the fitted volumes (%s to %s ml per "
                "chamber): extrapolated",
                state_label(p[i]),
                lo.tolist(),
                hi.tolist(),
            )
        out = design_matrix(p, self.terms, self.scale_ml) @ self.coef
        return out[0] if single else out

    def references(self, rec: Recording, channels: np.ndarray | None = None) -> dict[str, Any]:
        """trial name → c_0(p) of the trial's inflation, restricted to ``channels`` (pF)."""
        if list(self.pair_names) != list(rec.layout.pair_names):
            raise EctskinError(
                f"inflation model: fitted on pairs {list(self.pair_names)[:3]}... "
                f"({len(self.pair_names)}), the recording has "
                f"{list(rec.layout.pair_names)[:3]}... ({rec.n_pairs})"
            )
        keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
        states = recording_states(rec, need_values=True)
        c0 = {s: self.predict(s)[keep] for s in states}
        return {t.name: c0[tuple(t.inflation)] for t in rec.trials}

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values (non-finite coefficients as null): what a trained run stores."""
        return {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "terms": [list(e) for e in self.terms],
            "scale_ml": self.scale_ml,
            "pair_names": list(self.pair_names),
            "coef_pf": [[float(v) if np.isfinite(v) else None for v in row] for row in self.coef],
            "states_ml": [list(s) for s in self.states],
            "residual_rel": [float(v) if np.isfinite(v) else None for v in self.residual_rel],
            "divisor": self.divisor,
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any], source: str = "inflation model") -> InflationModel:
        """The model of :meth:`to_json`; anything malformed is an error naming ``source``."""
        if not isinstance(doc, Mapping) or doc.get("format") != MODEL_FORMAT:
            found = doc.get("format") if isinstance(doc, Mapping) else type(doc).__name__
            raise EctskinError(f"{source}: expected format {MODEL_FORMAT!r}, found {found!r}")
        if doc.get("version") != MODEL_VERSION:
            raise EctskinError(
                f"{source}: version {doc.get('version')!r} of {MODEL_FORMAT!r}, this ectskin "
                f"reads version {MODEL_VERSION}"
            )
        try:
            terms = tuple(tuple(int(v) for v in e) for e in doc["terms"])
            names = tuple(str(n) for n in doc["pair_names"])
            nan = np.nan
            coef = np.array(
                [[nan if v is None else v for v in row] for row in doc["coef_pf"]], np.float64
            )
            resid = np.array([nan if v is None else v for v in doc["residual_rel"]], np.float64)
            states = tuple(tuple(float(v) for v in s) for s in doc["states_ml"])
            scale = float(doc["scale_ml"])
            divisor = str(doc.get("divisor", "own"))
        except (KeyError, TypeError, ValueError) as exc:
            raise EctskinError(f"{source}: malformed inflation model ({exc!r})") from None
        ok = (
            terms
            and len({len(e) for e in terms}) == 1
            and coef.shape == (len(terms), len(names))
            and resid.shape == (len(names),)
            and states
            and all(len(s) == len(terms[0]) for s in states)
            and scale > 0
            and divisor in DIVISORS
        )
        if not ok:
            raise EctskinError(
                f"{source}: inflation model of inconsistent sizes: {len(terms)} terms, coef "
                f"{coef.shape}, {len(names)} pairs, {len(states)} states, scale {scale}, "
                f"divisor {divisor!r}"
            )
        return cls(coef, terms, scale, names, states, resid, divisor)
