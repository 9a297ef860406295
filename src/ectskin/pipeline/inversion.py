"""The reproduction's inversion step: the training-free physical inversion on the contact run's
test frames, scored as ContactNet is.

::

    inversion   OUT_DIR/inversion/metrics.json   the inversion (ectskin.inversion) of every
                                                 test frame of the contact run (runs/contact/
                                                 split.json) in a state with a response field,
                                                 with ContactNet's metrics, per state, and its
                                                 time per frame

The inversion reads each frame's absolute readouts (pF) alone (``window`` 1), fits 0, 1 or 2
fingers through the state's field (:class:`ectskin.inversion.Inversion`, the contact
protocol's readout noise) and needs no training data. Its answers are put in the columns of
ContactNet's predictions (:func:`prediction_columns`) and scored by the same function
(:func:`ectskin.learn.tasks.contact.contact_report`) on the same frames: the point error over
the skin of the frames with one finger on it, the force MAE there, the finger count, hover
detection. A frame of a state without a field is not inverted; it is counted
(``frames_without_field``).

The hand's push as a nuisance (:func:`ectskin.inversion.push_basis`, direct solves per state):
``push="auto"`` inverts up to :data:`PUSH_CHOICE_FRAMES` one-finger frames of the *validation*
trials with and without it and keeps the one with the lower mean point error (no test frame is
used to choose); ``"on"`` / ``"off"`` force it.

The finger's size (``finger_scale_sd``, e.g. :data:`ectskin.inversion.fit.FINGER_SCALE_SD`):
people's fingertips differ from the field's, so each finger's signal may be fitted with an
unknown relative scale under that prior (``Inversion(finger_scale_sd=...)``); None (the
default) fits the field's finger as it is.

The untouched readout (``untouched``): "field" (the default) compares each frame with the
field's untouched readout of its state; "auto" with the skin's own, the mean readout of the
recording's no-contact trials of that state (:func:`ectskin.io.calibration.is_no_contact`)
outside the test trials (:func:`untouched_readouts`; a state without one keeps the field's).
No label is read: it is the skin's baseline, as a real skin's is recorded before use. The
twin's body (its mesh) differs from the field's by tens of noise σ per channel, a pattern that
a common gain and offset cannot absorb (docs/inversion.md).

``press_check``: each hovering finger of the chosen fit is refitted pressing, and kept so where
that fits about as well (``Inversion(press_check=True)``).

The person's finger (``finger``): each pressing finger's pulp modulus and fingertip radius
fitted too (``Inversion(modulus=, radius=)``, their tables from coarse response fields of the
states, :func:`ectskin.twin.field_finger.finger_tables`, built into the field cache), and pooled
over the frames of each trial, one person's, before every frame is fitted again with what they
tell (:func:`ectskin.inversion.fit_frames` ``person=``; :mod:`ectskin.inversion.person`). No
label is read: the pooling uses the trial's readouts alone. ``"auto"`` keeps it where
:data:`PUSH_CHOICE_FRAMES` one-finger frames of the validation trials get a lower mean point
error with it than without; ``"on"`` / ``"off"`` force it.

Two fingers (``two_finger``): the evenly spread frames hold few with two fingers on the skin
(some 50-70 of 3000 in a quick reproduction, from a few trials), too few to tell a count
accuracy of 95 %; up to ``two_finger_frames`` (:data:`MAX_TWO_FINGER_FRAMES`) more of the test
frames with two fingers on the skin are inverted besides them and scored with them apart
(:func:`two_finger_score`: the count, the point error of each finger after matching, the count
accuracy per trial). The spread's metrics (``multi`` among them) stay the spread's. The labels
only pick which frames are scored, as they pick the one-finger frames of the point error.

The training trials (``train_trials``, as the reproduction runs the step): the inversion is not
trained, and its choices (push, the person's finger, the contact model, the model error) read
the validation trials only, so the contact run's *training* trials are frames it has not seen,
from many more trials than the test split's few with two fingers. Up to :data:`TRAIN_FRAMES`
of their frames, evenly spread, and up to :data:`TRAIN_TWO_FINGER_FRAMES` more with two fingers
on the skin are inverted as the test frames are (each trial's finger pooled over them) and
scored apart (the result's ``train_trials``: the point error and the count by true count of the
spread, the two-finger frames' :func:`two_finger_score`). The test split's numbers stay the
test split's.

The contact model of the states with a field (``choice``, as the reproduction runs the step):
the contact run's model, its k-NN and ridge baselines, the inversion and the hybrid (the
inversion seeded with the run's model's answer for the frame) are scored on up to
:data:`~ectskin.pipeline.contact_pick.CHOICE_FRAMES` frames of the *validation* trials in states
with a field, spread as the test frames; the one-standard-error rule chooses (the simplest
candidate whose mean point error is within one paired standard error of the lowest), and every
candidate is scored on the test frames too (:mod:`ectskin.pipeline.contact_pick`; the result's
``choice``). A frame of a state without a field can only be answered by the learned model.
The standard errors carry the field's model error (``bound_error``, the result's
``model_error``: :mod:`ectskin.pipeline.inversion_error`).

:func:`ectskin.pipeline.metrics.inversion_block` turns the step's metrics into metrics.json's
``inversion``.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import read_json, to_jsonable, write_json_atomic
from ectskin.inversion import Inversion, fit_frames, push_basis, results_to_arrays
from ectskin.inversion.fit import TWO_FINGER_MODELS
from ectskin.inversion.person import POOL_SD_FLOOR
from ectskin.inversion.seed import SEED_SEARCH
from ectskin.io import Recording, read_recording
from ectskin.io.calibration import untouched_readouts
from ectskin.learn.data.contact import ContactData, contact_dataset
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.learn.tasks.contact import contact_report
from ectskin.pipeline.bound import BOUND_DIR, BOUND_FILE, state_key
from ectskin.pipeline.config import CONTACT_RUN, ReproduceConfig
from ectskin.pipeline.contact_pick import CHOICE_FRAMES, RULE, contact_choice, load_learned
from ectskin.pipeline.field import field_cache_dir
from ectskin.pipeline.inversion_answers import (  # noqa: F401 (the step's answers, named here too)
    prediction_columns,
    two_finger_rows,
    two_finger_score,
    write_answers,
)
from ectskin.pipeline.inversion_error import (
    BOUND_ERROR_CHOICES,
    MODEL_ERROR_FRAMES,
    rows_frames,
    with_model_error,
)
from ectskin.pipeline.metrics import beside
from ectskin.pipeline.runner import StepRunner, digest
from ectskin.pipeline.steps import run_settings
from ectskin.twin.field import ResponseField
from ectskin.twin.field_finger import (
    FINGER_FIELD_FORCE_NODES,
    FINGER_FIELD_SPACING_MM,
    finger_tables,
)
from ectskin.twin.readout import ReadoutConfig

log = logging.getLogger(__name__)

INVERSION_DIR = "inversion"
METRICS_FILE = "metrics.json"
#: how the hand's push enters the inversion (module docstring)
PUSH_CHOICES = ("auto", "on", "off")
#: ``finger`` (the person's finger fitted and pooled per trial) of :func:`inversion_step`
FINGER_CHOICES = ("auto", "on", "off")
#: where each state's untouched readout comes from (module docstring)
UNTOUCHED_CHOICES = ("field", "auto")
#: validation frames with one finger on the skin (at most, evenly spread) that choose the push
PUSH_CHOICE_FRAMES = 240
#: test frames inverted (at most, evenly spread over the test trials' frames in order): the
#: inversion takes about 10-20 ms a frame, and a quick reproduction holds some 35 000 test frames
MAX_FRAMES = 3000
#: test frames with two fingers on the skin inverted besides the evenly spread ones (at most,
#: evenly spread over them) and scored apart (``two_finger``): the even spread holds some 50-70
#: of them in a quick reproduction, from a few trials, too few to tell a count accuracy of 95 %
MAX_TWO_FINGER_FRAMES = 1000
#: the training trials' frames (at most, evenly spread) that the step inverts besides the test
#: frames with ``train_trials`` (module docstring), and the frames with two fingers on the skin
#: among the rest (at most, evenly spread; none where ``two_finger_frames`` is 0): a two-finger
#: frame costs several one-finger frames' time, and 500 from some 20 trials tell the count
TRAIN_FRAMES = 1000
TRAIN_TWO_FINGER_FRAMES = 500
#: force is called observable at a frame whose fitted force's standard error (the Cramér–Rao
#: bound at the solution) is below this (N), as the bound step's ``force_threshold_n``
FORCE_OBSERVABLE_N = 0.1
#: two states are the same when their volumes differ by less than this (ml)
STATE_TOL_ML = 1e-6
#: the metrics of a contact report kept per state
STATE_KEYS = ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "face_accuracy", "force_mae_n",
              "hover_detect_mm", "contact_accuracy", "count_accuracy", "n_single_contact_frames")


def _field_of(fields: Mapping[tuple[float, ...], Any], state: Sequence[float]) -> Any:
    s = np.asarray(state, float)
    for k, f in fields.items():
        if len(k) == s.size and np.all(np.abs(np.asarray(k, float) - s) < STATE_TOL_ML):
            return f
    return None


def _frames(data: ContactData, single_only: bool, limit: int | None) -> np.ndarray:
    """Rows of ``data`` to invert: all, or those with one finger on the skin, at most ``limit``
    evenly spread."""
    rows = np.flatnonzero(data.count == 1) if single_only else np.arange(data.n_samples)
    if limit is not None and rows.size > limit:
        rows = rows[np.unique(np.linspace(0, rows.size - 1, limit).round().astype(int))]
    return rows


def invert_rows(inv: Inversion, rec: Recording, data: ContactData, rows: np.ndarray,
                seeds: Sequence[Any] | None = None, workers: int = 1, person: bool = False
                ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Invert the frames ``rows`` of ``data`` (samples of ``rec``'s trials, window 1): the
    arrays of :func:`ectskin.inversion.results_to_arrays` and each frame's seconds; ``seeds``:
    per row, the ``seeds`` of :meth:`ectskin.inversion.Inversion.fit` (the hybrid);
    ``workers``: processes fitting them (:func:`~ectskin.inversion.fit_frames`); ``person``:
    each trial's frames among them pool the finger (``fit_frames(person=)``: a trial is one
    person's)."""
    if seeds is not None and len(seeds) != rows.size:
        raise EctskinError(f"invert_rows: seeds must hold one entry per row ({rows.size}), got "
                           f"{len(seeds)}")
    groups = np.unique(data.group[rows])
    # rows grouped by trial in the order of np.unique: the rows must come in that order
    if not np.array_equal(np.concatenate([rows[data.group[rows] == g] for g in groups])
                          if rows.size else rows, rows):
        raise EctskinError("invert_rows: rows must be sorted by trial, then frame")
    if rows.size == 0:
        return results_to_arrays([]), np.zeros(0)
    readouts, states = rows_frames(rec, data, rows)
    # one frame per fit (window 1), so the frames of all trials go together
    results, seconds = fit_frames(inv, readouts, states, seeds=seeds, workers=workers,
                                  person=data.group[rows].tolist() if person else None)
    return results_to_arrays(results), seconds


def score(data: ContactData, arrays: Mapping[str, np.ndarray], seconds: np.ndarray
          ) -> dict[str, Any]:
    """The inversion's contact metrics on ``data`` (all its rows inverted, in order): those of
    :func:`~ectskin.learn.tasks.contact.contact_report` (with ``by_other_finger``: the point
    error with no other finger above the skin, one hovering near, one higher), per state
    (:data:`STATE_KEYS` with
    ``n_frames``), the force MAE where the fitted force's standard error is below
    :data:`FORCE_OBSERVABLE_N`, and the time per frame."""
    pred = prediction_columns(arrays, data.faces, data.face_extent)
    report = contact_report(data, pred, with_maps=False)
    out: dict[str, Any] = {k: report.get(k) for k in (
        "loc_mm_mean", "loc_mm_median", "loc_mm_p90", "face_accuracy", "force_mae_n",
        "force_rel", "hover_detect_mm", "contact_accuracy", "count_accuracy",
        "n_single_contact_frames", "per_face", "force", "hover", "multi", "sigma_mm_median",
        "by_other_finger")}
    per_state = {}
    for s, state in enumerate(data.states):
        rows = np.flatnonzero(data.state == s)
        if rows.size == 0:
            continue
        sub = contact_report(data.take(rows), pred[rows], with_maps=False)
        per_state[state_key(state)] = {**{k: sub.get(k) for k in STATE_KEYS},
                                       "n_frames": int(rows.size)}
    out["per_state"] = per_state
    single = data.count == 1
    a = len(PRED_COLUMNS)
    # the standard error of the force scored: slot 0's, the best-located pressing finger (0: none)
    se = pred[:, a + SLOT_COLUMNS.index("force_sigma_n")]
    ok = single & (pred[:, 0] >= 1) & (se > 0) & (se < FORCE_OBSERVABLE_N)
    err = np.abs(pred[:, a + SLOT_COLUMNS.index("force_n")] - data.force[:, 0])
    out["force_observable"] = {
        "threshold_n": FORCE_OBSERVABLE_N,
        "share": float(ok.sum() / single.sum()) if single.any() else None,
        "force_mae_n": float(err[ok].mean()) if ok.any() else None,
        "force_mae_n_not_observable": (float(err[single & ~ok].mean())
                                       if (single & ~ok).any() else None),
        "n_frames": int(ok.sum()),
    }
    ms = 1e3 * np.asarray(seconds, float)
    out["timing"] = {
        "ms_per_frame_median": float(np.median(ms)) if ms.size else None,
        "ms_per_frame_p95": float(np.percentile(ms, 95)) if ms.size else None,
        "ms_per_frame_mean": float(ms.mean()) if ms.size else None,
        "invert_s": float(ms.sum() / 1e3),
    }
    out["n_frames"] = int(data.n_samples)
    out["converged_share"] = float(np.mean(arrays["converged"])) if data.n_samples else None
    return out


def invert_spread(inv: Inversion, rec: Recording, data: ContactData, limit: int | None,
                  two_limit: int | None, workers: int = 1, person: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], np.ndarray,
                             dict[str, Any] | None]:
    """Invert ``limit`` frames of ``data`` evenly spread and up to ``two_limit`` more with two
    fingers on the skin (0: none; None: all), in one call (a trial's finger is pooled over
    both: its one-finger frames are in the spread). Returns the spread's rows, every row
    inverted, the fits of every row and their seconds (:func:`invert_rows`), and the
    :func:`two_finger_score` of every inverted frame with two fingers (None without one)."""
    rows = _frames(data, False, limit)
    extra = (two_finger_rows(data, rows, two_limit) if two_limit != 0
             else np.zeros(0, np.int64))
    every = np.union1d(rows, extra)
    both, seconds = invert_rows(inv, rec, data, every, workers=workers, person=person)
    keep = data.count[every] == 2
    two = (two_finger_score(data.take(every[keep]),
                            {k: np.asarray(v)[keep] for k, v in both.items()})
           if keep.any() else None)
    return rows, every, both, seconds, two


def train_score(inv: Inversion, rec: Recording, data: ContactData, limit: int | None,
                two_limit: int | None, workers: int = 1, person: bool = False) -> dict[str, Any]:
    """The inversion on frames of the contact run's training trials (``data``; module
    docstring), inverted as the test frames are (:func:`invert_spread`): the spread's point
    error and count by true count, the two-finger frames' :func:`two_finger_score`, and the
    seconds it took (wall); ``alone``: the point error of the spread's frames with no other
    finger above the skin (the frames the bound step bounds, ``train_alone``)."""
    t0 = time.perf_counter()
    rows, every, both, seconds, two = invert_spread(inv, rec, data, limit, two_limit, workers,
                                                    person)
    spread = np.searchsorted(every, rows)
    s = score(data.take(rows), {k: np.asarray(v)[spread] for k, v in both.items()},
              seconds[spread])
    alone = (s.get("by_other_finger") or {}).get("alone") or {}
    return {
        "n_trials": int(np.unique(data.group).size), "n_frames": int(rows.size),
        "loc_mm_mean": s["loc_mm_mean"], "loc_mm_median": s["loc_mm_median"],
        "alone": {"loc_mm_mean": alone.get("loc_mm_mean"), "n_frames": alone.get("n_frames"),
                  "share": alone.get("share")},
        "count_accuracy_by_true": (s.get("multi") or {}).get("count_accuracy_by_true"),
        "two_finger": two, "seconds": time.perf_counter() - t0,
    }


def _workers(config: ReproduceConfig) -> int:
    """The processes that fit the step's frames: the reproduction's workers (default all
    cores); the results do not depend on them."""
    return config.workers or os.cpu_count() or 1


def _dataset(rec: Recording, trials: Sequence[str]) -> ContactData | None:
    return contact_dataset(rec, window=1, trials=list(trials)) if trials else None


def _choose(rec: Recording, val: Sequence[str], off: tuple[Inversion, bool],
            on: tuple[Inversion, bool], workers: int = 1) -> dict[str, Any]:
    """The validation frames' mean point error (and force MAE) of two inversions, ``off`` and
    ``on`` ((the inversion, whether each trial pools the finger)), and whether ``on``'s is lower
    (ties and no validation frame: ``off``, the smaller model); ``workers``: processes fitting
    the frames."""
    data = _dataset(rec, val)
    rows = _frames(data, True, PUSH_CHOICE_FRAMES) if data is not None else np.zeros(0, int)
    if rows.size == 0:
        return {"use": False, "why": "no validation frame with one finger in a field state",
                "n_frames": 0}
    assert data is not None
    sub = data.take(rows)
    errors, forces = {}, {}
    for name, (inv, person) in (("off", off), ("on", on)):
        arrays, _ = invert_rows(inv, rec, data, rows, workers=workers, person=person)
        rep = contact_report(sub, prediction_columns(arrays, sub.faces, sub.face_extent),
                             with_maps=False)
        errors[name], forces[name] = rep["loc_mm_mean"], rep["force_mae_n"]
    return {"use": bool(errors["on"] < errors["off"]), "val_loc_mm_mean": errors,
            "val_force_mae_n": forces, "n_frames": int(rows.size),
            "why": "lower validation point error"}


def _choice(runner: StepRunner, config: ReproduceConfig, rec: Recording, source: str,
            inv: Inversion, split: Mapping[str, Any], val: Sequence[str], test: ContactData,
            own: tuple[Mapping[str, np.ndarray], np.ndarray], n_field: int, n_without: int,
            person: bool = False) -> dict[str, Any]:
    """The contact model choice on the field states (:func:`ectskin.pipeline.contact_pick.
    contact_choice`): validation frames of ``val`` spread as the test frames, at most
    :data:`~ectskin.pipeline.contact_pick.CHOICE_FRAMES`; ``test``: the test frames inverted,
    ``own`` their inversion (arrays, seconds); ``n_field``, ``n_without``: the test frames in
    states with and without a field; ``person``: the finger pooled per trial."""
    val_data = _dataset(rec, val)
    val_rows = (_frames(val_data, False, CHOICE_FRAMES) if val_data is not None
                else np.zeros(0, np.int64))

    def invert(data: ContactData, rows: np.ndarray, seeds: Sequence[Any] | None
               ) -> tuple[np.ndarray, np.ndarray]:
        arrays, seconds = invert_rows(inv, rec, data, rows, seeds, workers=_workers(config),
                                      person=person)
        return prediction_columns(arrays, data.faces, data.face_extent), seconds

    learned = load_learned(runner.out / "runs" / CONTACT_RUN, rec, source)
    total = n_field + n_without
    return contact_choice(
        learned, invert, val=val_data, val_rows=val_rows, test=test,
        test_rows=np.arange(test.n_samples),
        inversion_test=(prediction_columns(own[0], test.faces, test.face_extent), own[1]),
        train_trials=list(split.get("train") or []), seed=config.seed,
        share_without_field=n_without / total if total else None)


def inversion_step(
    runner: StepRunner,
    config: ReproduceConfig,
    fields: Mapping[tuple[float, ...], ResponseField],
    found: tuple[Path, Mapping[str, Any]],
    contact_metrics: Mapping[str, Any] | None = None,
    *,
    push: str = "auto",
    max_frames: int | None = MAX_FRAMES,
    finger_scale_sd: float | None = None,
    untouched: str = "field",
    press_check: bool = False,
    two_finger_frames: int | None = MAX_TWO_FINGER_FRAMES,
    choice: bool = False,
    two_fingers: str = "superposition",
    finger: str = "off",
    bound_error: str = "validation",
    train_trials: bool = False,
) -> dict[str, Any]:
    """Step "inversion": OUT_DIR/inversion/metrics.json (module docstring); returns it.

    ``fields``: {inflation: field} of the contact states; ``found``: (contact.h5, its settings)
    of the contact step; the test and validation trials are those of runs/contact/split.json.
    ``contact_metrics``: the contact run's metrics.json; given, the result's ``contact_run``
    holds ContactNet's and its baselines' point error on the states inverted
    (:func:`ectskin.pipeline.metrics.beside`, not stored: the run may change).
    ``max_frames``: the test frames inverted at most, evenly spread over them (None: every
    one). ``push``: "auto", "on" or "off"; ``finger_scale_sd``: the finger scale's prior;
    ``untouched``: "field" or "auto" (the no-contact trials outside the test trials);
    ``press_check``: refit hovering fingers pressing (module docstring).
    ``two_finger_frames``: the test frames with two fingers on the skin that are not among those
    ``max_frames`` spreads inverted besides them (at most, evenly spread; 0: none): the result's
    ``two_finger`` (:func:`two_finger_score`) scores them with the spread's own two-finger frames;
    the spread's metrics stay the spread's.
    ``choice``: also choose the contact model of the field states among the contact run's model
    (runs/contact), its k-NN and ridge baselines, the inversion and the hybrid on validation
    frames (:mod:`ectskin.pipeline.contact_pick`); the result's ``choice``.
    ``two_fingers``: the fit's two-finger model, "superposition" or "coupled"
    (:class:`~ectskin.inversion.Inversion`). ``finger``: "auto", "on" or "off", the person's
    finger fitted and pooled per trial (module docstring; the result's ``finger``).
    ``bound_error``: "validation" or "off", the standard errors' model error estimated from the
    validation frames' residuals (module docstring; the result's ``model_error``) or none.
    ``train_trials``: also score the inversion on the contact run's training trials (module
    docstring; the result's ``train_trials``, None where none is in a field state).
    """
    if max_frames is not None and not (isinstance(max_frames, int) and max_frames >= 1):
        raise EctskinError(f"inversion_step: max_frames must be an integer >= 1 or None, got "
                           f"{max_frames!r}")
    if two_finger_frames is not None and not (
            isinstance(two_finger_frames, int) and not isinstance(two_finger_frames, bool)
            and two_finger_frames >= 0):
        raise EctskinError(f"inversion_step: two_finger_frames must be an integer >= 0 or None, "
                           f"got {two_finger_frames!r}")
    if not fields:
        raise EctskinError("inversion_step: no response fields given")
    check_option("push", push, PUSH_CHOICES)
    check_option("untouched", untouched, UNTOUCHED_CHOICES)
    check_option("two_fingers", two_fingers, TWO_FINGER_MODELS)
    check_option("finger", finger, FINGER_CHOICES)
    check_option("bound_error", bound_error, BOUND_ERROR_CHOICES)
    for name, flag in (("press_check", press_check), ("choice", choice),
                       ("train_trials", train_trials)):
        if not isinstance(flag, bool):
            raise EctskinError(f"inversion_step: {name} must be True or False, got {flag!r}")
    fields = {tuple(float(x) for x in s): f for s, f in fields.items()}
    data_path, data_settings = found
    split_file = runner.out / "runs" / CONTACT_RUN / "split.json"
    if not split_file.is_file():
        raise EctskinError(f"inversion_step: {split_file} is missing; train the contact run first")
    split = read_json(split_file, "contact run split")
    test, val = list(split.get("test") or []), list(split.get("val") or [])
    if not test:
        raise EctskinError(f"{split_file}: the contact run has no test trials (key 'test')")
    protocol = config.contact_protocol()
    noise = protocol.readout if protocol is not None else ReadoutConfig()
    out_dir = runner.out / INVERSION_DIR
    settings = {
        "fields": {state_key(s): f.key for s, f in fields.items()},
        "data": digest(dict(data_settings)), "test_trials": test, "val_trials": val,
        "push": push, "push_choice_frames": PUSH_CHOICE_FRAMES, "noise": noise,
        "window": 1, "force_observable_n": FORCE_OBSERVABLE_N, "max_frames": max_frames,
        "finger_scale_sd": finger_scale_sd, "untouched": untouched, "press_check": press_check,
        "two_finger_frames": two_finger_frames,
        # named only when not the default, so that the steps cached before keep their key
        **({"two_fingers": two_fingers} if two_fingers != "superposition" else {}),
        **({"finger": finger, "finger_fields": [FINGER_FIELD_SPACING_MM, FINGER_FIELD_FORCE_NODES,
                                                POOL_SD_FLOOR]} if finger != "off" else {}),
        "bound_error": [bound_error, MODEL_ERROR_FRAMES], **config.figure_settings,
        # named only when on, so that the steps cached before keep their key
        **({"train_trials": [split.get("train") or [], TRAIN_FRAMES, TRAIN_TWO_FINGER_FRAMES]}
           if train_trials else {}),
    }
    if choice:  # the run's model and its baselines' seed are candidates' settings too
        settings.update(choice=True, choice_frames=CHOICE_FRAMES, choice_rule=RULE,
                        seed=config.seed,
                        seed_search=SEED_SEARCH[0],
                        run=digest(run_settings(config, CONTACT_RUN, dict(data_settings))))

    workers = _workers(config)

    def make() -> None:
        t0 = time.perf_counter()
        rec = read_recording(data_path)
        has = {t.name: _field_of(fields, t.inflation) is not None for t in rec.trials}
        unknown = [n for n in test + val if n not in has]
        if unknown:
            raise EctskinError(f"{split_file}: trial {unknown[0]!r} is not in {data_path}")
        without: dict[str, int] = {}
        for name in test:
            if not has[name]:
                t = rec.trial(name)
                without[state_key(t.inflation)] = without.get(state_key(t.inflation), 0) + t.n_frames
        base = (untouched_readouts(rec, fields, test, STATE_TOL_ML) if untouched == "auto"
                else {})
        plain: dict[str, Any] = {"press_check": press_check, "two_fingers": two_fingers,
                                 "untouched": {s: b["pF"] for s, b in base.items()} or None,
                                 "finger_scale_sd": finger_scale_sd}
        cols: dict[Any, np.ndarray] | None = None
        push_pick: dict[str, Any] = {"use": push == "on", "why": f"push={push!r}"}
        t_push = 0.0
        # the inversion without and with the push columns, those the choice needs, each built
        # once (its node tables)
        candidates = {} if push == "on" else {False: Inversion(fields, noise, **plain)}
        if push != "off":
            t1 = time.perf_counter()
            cols = {s: push_basis(f, noise=noise) for s, f in fields.items()}
            t_push = time.perf_counter() - t1
            candidates[True] = Inversion(fields, noise, push=cols, **plain)
            if push == "auto":
                push_pick = _choose(rec, [n for n in val if has[n]], (candidates[False], False),
                                    (candidates[True], False), workers)
        inv = candidates[bool(push_pick["use"])]
        finger_pick: dict[str, Any] = {"use": False, "why": f"finger={finger!r}"}
        if finger != "off":
            t1 = time.perf_counter()
            tables = finger_tables([f.spec for f in fields.values()],
                                   field_cache_dir(config.field_cache), workers=config.workers,
                                   progress=config.progress)
            t_tables = time.perf_counter() - t1
            pooled = Inversion(fields, noise, push=cols if push_pick["use"] else None,
                               modulus=tables["modulus"], radius=tables["radius"], **plain)
            finger_pick = ({"use": True, "why": "finger='on'"} if finger == "on" else
                           _choose(rec, [n for n in val if has[n]], (inv, False), (pooled, True),
                                   workers))
            finger_pick["tables_s"] = t_tables
            if finger_pick["use"]:
                inv = pooled
        person = bool(finger_pick["use"])
        model_error: dict[str, Any] = {"source": None, "why": f"bound_error={bound_error!r}"}
        if bound_error == "validation":
            t1, vdata = time.perf_counter(), _dataset(rec, [n for n in val if has[n]])
            vrows = _frames(vdata, False, MODEL_ERROR_FRAMES) if vdata is not None else None
            inv, model_error = with_model_error(inv, rec, vdata, vrows, workers, person)
            model_error["seconds"] = time.perf_counter() - t1
        data = _dataset(rec, [n for n in test if has[n]])
        n_without = sum(without.values())
        if data is None:
            result: dict[str, Any] = {"n_frames": 0, "per_state": {}}
        else:
            rows, every, both, all_seconds, two = invert_spread(
                inv, rec, data, max_frames, two_finger_frames, workers, person)
            test_data = data.take(rows)
            spread = np.searchsorted(every, rows)
            arrays = {k: np.asarray(v)[spread] for k, v in both.items()}
            seconds = all_seconds[spread]
            result = score(test_data, arrays, seconds)
            result["timing"]["push_basis_s"] = t_push
            result["n_frames_in_field_states"] = int(data.n_samples)
            if choice:
                result["choice"] = _choice(runner, config, rec, str(data_path), inv, split,
                                           [n for n in val if has[n]], test_data,
                                           (arrays, seconds), data.n_samples, n_without,
                                           person=person)
            if two is not None:
                result["two_finger"] = two
            if train_trials:
                tdata = _dataset(rec, [n for n in split.get("train") or [] if has.get(n)])
                result["train_trials"] = (None if tdata is None else train_score(
                    inv, rec, tdata, TRAIN_FRAMES,
                    0 if two_finger_frames == 0 else TRAIN_TWO_FINGER_FRAMES, workers, person))
            result["files"] = write_answers(
                out_dir, data, every, both, np.isin(every, rows),
                bound_file=runner.out / BOUND_DIR / BOUND_FILE, threshold_n=FORCE_OBSERVABLE_N,
                figure_format=config.figure_format, dpi=config.dpi)
        total = result.get("n_frames_in_field_states", 0) + n_without
        result.update(
            frames_without_field=without, n_frames_without_field=n_without,
            share_without_field=(n_without / total) if total else None,
            n_test_trials=len(test), push=push_pick, finger=finger_pick,
            model_error=model_error,
            settings={"window": 1, "kind": "absolute", "noise": to_jsonable(noise),
                      "push": push, "max_fingers": inv.max_fingers,
                      "finger_scale_sd": finger_scale_sd, "press_check": press_check,
                      "two_fingers": two_fingers, "min_separation_mm": inv.min_separation_mm,
                      "finger": finger,
                      "untouched": {"source": untouched,
                                    "trials": {state_key(st): b["trials"]
                                               for st, b in base.items()}},
                      "fields": settings["fields"]},
        )
        result["timing"] = {**result.get("timing", {}), "total_s": time.perf_counter() - t0}
        out_dir.mkdir(parents=True, exist_ok=True)
        write_json_atomic(out_dir / METRICS_FILE, result)
        log.info("inversion: %d test frames, %.2f mm mean point error, %.1f ms per frame "
                 "(median)", result["n_frames"], result.get("loc_mm_mean") or float("nan"),
                 (result.get("timing") or {}).get("ms_per_frame_median") or float("nan"))

    runner.step("inversion", settings, [out_dir], make)
    result = read_json(out_dir / METRICS_FILE, "inversion metrics")
    if contact_metrics is not None:  # the run's numbers as they are now (not stored: it may change)
        result["contact_run"] = beside(contact_metrics.get("contact", contact_metrics), result)
    return result
