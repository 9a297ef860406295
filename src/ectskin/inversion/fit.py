"""The inversion itself: fit 0, 1 or 2 fingers to one frame through the response field.

For a frame y (n_pairs,) pF of a known state (the model of :mod:`ectskin.inversion.model`):

1. **No finger**: y − c_u = N β + e, weighted linear least squares (closed form).
2. **One finger**: a coarse search over the node table (the noise-weighted distance of the
   frame, projected off the nuisance columns, to every node's signal, one matrix-vector
   product), then Levenberg–Marquardt (MINPACK's ``lmder``, the analytic Jacobian
   ∂Δ/∂(u, v, s) of the field and the nuisance columns) over (u, v, s, β) from the nearest
   node of each face and mode, best first; the face and the mode are those of the start, the
   field's ranges bound (u, v, s) (``_fit_fingers``).
   ``lmder`` is called through ``scipy.optimize.leastsq``: the algorithm and options of
   ``least_squares(method="lm")``, the same iterates, without that wrapper's cost per call
   (0.2 ms a fit); its warning when a fit runs out of evaluations is silenced (``converged``).
3. **Two fingers**: a coarse search over pairs of nodes (:meth:`NodeTable.pairs`), the
   one-finger solution with the node nearest what it leaves (y − c_u − Δ₁), and with
   ``scaled_pairs`` the best pair with each node's signal scaled by its best factor (fingers
   screen each other); from each, one fit of both and β (and ρ, ``two_fingers="coupled"``).

Counts and starts are tried in turn while the fits so far do not explain the frame within the
noise (the gate, ``gate_p``): a one-finger frame costs one fit, a two-finger frame two.

**Warm start** (``fit(..., warm=previous)``, a live stream): the fit of the previous frame's
count starts from the previous frame's fingers instead of the coarse search; while that fit
passes the gate the coarse search of that count is skipped. Otherwise the count is fitted from
its cold starts too and the better fit kept. Every other count is fitted as without ``warm``,
so a warm fit only ever adds a start; except where the warm fit passes the gate: a smaller
count's fit then starts from the warm fit's strongest fingers instead of its coarse search, is
screened on a few evaluations and run on only where it comes near its gate
(:mod:`ectskin.inversion.stream`).
**Seeds** (``fit(..., seeds=...)``, e.g. a learned model's guess): more starts of their counts,
beside the coarse search's or in place of it (``seed_search``; :mod:`ectskin.inversion.seed`).

Each fit's Gaussian log-likelihood ℓ = −½ χ² − Σ ln σ − (n/2) ln 2π, with the same σ for all
three (the noise at the frame's readout), and its BIC = k ln n − 2 ℓ (k: 3 per finger, + 1 for a
coupling, + the nuisance columns; n: the channels). The count with the lowest BIC wins. The standard errors of
the winner are the Cramér–Rao bound at the solution (:func:`ectskin.twin.bound.crb` with the
nuisances estimated): the Fisher information of the fitted model.

``model_error`` widens σ by a floor for what the field does not model, σ² + a² + (r |y − c_u|)²
(a in pF, r relative to the finger's signal): the field's interpolation error, the
superposition of two fingers, the twin's per-channel drift. Zero by default (the readout noise
alone; then the standard errors are the bound).

``bound_error`` is such a floor for the fingers' points', forces' and heights' standard errors
only, the fits and their weights unchanged (the standard errors are the fit's scatter as it
was weighted: :func:`~ectskin.inversion.result.sandwich`): (a, r) estimated from the fits'
residuals, no labels (:mod:`ectskin.inversion.model_error`).

**The untouched readout** (``untouched``): c_u may be the skin's own measured untouched
readout of each state instead of the field's (the fingers' signals stay the field's).

**Pressing or hovering** (``press_check``): after the count is chosen, each hovering finger of
the chosen fit is refitted pressing at its point and kept so when that fits within
``contact_bias`` times the frame's χ² per degree of freedom of the hovering fit, or when it
hovers at the field's lowest height; where not (two fingers), from the pressing node nearest
what the other leaves, kept where that fits better than hovering (docs/inversion.md).

**The finger's size** (``finger_scale_sd``): a bigger or softer fingertip than the field's
couples more at every channel alike (∂C/∂R ≈ κ ΔC, :mod:`ectskin.twin.bound_field`), so each
finger's signal is (1 + a) Δ, a with a Gaussian prior (a penalised fit, a BIC parameter). The
standard errors carry a as a nuisance: it is nearly confounded with the force (docs/inversion.md).

**The finger's pulp and radius** (``modulus``, ``radius``: tables of ∂C/∂ln E and ∂C/∂ln R per
state): each pressing finger's signal is Δ + x M_E + r M_R, x = ln(E / E0) and r = ln(R / R0)
fitted with Gaussian priors (:mod:`ectskin.inversion.finger_nuisance`; the fit itself is
:func:`ectskin.inversion.lm.fit_fingers`).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.stats import chi2

from ectskin._check import EctskinError, check_option
from ectskin.inversion.finger_nuisance import (
    MODULUS_PRIOR_SD,
    RADIUS_PRIOR_SD,
    finger_columns,
    finger_prior,
)
from ectskin.inversion.lm import (  # noqa: F401  (the fit's constants, named here too)
    BOUND_WEIGHT,
    LM_CONVERGED,
    LM_OPTIONS,
    MAX_NFEV,
    RHO_START,
    SCALE_BOUND_SD,
    fit_fingers,
)
from ectskin.inversion.model import MODES, FieldLike, StateModel
from ectskin.inversion.noise import check_floor, widened_sigma
from ectskin.inversion.result import FingerEstimate, Fit, InversionResult, build_result
from ectskin.inversion.seed import SEED_SEARCH, FingerGuess, seed_starts
from ectskin.inversion.stream import screened, strongest
from ectskin.inversion.stream import warm_start as stream_start
from ectskin.twin.readout import ReadoutConfig

# FingerEstimate and InversionResult live in :mod:`ectskin.inversion.result`; named here too
__all__ = ["FingerEstimate", "Inversion", "InversionResult"]

#: the kinds of readout :meth:`Inversion.fit` takes
KINDS = ("absolute", "relative", "difference")
#: how two fingers' signals combine
TWO_FINGER_MODELS = ("coupled", "superposition")
#: the state keys of two fields are the same state when they differ by less than this (ml)
STATE_TOL_ML = 1e-6
#: the finger scale's prior sd that κ ≈ 0.08 /mm (the largest of the twin's states,
#: :func:`ectskin.twin.bound_field.field_nuisances`) times a fingertip radius ±1.5 mm from the
#: field's gives (adult fingertips 7–10 mm around the field's 8 mm)
FINGER_SCALE_SD = 0.12
#: ``contact_bias``' default: a pressing finger is preferred to a hovering one that fits better
#: by up to this many times the frame's χ² per degree of freedom (chosen on the validation
#: trials of the twin's contact experiment among 0, 3, 5 and 10)
CONTACT_BIAS = 5.0
#: a hovering finger this close (in ln h) to the field's lowest height is at the range's end
PINNED_LN_H = 1e-3


class Inversion:
    """Training-free inversion of frames through per-state response fields (module docstring).

    Parameters
    ----------
    fields : {inflation state (ml per chamber): its response field (or any
        :class:`~ectskin.inversion.model.FieldLike`)}.
    noise : the readout's noise model (:class:`~ectskin.twin.readout.ReadoutConfig`).
    push : {state: (n_pairs, m) push columns} (:func:`~ectskin.inversion.model.push_basis`), or
        None for no push nuisance. A state missing from it has none.
    drift : the drift terms, some of ("gain", "offset").
    max_fingers : 0, 1 or 2: the largest count tried.
    model_error : (a pF, r) the σ floor of the module docstring.
    bound_error : (a pF, r) the σ floor of the points', forces' and heights' standard errors
        only (module docstring); :meth:`with_bound_error` sets it on a built inversion.
    starts : how many starts a count may take (one finger: the nearest node of each face and
        mode, best first; two: the best pairs of nodes, and the one-finger solution with the
        node nearest what it leaves); it stops at the first whose χ² passes the gate.
    push_prior_sd : a Gaussian prior of this standard deviation on each push coefficient (in
        the columns' unit: N for :func:`~ectskin.inversion.model.push_basis`), its term joins
        χ² (a penalised fit); None: the push is unknown, without a prior.
    finger_scale_sd : the prior sd of each finger's relative signal scale a (module docstring;
        :data:`FINGER_SCALE_SD` from the physics), or None: the field's finger, no scale.
    untouched : {state: (n_pairs,) pF} the skin's untouched readout of each state as measured
        (a recording without a finger), c_u in place of the field's (the fingers' signals stay
        the field's); a state missing from it, or None, has the field's.
    press_check : refit each hovering finger of a fit pressing instead (from its point, at
        the field's least force) and keep that when its χ² is at most the hovering fit's plus
        ``contact_bias`` × the frame's χ² per degree of freedom (at least 1): a finger just
        above the skin and one pressing lightly have nearly the same signal, and the search
        starts each finger in one mode.
    contact_bias : the χ² (in units of the fit's χ² per degree of freedom) by which a pressing
        finger may fit worse than a hovering one and still be preferred (``press_check``).
    scaled_pairs : start a two-finger fit also from the best pair of nodes with each node's
        signal scaled by its best factor (:meth:`NodeTable.pairs` ``scaled``; two fingers
        screen each other), in place of the second best plain pair; off by default
        (docs/inversion.md).
    modulus : {state: :class:`~ectskin.twin.bound_modulus.ModulusTable`}: fit each pressing
        finger's pulp modulus x = ln(E / E0) too, its signal Δ + x ∂C/∂ln E (the table's column
        at its point and force), with a Gaussian prior of sd ``modulus_prior_sd``
        (:mod:`ectskin.inversion.finger_nuisance`); a state missing from it, or None, has none.
    modulus_prior_sd : the prior sd of x (default: the twin's spread of people's pulp, ln 4/√12).
    radius, radius_prior_sd : the same for the fingertip's radius, r = ln(R / R0), its tables
        from :func:`~ectskin.inversion.finger_nuisance.radius_table` (default prior: the twin's
        fingertips, 7-10 mm, ln(10/7)/√12).
    seed_search : how the seeds of :meth:`fit` join a count's starts: "add" (beside the
        coarse search's; the best fit is kept) or "replace" (the count's coarse search is
        skipped where a seed gives it a start; :mod:`ectskin.inversion.seed`).
    two_fingers : "coupled" (two fingers as coupled conductors, one more parameter ρ:
        :mod:`ectskin.inversion.coupling`) or "superposition" (the sum of their signals).
    gate_p : a count of k + 1 fingers, or a further start, is tried only while the fits so
        far leave χ² above its upper ``gate_p`` quantile (χ² with n − 3k − m degrees of freedom
        for k fingers): the frame is not explained within the noise. 0 tries every count and
        every start.
    min_separation_mm : two fingers on one face whose fingertips' centres would lie closer than
        this (their lateral distance and the difference of their heights above the skin) are
        not an answer: fingertips are solids and cannot overlap, and such a pair, a finger split
        in two, is how a fit explains one finger larger or softer than the field's. None
        (default): twice the fields' fingertip radius; 0: no such rule.
    """

    def __init__(
        self,
        fields: Mapping[tuple[float, ...], FieldLike],
        noise: ReadoutConfig | None = None,
        *,
        push: Mapping[tuple[float, ...], np.ndarray] | None = None,
        drift: Sequence[str] = ("gain", "offset"),
        max_fingers: int = 2,
        model_error: tuple[float, float] = (0.0, 0.0),
        bound_error: tuple[float, float] = (0.0, 0.0),
        starts: int = 2,
        gate_p: float = 1e-4,
        push_prior_sd: float | None = None,
        two_fingers: str = "superposition",
        finger_scale_sd: float | None = None,
        untouched: Mapping[tuple[float, ...], np.ndarray] | None = None,
        press_check: bool = False,
        contact_bias: float = CONTACT_BIAS,
        scaled_pairs: bool = False,
        seed_search: str = "add",
        modulus: Mapping[tuple[float, ...], Any] | None = None,
        modulus_prior_sd: float = MODULUS_PRIOR_SD,
        radius: Mapping[tuple[float, ...], Any] | None = None,
        radius_prior_sd: float = RADIUS_PRIOR_SD,
        min_separation_mm: float | None = None,
    ) -> None:
        if not isinstance(fields, Mapping) or not fields:
            raise EctskinError(
                "Inversion: fields must be a non-empty mapping {inflation state: response field}, "
                f"got {type(fields).__name__}"
            )
        if max_fingers not in (0, 1, 2):
            raise EctskinError(f"Inversion: max_fingers must be 0, 1 or 2, got {max_fingers!r}")
        a, r = check_floor("model_error", model_error)
        if not (isinstance(starts, int) and starts >= 1):
            raise EctskinError(f"Inversion: starts must be an integer >= 1, got {starts!r}")
        if not (isinstance(gate_p, int | float) and 0 <= gate_p < 1):
            raise EctskinError(f"Inversion: gate_p must be in [0, 1), got {gate_p!r}")
        if push_prior_sd is not None and not (math.isfinite(push_prior_sd) and push_prior_sd > 0):
            raise EctskinError(f"Inversion: push_prior_sd must be > 0 or None, got {push_prior_sd!r}")
        if finger_scale_sd is not None and not (
                isinstance(finger_scale_sd, int | float) and 0 < finger_scale_sd < math.inf):
            raise EctskinError(
                f"Inversion: finger_scale_sd must be > 0 or None, got {finger_scale_sd!r}")
        if two_fingers not in TWO_FINGER_MODELS:
            raise EctskinError(
                f"Invalid value for 'two_fingers': allowed values are {list(TWO_FINGER_MODELS)}; "
                f"got {two_fingers!r}"
            )
        self.coupled = two_fingers == "coupled"
        if min_separation_mm is None:
            radii = [getattr(getattr(getattr(f, "spec", None), "finger", None), "radius_mm", None)
                     for f in fields.values()]
            known = [float(r) for r in radii if r is not None]
            min_separation_mm = 2.0 * min(known) if known and len(known) == len(radii) else 0.0
        if not (isinstance(min_separation_mm, int | float) and 0 <= min_separation_mm < math.inf):
            raise EctskinError(f"Inversion: min_separation_mm must be a number >= 0 (mm) or None, "
                               f"got {min_separation_mm!r}")
        self.min_separation_mm = float(min_separation_mm)
        self.starts = starts
        self.gate_p = float(gate_p)
        self.push_prior_sd = push_prior_sd
        self.finger_scale_sd = finger_scale_sd
        if not (isinstance(contact_bias, int | float) and 0 <= contact_bias < math.inf):
            raise EctskinError(f"Inversion: contact_bias must be a number >= 0, got {contact_bias!r}")
        self.press_check = bool(press_check)
        self.contact_bias = float(contact_bias)
        if not isinstance(scaled_pairs, bool):
            raise EctskinError(f"Inversion: scaled_pairs must be True or False, got {scaled_pairs!r}")
        self.scaled_pairs = scaled_pairs
        check_option("seed_search", seed_search, SEED_SEARCH)
        self.seed_search = seed_search
        self.noise = noise or ReadoutConfig()
        self.max_fingers = int(max_fingers)
        self.model_error = (a, r)
        self.bound_error = check_floor("bound_error", bound_error)
        self.states: list[tuple[float, ...]] = []
        self._models: list[StateModel] = []
        n_pairs = None
        for key, fld in fields.items():
            state = _state("fields key", key)
            if n_pairs is not None and fld.n_pairs != n_pairs:
                raise EctskinError(
                    f"Inversion: the field of state {list(state)} has {fld.n_pairs} pairs, "
                    f"another {n_pairs}"
                )
            n_pairs = int(fld.n_pairs)
            extra = None
            if push is not None:
                extra = next((np.asarray(v, float) for k, v in push.items()
                              if _same(_state("push key", k), state)), None)
                if extra is not None and (extra.ndim != 2 or extra.shape[0] != n_pairs
                                          or not np.all(np.isfinite(extra))):
                    raise EctskinError(
                        f"Inversion: push[{list(state)}] must be finite with shape ({n_pairs}, m), "
                        f"got shape {extra.shape}"
                    )
            self.states.append(state)
            base = None
            if untouched is not None:
                base = next((np.asarray(v, float) for k, v in untouched.items()
                             if _same(_state("untouched key", k), state)), None)
                found = (None if base is None else f"shape {base.shape}"
                         if base.shape != (n_pairs,) else "a value that is not finite"
                         if not np.all(np.isfinite(base)) else "a value <= 0"
                         if not np.all(base > 0) else None)
                if found:
                    raise EctskinError(f"Inversion: untouched[{list(state)}] must be ({n_pairs},) "
                                       f"finite readouts > 0 pF, got {found}")
            sm = StateModel(fld, extra, drift, self.noise, base)
            n_push = 0 if extra is None else extra.shape[1]
            # 1/sd of each nuisance coefficient's Gaussian prior (0: none)
            sm.prior_w = np.zeros(sm.N.shape[1])
            if push_prior_sd is not None:
                sm.prior_w[:n_push] = 1.0 / push_prior_sd
            # 1/sd of each finger's scale prior (0: no scale parameter)
            sm.scale_w = 0.0 if finger_scale_sd is None else 1.0 / float(finger_scale_sd)
            # each pressing finger's pulp modulus ln(E / E0) and radius ln(R / R0) where their
            # tables are given (finger_nuisance; none: {})
            sm.finger_columns = finger_columns(
                {"modulus": (modulus, modulus_prior_sd), "radius": (radius, radius_prior_sd)},
                state, lambda k, s: _same(_state("finger table key", k), s), n_pairs, sm.faces)
            self._models.append(sm)
            if self.coupled and max_fingers == 2 and sm.pairs is None:
                raise EctskinError(
                    f"Inversion: the field of state {list(state)} has {sm.n_pairs} channels, not "
                    "the pairs of a set of electrodes; two_fingers='coupled' needs them, use "
                    "'superposition'"
                )
        self.n_pairs = int(n_pairs or 0)
        #: {name: prior sd} of the finger nuisances some state has a table of (what
        #: :func:`~ectskin.inversion.person.pool_fingers` takes)
        self.finger_prior_sd: dict[str, float] = {
            q: float(sd) for q, (tables, sd) in (("modulus", (modulus, modulus_prior_sd)),
                                                 ("radius", (radius, radius_prior_sd)))
            if any(q in m.finger_columns for m in self._models) and tables is not None}

    # ------------------------------------------------------------------ the door
    def model(self, state: Any) -> StateModel:
        """The :class:`StateModel` of ``state`` (an inflation vector, ml)."""
        s = _state("state", state)
        for known, m in zip(self.states, self._models):
            if _same(known, s):
                return m
        raise EctskinError(
            f"Inversion: no response field for state {list(s)} ml; the fields cover "
            f"{[list(k) for k in self.states]}"
        )

    def observed(self, readouts: Any, state: Any, kind: str = "absolute",
                 reference: Any = None) -> tuple[np.ndarray, int]:
        """The frame's absolute readout (n_pairs,) pF and the number of frames averaged.

        ``readouts`` (n_pairs,) or a window (w, n_pairs) (averaged); ``kind``: "absolute" (pF),
        "relative" (paper Eq. 2, c = (c_t − c_0)/c_0 against ``reference`` c_0 (n_pairs,) pF) or
        "difference" (pF less the untouched readout of ``state``). NaN marks a masked channel
        (in any frame of the window, or in the reference): :meth:`fit` leaves it out.
        """
        m = self.model(state)
        y = np.asarray(readouts, dtype=np.float64)
        if y.ndim == 1:
            y = y[None]
        if y.ndim != 2 or y.shape[1] != self.n_pairs or y.shape[0] == 0:
            raise EctskinError(
                f"Inversion: readouts must have shape ({self.n_pairs},) or (n_frames, "
                f"{self.n_pairs}), got {np.shape(readouts)}"
            )
        if np.any(np.isinf(y)):
            k = tuple(int(i) for i in np.argwhere(np.isinf(y))[0])
            raise EctskinError(f"Inversion: readouts must be finite or NaN (masked); found {y[k]} at {k}")
        mean = y.mean(axis=0)
        if kind == "absolute":
            return mean, y.shape[0]
        if kind == "difference":
            return m.untouched + mean, y.shape[0]
        if kind == "relative":
            if reference is None:
                raise EctskinError("Inversion: kind 'relative' needs the reference c_0 (n_pairs,) pF")
            ref = np.asarray(reference, dtype=np.float64)
            if ref.shape != (self.n_pairs,) or np.any(np.isinf(ref)) or np.any(ref == 0):
                raise EctskinError(
                    f"Inversion: reference must be ({self.n_pairs},) nonzero pF (NaN: a masked "
                    f"channel), got shape {ref.shape}"
                )
            return ref * (1.0 + mean), y.shape[0]
        raise EctskinError(f"Invalid value for 'kind': allowed values are {list(KINDS)}; got {kind!r}")

    # ------------------------------------------------------------------ one frame
    def fit(self, readouts: Any, state: Any, *, kind: str = "absolute",
            reference: Any = None, warm: InversionResult | None = None,
            seeds: Sequence[Sequence[FingerGuess]] | None = None,
            finger: Mapping[str, tuple[float, float]] | None = None) -> InversionResult:
        """Invert one frame (or a window of frames, averaged) of ``state``; ``warm``: the
        result of the previous frame of a stream (of the same state), the start of the fit of
        its count (module docstring); ``seeds``: guesses of the fingers, each one more start of
        its count's fit (:mod:`ectskin.inversion.seed`); ``finger``: {"modulus" | "radius":
        (centre, sd)}, the prior of each pressing finger's nuisance in place of the
        population's, what other frames of the same person tell
        (:func:`~ectskin.inversion.pool_fingers`)."""
        m = self.model(state)
        prior = finger_prior(finger)
        warm_start = stream_start(m, warm)
        y, w = self.observed(readouts, state, kind, reference)
        ok = np.isfinite(y)
        if not ok.all():  # masked channels (NaN in any frame of the window) are left out
            nb = m.N.shape[1]
            if ok.sum() < 3 * max(self.max_fingers, 1) + nb + 1:
                raise EctskinError(
                    f"Inversion: {int(ok.sum())} unmasked channels of {ok.size} are too few to fit "
                    f"{self.max_fingers} finger(s) and {nb} nuisance terms"
                )
            m, y = m.masked(ok), y[ok]
        if prior:
            m = m.with_finger_prior(prior)
        sigma = self._sigma(m, y, w)
        delta = y - m.untouched
        n, nb = m.n_pairs, m.N.shape[1]
        fits: list[Fit | None] = [self._fit_none(m, delta, sigma)]
        passed = [self._passes(fits[0], 0, nb, n)]
        # a stream's warm start first: where it explains the frame, smaller counts are screened
        warm_fit = (None if warm_start is None
                    else self._fit_fingers(m, delta, sigma, warm_start, self.coupled))
        explained = (warm_fit is not None and self._passes(warm_fit, len(warm_fit.fingers), nb, n)
                     and not (len(warm_fit.fingers) == 2 and self._overlap(m, warm_fit)))
        starts: list[list[list[tuple[int, int, np.ndarray]]]] = [[]]
        seeded = seed_starts(m, seeds, self.max_fingers)
        # counts in turn, each from its first start while no count passes the gate; a count's
        # further starts only when no larger count passes either (a two-finger frame does not
        # spend them on one finger)
        for k in range(1, self.max_fingers + 1):
            if passed[-1]:
                break
            # the best fit of the warm start and the seeds of k fingers
            hot = warm_fit if warm_fit is not None and len(warm_fit.fingers) == k else None
            for start in seeded.get(k, []):
                f = self._fit_fingers(m, delta, sigma, start, self.coupled)
                hot = f if hot is None or f.chi2 < hot.chi2 else hot
            # a warm start that explains the frame, or seeds that replace the search: no
            # coarse search for this count
            if hot is not None and (self.seed_search == "replace" and k in seeded
                                    or k not in seeded and self._passes(hot, k, nb, n)):
                starts.append([])
                fits.append(hot)
            else:
                if explained and k < len(warm_fit.fingers):  # type: ignore[union-attr]
                    starts.append([strongest(m, warm_fit, k, sigma)])  # type: ignore[arg-type]
                    cold = screened(self._fit_fingers, m, delta, sigma, starts[k][0],
                                    self.coupled, lambda f: _chi2_gate(n - f.n_params, self.gate_p))
                else:
                    starts.append(self._starts(m, delta, k, fits[1] if k > 1 else None))
                    cold = self._fit_fingers(m, delta, sigma, starts[k][0], self.coupled)
                fits.append(hot if hot is not None and hot.chi2 < cold.chi2 else cold)
            passed.append(self._passes(fits[k], k, nb, n))
            if k == self.max_fingers:
                for j in range(k, 0, -1):
                    for start in starts[j][1:]:
                        if passed[j]:
                            break
                        f = self._fit_fingers(m, delta, sigma, start, self.coupled)
                        if f.chi2 < fits[j].chi2:  # type: ignore[union-attr]
                            fits[j] = f
                            passed[j] = self._passes(f, j, nb, n)
                    if passed[j]:
                        break
        fits += [None] * (self.max_fingers + 1 - len(fits))
        if len(fits) > 2 and fits[2] is not None and self._overlap(m, fits[2]):
            fits[2] = None  # one finger split in two: not a configuration of two fingertips
        const = -float(np.sum(np.log(sigma))) - 0.5 * n * math.log(2 * math.pi)
        lls = [-math.inf if f is None else const - 0.5 * f.chi2 for f in fits]
        bics = [math.inf if f is None else f.n_params * math.log(n) - 2 * ll
                for f, ll in zip(fits, lls)]
        best_k = int(np.argmin(bics))
        chosen = fits[best_k]
        if chosen is None:  # never: the no-finger fit always exists and has a finite BIC
            raise RuntimeError("inversion: no fit to choose")
        if self.press_check and chosen.fingers and "contact" in m.modes:
            # the count is chosen; now whether its hovering fingers press (the mode)
            chosen = self._pressing(m, delta, sigma, chosen)
            lls[best_k] = const - 0.5 * chosen.chi2
            bics[best_k] = chosen.n_params * math.log(n) - 2 * lls[best_k]
        result = build_result(m, chosen, w, lls[best_k], bics, self._sigma,
                              self._point_sigma if any(self.bound_error) else None)
        if not ok.all():  # the fitted readout on every channel, NaN where left out
            fitted, hat = np.full(ok.size, np.nan), np.full(ok.size, np.nan)
            fitted[ok], hat[ok] = result.fitted, result.leverage
            result = dataclasses.replace(result, fitted=fitted, leverage=hat)
        return result

    def with_bound_error(self, bound_error: tuple[float, float]) -> Inversion:
        """This inversion (its fields, tables and options shared) with ``bound_error`` (a pF, r)
        in place of its own: the fits are the same, the points', forces' and heights' standard
        errors those of that model error (module docstring)."""
        other = copy.copy(self)
        other.bound_error = check_floor("bound_error", bound_error)
        return other

    def _overlap(self, m: StateModel, fit: Fit) -> bool:
        """Whether the two fingers of ``fit`` lie on one face with their fingertips' centres
        closer than ``min_separation_mm`` (their lateral distance and the difference of their
        heights above the skin: 0 pressing, h hovering)."""
        (fa, ma, xa), (fb, mb, xb) = fit.fingers
        if fa != fb or self.min_separation_mm <= 0:
            return False
        ha = math.exp(xa[2]) if MODES[ma] == "hover" else 0.0
        hb = math.exp(xb[2]) if MODES[mb] == "hover" else 0.0
        return math.hypot(xa[0] - xb[0], xa[1] - xb[1], ha - hb) < self.min_separation_mm

    def _passes(self, fit: Fit | None, k: int, nb: int, n: int) -> bool:
        """Whether the k-finger fit explains the frame of n channels within the noise (the
        gate)."""
        if fit is None or not self.gate_p:
            return False
        return fit.chi2 <= _chi2_gate(n - fit.n_params, self.gate_p)

    def _sigma(self, m: StateModel, y: np.ndarray, w: int) -> np.ndarray:
        return widened_sigma(m, y, w, self.model_error)

    def _point_sigma(self, m: StateModel, y: np.ndarray, w: int) -> np.ndarray:
        """The points', forces' and heights' noise: the fit's, widened by ``bound_error``."""
        return widened_sigma(m, y, w, self.model_error, self.bound_error)

    def _starts(self, m: StateModel, delta: np.ndarray, k: int,
                one: Fit | None) -> list[list[tuple[int, int, np.ndarray]]]:
        """Starting points of a k-finger fit, best first: for one finger the nearest node of
        each face and mode; for two the best pair of nodes (:meth:`NodeTable.pairs`), the
        one-finger solution with the node nearest what it leaves, (``scaled_pairs``) the best
        pair with each node's signal scaled by its best factor, then the next pairs."""
        t = m.table

        def node(i: int) -> tuple[int, int, np.ndarray]:
            return int(t.face[i]), int(t.mode[i]), t.x[i].copy()

        if k == 1:
            return [[node(i)] for i in t.starts(delta, self.starts, m.scale_w)]
        # the best pair as the nodes are, then (scaled_pairs) the best with each node's size
        # left free (two fingers screen each other), then the next as they are
        plain = t.pairs(delta, self.starts)
        pairs = plain[:1]
        if self.scaled_pairs:
            pairs += [p for p in t.pairs(delta, 1, scaled=True) if p not in pairs]
        out = [[node(i), node(j)] for i, j in pairs + [p for p in plain[1:] if p not in pairs]]
        if one is not None:
            fi, mi, x = one.fingers[0]
            rest = delta - m.signal(m.faces[fi], MODES[mi], x)[0]
            out.insert(1, [(fi, mi, x.copy()), node(t.starts(rest, 1, m.scale_w)[0])])
        return out[: self.starts + 1]

    def _pressing(self, m: StateModel, delta: np.ndarray, sigma: np.ndarray, fit: Fit) -> Fit:
        """``fit`` with each hovering finger refitted pressing, in turn (``press_check``)."""
        lo_f = float(m.field.spec.force_range_n[0])
        for j, (fi, mi, x) in enumerate(fit.fingers):
            if MODES[mi] != "hover":
                continue
            start = [(a, b, y.copy()) for a, b, y in fit.fingers]
            start[j] = (fi, MODES.index("contact"), np.array([x[0], x[1], lo_f]))
            alt = self._fit_fingers(m, delta, sigma, start, self.coupled)
            dof = max(1, m.n_pairs - fit.n_params)
            tol = self.contact_bias * max(1.0, fit.chi2 / dof)
            # at the field's lowest height the fit would go lower still: the finger touches
            pinned = x[2] <= m.bounds[(m.faces[fi], "hover")][0][2] + PINNED_LN_H
            if not pinned and len(fit.fingers) > 1 and alt.chi2 > fit.chi2 + tol:
                # pressing there does not fit: from the pressing node nearest what the other
                # leaves, kept where it fits better than hovering (it moves the finger: no bias)
                t, press = m.table, MODES.index("contact")
                rest = delta - sum((m.signal(m.faces[a], MODES[b], y)[0] for i, (a, b, y)
                                    in enumerate(fit.fingers) if i != j), np.zeros_like(delta))
                for i in [n for n in t.starts(rest, len(t.groups), m.scale_w)
                          if t.mode[n] == press][:1]:
                    alt = self._fit_fingers(m, delta, sigma, start[:j] + [
                        (int(t.face[i]), press, t.x[i].copy())] + start[j + 1:], self.coupled)
                    tol = 0.0
            if pinned or alt.chi2 <= fit.chi2 + tol:
                fit = alt
        return fit

    @staticmethod
    def _fit_none(m: StateModel, delta: np.ndarray, sigma: np.ndarray) -> Fit:
        nb = m.N.shape[1]
        Nw = np.vstack([m.N / sigma[:, None], np.diag(m.prior_w)])
        z = np.concatenate([delta / sigma, np.zeros(nb)])
        beta = np.linalg.lstsq(Nw, z, rcond=None)[0] if nb else np.zeros(0)
        r = z - Nw @ beta
        return Fit([], beta, float(r @ r), True)

    #: one Levenberg–Marquardt fit from a start (:func:`ectskin.inversion.lm.fit_fingers`)
    _fit_fingers = staticmethod(fit_fingers)


@functools.lru_cache(maxsize=64)
def _chi2_gate(dof: int, p: float) -> float:
    """The upper ``p`` quantile of χ² with ``dof`` degrees of freedom (inf if dof < 1)."""
    return float(chi2.isf(p, dof)) if dof >= 1 else math.inf


def _state(name: str, value: Any) -> tuple[float, ...]:
    try:
        s = tuple(float(x) for x in np.atleast_1d(np.asarray(value, dtype=np.float64)))
    except (TypeError, ValueError):
        raise EctskinError(f"Inversion: {name} must be an inflation vector (ml), got {value!r}") from None
    if not all(math.isfinite(x) for x in s):
        raise EctskinError(f"Inversion: {name} must be finite, got {list(s)}")
    return s


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return len(a) == len(b) and all(abs(x - y) <= STATE_TOL_ML for x, y in zip(a, b))
