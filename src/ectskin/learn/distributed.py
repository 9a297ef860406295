"""Distributed data parallel set-up: one process group per process, detected from torchrun.

:func:`setup` reads ``WORLD_SIZE``/``RANK``/``LOCAL_RANK`` (set by ``torchrun --nproc_per_node
N``), picks the device (``cuda:LOCAL_RANK`` when CUDA is available, else the CPU), initialises
the process group once (nccl on CUDA, gloo on CPU; destroyed at exit) and returns a :class:`Dist`.
A single process gets ``Dist()``: rank 0 of 1, every collective a no-op.
"""

from __future__ import annotations

import atexit
import inspect
import os
from dataclasses import dataclass, field

import torch
import torch.distributed as dist
from torch import nn

from ectskin._check import EctskinError


@dataclass
class Dist:
    """This process's place in the group: rank, world size and its device."""

    rank: int = 0
    world_size: int = 1
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def main(self) -> bool:
        """Rank 0: the one process that writes files and shows progress."""
        return self.rank == 0


def setup(device: str | torch.device | None) -> Dist:
    """Detect torchrun (``WORLD_SIZE`` > 1), initialise the process group, pick the device."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    if device is None:
        device = f"cuda:{local_rank}" if torch.cuda.is_available() else "cpu"
    device = torch.device(device)
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", local_rank if world > 1 else 0)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise EctskinError(f"device {str(device)!r} requested, but CUDA is not available")
    if world <= 1:
        return Dist(device=device)
    if not dist.is_initialized():
        # one process group for the life of the process (a later train() call reuses it)
        backend = "nccl" if device.type == "cuda" else "gloo"
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group(backend=backend)
        atexit.register(_destroy_group)
    return Dist(dist.get_rank(), dist.get_world_size(), device)


def _destroy_group() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def all_reduce(t: torch.Tensor, d: Dist, op: dist.ReduceOp | None = None) -> torch.Tensor:
    """Reduce ``t`` in place over the ranks (sum by default); unchanged in a single process."""
    if d.enabled:
        dist.all_reduce(t, op=op or dist.ReduceOp.SUM)
    return t


def barrier(d: Dist) -> None:
    """Wait for every rank (a no-op in a single process)."""
    if d.enabled:
        dist.barrier()


def wrap(model: nn.Module, d: Dist) -> nn.Module:
    """``model`` in DistributedDataParallel under DDP (``model`` itself in a single process).

    The buffers are the normalisation: synced once at construction, constant after, so the
    per-forward buffer broadcast is switched off.
    """
    if not d.enabled:
        return model
    params = inspect.signature(nn.parallel.DistributedDataParallel).parameters
    no_sync = (
        {"forward_sync_buffers": False}
        if "forward_sync_buffers" in params
        else {"broadcast_buffers": False}
    )
    return nn.parallel.DistributedDataParallel(
        model, device_ids=[d.device.index] if d.device.type == "cuda" else None, **no_sync
    )
