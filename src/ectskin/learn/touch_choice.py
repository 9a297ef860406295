"""The touch model choice of a training run (``TrainConfig.model``, ``--model``).

"mlp" (default) trains the paper's TouchMLP and nothing else (:mod:`ectskin.learn.train`);
"auto" trains it, then :func:`choose_after_mlp` fits the classical candidates
(:mod:`ectskin.learn.candidates`) on the same training split, scores every candidate on the
validation split and writes ``candidates.json`` (and ``model.skops`` when a classical model is
selected); a classical name ("gbt", "random_forest", "logreg", "knn") is fit alone, without an
MLP (:func:`fit_classical`). The choice is recorded in ``config.json`` (``model_choice``): a run is
resumed only with the same choice (:func:`check_model_choice`). Resuming an "auto" run refits
the classical candidates (seeded: the same models) and selects again. Only rank 0 fits them.

The selection is committed so that an interrupted run never names another model than
``model.skops`` holds: ``candidates.json`` is removed first and written last (atomically).
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError, check_option
from ectskin._files import read_json_object
from ectskin.learn.candidates import (
    CANDIDATES_FILE,
    CLASSICAL,
    CLASSICAL_FILE,
    TOUCH_MODELS,
    CandidateResult,
    ClassicalModel,
    accuracy,
    candidate_names,
    fit_candidates,
    read_candidates,
    save_classical,
    select_candidate,
    write_candidates,
)
from ectskin.learn.checkpoint import load_checkpoint
from ectskin.learn.data.touch import TouchData
from ectskin.learn.distributed import Dist, barrier
from ectskin.learn.profiles import TrainConfig
from ectskin.learn.runfiles import fingerprint, split_names_of, write_run_config
from ectskin.learn.tasks import Task

logger = logging.getLogger(__name__)

__all__ = ["check_model_choice", "choose_after_mlp", "fit_classical", "remove_stale"]


def check_model_choice(task: Task, model: str, out: str | Path, *, resume: bool) -> None:
    """Refuse a model choice the task does not have ("mlp" only for tracking; contact: the
    choices of :mod:`ectskin.learn.contact_choice`) or, when resuming, one other than the run's
    own (config.json's ``model_choice``; the task's network when absent)."""
    if task.name == "contact":
        from ectskin.learn.contact_choice import normalise_choice

        model = normalise_choice(model)
    else:
        check_option("model", model, TOUCH_MODELS)
    if task.name not in ("touch", "contact") and model != "mlp":
        raise EctskinError(
            f"--model applies to 'touch' and 'contact' only: {task.name!r} trains its paper "
            f"model, got model={model!r}"
        )
    path = Path(out) / "config.json"
    if not (resume and path.is_file()):
        return
    before = read_json_object(path, "run config").get("model_choice", "mlp")
    if task.name == "contact":
        before = "contactnet" if before == "mlp" else before
    if before != model:
        raise EctskinError(
            f"{path}: the run in this folder was trained with --model {before}, not --model "
            f"{model}; use another output folder, or start over with --overwrite"
        )


def remove_stale(out: Path, model: str, task: str = "touch") -> None:
    """Starting over (``resume=False``): remove the files of an earlier run that this one would
    not replace, so that no earlier selection or model survives beside the new one."""
    stale = [CANDIDATES_FILE, CLASSICAL_FILE]
    if task == "contact":
        from ectskin.learn.contact_choice import CONTACT_CLASSICAL

        classical = model in CONTACT_CLASSICAL
    else:
        classical = model in CLASSICAL
    if classical:
        stale += ["model.pt", "last.pt", "metrics.csv"]  # no MLP in this run
    gone = [out / n for n in stale if (out / n).is_file()]
    for p in gone:
        p.unlink()
    if gone:
        logger.warning("starting over (--overwrite): removed %s", ", ".join(str(p) for p in gone))


def _fingerprints(train_data: TouchData, val_data: TouchData) -> dict[str, str]:
    return {
        "train_fingerprint": fingerprint(train_data.x, train_data.y),
        "val_fingerprint": fingerprint(val_data.x, val_data.y),
    }


def choose_after_mlp(
    task: Task,
    config: TrainConfig,
    out: Path,
    train_data: TouchData,
    val_data: TouchData,
    mlp_summary: dict[str, Any],
    threads: int | None,
) -> dict[str, Any]:
    """``model="auto"`` after the MLP is trained (rank 0): the MLP's kept weights (``out/model.pt``,
    trained as ``mlp_summary`` says) and every classical candidate scored on the whole validation
    split; the best selected and committed. Returns what train's summary adds."""
    mlp, mlp_config, _ = load_checkpoint(out / "model.pt")
    mlp_acc = accuracy(task.predict(mlp, val_data), val_data.y)
    logger.info("touch candidate mlp: validation accuracy %.4f", mlp_acc)
    names = tuple(n for n in candidate_names("auto") if n != "mlp")
    results, models = fit_candidates(names, train_data, val_data, seed=config.seed, threads=threads)
    results = {
        "mlp": CandidateResult(
            "mlp",
            mlp_acc,
            float(mlp_summary["seconds_total"]),
            int(train_data.x.shape[0]),
            {
                "profile": config.profile,
                "best_epoch": mlp_summary["best_epoch"],
                **asdict(mlp_config),
            },
        ),
        **results,
    }
    return _commit(config, out, train_data, val_data, results, models)


def fit_classical(
    task: Task,
    config: TrainConfig,
    out: Path,
    train_data: TouchData,
    val_data: TouchData,
    threads: int | None,
    *,
    d: Dist,
    split: dict[str, Any] | None,
) -> dict[str, Any]:
    """``config.model`` = one classical candidate: fit it alone (rank 0) and commit it, writing
    the run's ``config.json`` and ``split.json`` (``split``, default the train/val trial names);
    a finished run with the same seed and data is left as it is. Returns train's summary."""
    name = config.model
    t0 = time.perf_counter()
    if d.main:
        done = read_candidates(out) if config.resume else None
        fps = _fingerprints(train_data, val_data)
        if done is not None:
            same = done.get("seed") == config.seed and all(done.get(k) == v for k, v in fps.items())
            if not same:
                raise EctskinError(
                    f"{out / CANDIDATES_FILE}: the run was fit with another seed or other data; "
                    "use another output folder, or start over with --overwrite"
                )
            logger.info("%s: %s already fit; nothing to do", out / CANDIDATES_FILE, name)
            return _classical_summary(task, config, out, d, done, time.perf_counter() - t0)
        out.mkdir(parents=True, exist_ok=True)
        header = {
            "task": task.name,
            "model_choice": name,
            "seed": config.seed,
            "n_train": int(train_data.x.shape[0]),
            "n_val": int(val_data.x.shape[0]),
            "pair_names": list(getattr(train_data, "pair_names", []) or []),
            "data_fingerprint": fps["train_fingerprint"],
        }
        write_run_config(out / "config.json", header)
        split = split or {
            "train": split_names_of(train_data),
            "val": split_names_of(val_data),
        }
        write_run_config(out / "split.json", split)
        results, models = fit_candidates(
            (name,), train_data, val_data, seed=config.seed, threads=threads
        )
        _commit(config, out, train_data, val_data, results, models)
    barrier(d)
    return _classical_summary(task, config, out, d, read_candidates(out), time.perf_counter() - t0)


def _commit(
    config: TrainConfig,
    out: Path,
    train_data: TouchData,
    val_data: TouchData,
    results: dict[str, CandidateResult],
    models: dict[str, ClassicalModel],
) -> dict[str, Any]:
    """Select among ``results`` and write the selection: candidates.json is removed first and
    written last (atomically), so a run interrupted in between has no selection, never one that
    names another model than model.skops holds."""
    name, why = select_candidate({k: r.val_accuracy for k, r in results.items()})
    (out / CANDIDATES_FILE).unlink(missing_ok=True)
    if name in models:
        save_classical(out / CLASSICAL_FILE, models[name])
    else:
        (out / CLASSICAL_FILE).unlink(missing_ok=True)  # an earlier selection's
    doc = {
        "model": config.model,
        "selected": name,
        "selected_because": why,
        "metric": "validation accuracy (the whole validation split)",
        "tie_order": list(candidate_names("auto")),
        "seed": config.seed,
        **_fingerprints(train_data, val_data),
        "n_train": int(train_data.x.shape[0]),
        "n_val": int(val_data.x.shape[0]),
        "candidates": {k: r.to_json() for k, r in results.items()},
    }
    write_candidates(out, doc)
    logger.info("touch model: selected %s (%s)", name, why)
    return {
        "model_choice": config.model,
        "selected_model": name,
        "selected_because": why,
        "candidates": {k: r.val_accuracy for k, r in results.items()},
    }


def _classical_summary(
    task: Task,
    config: TrainConfig,
    out: Path,
    d: Dist,
    doc: dict[str, Any] | None,
    seconds: float,
) -> dict[str, Any]:
    """train's return value for a classical model alone."""
    doc = doc or {}
    cands = doc.get("candidates", {})
    selected = doc.get("selected", config.model)
    return {
        "task": task.name,
        "model_choice": config.model,
        "selected_model": selected,
        "selected_because": doc.get("selected_because"),
        "candidates": {k: c.get("val_accuracy") for k, c in cands.items()},
        "best_val_metric": cands.get(selected, {}).get("val_accuracy"),
        "metric": task.metric_name,
        "fit_seconds": cands.get(selected, {}).get("fit_seconds"),
        "seconds_total": seconds,
        "world_size": d.world_size,
        "device": "cpu",
        "out_dir": str(out),
    }
