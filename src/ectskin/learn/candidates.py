"""Touch model choice: classical candidates beside the paper's TouchMLP, chosen on validation.

``ectskin train touch DATA OUT --model NAME`` (:func:`ectskin.learn.train.train`, ``model=``):

==================  =====================================================================
``mlp``             the paper's TouchMLP alone (the default; the run is as without a choice)
``auto``            every candidate below; the best validation accuracy is selected
``gbt``             gradient-boosted trees (``HistGradientBoostingClassifier``)
``random_forest``   ``RandomForestClassifier``
``logreg``          multinomial ``LogisticRegression`` (lbfgs)
``knn``             k-nearest-neighbour vote
==================  =====================================================================

The classical candidates (:mod:`ectskin.learn.classical`: their settings, fitting, single-frame
export and ``model.skops``; its names are importable from here too) are fit on the run's
**training** split and scored on the **validation** split only (:func:`fit_candidates`). The
test split is never used to choose.

Selection (:func:`select_candidate`): the highest validation accuracy; on a tie the earlier in
:data:`PREFERENCE` wins: the paper's MLP, then the simpler model (logistic regression, k-NN,
random forest, gradient boosting).

Files of the run directory (beside the MLP's ``model.pt`` when the MLP was trained):

* ``candidates.json`` (:func:`write_candidates` / :func:`read_candidates`): every candidate with
  its validation accuracy, fit seconds, training frames used and settings; the one selected and
  why; the seed and the fingerprints of the training and validation data. Written last and
  atomically: it is what tells evaluation and inference which model the run answers with.
* ``model.skops`` (:func:`~ectskin.learn.classical.save_classical` /
  :func:`~ectskin.learn.classical.load_classical`): the selected classical model.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import read_json_object, write_json_atomic
from ectskin.learn.classical import (
    CLASSICAL,
    CLASSICAL_FILE,
    MAX_TRAIN,
    SETTINGS,
    SKOPS_FORMAT,
    SKOPS_TRUSTED,
    SKOPS_VERSION,
    ClassicalConfig,
    ClassicalModel,
    fit_classical,
    load_classical,
    save_classical,
    thread_limit,
)
from ectskin.learn.data.touch import TouchData

log = logging.getLogger(__name__)

__all__ = [
    "CANDIDATES_FILE",
    "CLASSICAL",
    "CLASSICAL_FILE",
    "MAX_TRAIN",
    "PREFERENCE",
    "SETTINGS",
    "SKOPS_FORMAT",
    "SKOPS_TRUSTED",
    "SKOPS_VERSION",
    "TOUCH_MODELS",
    "CandidateResult",
    "ClassicalConfig",
    "ClassicalModel",
    "accuracy",
    "candidate_names",
    "fit_candidates",
    "fit_classical",
    "load_classical",
    "read_candidates",
    "save_classical",
    "select_candidate",
    "selected_model",
    "thread_limit",
    "write_candidates",
]

#: the values of ``--model``: the paper's MLP (default), every candidate, or one of them
TOUCH_MODELS = ("mlp", "auto", *CLASSICAL)
#: tie order of :func:`select_candidate`: on equal validation accuracy the earlier wins
PREFERENCE = ("mlp", "logreg", "knn", "random_forest", "gbt")
CANDIDATES_FILE = "candidates.json"
CANDIDATES_FORMAT = "ectskin.touch_candidates"


@dataclass
class CandidateResult:
    """One candidate scored on the validation split (what ``candidates.json`` stores)."""

    name: str
    val_accuracy: float
    fit_seconds: float
    n_train_used: int
    settings: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "val_accuracy": self.val_accuracy,
            "fit_seconds": self.fit_seconds,
            "n_train_used": self.n_train_used,
            "settings": dict(self.settings),
        }


def candidate_names(model: str) -> tuple[str, ...]:
    """The candidates ``--model`` trains, in :data:`PREFERENCE` order: all for "auto"."""
    check_option("model", model, TOUCH_MODELS)
    return PREFERENCE if model == "auto" else (model,)


def accuracy(pred: np.ndarray, y: np.ndarray) -> float:
    """Fraction of ``pred == y`` (NaN for no samples)."""
    return float(np.mean(np.asarray(pred) == np.asarray(y))) if len(y) else math.nan


# --------------------------------------------------------------------------- fitting
def fit_candidates(
    names: tuple[str, ...],
    train: TouchData,
    val: TouchData,
    *,
    seed: int = 0,
    threads: int | None = 1,
) -> tuple[dict[str, CandidateResult], dict[str, ClassicalModel]]:
    """Fit the classical ``names`` on ``train`` and score each on ``val`` (accuracy), with
    ``threads`` native threads (:func:`thread_limit`)."""
    results: dict[str, CandidateResult] = {}
    models: dict[str, ClassicalModel] = {}
    for name in names:
        with thread_limit(threads):
            model, used, seconds = fit_classical(name, train, seed=seed)
        acc = accuracy(model.predict(val.x), val.y)
        results[name] = CandidateResult(name, acc, seconds, used, model.settings)
        models[name] = model
        log.info(
            "touch candidate %s: validation accuracy %.4f (fit on %d frames, %.1f s)",
            name,
            acc,
            used,
            seconds,
        )
    return results, models


def select_candidate(val_accuracy: Mapping[str, float]) -> tuple[str, str]:
    """The candidate with the highest validation accuracy, ties to the earlier in
    :data:`PREFERENCE`; returns (name, the reason in words)."""
    if not val_accuracy:
        raise EctskinError("select_candidate: no candidates")
    unknown = sorted(set(val_accuracy) - set(PREFERENCE))
    if unknown:
        raise EctskinError(f"select_candidate: unknown candidate(s) {', '.join(unknown)}")
    finite = {k: v for k, v in val_accuracy.items() if math.isfinite(v)}
    if not finite:
        raise EctskinError("select_candidate: no candidate has a finite validation accuracy")
    best = max(finite.values())
    tied = [k for k in PREFERENCE if finite.get(k) == best]
    name = tied[0]
    if len(val_accuracy) == 1:
        return name, "the only candidate (--model asked for it)"
    why = f"highest validation accuracy ({best:.4f})"
    if len(tied) > 1:
        why += f", tied with {', '.join(tied[1:])}: the paper's MLP, then the simpler model wins"
    return name, why


# --------------------------------------------------------------------------- candidates.json
def write_candidates(run_dir: str | Path, doc: Mapping[str, Any]) -> Path:
    """Write ``run_dir/candidates.json`` atomically (strict JSON)."""
    return write_json_atomic(Path(run_dir) / CANDIDATES_FILE, {"format": CANDIDATES_FORMAT, **doc})


def read_candidates(run_dir: str | Path) -> dict[str, Any] | None:
    """The run's ``candidates.json`` checked, or None when the run has none (an MLP run). A
    contact run's (``"task": "contact"``) is checked by
    :func:`ectskin.learn.contact_choice.check_contact_candidates`.

    It must name the ``model`` choice, the ``selected`` candidate (one of ``candidates``) and
    per candidate a ``val_accuracy``; a selected classical model needs ``model.skops``.
    """
    run = Path(run_dir)
    path = run / CANDIDATES_FILE
    if not path.exists():
        return None
    doc = read_json_object(path, "candidates file")
    if doc.get("task") == "contact":  # a contact run's choice (ectskin.learn.contact_choice)
        from ectskin.learn.contact_choice import CANDIDATES_FORMAT as CONTACT_FORMAT
        from ectskin.learn.contact_choice import check_contact_candidates

        if doc.get("format") == CONTACT_FORMAT:
            return check_contact_candidates(path, doc)
    if doc.get("format") != CANDIDATES_FORMAT:
        raise EctskinError(
            f"{path}: expected format {CANDIDATES_FORMAT!r}, found {doc.get('format')!r}"
        )
    choice = doc.get("model")
    if choice not in TOUCH_MODELS or choice == "mlp":
        raise EctskinError(
            f"{path}: field 'model' is {choice!r}, expected one of {TOUCH_MODELS[1:]}"
        )
    cands = doc.get("candidates")
    if not isinstance(cands, dict) or not cands or not set(cands) <= set(PREFERENCE):
        raise EctskinError(
            f"{path}: field 'candidates' must map candidate names ({', '.join(PREFERENCE)}) to "
            f"their results, found {cands!r:.200}"
        )
    for name, c in cands.items():
        if not isinstance(c, dict) or not isinstance(c.get("val_accuracy"), int | float | None):
            raise EctskinError(f"{path}: candidate {name!r} has no 'val_accuracy'")
    selected = doc.get("selected")
    if selected not in cands:
        raise EctskinError(
            f"{path}: field 'selected' is {selected!r}, expected one of {sorted(cands)}"
        )
    if selected != "mlp" and not (run / CLASSICAL_FILE).is_file():
        raise EctskinError(
            f"{path}: selects {selected!r} but the run has no {CLASSICAL_FILE}; train again"
        )
    if selected == "mlp" and not (run / "model.pt").is_file():
        raise EctskinError(f"{path}: selects the MLP but the run has no model.pt; train again")
    return doc


def selected_model(run_dir: str | Path) -> str:
    """The model a run answers with: "mlp" (no ``candidates.json``, or it selects the MLP) or
    the name of the classical candidate in ``model.skops``."""
    doc = read_candidates(run_dir)
    return "mlp" if doc is None else str(doc["selected"])
