"""The contact model choice of the reproduction's inversion step, on the states with a field.

Candidates, each scored by the same function (:func:`ectskin.learn.tasks.contact.contact_report`)
on the same frames:

==============  ==========================================================================
the run's name  the contact run's own model (``runs/contact``: ContactNet, ``contactnet``, or
                the classical model its ``candidates.json`` selects), on its own windows
                (its window and Eq. 2 reference, :func:`ectskin.learn.evaluate.calibration`)
``knn``         the run's k-NN baseline, fit again on the run's training trials with the run's
``ridge``       seed (and ridge): the same fit as the run's evaluation makes
                (:func:`ectskin.learn.contact_classical.fit_contact_classical`, at most
                :data:`~ectskin.learn.baselines.contact.MAX_TRAIN` frames)
``inversion``   the training-free inversion (:mod:`ectskin.inversion`), as the step runs it
``hybrid``      the same inversion seeded with the run's model's answer for the same frame
                (:func:`seeds_from_predictions`: its first finger as a one-finger start, and
                both fingers as a two-finger start where it counts two)
==============  ==========================================================================

**Selection is on validation frames only**: those of the run's validation trials in states with
a field, spread as the step spreads the test frames, at most :data:`CHOICE_FRAMES`, by the
mean point error over the skin of the frames with one finger and the **one-standard-error
rule** (:data:`RULE`; Breiman et al., *CART*; Hastie et al., *ESL* §7.10): of the candidates
whose mean is within one standard error of the lowest, the simplest
(:data:`SIMPLICITY`) is chosen. The standard error is that of the *paired* difference between
a candidate's and the lowest one's per-frame errors on the same frames
(:func:`~ectskin.learn.tasks.contact.point_errors`): sd of the differences / √n
(:func:`paired_se`). A difference the frames' sampling could make does not buy the more complex
model; the paired error is the one that counts, since every candidate answers the same frames
and their errors move together (a hard frame is hard for all). Every candidate's test numbers
are then those on the step's test frames. The run's model and its baselines are candidates, so
the selected model's validation error exceeds theirs by at most one paired standard error.

The choice covers the frames of states with a response field only: a frame of a state without
one can only be answered by the learned model (``answers`` says which share of the test frames
each answers).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.inversion import FingerGuess
from ectskin.io import Recording
from ectskin.learn.baselines.contact import MAX_TRAIN
from ectskin.learn.contact_classical import fit_contact_classical
from ectskin.learn.data.contact import MAX_FINGERS, ContactData, contact_dataset
from ectskin.learn.evaluate import calibration, read_run
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.learn.tasks.contact import contact_report, point_errors
from ectskin.pipeline.bound import state_key

log = logging.getLogger(__name__)

__all__ = ["BASELINES", "CHOICE_FRAMES", "LEARNED", "METRIC", "RULE", "SIMPLICITY",
           "LearnedModel", "choose", "load_learned", "one_se_choice", "paired_se", "score",
           "scored", "seeds_from_predictions"]

#: validation frames (at most, evenly spread over all frames of the field states' validation
#: trials, as the test frames) that choose
CHOICE_FRAMES = 480
#: the run's baselines that are candidates
BASELINES = ("ridge", "knn")
#: the inversion's two candidates, after the run's model and its baselines in the tie order
INVERSIONS = ("inversion", "hybrid")
METRIC = "validation point error, mm (mean over the skin, frames with one finger)"
#: the rule that chooses (metrics.json's ``inversion.choice.rule``; :func:`one_se_choice`)
RULE = "one standard error (paired)"
#: the rule where a candidate's per-frame errors are missing: the lowest mean
PLAIN_RULE = "lowest mean"
#: stands for the run's own model in :data:`SIMPLICITY`, whatever the run names it (a candidate
#: not named there takes this place)
LEARNED = "learned"
#: the candidates from the simplest: the one-standard-error rule takes the first of those within
#: one standard error of the lowest. The classical baselines first (``ridge``, a linear map of
#: the readout, then ``knn``, the training frames themselves: a closed-form fit, no field, no
#: iteration); then the training-free ``inversion`` (nothing fit to the recording: the physics
#: field and a fit per frame); then the run's model (trained on the recording's frames: its
#: weights, epochs, seed and normaliser); then the ``hybrid``, which needs both the trained model
#: and the inversion.
SIMPLICITY = ("ridge", "knn", "inversion", LEARNED, "hybrid")
#: the metrics kept per candidate and split
SCORE_KEYS = ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "face_accuracy", "force_mae_n",
              "count_accuracy", "contact_accuracy", "hover_detect_mm", "n_single_contact_frames")

#: (data, rows, seeds or None) → (the inversion's prediction columns, seconds per frame)
Invert = Callable[[ContactData, np.ndarray, Sequence[Any] | None], tuple[np.ndarray, np.ndarray]]


class LearnedModel:
    """The model a contact run answers with, on frames of a recording: its name, window and
    Eq. 2 reference (those the run's evaluation uses), and :meth:`predict`."""

    def __init__(self, run_dir: str | Path, rec: Recording, source: str) -> None:
        run = read_run(run_dir)
        if run.task.name != "contact":
            raise EctskinError(f"{run_dir}: not a contact run (task {run.task.name!r})")
        self.run = run
        self.name = str(run.selected)
        self.window = int(run.config.window)
        self.reference = calibration(run, rec, None, source).value
        self.rec = rec

    def windows(self, data: ContactData, rows: np.ndarray) -> ContactData:
        """The samples ``rows`` of ``data`` (samples of this recording, any window) rebuilt
        with the run's window and reference."""
        rows = np.asarray(rows, dtype=np.int64)
        groups = np.unique(data.group[rows])
        own = contact_dataset(self.rec, window=self.window, reference=self.reference,
                              trials=[data.group_names[g] for g in groups])
        # a trial's samples are its frames in order: sample = the trial's first + the frame
        first = np.searchsorted(own.group, np.arange(groups.size))
        idx = first[np.searchsorted(groups, data.group[rows])] + data.frame[rows]
        if (idx.size and idx.max() >= own.n_samples) or not (
                np.array_equal(own.frame[idx], data.frame[rows])
                and np.array_equal(np.asarray(own.group_names)[own.group[idx]],
                                   np.asarray(data.group_names)[data.group[rows]])):
            raise EctskinError("contact choice: the run's samples of the trials do not line up "
                               "with the step's (another recording?)")
        return own.take(idx)

    def predict(self, sub: ContactData) -> np.ndarray:
        """The run's prediction columns (:data:`~ectskin.learn.models.contact.PRED_COLUMNS`,
        then per slot :data:`~ectskin.learn.models.contact.SLOT_COLUMNS`) of samples made by
        :meth:`windows`."""
        if self.run.classical is not None:
            return np.asarray(self.run.classical.predict(sub.x), dtype=np.float64)
        if self.run.model is None:  # never: read_run loads model.pt unless a classical answers
            raise EctskinError(f"{self.run.path}: the run has no model to answer with")
        return np.asarray(self.run.task.predict(self.run.model, sub), dtype=np.float64)


def load_learned(run_dir: str | Path, rec: Recording, source: str) -> LearnedModel:
    """The contact run's model (:class:`LearnedModel`) on ``rec`` (read from ``source``)."""
    return LearnedModel(run_dir, rec, source)


def fit_baselines(learned: LearnedModel, train_trials: Sequence[str], seed: int
                  ) -> dict[str, Any]:
    """{name: fitted model} of :data:`BASELINES` on the run's training trials (in the
    recording's order, as the run's evaluation takes them: the seeded subsample picks the same
    frames), each frame calibrated as the run's (they read the window's last frame alone:
    window 1 is the same)."""
    wanted = set(train_trials)
    names = [t.name for t in learned.rec.trials if t.name in wanted]  # in the recording's order
    if not names:
        return {}
    train = contact_dataset(learned.rec, window=1, reference=learned.reference, trials=names)
    return {name: fit_contact_classical(name, train, seed=seed, max_train=MAX_TRAIN)[0]
            for name in BASELINES}


def seeds_from_predictions(pred: np.ndarray, faces: Sequence[str], *, pressing_only: bool = True
                           ) -> list[list[list[FingerGuess]]]:
    """Per row of a learned model's prediction columns, the seeds of the hybrid: the first
    slot's finger pressing at its predicted point and force (one finger), and with a predicted
    count of two both slots' fingers (two); ``pressing_only``: none where the model counts no
    finger pressing (its point then guesses nothing). The force is the prediction's, at least 0
    (the inversion clips it into its field's range); a face index outside ``faces`` gives no
    seed."""
    pred = np.asarray(pred, dtype=np.float64)
    if pred.ndim != 2 or pred.shape[1] != len(PRED_COLUMNS) + MAX_FINGERS * len(SLOT_COLUMNS):
        raise EctskinError(f"seeds_from_predictions: pred must have shape (n, "
                           f"{len(PRED_COLUMNS) + MAX_FINGERS * len(SLOT_COLUMNS)}), got "
                           f"{pred.shape}")
    col = {name: i for i, name in enumerate(SLOT_COLUMNS)}
    out: list[list[list[FingerGuess]]] = []
    for row in pred:
        guesses: list[FingerGuess] = []
        count = int(round(row[PRED_COLUMNS.index("count")]))
        for slot in range(MAX_FINGERS if count >= 1 or not pressing_only else 0):
            a = len(PRED_COLUMNS) + slot * len(SLOT_COLUMNS)
            face, u, v = row[a + col["face"]], row[a + col["u_mm"]], row[a + col["v_mm"]]
            force = row[a + col["force_n"]]
            if not (np.isfinite([face, u, v, force]).all() and 0 <= face < len(faces)):
                break
            guesses.append(FingerGuess(str(faces[int(face)]), float(u), float(v),
                                       force_n=max(float(force), 0.0)))
        seeds = [guesses[:1]] if guesses else []
        if len(guesses) >= 2 and count >= 2:
            seeds.append(guesses[:2])
        out.append(seeds)
    return out


def score(data: ContactData, pred: np.ndarray, seconds: np.ndarray | None = None
          ) -> dict[str, Any]:
    """:data:`SCORE_KEYS` of ``pred`` on ``data`` (every row), the point error per state
    (:func:`scored`), with the median time per frame (ms) where ``seconds`` are given."""
    return scored(data, pred, seconds)[0]


def scored(data: ContactData, pred: np.ndarray, seconds: np.ndarray | None = None
           ) -> tuple[dict[str, Any], np.ndarray]:
    """(:func:`score`, the per-frame point errors of the frames with one finger in row order,
    :func:`~ectskin.learn.tasks.contact.point_errors`: their mean is ``loc_mm_mean``). The score
    holds their mean per inflation state too (``per_state_loc_mm_mean``, {"0/20/0 ml": mm}) and
    the worst of those (``worst_state``: [state, mm])."""
    report = contact_report(data, pred, with_maps=False) if data.n_samples else {}
    out: dict[str, Any] = {k: report.get(k) for k in SCORE_KEYS}
    out["n_frames"] = int(data.n_samples)
    if seconds is not None and len(seconds):
        out["ms_per_frame_median"] = float(np.median(seconds) * 1e3)
        out["ms_per_frame_mean"] = float(np.mean(seconds) * 1e3)
    errors = point_errors(data, pred) if data.n_samples else np.zeros(0)
    # the point error per inflation state (the frames with one finger), and the worst state
    state = data.state[data.count == 1] if data.n_samples else np.zeros(0, np.int64)
    per = {state_key(data.states[s]): float(errors[state == s].mean())
           for s in np.unique(state)}
    out["per_state_loc_mm_mean"] = per
    out["worst_state"] = max(per.items(), key=lambda kv: kv[1]) if per else None
    return out, errors


def paired_se(errors: np.ndarray, reference: np.ndarray) -> float | None:
    """The standard error of the mean of the paired differences ``errors − reference`` (the same
    frames in the same order): their sample standard deviation (divisor n − 1) / √n; None with
    fewer than two frames."""
    a, b = np.asarray(errors, dtype=np.float64), np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise EctskinError(f"paired_se: errors and reference must be two 1-D arrays of one "
                           f"length (the same frames), got shapes {a.shape} and {b.shape}")
    if a.size < 2:
        return None
    return float(np.std(a - b, ddof=1) / math.sqrt(a.size))


def _simplicity(name: str, order: Sequence[str]) -> tuple[int, int]:
    slot = SIMPLICITY.index(name) if name in SIMPLICITY else SIMPLICITY.index(LEARNED)
    return slot, list(order).index(name)


def one_se_choice(errors: Mapping[str, float | None], order: Sequence[str],
                  per_frame: Mapping[str, np.ndarray | None] | None = None) -> dict[str, Any]:
    """The one-standard-error rule (module docstring) over the candidates ``order``, from their
    mean validation errors ``errors`` and their per-frame errors ``per_frame`` (the same frames
    for every candidate; their mean must be ``errors``'): {``selected``, ``why``, ``rule``,
    ``best`` (the lowest finite mean; ties: the earlier in ``order``), ``se`` ({name: the standard
    error of its paired difference to the best, 0 for the best, None where it has no per-frame
    errors or fewer than two frames}), ``within`` ({name: whether its mean exceeds the best's by
    at most that}), ``simplicity`` (``order`` from the simplest, :data:`SIMPLICITY`)}.

    Where the best has no per-frame errors (None, or ``per_frame`` None) the lowest mean is
    chosen (``rule`` :data:`PLAIN_RULE`); a candidate without them is chosen only as the best."""
    if not order:
        raise EctskinError("contact choice: no candidates")
    simplest = sorted(order, key=lambda k: _simplicity(k, order))
    out: dict[str, Any] = {"rule": RULE, "best": None, "se": {k: None for k in order},
                           "within": {k: None for k in order}, "simplicity": simplest}
    finite = sorted((float(e), i, k) for i, k in enumerate(order)
                    if (e := errors.get(k)) is not None and math.isfinite(e))
    if not finite:
        return {**out, "selected": order[0], "rule": PLAIN_RULE,
                "why": f"no validation frame with one finger to compare on: the first of "
                       f"{', '.join(order)}"}
    low, _, best = finite[0]
    frames = {k: np.asarray(v, dtype=np.float64) for k, v in (per_frame or {}).items()
              if v is not None}
    for k, v in frames.items():
        mean = float(v.mean()) if v.ndim == 1 and v.size else math.nan
        given = math.nan if errors.get(k) is None else float(errors[k] or 0.0)
        if v.ndim != 1 or not (math.isclose(mean, given, rel_tol=1e-9, abs_tol=1e-12)
                               or math.isnan(mean) and math.isnan(given)):
            raise EctskinError(f"contact choice: the per-frame errors of {k!r} (mean {mean:.6g} "
                               f"over {v.size} frames, shape {v.shape}) do not average to its "
                               f"validation error {given:.6g}")
    out["best"] = best
    if best not in frames:
        why = f"the lowest {METRIC}: {best} {low:.3f}"
        if len(finite) > 1:
            why += f" (next {finite[1][2]} {finite[1][0]:.3f}; no per-frame errors to rule on)"
        return {**out, "selected": best, "rule": PLAIN_RULE, "why": why}
    ref = frames[best]
    for err, _, k in finite:
        if k not in frames:
            continue
        if frames[k].shape != ref.shape:
            raise EctskinError(f"contact choice: {k!r} has per-frame errors of {frames[k].size} "
                               f"frames, the best ({best!r}) of {ref.size}: not the same frames")
        se = 0.0 if k == best else paired_se(frames[k], ref)
        out["se"][k] = se
        out["within"][k] = k == best or (se is not None and err - low <= se)
    chosen = min((k for k in order if out["within"][k]), key=lambda k: _simplicity(k, order))
    means = {k: e for e, _, k in finite}
    rivals = [f"{k} +{means[k] - low:.4f} (SE {out['se'][k]:.4f})" for k in simplest
              if k != best and out["se"][k] is not None
              and _simplicity(k, order) < _simplicity(best, order)]
    if chosen == best:
        why = (f"the lowest {METRIC}: {best} {low:.3f}; no simpler candidate within one paired "
               f"standard error of it" + (f" ({', '.join(rivals)})" if rivals else ""))
    else:
        why = (f"the simplest candidate within one paired standard error of the lowest {METRIC}, "
               f"{best}'s {low:.3f}: {chosen} {means[chosen]:.3f}, "
               f"+{means[chosen] - low:.4f} (SE {out['se'][chosen]:.4f})")
    return {**out, "selected": chosen, "why": why}


def choose(errors: Mapping[str, float | None], order: Sequence[str],
           per_frame: Mapping[str, np.ndarray | None] | None = None) -> tuple[str, str]:
    """(the candidate of ``order`` the one-standard-error rule chooses, the reason in words):
    :func:`one_se_choice`; without ``per_frame``, the lowest finite validation error (ties: the
    earlier in ``order``)."""
    c = one_se_choice(errors, order, per_frame)
    return c["selected"], c["why"]


def contact_choice(
    learned: LearnedModel,
    invert: Invert,
    *,
    val: ContactData | None,
    val_rows: np.ndarray,
    test: ContactData,
    test_rows: np.ndarray,
    inversion_test: tuple[np.ndarray, np.ndarray],
    train_trials: Sequence[str],
    seed: int,
    share_without_field: float | None,
) -> dict[str, Any]:
    """The choice (module docstring): every candidate's validation and test numbers, the
    selection and why, and which model answers which share of the test frames.

    ``val``, ``val_rows``: the validation samples (window 1) and the rows that choose;
    ``test``, ``test_rows``: the step's test samples and the rows it inverted;
    ``inversion_test``: the step's own inversion of those rows (prediction columns, seconds);
    ``invert(data, rows, seeds)``: the step's inversion of other rows (``seeds`` per row, or
    None); ``share_without_field``: the share of the test frames in states without a field.
    """
    t0 = time.perf_counter()
    models = fit_baselines(learned, train_trials, seed)
    t_fit = time.perf_counter() - t0
    # a run whose own model is a baseline (``--model knn``) answers as that baseline does
    order = [learned.name, *[b for b in BASELINES if b in models and b != learned.name],
             *INVERSIONS]
    splits: dict[str, dict[str, dict[str, Any]]] = {k: {} for k in order}
    per_frame: dict[str, np.ndarray] = {}  # the validation frames' point errors
    n_frames = {}
    for split, data, rows in (("val", val, val_rows), ("test", test, test_rows)):
        if data is None or not len(rows):
            n_frames[split] = 0
            continue
        n_frames[split] = int(len(rows))
        sub, own_windows = data.take(rows), learned.windows(data, rows)
        pred = learned.predict(own_windows)
        preds: dict[str, tuple[np.ndarray, np.ndarray | None]] = {learned.name: (pred, None)}
        for name, model in models.items():  # they read the window's last frame
            if name in splits and name != learned.name:
                preds[name] = (np.asarray(model.predict(own_windows.x)), None)
        preds["inversion"] = inversion_test if split == "test" else invert(data, rows, None)
        preds["hybrid"] = invert(data, rows, seeds_from_predictions(pred, data.faces))
        for name, (p, seconds) in preds.items():
            splits[name][split], frame_errors = scored(sub, p, seconds)
            if split == "val":
                per_frame[name] = frame_errors
    errors = {k: (v.get("val") or {}).get("loc_mm_mean") for k, v in splits.items()}
    rule = one_se_choice({k: (math.nan if e is None else float(e)) for k, e in errors.items()},
                         order, per_frame)
    selected, why = rule["selected"], rule["why"]
    kinds = {"knn": "the contact run's baseline", "ridge": "the contact run's baseline",
             "inversion": "training-free inversion",
             "hybrid": f"inversion seeded with {learned.name}'s answer",
             learned.name: "the contact run's model"}
    share = share_without_field or 0.0
    log.info("contact choice on %d validation frames: %s (%s)", n_frames["val"], selected, why)
    return {
        "selected": selected,
        "why": why,
        "metric": METRIC,
        "rule": rule["rule"],
        "best": rule["best"],
        "simplicity": rule["simplicity"],
        "order": order,
        "candidates": {k: {"kind": kinds[k], "val": splits[k].get("val"),
                           "test": splits[k].get("test"), "val_se_to_best_mm": rule["se"][k],
                           "within_one_se": rule["within"][k], "selected": k == selected}
                       for k in order},
        "n_val_frames": n_frames["val"],
        "n_test_frames": n_frames["test"],
        "answers": {
            "field_states": {"model": selected, "share_of_test_frames": 1.0 - share},
            "states_without_field": {
                "model": learned.name, "share_of_test_frames": share,
                "why": "a frame of a state without a response field can only be answered by "
                       "the learned model"},
        },
        "baselines_fit_s": t_fit,
        "seconds": time.perf_counter() - t0,
    }
