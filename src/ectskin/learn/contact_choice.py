"""The contact model choice of a training run (``ectskin train contact --model``).

==================  =====================================================================
``contactnet``      ContactNet alone (the default; ``mlp``, the touch default, means it too)
``auto``            ContactNet and every classical candidate; the lowest validation point
                    error is selected
``knn``             k nearest training frames (:mod:`ectskin.learn.contact_classical`)
``ridge``           ridge regression, logistic regression for the classes
``gbt``             gradient-boosted trees (one ``HistGradientBoostingRegressor`` per output)
``gp``              a Gaussian process (in ``auto`` only when the training split holds at
                    most :data:`GP_AUTO_MAX` frames)
==================  =====================================================================

Selection is on the **validation** split only, by the contact point error: the mean distance
over the skin (mm) between the true and the predicted point of the frames with one finger,
computed for every candidate by the same function (:func:`val_point_error`, the
``loc_mm_mean`` of :func:`ectskin.learn.tasks.contact.contact_report`). Ties go to the earlier
in :data:`PREFERENCE`. The ``knn`` and ``ridge`` candidates are the task's own k-NN and ridge
baselines (the same fit), so the model ``auto`` selects never has a higher validation error
than they have: where ContactNet loses to them, the simple model is what the run answers with.

Files, as for touch (:mod:`ectskin.learn.touch_choice`): ``candidates.json`` (format
:data:`CANDIDATES_FORMAT`: every candidate's validation error, fit seconds, frames used and
settings; the selection and why; seed and data fingerprints), removed first and written last;
``model.skops`` the selected classical model (:func:`~ectskin.learn.contact_classical.save_contact_classical`).
Evaluation (``ectskin evaluate``) adds every candidate's test numbers (:func:`candidates_on_test`)
and answers with the selected model; so does :class:`~ectskin.learn.predict.ContactPredictor`.
"""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import write_json_atomic
from ectskin.learn.contact_classical import (
    CONTACT_CLASSICAL,
    ContactClassical,
    fit_contact_classical,
    load_contact_classical,
    save_contact_classical,
)
from ectskin.learn.runfiles import fingerprint, split_names_of, write_run_config

log = logging.getLogger(__name__)

__all__ = [
    "CANDIDATES_FORMAT",
    "CONTACT_MODELS",
    "GP_AUTO_MAX",
    "NET",
    "PREFERENCE",
    "candidate_predictions",
    "candidates_on_test",
    "check_contact_candidates",
    "choose_after_net",
    "contact_candidate_names",
    "fit_contact_alone",
    "normalise_choice",
    "select_contact",
    "val_point_error",
]

NET = "contactnet"
#: the values of ``--model`` for contact ("mlp", the command's default, means ContactNet)
CONTACT_MODELS = (NET, "auto", *CONTACT_CLASSICAL)
#: tie order: on equal validation error the earlier wins (ContactNet, then the simpler model)
PREFERENCE = (NET, "ridge", "knn", "gp", "gbt")
#: ``auto`` fits a Gaussian process only on training splits of at most this many frames
GP_AUTO_MAX = 2_000
CANDIDATES_FILE = "candidates.json"
CLASSICAL_FILE = "model.skops"
CANDIDATES_FORMAT = "ectskin.contact_candidates"
METRIC = "validation point error, mm (mean over the skin, frames with one finger)"


def normalise_choice(model: str) -> str:
    """``--model`` of a contact run: "mlp" (the command's default) is ContactNet."""
    model = NET if model == "mlp" else model
    check_option("model", model, CONTACT_MODELS)
    return model


def contact_candidate_names(model: str, n_train: int) -> tuple[str, ...]:
    """The candidates ``--model`` trains, in :data:`PREFERENCE` order."""
    model = normalise_choice(model)
    if model != "auto":
        return (model,)
    return tuple(n for n in PREFERENCE if n != "gp" or n_train <= GP_AUTO_MAX)


def val_point_error(data: Any, pred: np.ndarray) -> float:
    """The selection metric (module docstring); NaN without a frame of one finger."""
    from ectskin.learn.tasks.contact import contact_report

    loc = contact_report(data, pred, with_maps=False)["loc_mm_mean"]
    return math.nan if loc is None else float(loc)


def select_contact(errors: dict[str, float]) -> tuple[str, str]:
    """The candidate with the lowest finite validation error (ties: :data:`PREFERENCE`);
    returns (name, the reason in words)."""
    if not errors:
        raise EctskinError("select_contact: no candidates")
    finite = {k: v for k, v in errors.items() if math.isfinite(v)}
    order = [k for k in PREFERENCE if k in errors]
    if len(errors) == 1:
        return order[0], "the only candidate (--model asked for it)"
    if not finite:
        return order[0], (
            "no validation frame with one finger to compare on: the first in the preference "
            f"order {', '.join(order)}"
        )
    best = min(finite.values())
    tied = [k for k in order if finite.get(k) == best]
    why = f"lowest validation point error ({best:.3f} mm)"
    if len(tied) > 1:
        why += f", tied with {', '.join(tied[1:])}: ContactNet, then the simpler model wins"
    return tied[0], why


def _fingerprints(train: Any, val: Any) -> dict[str, str]:
    return {
        "train_fingerprint": fingerprint(train.x, train.uv, train.count),
        "val_fingerprint": fingerprint(val.x, val.uv, val.count),
    }


def _fit(names, train, val, seed: int, threads: int | None) -> tuple[dict, dict]:
    from ectskin.learn.classical import thread_limit

    results: dict[str, dict[str, Any]] = {}
    models: dict[str, ContactClassical] = {}
    for name in names:
        with thread_limit(threads):
            model, used, seconds = fit_contact_classical(name, train, seed=seed)
        err = val_point_error(val, model.predict(val.x))
        results[name] = {
            "val_loc_mm": err,
            "fit_seconds": seconds,
            "n_train_used": used,
            "settings": model.settings,
        }
        models[name] = model
        log.info(
            "contact candidate %s: validation point error %.3f mm (%.1f s)", name, err, seconds
        )
    return results, models


def choose_after_net(
    config: Any,
    out: Path,
    train: Any,
    val: Any,
    net_summary: dict[str, Any],
    threads: int | None,
) -> dict[str, Any]:
    """``--model auto`` after ContactNet is trained (rank 0): its kept weights (``model.pt``) and
    every classical candidate scored on the validation split; the best committed."""
    from ectskin.learn.checkpoint import load_checkpoint
    from ectskin.learn.tasks import get_task

    net, _, _ = load_checkpoint(out / "model.pt", kind="contact_net")
    err = val_point_error(val, get_task("contact").predict(net, val))
    log.info("contact candidate %s: validation point error %.3f mm", NET, err)
    names = [n for n in contact_candidate_names("auto", train.n_samples) if n != NET]
    results, models = _fit(names, train, val, config.seed, threads)
    results = {
        NET: {
            "val_loc_mm": err,
            "fit_seconds": float(net_summary["seconds_total"]),
            "n_train_used": int(train.n_samples),
            "settings": {"profile": config.profile, "best_epoch": net_summary["best_epoch"]},
        },
        **results,
    }
    return _commit(config, out, train, val, results, models)


def fit_contact_alone(
    config: Any, out: Path, train: Any, val: Any, threads: int | None, *, d: Any, split: Any
) -> dict[str, Any]:
    """``--model`` one classical candidate: fit it alone (rank 0), write config.json, split.json
    and the selection (refit when resuming; a run of another seed or other data in ``out`` is
    refused unless starting over). Returns train's summary."""
    from ectskin.learn.distributed import barrier

    name = normalise_choice(config.model)
    t0 = time.perf_counter()
    summary: dict[str, Any] = {}
    if d.main:
        before = out / CANDIDATES_FILE
        if config.resume and before.is_file():
            done = json.loads(before.read_text(encoding="utf-8"))
            fps = _fingerprints(train, val)
            if done.get("seed") != config.seed or any(done.get(k) != v for k, v in fps.items()):
                raise EctskinError(
                    f"{before}: the run was fit with another seed or other data; use another "
                    "output folder, or start over with --overwrite"
                )
        out.mkdir(parents=True, exist_ok=True)
        header = {
            "task": "contact",
            "model_choice": name,
            "seed": config.seed,
            "n_train": int(train.n_samples),
            "n_val": int(val.n_samples),
            "window": int(train.x.shape[1]),
            "pair_names": list(train.pair_names),
            "data_fingerprint": _fingerprints(train, val)["train_fingerprint"],
        }
        write_run_config(out / "config.json", header)
        split = split or {"train": split_names_of(train), "val": split_names_of(val)}
        write_run_config(out / "split.json", split)
        results, models = _fit((name,), train, val, config.seed, threads)
        summary = _commit(config, out, train, val, results, models)
    barrier(d)
    summary.update(
        {
            "task": "contact",
            "metric": "loc_mm",
            "best_val_metric": summary.get("candidates", {}).get(name),
            "seconds_total": time.perf_counter() - t0,
            "world_size": d.world_size,
            "device": "cpu",
            "out_dir": str(out),
        }
    )
    return summary


def _commit(config, out: Path, train, val, results: dict, models: dict) -> dict[str, Any]:
    """Select and write: candidates.json removed first and written last (atomically)."""
    errors = {k: float(r["val_loc_mm"]) for k, r in results.items()}
    name, why = select_contact(errors)
    (out / CANDIDATES_FILE).unlink(missing_ok=True)
    if name in models:
        save_contact_classical(out / CLASSICAL_FILE, models[name])
    else:
        (out / CLASSICAL_FILE).unlink(missing_ok=True)
    doc = {
        "format": CANDIDATES_FORMAT,
        "task": "contact",
        "model": normalise_choice(config.model),
        "selected": name,
        "selected_because": why,
        "metric": METRIC,
        "tie_order": list(PREFERENCE),
        "seed": config.seed,
        **_fingerprints(train, val),
        "n_train": int(train.n_samples),
        "n_val": int(val.n_samples),
        "candidates": {k: {**r, "val_loc_mm": _num(r["val_loc_mm"])} for k, r in results.items()},
    }
    write_json_atomic(out / CANDIDATES_FILE, doc)
    log.info("contact model: selected %s (%s)", name, why)
    return {
        "model_choice": doc["model"],
        "selected_model": name,
        "selected_because": why,
        "candidates": {k: _num(v) for k, v in errors.items()},
    }


def _num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def check_contact_candidates(path: Path, doc: dict[str, Any]) -> dict[str, Any]:
    """A contact ``candidates.json`` (read by :func:`ectskin.learn.candidates.read_candidates`)
    checked: its model choice, candidates and selection, and the files the selection needs."""
    run = path.parent
    choice = doc.get("model")
    if choice not in CONTACT_MODELS:
        raise EctskinError(f"{path}: field 'model' is {choice!r}, expected one of {CONTACT_MODELS}")
    cands = doc.get("candidates")
    if not isinstance(cands, dict) or not cands or not set(cands) <= set(PREFERENCE):
        raise EctskinError(
            f"{path}: field 'candidates' must map candidate names ({', '.join(PREFERENCE)}) to "
            f"their results, found {cands!r:.200}"
        )
    for name, c in cands.items():
        if not isinstance(c, dict) or not isinstance(c.get("val_loc_mm"), int | float | None):
            raise EctskinError(f"{path}: candidate {name!r} has no 'val_loc_mm'")
    selected = doc.get("selected")
    if selected not in cands:
        raise EctskinError(
            f"{path}: field 'selected' is {selected!r}, expected one of {sorted(cands)}"
        )
    need = "model.pt" if selected == NET else CLASSICAL_FILE
    if not (run / need).is_file():
        raise EctskinError(f"{path}: selects {selected!r} but the run has no {need}; train again")
    return doc


def load_selected(run: Path, doc: dict[str, Any]) -> ContactClassical:
    """The selected classical model of a contact run (its ``model.skops``), checked against
    the selection."""
    model = load_contact_classical(run / CLASSICAL_FILE)
    if model.name != doc["selected"]:
        raise EctskinError(
            f"{run / CLASSICAL_FILE}: holds {model.name!r} but candidates.json selects "
            f"{doc['selected']!r}; train again"
        )
    return model


def candidate_predictions(
    run: Any, test: Any, pred: np.ndarray, train: Any
) -> dict[str, tuple[np.ndarray | None, str]]:
    """{name: (predictions on ``test`` or None, where they came from)} of every candidate of a
    contact run's candidates.json ({} without one): the selected model's are ``pred``,
    ContactNet answers from model.pt, the other classical candidates are refit on ``train``
    (the run's training split as a ContactData; or an object with ``data`` and ``note``, as
    :func:`ectskin.learn.evaluate.evaluate_run` passes it) with their recorded seed and settings
    (None when no training split is at hand)."""
    from ectskin.learn.classical import thread_limit

    data, note = getattr(train, "data", train), getattr(train, "note", "")
    out: dict[str, tuple[np.ndarray | None, str]] = {}
    for name, info in (run.candidates or {}).get("candidates", {}).items():
        if name == run.selected:
            out[name] = (pred, run.model_file.name)
        elif name == NET:
            out[name] = (run.task.predict(run.model, test), "model.pt")
        elif data is None:
            out[name] = (None, f"not refit: {note}")
        else:
            s = info.get("settings") or {}
            with thread_limit(1):
                model, _, _ = fit_contact_classical(
                    name, data, seed=int(s.get("seed", 0)), max_train=s.get("max_train")
                )
            out[name] = (model.predict(test.x), "refit on the train split")
    return out


def candidates_on_test(run: Any, case: Any, train: Any) -> dict[str, Any]:
    """Every candidate of a contact run's candidates.json on the test frames: {name:
    val_loc_mm, test_loc_mm (mean), test_loc_mm_median, test_force_mae_n,
    test_count_accuracy, model (where it came from), selected}. The selected model answers
    from its file, ContactNet from model.pt, the other classical candidates are refit on the
    run's training split with their recorded seed and settings (test numbers None when the
    training trials are not at hand)."""
    from ectskin.learn.tasks.contact import contact_report

    test, doc = case.test, run.candidates or {}
    out: dict[str, Any] = {}
    for name, (pred, source) in candidate_predictions(run, test, case.pred, train).items():
        info = doc["candidates"][name]
        m = None if pred is None else contact_report(test, pred, with_maps=False)
        out[name] = {
            "val_loc_mm": info.get("val_loc_mm"),
            "test_loc_mm": None if m is None else m["loc_mm_mean"],
            "test_loc_mm_median": None if m is None else m["loc_mm_median"],
            "test_force_mae_n": None if m is None else m["force_mae_n"],
            "test_force_coverage_1sigma": None if m is None else m["force_coverage_1sigma"],
            "test_force_coverage_2sigma": None if m is None else m["force_coverage_2sigma"],
            "test_count_accuracy": None if m is None else m["count_accuracy"],
            "model": source,
            "selected": name == run.selected,
        }
    return out
