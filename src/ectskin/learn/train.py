"""Training of a task's model with named profiles, exact resume and optional DDP.

* :func:`train_from_recording`: everything ``ectskin train TASK DATA --out RUN`` does, from a
  recording file, with a :class:`TrainConfig`.
* :func:`train`: the same on in-memory splits (the task's data sets, :mod:`ectskin.learn.data`),
  with the same :class:`TrainConfig`.

Both write a run directory (files: :mod:`ectskin.learn.runfiles`). The task
(:mod:`ectskin.learn.tasks`) builds the model and its criterion; the profile
(:mod:`ectskin.learn.profiles`) gives the optimisation settings: Adam, StepLR, the weights of the
best validation epoch kept (lowest loss, or best metric for the ``robust`` recipe). The epoch
loops are :mod:`ectskin.learn.engine`; the touch model choice (``TrainConfig.model``,
``--model``: the paper's TouchMLP by default, or classical candidates) is
:mod:`ectskin.learn.touch_choice`, the contact one :mod:`ectskin.learn.contact_choice`;
fine-tuning a trained run (``TrainConfig.init_from``, ``--init-from``) is
:mod:`ectskin.learn.finetune`.

Determinism and resume: every random draw of an epoch is seeded from ``(seed, epoch, rank)``
(see :mod:`ectskin.learn.engine`), so a run that is stopped and resumed from ``last.pt``
produces the same weights, bit for bit on CPU, as an uninterrupted one. Training runs on
:data:`~ectskin.learn.threads.TRAIN_DEFAULT_THREADS` torch CPU thread(s) unless told otherwise:
results depend on the thread count.

Distributed data parallel: the same :func:`train` runs unchanged under
``torchrun --nproc_per_node N`` (:mod:`ectskin.learn.distributed`), with a per-rank batch of
``ceil(batch_size / N)``, so the global batch matches the single-process one (exactly when
``batch_size`` is divisible by N). Only rank 0 writes files and shows progress. Each rank
augments its own shard (mixup pairs frames within the rank's batch).

"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ectskin._check import EctskinError, check_seed
from ectskin._files import to_jsonable
from ectskin.io import read_recording
from ectskin.learn import contact_choice as cc
from ectskin.learn import finetune
from ectskin.learn.candidates import CLASSICAL
from ectskin.learn.checkpoint import save_checkpoint
from ectskin.learn.data import SampleData
from ectskin.learn.distributed import Dist, barrier, setup, wrap
from ectskin.learn.engine import (
    Progress,
    Tensors,
    epoch_indices,
    evaluate,
    improved,
    seed_for,
    train_one_epoch,
    val_indices,
)
from ectskin.learn.extra_train import extra_training_data, join_training
from ectskin.learn.profiles import RECIPE_FIELDS, TrainConfig, TrainSettings
from ectskin.learn.runfiles import (
    RunState,
    check_run_folder,
    data_identity,
    fingerprint,
    resume_run,
    split_names_of,
    write_metrics,
    write_run_config,
)
from ectskin.learn.splits import split_groups, split_names
from ectskin.learn.tasks import Criterion, Task, get_task
from ectskin.learn.threads import TRAIN_DEFAULT_THREADS, resolve_threads, torch_threads
from ectskin.learn.touch_choice import (
    check_model_choice,
    choose_after_mlp,
    fit_classical,
    remove_stale,
)

logger = logging.getLogger(__name__)

__all__ = ["TrainConfig", "train", "train_from_recording"]

#: profiles meant for a GPU: training with one on a CPU warns at the start
GPU_PROFILES = ("paper",)
#: the largest data set of windows (track, contact) a training builds: frames x window x pairs
#: x 4 bytes (the paper's tracking data with its 10-frame windows: about 0.2 GiB)
MAX_WINDOW_BYTES = 8 * 2**30


def train_from_recording(
    task: str, data_path: str | Path, out: str | Path, config: TrainConfig | None = None
) -> dict[str, Any]:
    """Train ``task`` on a recording file and write the run directory ``out``.

    Reads the recording (:func:`ectskin.io.read_recording`: HDF5, or a generic ``.npz``/``.csv``),
    builds the task's data set, splits the trials with
    :func:`~ectskin.learn.splits.split_groups` (``config.counts``, default the task's; touch
    stratified by region; seed ``config.split_seed``, default ``config.seed``), records the split
    in ``split.json`` (train/val/test trial names, task, data file, counts, split seed, and the
    recording's trial digests and rest reference: :func:`~ectskin.learn.runfiles.data_identity`)
    and calls :func:`train`. A touch recording of one class, or windows too large for memory
    (:data:`MAX_WINDOW_BYTES`), are refused before the data set is split. An existing ``out``
    must be a run directory (resumed) unless ``config.resume`` is False. Runs unchanged under
    ``torchrun`` (every rank reads the data; only rank 0 writes). Returns train's summary plus
    ``n_train``/``n_val``/``n_test`` samples. ``config`` None: ``TrainConfig()``.
    """
    config = TrainConfig() if config is None else config
    t = get_task(task)
    config.settings_for(task)  # a bad profile or setting fails before the data is read
    _check_seeds(config)
    t.check_options(window=config.window, prior=config.prior)
    resolve_threads(config.threads)
    check_run_folder(out, resume=config.resume)
    check_model_choice(t, config.model, out, resume=config.resume)
    data_path = Path(data_path)
    rec = read_recording(data_path)
    if t.windowed:
        _check_window_size(rec, config.window, data_path)
    data = t.dataset(
        rec, window=config.window, prior=config.prior, reference=config.reference_for(task)
    )
    t.check_trainable(data, str(data_path))
    counts = config.counts or t.split_counts
    split_seed = config.seed if config.split_seed is None else config.split_seed
    split_ids = split_groups(data.group_names, counts, seed=split_seed, stratify=t.stratify(data))
    parts = {k: data.select(v) for k, v in split_ids.items()}
    split = {
        **split_names(split_ids, data.group_names),
        "task": task,
        "data": str(data_path.resolve()),
        "counts": [float(c) for c in counts],
        "split_seed": split_seed,
        **data_identity(rec),
    }
    if config.extra_train:  # trials for the training split alone (ectskin.learn.extra_train)
        options = {"window": config.window, "prior": config.prior}
        extras, split["extra_train"] = extra_training_data(
            t, config.extra_train, reference=config.reference_for(task), options=options,
            run_digests=split["trial_digests"],
        )
        parts["train"] = join_training(parts["train"], extras, config.extra_train)
    if getattr(data, "reference", None):  # touch: the Eq. 2 reference, re-applied by evaluate
        split["touch_reference"] = data.reference
    summary = train(task, parts["train"], parts["val"], out, config, split=split)
    summary.update({f"n_{k}": int(p.n_samples) for k, p in parts.items()})
    return summary


def train(
    task: str,
    train_data: SampleData,
    val_data: SampleData,
    out_dir: str | Path,
    config: TrainConfig | None = None,
    *,
    split: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train the model of ``task`` ("touch": TouchMLP, "track": C2DT, "contact": ContactNet) as
    ``config`` says and write ``out_dir``.

    Parameters
    ----------
    train_data, val_data : the task's data (TouchData for "touch", TrackData for "track",
        ContactData for "contact").
    out_dir : run directory (created). If it holds ``last.pt`` and ``config.resume`` is true,
        training continues from it (same settings and data required); ``config.epochs`` may be
        raised to extend a finished run. With ``resume=False`` an existing run is overwritten.
    config : :class:`TrainConfig` (None: the default): the profile and its overrides (the robust recipe's inflation
        shift needs two no-contact trials (``group_region`` 0) in ``train_data``; with fewer it
        is skipped with a warning, the rest of the recipe applies, config.json's ``recipe``:
        ``inflation_shift_states`` 0), seed, device, progress, model options, threads and the
        touch model choice (:mod:`ectskin.learn.touch_choice`). Its data-set fields (``window``,
        ``prior``, ``counts``, ``split_seed``) are not read: the data sets are built.
    split : trial names per split to record in ``split.json`` (default: the train/val names).

    Returns a summary dict: best_epoch (1-based), best_val_loss, best_val_metric, metric
    (its name), select (the rule that chose best_epoch), recipe (as in config.json), epochs,
    epochs_run, resumed_from, seconds_total, seconds_this_run, seconds_per_epoch, world_size,
    device, out_dir. With a model choice other than "mlp" also model_choice, selected_model,
    selected_because and candidates ({name: validation accuracy}); a classical model alone has
    no epochs (best_val_metric is its validation accuracy).
    """
    config = TrainConfig() if config is None else config
    t = get_task(task)
    _check_seeds(config)
    check_model_choice(t, config.model, out_dir, resume=config.resume)
    finetune.check_init_choice(task, config.model, config.init_from)
    s = config.settings_for(task)
    t.check_data(train_data, "train_data")
    t.check_data(val_data, "val_data")
    t.check_trainable(train_data, "train_data")
    tr_shape, va_shape = train_data.x.shape[1:], val_data.x.shape[1:]
    if tr_shape != va_shape:
        raise EctskinError(
            f"train_data and val_data disagree: x samples of shape {tr_shape} vs {va_shape}"
        )
    n_threads = TRAIN_DEFAULT_THREADS if config.threads is None else config.threads
    resolve_threads(n_threads)  # an invalid value fails before the process group is set up
    d = setup(config.device)
    out = Path(out_dir)
    job = _Job(t, s, config, int(config.seed), d, split, out)
    contact = t.name == "contact"
    if d.main and not config.resume:
        remove_stale(out, config.model, t.name)
    with torch_threads(n_threads if d.device.type == "cpu" else None) as used_threads:
        native = used_threads if d.device.type == "cpu" else resolve_threads(n_threads)
        if contact and config.model in cc.CONTACT_CLASSICAL:
            return cc.fit_contact_alone(config, out, train_data, val_data, native, d=d, split=split)
        if not contact and config.model in CLASSICAL:
            return fit_classical(t, config, out, train_data, val_data, native, d=d, split=split)
        summary = _train(job, train_data, val_data)
        if config.model == "auto" and d.main:
            choose = cc.choose_after_net if contact else partial(choose_after_mlp, t)
            summary.update(choose(config, out, train_data, val_data, summary, native))
        return summary


def _check_window_size(rec: Any, window: int, source: Path) -> None:
    """Refuse windows whose data set would not fit in memory (one window of ``window`` frames
    per frame, float32), naming the size, before it is built."""
    frames = sum(t.n_frames for t in rec.trials)
    nbytes = frames * int(window) * rec.n_pairs * 4
    if nbytes > MAX_WINDOW_BYTES:
        raise EctskinError(
            f"{source}: --window {window}: {frames} frames x {window} frames per window x "
            f"{rec.n_pairs} pairs x 4 bytes = {nbytes / 2**30:.1f} GiB of windows; at most "
            f"{MAX_WINDOW_BYTES / 2**30:.0f} GiB (ectskin.learn.train.MAX_WINDOW_BYTES): choose a "
            "shorter window (the paper's: 10 frames)"
        )


def _check_seeds(config: TrainConfig) -> None:
    check_seed("seed", config.seed, source="TrainConfig")
    if config.split_seed is not None:
        check_seed("split_seed", config.split_seed, source="TrainConfig")


# ============================================================================ the run
@dataclass(frozen=True)
class _Job:
    """What :func:`train` was asked to do, checked (``settings``: the profile's, overridden)."""

    task: Task
    settings: TrainSettings
    config: TrainConfig
    seed: int
    d: Dist
    split: dict[str, Any] | None
    out_dir: Path


@dataclass
class _Model:
    """The model being trained with everything saved beside it."""

    model: nn.Module
    normalizer: dict[str, Any]
    extra: dict[str, Any]
    optimizer: torch.optim.Optimizer
    scheduler: Any
    fingerprint: str


def _train(job: _Job, train_data: SampleData, val_data: SampleData) -> dict[str, Any]:
    """The body of :func:`train` once inputs are checked and the process group is set up."""
    task, s, d = job.task, job.settings, job.d
    m = _build(job, train_data)
    state = resume_run(  # the run in last.pt, weights, optimizer and scheduler restored
        job.out_dir,
        resume=job.config.resume,
        model=m.model,
        optimizer=m.optimizer,
        scheduler=m.scheduler,
        task=task.name,
        settings=s,
        seed=job.seed,
        data_fingerprint=m.fingerprint,
        d=d,
    )
    criterion = task.criterion(m.model, s, train_data, d.device)
    for note in criterion.notes if d.main else ():
        logger.warning(note)
    if job.config.init_from is not None and state.epoch == 0:  # the base weights: epoch 0
        scores = finetune.keep_base(task, m.model, criterion, val_data, s, d)
        state.best_loss, state.best_metric = scores
        if d.main:
            job.out_dir.mkdir(parents=True, exist_ok=True)
            finetune.save_base(job.out_dir, m.model, m.normalizer, m.extra, scores)
    recipe = {k: getattr(s, k) for k in RECIPE_FIELDS}
    recipe["inflation_shift_states"] = criterion.shift_states
    if getattr(train_data, "reference", None):  # touch: which Eq. 2 reference calibrated it
        recipe["reference"] = train_data.reference.get("mode")
    extra = (job.split or {}).get("extra_train") or []
    if extra:  # trials that joined the training split only (ectskin.learn.extra_train)
        recipe["extra_train"] = [
            {"file": Path(x["file"]).name, "trials": len(x["trial_digests"])} for x in extra
        ]
    rank_batch = math.ceil(s.batch_size / d.world_size)
    if d.main:
        _write_header(job, m, recipe, rank_batch, train_data, val_data)
    t_run = time.perf_counter()
    _epochs(job, m, state, criterion, train_data, val_data, rank_batch)
    barrier(d)  # rank 0 has written every file before anyone returns
    return _summary(job, state, recipe, time.perf_counter() - t_run)


def _build(job: _Job, train_data: SampleData) -> _Model:
    """The model (seeded initialisation, normalisation fitted on the training data), its
    optimizer and scheduler, and the checkpoint metadata."""
    task, s, d = job.task, job.settings, job.d
    torch.manual_seed(job.seed)  # model initialisation: identical on every rank
    base: dict[str, Any] = {}
    if job.config.init_from is not None:  # fine-tuning: the base run's config, normaliser, weights
        model, normalizer, base = finetune.base_model(
            job.config.init_from, task, train_data, job.config.model_options
        )
    else:
        model = task.build_model(train_data, job.config.model_options)
        normalizer = task.fit_normalization(model, train_data)
    extra = {
        **base,
        "task": task.name,
        "pair_names": list(getattr(train_data, "pair_names", []) or []),
        "profile": job.config.profile,
        "seed": job.seed,
        "device": str(d.device),
        "world_size": d.world_size,
        **task.checkpoint_extra(train_data),
    }
    model.to(d.device)
    opt_kwargs = {"fused": True} if d.device.type in ("cpu", "cuda") else {}
    optimizer = torch.optim.Adam(model.parameters(), lr=s.lr, **opt_kwargs)
    scheduler = torch.optim.lr_scheduler.StepLR(optimizer, step_size=s.step_size, gamma=s.gamma)
    fp = fingerprint(*(getattr(train_data, name) for name in task.arrays))
    return _Model(model, normalizer, extra, optimizer, scheduler, fp)


def _write_header(
    job: _Job,
    m: _Model,
    recipe: dict,
    rank_batch: int,
    train_data: SampleData,
    val_data: SampleData,
) -> None:
    """config.json and split.json of the run (rank 0)."""
    d = job.d
    job.out_dir.mkdir(parents=True, exist_ok=True)
    config = {
        "task": job.task.name,
        "model_choice": job.config.model,
        "profile": job.config.profile,
        "seed": job.seed,
        "settings": asdict(job.settings),
        "recipe": recipe,
        "model_kind": m.model.kind,
        "model": asdict(m.model.config),
        "world_size": d.world_size,
        "batch_per_rank": rank_batch,
        "device": str(d.device),
        "n_train": int(train_data.x.shape[0]),
        "n_val": int(val_data.x.shape[0]),
        "pair_names": m.extra["pair_names"],
        "data_fingerprint": m.fingerprint,
        **({"init_from": m.extra["init_from"]} if "init_from" in m.extra else {}),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
    }
    write_run_config(job.out_dir / "config.json", config)
    split = job.split
    if split is None:
        split = {"train": split_names_of(train_data), "val": split_names_of(val_data)}
    write_run_config(job.out_dir / "split.json", split)
    s = job.settings
    logger.info(
        "training %s with profile %r (%d epochs, batch %d%s) on %s x %d (batch %d per rank), "
        "%d training samples",
        job.task.name,
        job.config.profile,
        s.epochs,
        s.batch_size,
        f", {s.samples_per_epoch} samples per epoch" if s.samples_per_epoch else "",
        d.device,
        d.world_size,
        rank_batch,
        int(train_data.x.shape[0]),
    )
    if d.device.type == "cpu" and job.config.profile in GPU_PROFILES:
        logger.warning(
            "profile %r holds the paper's settings, meant for a GPU: on a CPU they take hours "
            "on the paper's data set (the time left is logged after the first epoch); "
            "--profile quick is the setting for a CPU",
            job.config.profile,
        )


def _epochs(
    job: _Job,
    m: _Model,
    state: RunState,
    criterion: Criterion,
    train_data: SampleData,
    val_data: SampleData,
    rank_batch: int,
) -> None:
    """Train from ``state.epoch`` to the profile's epochs, updating ``state`` and the files."""
    task, s, d = job.task, job.settings, job.d
    ddp_model = wrap(m.model, d)
    train_t: Tensors = task.tensors(train_data, d.device)
    val_t: Tensors = task.tensors(val_data, d.device)
    val_idx = val_indices(val_t.n, s.val_samples, d.rank, d.world_size)
    n_per_epoch = min(s.samples_per_epoch or train_t.n, train_t.n)
    n_batches = math.ceil(math.ceil(n_per_epoch / d.world_size) / rank_batch)
    bars = Progress(task.name, s.epochs, state.epoch, n_batches, show=job.config.progress, d=d)
    t_run = time.perf_counter()
    try:
        for epoch in range(state.epoch, s.epochs):
            t0 = time.perf_counter()
            torch.manual_seed(seed_for(job.seed, epoch, d.rank))  # dropout etc. of this epoch
            aug_rng = (
                np.random.default_rng(seed_for(job.seed, epoch, d.rank, 0xA6))  # augmentation
                if criterion.augments
                else None
            )
            idx = epoch_indices(
                train_t.n,
                epoch,
                job.seed,
                rank=d.rank,
                world_size=d.world_size,
                samples=s.samples_per_epoch,
            )
            bars.start_epoch(epoch)
            lr = m.optimizer.param_groups[0]["lr"]
            train_loss = train_one_epoch(
                ddp_model,
                criterion,
                m.optimizer,
                train_t,
                idx,
                rank_batch,
                epoch=epoch,
                d=d,
                bar=bars.batch,
                rng=aug_rng,
            )
            val_loss, val_metric = evaluate(
                m.model, criterion, val_t, val_idx, s.eval_batch_size, d
            )
            m.scheduler.step()
            seconds = time.perf_counter() - t0
            row = {
                "epoch": epoch + 1,
                "train_loss": train_loss,
                "val_loss": val_loss,
                "val_metric": val_metric,
                "lr": lr,
                "seconds": seconds,
            }
            _end_epoch(job, m, state, row, state.seconds_before + time.perf_counter() - t_run)
            bars.end_epoch(row, task.metric_name)
            left = s.epochs - epoch - 1
            if epoch == state.resumed_from and left > 0 and d.main:
                logger.info(
                    "epoch %d took %.1f s: about %s left for the other %d epoch(s)",
                    epoch + 1,
                    seconds,
                    _duration(seconds * left),
                    left,
                )
    finally:
        bars.close()


def _end_epoch(job: _Job, m: _Model, state: RunState, row: dict, elapsed: float) -> None:
    """Record one epoch: the kept weights (model.pt) when it improved, metrics.csv, last.pt."""
    task, s, d = job.task, job.settings, job.d
    state.rows.append(row)
    state.epoch = epoch = row["epoch"]
    val_loss, val_metric = row["val_loss"], row["val_metric"]
    better = improved(
        s.select,
        task.lower_is_better_metric,
        val_loss,
        val_metric,
        state.best_loss,
        state.best_metric,
        state.best_epoch,
    )
    if better:
        state.best_loss, state.best_metric, state.best_epoch = val_loss, val_metric, epoch
    if not d.main:
        return
    extra = {
        **m.extra,
        "epoch": epoch,
        "val_loss": val_loss,
        "val_metric": val_metric,
        "metric": task.metric_name,
    }
    model, config = m.model, m.model.config
    if better:
        save_checkpoint(
            job.out_dir / "model.pt", model, config, normalizer=m.normalizer, extra=extra
        )
    write_metrics(job.out_dir / "metrics.csv", state.rows)
    save_checkpoint(
        job.out_dir / "last.pt",
        model,
        config,
        normalizer=m.normalizer,
        extra=extra,
        resume={
            "epoch": epoch,
            "optimizer": m.optimizer.state_dict(),
            "scheduler": m.scheduler.state_dict(),
            "best_val_loss": state.best_loss,
            "best_val_metric": state.best_metric,
            "best_epoch": state.best_epoch,
            "seconds": elapsed,
            "settings": to_jsonable(asdict(s)),
            "seed": job.seed,
            "task": task.name,
            "data_fingerprint": m.fingerprint,
        },
    )


def _duration(seconds: float) -> str:
    """ "42 s", "7 min", "2.5 h": a rough time for a log line."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _summary(job: _Job, state: RunState, recipe: dict, this_run: float) -> dict[str, Any]:
    """train's return value (see :func:`train`); logged by rank 0."""
    s, d, metric = job.settings, job.d, job.task.metric_name
    total = state.seconds_before + this_run
    if d.main:
        logger.info(
            "%s training done: best epoch %d, val_loss %.4g, val_%s %.4g (%.1f s)",
            job.task.name,
            state.best_epoch,
            state.best_loss,
            metric,
            state.best_metric,
            total,
        )
    return {
        "task": job.task.name,
        "best_epoch": state.best_epoch,
        "best_val_loss": state.best_loss,
        "best_val_metric": state.best_metric,
        "metric": metric,
        "select": s.select,
        "recipe": recipe,
        "epochs": s.epochs,
        "epochs_run": max(s.epochs - state.resumed_from, 0),
        "resumed_from": state.resumed_from,
        "seconds_total": total,
        "seconds_this_run": this_run,
        "seconds_per_epoch": total / max(state.resumed_from, s.epochs, 1),
        "world_size": d.world_size,
        "device": str(d.device),
        "out_dir": str(job.out_dir),
    }
