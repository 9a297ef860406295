"""``ectskin train touch|track DATA --out RUN_DIR``: train TouchMLP or C2DT on a recording.

Thin wrapper over :func:`ectskin.learn.train.main_from_args`. Runs unchanged on several
processes (distributed data parallel)::

    torchrun --nproc_per_node 3 -m ectskin.cli train track data.h5 --out runs/track

(``WORLD_SIZE``/``RANK`` from torchrun are detected by :mod:`ectskin.learn.train`; every rank
reads the data, only rank 0 writes the run directory and logs the summary.)
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

from ectskin._check import EctskinError

HELP = "train the touch classifier (TouchMLP) or the tracking transformer (C2DT) on a recording"
log = logging.getLogger(__name__)

#: Files of a run directory; an existing folder holding anything else is not silently reused.
RUN_FILES = {"model.pt", "last.pt", "metrics.csv", "config.json", "split.json", "metrics.json"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("task", choices=("touch", "track"), help="touch: TouchMLP; track: C2DT")
    p.add_argument("data", help="recording: HDF5 (.h5) or a generic .npz / .csv import")
    p.add_argument(
        "--out", required=True, help="run directory (model.pt, metrics.csv, split.json, ...)"
    )
    p.add_argument(
        "--profile",
        choices=("paper", "quick", "robust"),
        default="paper",
        help="training settings: the paper's (default), quick for a CPU, or robust (touch only: "
        "the paper's TouchMLP with a recipe that generalises to unseen inflation/touch "
        "combinations, see docs/architecture.md)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the split and training (default 0)")
    p.add_argument("--epochs", type=int, default=None, help="override the profile's epochs")
    p.add_argument("--batch-size", type=int, default=None, help="override the profile's batch size")
    p.add_argument("--window", type=int, default=10, help="track: frames per window (default 10)")
    p.add_argument(
        "--no-prior",
        action="store_true",
        help="track ablation: absolute calibration, no initial marker coordinates",
    )
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA if available)")
    p.add_argument(
        "--force",
        action="store_true",
        help="start over, replacing an existing run in --out (default: resume it)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from ectskin.learn.train import main_from_args, profile_settings

    if args.epochs is not None and args.epochs < 1:
        raise EctskinError(f"--epochs must be >= 1, got {args.epochs}")
    if args.window < 1:
        raise EctskinError(f"--window must be >= 1 frame, got {args.window}")
    if args.task == "touch" and (args.no_prior or args.window != 10):
        raise EctskinError("--window and --no-prior apply to 'track' only")
    profile_settings(args.task, args.profile)  # e.g. 'robust' exists for touch only
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise EctskinError(f"--out {out} exists and is not a folder")
    rank0 = int(os.environ.get("RANK", "0")) == 0
    if out.is_dir() and not args.force:
        others = sorted(
            p.name
            for p in out.iterdir()
            if p.name not in RUN_FILES and not p.name.startswith(".") and p.suffix != ".png"
        )
        if others:
            raise EctskinError(
                f"--out {out} is a non-empty folder that is not a run directory (holds "
                f"{', '.join(others[:5])}); choose another folder or pass --force"
            )
        if (out / "model.pt").exists() and not (out / "last.pt").exists():
            raise EctskinError(
                f"--out {out} holds a model.pt without last.pt (cannot resume); pass --force "
                "to train again"
            )
        if (out / "last.pt").exists() and rank0:
            log.info(
                "%s holds a run: resuming it (same settings required; --force starts over)", out
            )
    summary = main_from_args(
        args.task,
        args.data,
        out,
        profile=args.profile,
        seed=args.seed,
        epochs=args.epochs,
        batch_size=args.batch_size,
        window=args.window,
        prior=not args.no_prior,
        resume=not args.force,
        device=args.device,
        progress=not args.no_progress,
    )
    if rank0:
        if summary.get("epochs_run", 1) == 0:
            log.info(
                "the run in %s had already finished its %d epochs; nothing to train",
                out,
                summary["epochs"],
            )
        log.info(
            "%s: best epoch %d of %d, val_loss %.4g, val_%s %.4g, %.1f s on %s x %d -> %s",
            args.task,
            summary["best_epoch"],
            summary["epochs"],
            summary["best_val_loss"],
            summary["metric"],
            summary["best_val_metric"],
            summary["seconds_total"],
            summary["device"],
            summary["world_size"],
            out / "model.pt",
        )
    return 0
