"""Calibrated capacitance, paper Eq. 2: c = (c_t − c_0) / c_0, against an explicit reference c_0.

This is the only place Eq. 2 is written: :func:`relative_change` is the bare kernel (the twin's
characterisation and the live engine call it), :func:`calibrate` the checked version that
datasets use. It lives in ``io`` because calibrating a recording is part of bringing it in, and
every layer above (twin characterisation, learning, live) uses it.

The paper calibrates every readout against a *reference state*: the uninflated, untouched
manipulator for touch recognition, and the first frame of each trajectory for deformation tracking
("prior knowledge", §4.2). This module holds Eq. 2 itself and the choice of the touch reference;
the tracking reference (first frame per trajectory) is taken in :mod:`ectskin.learn.data`.

A reference is checked before it is divided by: a zero, tiny or non-finite c_0 is an
:class:`~ectskin.EctskinError` naming the channel, and a non-finite frame is an error naming the
trial, the frame index and the channel. Nothing here ever returns a silent inf or NaN.

Where references come from (``reference`` argument of :func:`touch_reference`):

``"auto"``   every trial carries its own ``trial.meta["reference"]`` (generic imports with a
             reference field, see ``docs/import-format.md``) → those; otherwise ``"rest"``.
``"rest"``   the mean readout of the rest state: the trial(s) with inflation all 0 ml and no
             contact (``meta["kind"] == "no_contact"``, or region 0 with all labels 0). A
             recording with no inflation information at all (every ``trial.inflation == ()``, a
             non-inflatable skin) uses its no-contact trials. Error if there is none.
``"meta"``   ``trial.meta["reference"]`` of every trial (error if one lacks it).
``"state"``  the mean readout of the no-contact trial(s) of each trial's own inflation state
             (:func:`ectskin.io.inflation_reference.state_reference`; error naming a state
             without one).
``"inflation"``  c_0(p) predicted from each trial's inflation by an
             :class:`~ectskin.io.inflation_reference.InflationModel` fitted on the rest readouts
             of the recording's states; an :class:`InflationModel` given instead (e.g. the one a
             trained run stores) is applied as it is.
``"state-offset"``, ``"inflation-offset"``  c_0(p) as "state" / "inflation", but Eq. 2 divides
             by the rest state's readout: c = (c_t − c_0(p)) / c_0(0). This function returns
             c_0(p); the divisor is :func:`reference_divisor`.
array        an explicit (n_pairs,) reference in the recording's units (pF); only the measured
             channels are used (an unmeasured one may be NaN).

"rest" is the paper's Eq. 2 (one reference for every trial); "state" and "inflation" follow the
inflation the pump sets (:mod:`ectskin.io.inflation_reference`).

**Readouts that are already differences** (difference imaging; a generic import with
``readouts="difference"``, ``docs/import-format.md``): the recording's ``meta["readouts"]`` is
``"difference"`` (:func:`is_difference`). Eq. 2 has no reference to divide by: the calibrated
readout is the difference itself (``reference=None`` in :func:`calibrate`, the identity), every
trial's touch reference is None, and an explicit reference array is refused.

:func:`own_reference` says which of these a recording carries itself ("meta", "rest",
"difference" or None);
:func:`rest_reference` is the rest-state mean alone (what a trained run stores, so that it can
calibrate a recording without a rest state of its own); :func:`choose_reference` picks among a
reference recording given, the recording's own and a stored one, and says which it took.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.inflation_reference import InflationModel, state_reference
from ectskin.io.recording import Recording, Trial

log = logging.getLogger(__name__)

REFERENCE_OPTIONS = (
    "auto",
    "rest",
    "meta",
    "state",
    "inflation",
    "state-offset",
    "inflation-offset",
)
#: ``rec.meta["readouts"]`` of a recording whose readouts are differences (difference imaging)
DIFFERENCE = "difference"

#: A reference channel is "tiny" when |c_0| <= REFERENCE_RTOL * max_j |c_0,j|: dividing by it
#: would turn readout noise into huge calibrated values. Readouts of one skin span at most a few
#: decades, never six.
REFERENCE_RTOL = 1e-6


def _channel(j: int, pair_names: Sequence[str] | None) -> str:
    if pair_names is not None and j < len(pair_names):
        return f"channel {j} ({pair_names[j]!r})"
    return f"channel {j}"


def check_reference(
    reference: np.ndarray,
    n_pairs: int,
    *,
    source: str = "reference",
    pair_names: Sequence[str] | None = None,
) -> np.ndarray:
    """Check a reference c_0 for Eq. 2 and return it as float64.

    Parameters
    ----------
    reference : (n_pairs,) or (n_frames, n_pairs) array, pF
        One reference for all frames, or one per frame.
    n_pairs : int
        Expected channel count.

    Raises
    ------
    EctskinError
        Wrong shape, non-numeric, or a channel whose reference is non-finite, zero or tiny
        (|c_0| <= ``REFERENCE_RTOL`` × the largest |c_0|): the message names the channel.
    """
    try:
        ref = np.asarray(reference, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{source}: reference must be numeric; {exc}") from None
    if ref.ndim not in (1, 2) or ref.shape[-1] != n_pairs:
        raise EctskinError(
            f"{source}: reference must have shape ({n_pairs},) or (n_frames, {n_pairs}), "
            f"got {ref.shape}"
        )
    rows = ref.reshape(-1, n_pairs)
    scale = np.max(np.abs(np.where(np.isfinite(rows), rows, 0.0)), axis=1, initial=0.0)
    # non-finite, or |c_0| tiny next to the largest channel of the same reference row
    bad = ~np.isfinite(rows) | (np.abs(rows) <= REFERENCE_RTOL * scale[:, None])
    if bad.any():
        r, j = (int(v) for v in np.argwhere(bad)[0])
        where_ = f"{source}: reference" + (f" of frame {r}" if ref.ndim == 2 else "")
        if not np.isfinite(rows[r, j]):
            raise EctskinError(
                f"{where_}, {_channel(j, pair_names)} is {rows[r, j]}; Eq. 2 needs a finite, "
                f"non-zero reference readout"
            )
        raise EctskinError(
            f"{where_}, {_channel(j, pair_names)} is {rows[r, j]:.6g} (largest channel "
            f"{scale[r]:.6g}); Eq. 2 divides by the reference, expected a non-zero readout"
        )
    return ref


def relative_change(c_t: np.ndarray, c_0: np.ndarray) -> np.ndarray:
    """Paper Eq. 2 without checks: ``(c_t − c_0) / c_0`` in float64, broadcasting ``c_0``.

    ``c_t`` is (..., n_pairs) pF, ``c_0`` (n_pairs,) or of ``c_t``'s shape. A NaN in either
    propagates; callers check the reference first (:func:`check_reference`) or mask channels.
    """
    c_t = np.asarray(c_t, dtype=np.float64)
    c_0 = np.asarray(c_0, dtype=np.float64)
    return (c_t - c_0) / c_0


def is_difference(rec: Recording) -> bool:
    """Whether the readouts of ``rec`` are already differences (``meta["readouts"]``): Eq. 2 is
    then the identity on them (module docstring)."""
    return rec.meta.get("readouts") == DIFFERENCE


def calibrate(
    frames: np.ndarray,
    reference: np.ndarray | None,
    *,
    source: str = "frames",
    pair_names: Sequence[str] | None = None,
    allow_nonfinite: bool = False,
) -> np.ndarray:
    """Calibrated capacitance by paper Eq. 2: c = (c_t − c_0) / c_0.

    Parameters
    ----------
    frames : (n_frames, n_pairs) or (n_pairs,) array
        Raw readouts c_t, pF (any unit: Eq. 2 is a ratio).
    reference : (n_pairs,) or (n_frames, n_pairs) array, or None
        Reference readouts c_0 in the same unit, one for all frames or one per frame. None:
        the frames are already differences (difference imaging), returned as they are (the
        identity; checked as above).
    source : str
        Where the frames come from, for error messages, e.g. ``"trial 'touch_003'"``.
    pair_names : sequence of str, optional
        Channel names for error messages.
    allow_nonfinite : bool
        If False (default) a non-finite frame value is an error naming the frame and channel.
        If True such values propagate as NaN (the caller drops those frames).

    Returns
    -------
    (n_frames, n_pairs) or (n_pairs,) float32
        Relative change, dimensionless (0.4 = +40 %).
    """
    try:
        c_t = np.asarray(frames, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{source}: readouts must be numeric; {exc}") from None
    single = c_t.ndim == 1
    if single:
        c_t = c_t[None, :]
    if c_t.ndim != 2:
        raise EctskinError(
            f"{source}: readouts must have shape (n_frames, n_pairs), got {c_t.shape}"
        )
    n, n_pairs = c_t.shape
    c_0 = (
        None
        if reference is None
        else check_reference(reference, n_pairs, source=source, pair_names=pair_names)
    )
    if c_0 is not None and c_0.ndim == 2 and c_0.shape[0] != n:
        raise EctskinError(
            f"{source}: a per-frame reference must have {n} rows (one per frame), got {c_0.shape[0]}"
        )
    finite = np.isfinite(c_t)
    if not allow_nonfinite and not finite.all():
        i, j = (int(v) for v in np.argwhere(~finite)[0])
        raise EctskinError(
            f"{source}: frame {i}, {_channel(j, pair_names)} is {c_t[i, j]}; calibrated readouts "
            f"must be finite (drop masked frames, e.g. touch_dataset(..., nonfinite='drop'))"
        )
    c = c_t if c_0 is None else relative_change(c_t, c_0)  # Eq. 2 (identity on differences)
    # float32 cannot hold everything float64 can: refuse an overflow rather than return inf.
    big = finite & (np.abs(c) > np.finfo(np.float32).max)
    if big.any():
        i, j = (int(v) for v in np.argwhere(big)[0])
        raise EctskinError(
            f"{source}: frame {i}, {_channel(j, pair_names)} calibrates to {c[i, j]:.3g}, too "
            f"large for float32; is the reference in the same unit as the readouts?"
        )
    out = c.astype(np.float32)
    return out[0] if single else out


# --------------------------------------------------------------------------- references
def is_no_contact(trial: Trial) -> bool:
    """True for a trial without contact: ``meta["kind"] == "no_contact"``, or (when the trial has
    no ``kind``) region 0 with every frame labelled 0."""
    kind = trial.meta.get("kind")
    if kind is not None:
        return kind == "no_contact"
    return trial.region == 0 and not np.any(trial.labels)


def untouched_readouts(rec: Recording, states: Iterable[Sequence[float]],
                       exclude: Sequence[str] = (), tol_ml: float = 1e-6
                       ) -> dict[tuple[float, ...], dict[str, Any]]:
    """{state: {"pF": (n_pairs,) mean readout, "trials": names}} of every state of ``states``
    (inflation vectors, ml; a trial's state within ``tol_ml`` of one) that has a no-contact trial
    in ``rec`` (:func:`is_no_contact`) not in ``exclude``: the mean of their frames, per channel
    over the finite readouts. A state without one, or with a channel never read, is left out."""
    keys = [tuple(float(x) for x in s) for s in states]
    found: dict[tuple[float, ...], list[Trial]] = {}
    skip = set(exclude)
    for t in rec.trials:
        if t.name in skip or not is_no_contact(t):
            continue
        infl = np.asarray(t.inflation, float)
        for state in keys:
            if len(state) == infl.size and np.all(np.abs(np.asarray(state) - infl) < tol_ml):
                found.setdefault(state, []).append(t)
    out = {}
    for state, trials in found.items():
        frames = np.concatenate([t.capacitance for t in trials], axis=0)
        ok = np.isfinite(frames)
        if not ok.any(axis=0).all():
            continue
        mean = np.where(ok, frames, 0.0).sum(axis=0) / ok.sum(axis=0)
        out[state] = {"pF": mean, "trials": [t.name for t in trials]}
    return out


def is_uninflated(trial: Trial) -> bool:
    """True when the trial's inflation vector is known and all zero (ml)."""
    return len(trial.inflation) > 0 and all(v == 0 for v in trial.inflation)


def rest_trials(rec: Recording) -> list[Trial]:
    """The rest-state trials of ``rec``: uninflated (all chambers 0 ml) and without contact.

    A recording without any inflation information (every ``trial.inflation == ()``) is taken as
    a non-inflatable skin: its no-contact trials are the rest state.
    """
    if all(len(t.inflation) == 0 for t in rec.trials):
        return [t for t in rec.trials if is_no_contact(t)]
    return [t for t in rec.trials if is_no_contact(t) and is_uninflated(t)]


def meta_reference(trial: Trial, n_pairs: int, channels: np.ndarray | None = None) -> np.ndarray:
    """A trial's own reference ``trial.meta["reference"]`` as (n_pairs,) float64 (None → NaN).

    ``channels`` (indices) selects the measured channels before the check.
    """
    src = f"trial {trial.name!r}"
    if "reference" not in trial.meta:
        raise EctskinError(f"{src}: meta has no 'reference' (expected one per trial)")
    raw = trial.meta["reference"]
    try:
        ref = np.array([np.nan if v is None else v for v in raw], dtype=np.float64)
    except (TypeError, ValueError):
        raise EctskinError(f"{src}: meta['reference'] must be a list of numbers") from None
    if ref.shape != (trial.n_pairs,):
        raise EctskinError(
            f"{src}: meta['reference'] must hold {trial.n_pairs} values (one per channel), "
            f"got shape {ref.shape}"
        )
    if channels is not None:
        ref = ref[channels]
    return check_reference(ref, ref.shape[0], source=src)


def touch_reference(
    rec: Recording,
    *,
    reference: str | np.ndarray | InflationModel = "auto",
    channels: np.ndarray | None = None,
) -> dict[str, Any]:  # (n_kept,) arrays; None for differences
    """The touch-recognition reference c_0 of every trial (see the module docstring).

    Parameters
    ----------
    rec : Recording
    reference : "auto" | "rest" | "meta" | "state" | "inflation" | InflationModel | (n_pairs,)
        array
    channels : (n_kept,) int array, optional
        Measured channel indices; the references returned are restricted to them.

    Returns
    -------
    dict trial name → (n_kept,) float64 reference, pF; None for every trial of a recording of
    differences (:func:`is_difference`: Eq. 2 is the identity, any ``reference`` option but an
    array is accepted and means none).
    """
    keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
    names = [rec.layout.pair_names[j] for j in keep]
    if is_difference(rec):
        if not isinstance(reference, str):
            found = "a model" if isinstance(reference, InflationModel) else "an array"
            raise EctskinError(
                "reference: the recording's readouts are differences (meta 'readouts': "
                f"'difference'): Eq. 2 takes no reference, expected none, found {found}"
            )
        return {t.name: None for t in rec.trials}
    if isinstance(reference, InflationModel):
        refs = reference.references(rec, keep)
        return {
            n: check_reference(
                r, keep.size, source=f"trial {n!r}: inflation reference", pair_names=names
            )
            for n, r in refs.items()
        }
    if not isinstance(reference, str):
        try:
            full = np.asarray(reference, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise EctskinError(f"reference: reference must be numeric; {exc}") from None
        if full.shape != (rec.n_pairs,):
            raise EctskinError(f"reference must have shape ({rec.n_pairs},), got {full.shape}")
        ref = check_reference(full[keep], keep.size, source="reference", pair_names=names)
        return {t.name: ref for t in rec.trials}
    if reference not in REFERENCE_OPTIONS:
        raise EctskinError(
            f"Invalid value for 'reference': allowed values are "
            f"{', '.join(repr(o) for o in REFERENCE_OPTIONS)} or an array of {rec.n_pairs} "
            f"readouts; got {reference!r}"
        )
    if reference == "meta" or (reference == "auto" and own_reference(rec) == "meta"):
        return {t.name: meta_reference(t, rec.n_pairs, keep) for t in rec.trials}
    if reference in ("state", "state-offset"):
        return {
            n: check_reference(
                r, keep.size, source=f"trial {n!r}: state reference", pair_names=names
            )
            for n, r in state_reference(rec, keep).items()
        }
    if reference in ("inflation", "inflation-offset"):
        divisor = "own" if reference == "inflation" else "rest"
        model = InflationModel.fit(rec, keep, divisor=divisor)
        return touch_reference(rec, reference=model, channels=channels)
    ref, _ = rest_reference(rec, channels=keep)
    return {t.name: ref for t in rec.trials}


def reference_divisor(
    rec: Recording, reference: Any, channels: np.ndarray | None = None
) -> np.ndarray | None:
    """What Eq. 2 divides by when it is not the reference c_0(p) itself: the rest state's
    readout c_0(0), (n_kept,) pF, for "state-offset" (the rest state of ``rec``) and an
    :class:`InflationModel` of divisor "rest" (its prediction at 0 ml); None otherwise."""
    keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
    names = [rec.layout.pair_names[j] for j in keep]
    if is_difference(rec):
        return None
    if isinstance(reference, InflationModel) and reference.divisor == "rest":
        return check_reference(
            reference.rest_readout()[keep],
            keep.size,
            source="inflation model at 0 ml",
            pair_names=names,
        )
    if isinstance(reference, str) and reference == "state-offset":
        return rest_reference(rec, channels=keep)[0]
    return None


def own_reference(rec: Recording) -> str | None:
    """The reference ``rec`` carries itself: "difference" (its readouts are differences and need
    none), "meta" (every trial has ``meta["reference"]``), "rest" (a rest-state trial,
    :func:`rest_trials`) or None (neither: it needs one from elsewhere, e.g. the rest state of
    another recording of the same skin)."""
    if is_difference(rec):
        return DIFFERENCE
    if rec.trials and all("reference" in t.meta for t in rec.trials):
        return "meta"
    return "rest" if rest_trials(rec) else None


def rest_reference(
    rec: Recording, *, channels: np.ndarray | None = None
) -> tuple[np.ndarray, list[str]]:
    """The rest-state reference of ``rec``: the mean readout of its rest-state trials
    (:func:`rest_trials`; per channel over the finite readouts), restricted to ``channels``;
    with the names of the trials averaged. An error when there is none."""
    keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
    names = [rec.layout.pair_names[j] for j in keep]
    rest = rest_trials(rec)
    if not rest:
        where_ = f"{rec.source}: " if getattr(rec, "source", None) else ""
        raise EctskinError(
            f"{where_}recording has no rest-state trial (inflation all 0 ml and no contact) to "
            "calibrate against (paper Eq. 2); record one (inflation 0 ml, no touch), import the "
            "file with a reference field (docs/import-format.md) or, in Python, pass "
            f"reference=<array of {rec.n_pairs} readouts>"
        )
    frames = np.concatenate([t.capacitance[:, keep] for t in rest], axis=0)
    if not np.all(np.isfinite(frames)):
        # the mean of masked frames would be NaN: average only the finite readouts per channel
        count = np.isfinite(frames).sum(axis=0)
        if (count == 0).any():
            j = int(np.argmax(count == 0))
            raise EctskinError(
                f"rest-state trial(s) {[t.name for t in rest]}: {_channel(j, names)} has no "
                f"finite readout to use as reference"
            )
        ref = np.nanmean(frames, axis=0)
    else:
        ref = frames.mean(axis=0)
    log.info(
        "touch reference: mean of %d frames of rest-state trial(s) %s",
        frames.shape[0],
        ", ".join(t.name for t in rest),
    )
    ref = check_reference(ref, keep.size, source="rest-state reference", pair_names=names)
    return ref, [t.name for t in rest]


@dataclass(frozen=True)
class ReferenceChoice:
    """The reference chosen by :func:`choose_reference`: ``value`` as the data sets take it
    (``reference=``: "auto", or an (n_pairs,) array, NaN on unmeasured pairs), its ``source``
    ("recording": the recording's own; "file": another recording given; "run": one stored with
    a trained model; "trajectory": each trajectory's first frame), the rest-state ``trials``
    averaged, the ``file`` it came from and a sentence saying so."""

    value: Any
    source: str
    text: str
    trials: list[str] = field(default_factory=list)
    file: str | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"source": self.source, "text": self.text, "trials": self.trials}
        if self.file is not None:
            out["file"] = self.file
        return out


def choose_reference(
    rec: Recording,
    *,
    given: Recording | None = None,
    given_name: str | None = None,
    stored: tuple[np.ndarray, list[str]] | None = None,
    stored_from: str = "the training recording",
    channels: np.ndarray | None = None,
    source: str = "data",
) -> ReferenceChoice:
    """The touch reference to calibrate ``rec`` (called ``source`` in messages) with: the rest
    state of ``given`` (another recording of the same skin) if given; else ``rec``'s own
    (:func:`own_reference`: per-trial references or its rest-state trials); else ``stored``
    ((n_pairs,) pF with its rest-state trials, kept from ``stored_from``); else an error.
    ``channels``: the measured channels of ``rec`` (the others are NaN in an array value)."""
    keep = np.arange(rec.n_pairs) if channels is None else np.asarray(channels)
    if is_difference(rec):
        if given is not None:
            raise EctskinError(
                f"--reference does not apply to {source}: its readouts are differences "
                "(difference imaging), Eq. 2 takes no reference"
            )
        text = f"none: the readouts of {source} are differences (Eq. 2 is the identity on them)"
        return ReferenceChoice("auto", "recording", text)
    if given is not None:
        name = given_name or "the given recording"
        if list(given.layout.pair_names) != list(rec.layout.pair_names):
            raise EctskinError(
                f"reference {name}: its pairs {list(given.layout.pair_names)[:3]}... are not "
                f"those of {source} {list(rec.layout.pair_names)[:3]}..."
            )
        ref, trials = rest_reference(given, channels=keep)
        full = np.full(rec.n_pairs, np.nan)
        full[keep] = ref
        text = f"the rest state of {name} (--reference; trial(s) {', '.join(trials[:5])})"
        return ReferenceChoice(full, "file", text, trials, name)
    own = own_reference(rec)
    if own == "meta":
        return ReferenceChoice("auto", "recording", f"the per-trial references of {source}")
    if own == "rest":
        trials = [t.name for t in rest_trials(rec)]
        text = f"the rest state of {source} itself (trial(s) {', '.join(trials[:5])})"
        return ReferenceChoice("auto", "recording", text, trials)
    if stored is None:
        raise EctskinError(
            f"{source}: has no rest-state trial (inflation all 0 ml and no contact) to calibrate "
            "against (paper Eq. 2)"
        )
    values, trials = stored
    text = (
        f"the rest state of the training recording, stored in the run ({stored_from}, trial(s) "
        f"{', '.join(trials[:5])}): {source} has no rest-state trial of its own"
    )
    return ReferenceChoice(values, "run", text, list(trials), stored_from)
