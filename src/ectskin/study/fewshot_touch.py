"""Few-shot adaptation of touch recognition to a new skin: how many labelled frames of another
skin a trained touch run needs, against training from scratch and against logistic regression
and k-NN on the same frames (``ectskin study few-shot-touch RUN NEW.h5 -o OUT``,
:func:`few_shot_touch_curve`).

The touch counterpart of :mod:`ectskin.study.fewshot` (the contact study), with its draws, its
networks' settings and its outputs: the source is a trained touch run with a network
(``ectskin train touch``, its TouchMLP ``model.pt``); the new skin a labelled recording of a
skin that differs physically, with the same pair count and no more touch classes. The new
recording's trials are split as ``ectskin train touch NEW.h5 --seed SEED`` splits them (the
touch task's trial fractions, stratified by region): its **test** trials score every method,
its **train** trials are the pool the N labelled frames are drawn from
(:func:`~ectskin.study.fewshot.draw_frames`: nested in N, the same frames for every method).

==============  ========================================================================
``finetune``    the source run fine-tuned on them through the path of ``ectskin train
                touch NEW.h5 --init-from RUN``
                (:func:`ectskin.design.variability.finetune_run`: the source's config,
                normaliser and weights; the source weights kept unless an epoch beats them
                on validation). N = 0: the source run as it is.
``scratch``     a TouchMLP trained from a seeded initialisation on them (normaliser fit on
                them), the same settings otherwise.
``logreg``      the touch baseline's logistic regression (standardised frames,
                :func:`ectskin.learn.baselines.touch.sklearn_touch_baseline`), fit on all N.
``knn``         the touch baseline's 5-nearest-neighbour vote, likewise.
==============  ========================================================================

The networks hold out every ``val_every``-th drawn frame to pick their kept epoch and train with
the touch ``profile`` (default ``quick``) for about ``steps`` optimiser steps
(:func:`~ectskin.study.fewshot.net_config`).

Frames are calibrated (Eq. 2) against the new skin's own rest readout, or, for a source run
that calibrates against the rest readout at each trial's own inflation (its reference mode
"state", "inflation", "state-offset" or "inflation-offset", :mod:`ectskin.learn.data.touch`),
the same mode on the new skin's own recording (an inflation model refitted there: the source
skin's would not apply). Scores on the test trials (:data:`METRICS`): ``accuracy`` over every
frame and ``touch_accuracy`` over the frames with a touch (class > 0), where the no-touch class
does not dominate. ``OUT/few_shot.json`` and ``OUT/few_shot.png`` as the contact study's.
"""

from __future__ import annotations

import argparse
import logging
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ectskin._check import EctskinError
from ectskin.study.fewshot import (
    FewShotConfig,
    common_arguments,
    curve_document,
    curve_values,
    draw_frames,
    net_config,
    net_split,
    run_study,
)

log = logging.getLogger(__name__)

HELP = (
    "few-shot curves on a new skin: a trained touch run fine-tuned on N labelled frames, "
    "against a TouchMLP from scratch and logistic regression / k-NN on the same frames"
)
EXAMPLES = """\
  ectskin study few-shot-touch runs/touch new.h5 -o fewshot-touch    # N = 0, 100, 300, 1000
  ectskin study few-shot-touch runs/touch new.h5 -o fst --simulate   # record new.h5 first
"""

#: the methods compared (module docstring)
METHODS = ("finetune", "scratch", "logreg", "knn")
#: the metrics scored, and their axis labels
METRICS = {
    "accuracy": "accuracy (every test frame)",
    "touch_accuracy": "accuracy on touched frames",
}


@dataclass(frozen=True)
class TouchFewShotConfig(FewShotConfig):
    """What :func:`few_shot_touch_curve` does: :class:`~ectskin.study.fewshot.FewShotConfig`'s
    fields, with the touch methods (:data:`METHODS`); ``counts`` default the touch task's."""

    ALLOWED: ClassVar[tuple[str, ...]] = METHODS
    methods: tuple[str, ...] = METHODS


def few_shot_touch_curve(
    source_run: str | Path,
    new_data: Any,
    out: str | Path | None = None,
    config: TouchFewShotConfig | None = None,
) -> dict[str, Any]:
    """The few-shot curves of ``source_run`` (a touch run folder) on ``new_data`` (a Recording
    or its file): see the module docstring. Writes ``out/few_shot.json`` and
    ``out/few_shot.png`` when ``out`` is given; returns what the JSON holds."""
    from ectskin.io import Recording, read_recording
    from ectskin.learn.data.touch import touch_dataset
    from ectskin.learn.splits import split_groups

    config = TouchFewShotConfig() if config is None else config
    if not isinstance(config, TouchFewShotConfig):
        raise EctskinError(
            f"few-shot-touch: config must be a TouchFewShotConfig, got {type(config).__name__}"
        )
    t0 = time.perf_counter()
    run = _source_run(source_run)
    task = run.task
    if isinstance(new_data, Recording):
        rec, data_desc = new_data, str(new_data.source or "given Recording")
    else:
        rec, data_desc = read_recording(new_data), str(new_data)
    reference = source_reference(run)
    ds = touch_dataset(rec, reference=reference)
    if ds.n_pairs != int(run.config.n_pairs):
        raise EctskinError(
            f"few-shot-touch: new_data {data_desc}: {ds.n_pairs} pairs, the source run's model "
            f"reads {run.config.n_pairs}; the new skin needs the same pair count"
        )
    if ds.n_classes > int(run.config.n_classes):
        raise EctskinError(
            f"few-shot-touch: new_data {data_desc}: {ds.n_classes} touch classes, the source "
            f"run's model knows {run.config.n_classes}; the new skin needs no more classes"
        )
    counts = config.counts or task.split_counts
    ids = split_groups(ds.group_names, counts, seed=config.seed, stratify=task.stratify(ds))
    pool, test = ds.select(ids["train"]), ds.select(ids["test"])
    draws = draw_frames(pool.n_samples, tuple(config.frames), config.draws, config.seed)
    base = scores(test, task.predict(run.model, test))
    log.info(
        "few-shot-touch: source %s on the new skin's %d test frames: accuracy %.4f, on touched "
        "frames %.4f",
        run.path,
        test.n_samples,
        base["accuracy"],
        base["touch_accuracy"] if base["touch_accuracy"] is not None else math.nan,
    )
    values, seconds = curve_values(
        draws, config, pool, base,
        lambda method, sample, d: _fit_predict(method, run, sample, test, config,
                                               seed=config.seed + d),
        lambda pred: scores(test, pred),
        lambda d, n, method, v: log.info("few-shot-touch draw %d, N = %d, %s: accuracy %.4f",
                                         d, n, method, v["accuracy"]),
    )
    study = dict(task=task, run=run, rec=rec, data_desc=data_desc, config=config, counts=counts,
                 ds=ds, ids=ids, pool=pool, test=test, draws=draws, base=base)
    split = {"test_touch_frames": base["n_touch_frames"]}
    return curve_document(study, METRICS, values, seconds, t0, out, split=split,
                          extra={"reference": ds.reference})


def source_reference(run: Any) -> str:
    """The Eq. 2 reference of the new skin's frames for a source ``run`` (module docstring):
    the run's own mode when it follows the inflation, else "auto" (the new skin's rest)."""
    from ectskin.learn.data.touch import FOLLOWS_INFLATION

    doc = run.split.get("touch_reference") or run.payload.get("extra", {}).get("reference") or {}
    mode = doc.get("mode") if isinstance(doc, dict) else None
    return str(mode) if mode in FOLLOWS_INFLATION else "auto"


def scores(test: Any, pred: np.ndarray) -> dict[str, Any]:
    """``accuracy`` over ``test``'s frames, ``touch_accuracy`` over those with a touch (None
    without any), and the frame counts."""
    y, p = np.asarray(test.y), np.asarray(pred)
    touched = y > 0
    return {
        "accuracy": float(np.mean(p == y)) if y.size else None,
        "touch_accuracy": float(np.mean(p[touched] == y[touched])) if touched.any() else None,
        "n_frames": int(y.size),
        "n_touch_frames": int(touched.sum()),
    }


def _source_run(source_run: str | Path):
    """The source run, read and checked: a touch run with a network."""
    from ectskin.learn.evaluate import read_run

    path = Path(source_run)
    if not path.is_dir():
        raise EctskinError(f"few-shot-touch: source_run {path}: not a run folder")
    run = read_run(path)
    if run.task.name != "touch":
        raise EctskinError(
            f"few-shot-touch: source_run {path}: field 'task' is {run.task.name!r}, expected "
            "'touch' (a run of ectskin train touch; a contact run: ectskin study few-shot)"
        )
    if run.model is None:
        raise EctskinError(
            f"few-shot-touch: source_run {path}: field 'model' is a classical model alone "
            f"({run.selected}); fine-tuning needs the run's network (model.pt)"
        )
    return run


def _fit_predict(method: str, run, sample, test, config: TouchFewShotConfig, *, seed: int):
    """``method`` fit on the drawn frames ``sample``; its predicted classes on ``test``."""
    if method in ("logreg", "knn"):
        from ectskin.learn.baselines.touch import sklearn_touch_baseline

        return sklearn_touch_baseline(method, sample, test, seed=seed, n_jobs=1).pred
    from ectskin.design.variability import finetune_run
    from ectskin.learn.checkpoint import load_checkpoint
    from ectskin.learn.train import train

    tr, va = net_split(sample.n_samples, config.val_every)
    train_data, val_data = sample.take(tr), sample.take(va)
    if method == "finetune":
        cfg = net_config(config, len(tr), config.finetune_lr, seed)
        model, _ = finetune_run("touch", run.path, train_data, val_data, cfg)
    else:
        cfg = net_config(config, len(tr), config.scratch_lr, seed)
        with tempfile.TemporaryDirectory(prefix="ectskin-scratch-") as folder:
            train("touch", train_data, val_data, folder, cfg)
            model, _, _ = load_checkpoint(Path(folder) / "model.pt", kind=run.task.model_kind)
        model.eval()
    return run.task.predict(model, test)


# ----------------------------------------------------------------------------- the command
def add_arguments(p: argparse.ArgumentParser) -> None:
    common_arguments(p, "touch", METHODS)


def run(args: argparse.Namespace) -> int:
    return run_study(args, TouchFewShotConfig, few_shot_touch_curve)
