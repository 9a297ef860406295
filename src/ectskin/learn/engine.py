"""The epoch loops (DETR ``engine.py`` style): :func:`train_one_epoch` and :func:`evaluate`.

Both take a task's criterion (:mod:`ectskin.learn.tasks`): its ``loss`` on a training batch, its
``eval_sums`` (a fixed-length vector of float64 sums per batch) and ``finish`` (those sums → validation loss and
metric). A non-finite training loss stops training with an error naming the epoch and batch.

Determinism: :func:`epoch_indices` and :func:`seed_for` derive every seed of an epoch from
``(seed, epoch, rank)``, so a run that is stopped and resumed produces the same weights, bit for
bit on CPU, as an uninterrupted one. Under DDP each rank takes every N-th index of the same
epoch permutation (the ``DistributedSampler`` scheme, padded to a multiple of N); losses and
sums are all-reduced.
"""

from __future__ import annotations

import hashlib
import logging
import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch import nn

from ectskin._check import EctskinError
from ectskin.learn.distributed import Dist, all_reduce

logger = logging.getLogger(__name__)


@dataclass
class Tensors:
    """One split as tensors on the training device, in the order the task's model takes them.

    ``fields``: e.g. touch (x (n, P) float32, y (n,) int64); track (x (n, k, P), init (n, M, 3),
    y (n, M, 3)) — the target last.
    """

    fields: tuple[torch.Tensor, ...]

    @property
    def n(self) -> int:
        return int(self.fields[0].shape[0])

    def batch(self, idx: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return tuple(t[idx] for t in self.fields)


def seed_for(*values: int) -> int:
    """A 63-bit seed from integers (seed, epoch, rank) — deterministic, well spread."""
    h = hashlib.blake2b(",".join(str(int(v)) for v in values).encode(), digest_size=8)
    return int.from_bytes(h.digest(), "little") & ((1 << 63) - 1)


def epoch_indices(
    n: int,
    epoch: int,
    seed: int,
    *,
    rank: int = 0,
    world_size: int = 1,
    samples: int | None = None,
) -> torch.Tensor:
    """Training indices of one rank for one epoch (int64 CPU tensor).

    A permutation of ``range(n)`` seeded by ``(seed, epoch)`` — the same on every rank —
    optionally cut to its first ``samples`` entries, padded with its own head to a multiple of
    ``world_size`` and dealt round-robin: rank r gets entries r, r + N, r + 2N, ...
    """
    g = torch.Generator().manual_seed(seed_for(seed, epoch, 0x5EED))
    perm = torch.randperm(n, generator=g)
    if samples is not None and samples < n:
        perm = perm[:samples]
    pad = (-len(perm)) % world_size
    if pad:
        perm = torch.cat([perm, perm[:pad]])
    return perm[rank::world_size]


def val_indices(n: int, samples: int | None, rank: int, world_size: int) -> torch.Tensor:
    """Validation indices of one rank: a fixed, evenly strided subset when ``samples`` < n."""
    if samples is not None and samples < n:
        idx = torch.from_numpy(np.linspace(0, n - 1, samples).round().astype(np.int64))
    else:
        idx = torch.arange(n)
    return idx[rank::world_size]


def improved(
    select: str,
    lower_is_better_metric: bool,
    val_loss: float,
    val_metric: float,
    best_loss: float,
    best_metric: float,
    best_epoch: int,
) -> bool:
    """Whether this epoch's weights replace the kept ones: lower validation loss (``select`` =
    "val_loss", the paper's rule), or a better validation metric with ties broken by the lower
    validation loss ("val_metric")."""
    if select == "val_loss":
        return val_loss < best_loss
    if best_epoch == 0 and not math.isfinite(best_metric):  # nothing kept yet
        return True
    sign = 1.0 if lower_is_better_metric else -1.0
    new, old = sign * val_metric, sign * best_metric
    return new < old or (new == old and val_loss < best_loss)


def train_one_epoch(
    model: nn.Module,
    criterion: Any,
    optimizer: torch.optim.Optimizer,
    data: Tensors,
    indices: torch.Tensor,
    batch_size: int,
    *,
    epoch: int,
    d: Dist,
    bar: Any = None,
    rng: np.random.Generator | None = None,
) -> float:
    """One pass over ``indices`` in batches; returns the mean training loss over all ranks.

    ``rng`` (criteria that augment): the generator of this epoch and rank for the augmentation's
    draws; None trains on the batches as they are.

    Raises EctskinError on a non-finite loss, naming the epoch and the batch. On one CPU process
    each batch is checked at once; on CUDA or under DDP the first bad batch is recorded without
    a per-batch device sync and reported (on every rank together) at the end of the epoch.
    """
    model.train()
    dev = d.device
    check_now = not d.enabled and dev.type == "cpu"
    total = torch.zeros((), dtype=torch.float64, device=dev)
    first_bad = torch.full((), -1, dtype=torch.int64, device=dev)
    count = 0
    indices = indices.to(dev)
    n_batches = math.ceil(len(indices) / batch_size)
    for b in range(n_batches):
        idx = indices[b * batch_size : (b + 1) * batch_size]
        loss = criterion.loss(model, data.batch(idx), rng)
        if check_now:
            if not torch.isfinite(loss):
                raise EctskinError(
                    f"training stopped: non-finite loss ({loss.item()}) at epoch {epoch + 1}, "
                    f"batch {b + 1} of {n_batches}; lower the learning rate or check the data"
                )
        else:
            bad = (~torch.isfinite(loss)) & (first_bad < 0)
            first_bad = torch.where(bad, torch.full_like(first_bad, b), first_bad)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        total += loss.detach().double() * len(idx)
        count += len(idx)
        if bar is not None:
            bar.update(1)
    sums = torch.stack([total, torch.tensor(float(count), dtype=torch.float64, device=dev)])
    all_reduce(sums, d)
    if not check_now:
        flag = torch.where(first_bad < 0, torch.full_like(first_bad, 1 << 62), first_bad)
        all_reduce(flag, d, dist.ReduceOp.MIN if d.enabled else None)
        if int(flag) != 1 << 62:
            raise EctskinError(
                f"training stopped: non-finite loss at epoch {epoch + 1}, batch {int(flag) + 1} "
                f"of {n_batches}; lower the learning rate or check the data"
            )
    total_sum, n = sums.tolist()
    return float(criterion.loss_to_report(torch.tensor(total_sum / max(n, 1))))


@torch.no_grad()
def evaluate(
    model: nn.Module,
    criterion: Any,
    data: Tensors,
    indices: torch.Tensor,
    batch_size: int,
    d: Dist,
) -> tuple[float, float]:
    """(val_loss, val_metric) over ``indices`` of every rank (touch: CE, accuracy; track: mm², AD mm)."""
    model.eval()
    indices = indices.to(d.device)
    sums = None
    for b in range(0, len(indices), batch_size):
        part = criterion.eval_sums(model, data.batch(indices[b : b + batch_size])).double()
        sums = part if sums is None else sums + part
    if sums is None:
        raise EctskinError("evaluate: no validation samples")
    all_reduce(sums, d)
    return criterion.finish(sums.cpu())


class Progress:
    """Progress of a run: tqdm bars (epochs, batches) on a terminal of rank 0; otherwise one
    log line per epoch (INFO with ``progress``, DEBUG without). ``batch`` is the batch bar to
    pass to :func:`train_one_epoch` (None without bars)."""

    def __init__(
        self, name: str, epochs: int, start_epoch: int, n_batches: int, *, show: bool, d: Dist
    ) -> None:
        self.epochs, self.n_batches = epochs, n_batches
        use_bar = bool(show) and d.main and sys.stderr.isatty()
        self.log_epochs = bool(show) and d.main and not use_bar
        self.epoch_bar = self.batch = None
        if use_bar:
            from tqdm.auto import tqdm  # imported on use, for start-up speed: terminal runs only

            desc = f"train {name}"
            self.epoch_bar = tqdm(total=epochs, initial=start_epoch, desc=desc, unit="epoch")
            self.batch = tqdm(total=n_batches, leave=False, unit="batch", desc="epoch")

    def start_epoch(self, epoch: int) -> None:
        if self.batch is not None:
            self.batch.reset(total=self.n_batches)
            self.batch.set_description(f"epoch {epoch + 1}")

    def end_epoch(self, row: dict[str, Any], metric: str) -> None:
        msg = (
            f"epoch {row['epoch']}/{self.epochs}: train_loss {row['train_loss']:.4g} val_loss "
            f"{row['val_loss']:.4g} val_{metric} {row['val_metric']:.4g} lr {row['lr']:.3g} "
            f"({row['seconds']:.1f} s)"
        )
        if self.epoch_bar is not None:
            self.epoch_bar.set_postfix(
                val_loss=f"{row['val_loss']:.4g}", **{metric: f"{row['val_metric']:.4g}"}
            )
            self.epoch_bar.update(1)
        if self.log_epochs:
            logger.info(msg)
        else:
            logger.debug(msg)

    def close(self) -> None:
        for bar in (self.batch, self.epoch_bar):
            if bar is not None:
                bar.close()
