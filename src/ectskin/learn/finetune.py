"""Fine-tuning a trained run on another skin: ``ectskin train touch|contact NEW.h5 --init-from
RUN`` (``TrainConfig.init_from``).

The run's network (``RUN/model.pt``, or a checkpoint file itself; loaded with
``torch.load(weights_only=True)``, :mod:`ectskin.learn.checkpoint`) is the starting point:

* its **config** (the architecture; ``model_options`` are refused beside it) and **weights**;
* its **normaliser**: the per-pair statistics and (contact) the face centres and force scale of
  the base run's training data stay as they are, in the model's buffers and in the new
  ``model.pt``; nothing is refit on the new frames, so the few new frames are read exactly as
  the base model reads frames.

Then training runs as usual (a fresh optimiser, the profile's epochs, seeded), except that the
base weights are scored on the new validation split first and kept as epoch 0 (``model.pt``):
a later epoch replaces them only where it is better on validation, so a fine-tune never keeps
weights worse than the base on that split, and a fine-tune of 0 epochs answers exactly as the
base run does.

The same path on data sets in memory (no recording file, no split of it):
``ectskin.design.variability.finetune_run``, what the variability study's fine-tuning recovery
and the few-shot study (``ectskin study few-shot``) call.

Refused (an EctskinError naming the run): a model of another task, a layout with another pair
count than the base model reads, a contact window other than the base's, touch classes the
base model does not have, and ``--init-from`` with a classical model choice.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import torch
from torch import nn

from ectskin._check import EctskinError
from ectskin.learn.checkpoint import load_checkpoint, save_checkpoint

log = logging.getLogger(__name__)

__all__ = ["base_model", "check_init_choice", "keep_base"]


def _model_file(init_from: str | Path) -> Path:
    path = Path(init_from)
    return path / "model.pt" if path.is_dir() else path


def check_init_choice(task: str, model: str, init_from: Any) -> None:
    """``--init-from`` fine-tunes a network: refuse it with a classical model choice."""
    if init_from is None:
        return
    if model not in ("mlp", "contactnet", "auto"):
        raise EctskinError(
            f"--init-from {init_from}: fine-tunes the run's network, but --model {model} fits "
            f"a classical {task} model alone; use --model {'contactnet' if task == 'contact' else 'mlp'} "
            "or auto"
        )


def base_model(
    init_from: str | Path, task: Any, train_data: Any, model_options: Any
) -> tuple[nn.Module, dict[str, Any], dict[str, Any]]:
    """The base run's network, its normaliser (as stored) and what the new run records of it,
    checked against the task and ``train_data``."""
    path = _model_file(init_from)
    if not path.is_file():
        raise EctskinError(
            f"--init-from {init_from}: no model file {path} (a run of a classical model alone "
            "has no network to fine-tune)"
        )
    if model_options:
        raise EctskinError(
            f"--init-from {init_from}: the model's settings come from the base run; expected "
            f"no model_options, found {sorted(model_options)}"
        )
    model, config, payload = load_checkpoint(path, kind=task.model_kind)
    n_data = int(train_data.x.shape[-1])
    if int(config.n_pairs) != n_data:
        raise EctskinError(
            f"--init-from {init_from}: its model reads {config.n_pairs} electrode pairs, the new "
            f"data has {n_data}; fine-tuning needs a skin with the same pair count (the layouts' "
            "pair counts differ)"
        )
    window = getattr(config, "window", None)
    if task.windowed and window is not None and int(window) != int(train_data.x.shape[1]):
        raise EctskinError(
            f"--init-from {init_from}: its model reads windows of {window} frames, the new data "
            f"{train_data.x.shape[1]}; pass --window {window}"
        )
    n_classes = getattr(config, "n_classes", None)
    if n_classes is not None and int(getattr(train_data, "n_classes", 0)) > int(n_classes):
        raise EctskinError(
            f"--init-from {init_from}: its model knows {n_classes} touch classes, the new data "
            f"has {train_data.n_classes}"
        )
    normalizer = dict(payload.get("normalizer") or {})
    record = {"init_from": str(path.resolve()), "init_epoch": payload.get("extra", {}).get("epoch")}
    log.info("fine-tuning %s (%s), its normaliser kept", path, payload["kind"])
    return model.train(), normalizer, record


def keep_base(
    task: Any, model: nn.Module, criterion: Any, val_data: Any, settings: Any, d: Any
) -> tuple[float, float]:
    """The base weights scored on the new validation split (as every epoch is): (val_loss,
    val_metric). Scoring leaves the base model as it was: a buffer the validation pass sets
    (the contact force σ's scale, :mod:`ectskin.learn.tasks.contact`) is put back, so epoch 0
    is the base run bit for bit; the epochs after it set theirs on the new split as usual."""
    from ectskin.learn.engine import evaluate, val_indices

    before = {k: v.detach().clone() for k, v in model.named_buffers()}
    val_t = task.tensors(val_data, d.device)
    idx = val_indices(val_t.n, settings.val_samples, d.rank, d.world_size)
    scores = evaluate(model, criterion, val_t, idx, settings.eval_batch_size, d)
    with torch.no_grad():
        for k, v in model.named_buffers():
            v.copy_(before[k])
    return scores


def save_base(out: Path, model: nn.Module, normalizer: dict, extra: dict, scores) -> None:
    """model.pt = the base weights as epoch 0 (rank 0)."""
    val_loss, val_metric = scores
    save_checkpoint(
        out / "model.pt",
        model,
        model.config,
        normalizer=normalizer,
        extra={**extra, "epoch": 0, "val_loss": val_loss, "val_metric": val_metric},
    )
