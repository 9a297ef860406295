"""``ectskin train touch|track DATA -o RUN_DIR``: train TouchMLP or C2DT on a recording.

Thin wrapper over :func:`ectskin.learn.train.train_from_recording`. An existing run in RUN_DIR
is resumed (same settings and data); ``--overwrite`` (alias ``--force``) starts it over. The
default profile is the paper's, meant for a GPU: on a CPU the training says so at the start and
estimates its remaining time after the first epoch; ``--profile quick`` is the CPU setting. Runs
``--model`` (touch) chooses the classifier: the paper's TouchMLP (``mlp``, default), ``auto`` (the
MLP and the classical candidates, the best validation accuracy selected, see
:mod:`ectskin.learn.candidates`) or one classical model alone; for contact ContactNet
(default), ``auto`` or one of knn, ridge, gbt, gp (:mod:`ectskin.learn.contact_choice`).
``--init-from RUN`` fine-tunes a trained run (:mod:`ectskin.learn.finetune`). Runs
unchanged on several processes (distributed data parallel)::

    torchrun --nproc_per_node 3 -m ectskin.cli train track data.h5 --out runs/track

(``WORLD_SIZE``/``RANK`` from torchrun are detected by :mod:`ectskin.learn.distributed`; every
rank reads the data, only rank 0 writes the run directory and logs the summary.)
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

from ectskin._check import EctskinError
from ectskin.commands._options import add_out, add_overwrite, add_seed, integer, resolve_out
from ectskin.learn.profiles import PROFILE_REFERENCE, PROFILE_TASKS, PROFILES, REFERENCES

#: ``--model`` values: ectskin.learn.candidates.TOUCH_MODELS and the contact-only ones of
#: ectskin.learn.contact_choice.CONTACT_MODELS, listed here because importing those modules
#: loads torch, which every ``ectskin`` call would pay for (a test keeps them equal)
MODELS = ("mlp", "auto", "gbt", "random_forest", "logreg", "knn", "contactnet", "ridge", "gp")

HELP = "train the touch classifier (TouchMLP) or the tracking transformer (C2DT) on a recording"
EXAMPLES = """\
  ectskin train touch data.h5 -o runs/touch --profile quick   # minutes on a laptop CPU
  ectskin train track data.h5 -o runs/track                   # the paper's settings (GPU)
  ectskin train track data.h5 -o runs/track --epochs 200      # resume, extended to 200 epochs
  ectskin train touch data.h5 -o runs/touch --overwrite       # start the run over
  ectskin train touch data.h5 -o runs/auto --model auto --profile quick  # best on validation
  ectskin train touch data.h5 -o runs/gbt --model gbt         # gradient-boosted trees alone
  ectskin train touch data.h5 -o runs/st --reference state    # Eq. 2 at each state's own rest
  ectskin train contact press.h5 -o runs/c --model auto --window 1 --profile quick
  ectskin train contact new.h5 -o runs/ft --init-from runs/c --window 1 --epochs 5
  torchrun --nproc_per_node 3 -m ectskin.cli train track data.h5 -o runs/track
"""
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "task",
        choices=PROFILE_TASKS,
        help="touch: TouchMLP; track: C2DT; contact: ContactNet (docs/contact.md)",
    )
    p.add_argument("data", help="recording: HDF5 (.h5) or a generic .npz / .csv import")
    add_out(p, help="run directory (model.pt, metrics.csv, split.json, ...); required")
    p.add_argument(
        "--profile",
        choices=tuple(PROFILES),
        default="paper",
        help="training settings: the paper's (default; meant for a GPU, slow on a CPU), quick "
        "for a CPU, or robust (touch only: the paper's TouchMLP with a recipe that generalises "
        "to unseen inflation/touch combinations, see docs/architecture.md)",
    )
    p.add_argument(
        "--model",
        choices=MODELS,
        default="mlp",
        help="touch classifier: mlp, the paper's TouchMLP (default); auto: the MLP and the "
        "classical candidates (gbt, random_forest, logreg, knn), the best validation accuracy "
        "selected (candidates.json); or one classical model alone (model.skops). contact: "
        "contactnet (default; mlp means it too); auto: ContactNet and knn, ridge, gbt (and gp "
        "on at most 2000 training frames), the lowest validation point error selected; or one "
        "of knn, ridge, gbt, gp alone",
    )
    defaults = ", ".join(f"{k} {v}" for k, v in PROFILE_REFERENCE.items())
    p.add_argument(
        "--reference",
        choices=REFERENCES,
        default=None,
        help="touch: the reference c_0 of Eq. 2: auto/rest the uninflated, untouched state (the "
        "paper's); state the no-contact trial(s) of each trial's own inflation state; inflation "
        "a model of the rest readout over the chamber volumes fitted on the recording's states "
        "(works at unseen inflation levels; stored in the run); state-offset, inflation-offset "
        "the same rest readout subtracted but divided by the 0-ml rest readout; meta per-trial "
        f"references of an import. Default: the profile's ({defaults}); see "
        "ectskin.io.inflation_reference",
    )
    add_seed(p, help="seed of the split and training (default 0)")
    p.add_argument(
        "--epochs",
        type=integer(0),
        default=None,
        help="override the profile's epochs (0 only with --init-from: the base run's weights)",
    )
    p.add_argument(
        "--init-from",
        metavar="RUN",
        default=None,
        help="fine-tune a trained run (its config, normaliser and weights) on this data, e.g. "
        "a few labelled frames of another skin with the same pair count "
        "(ectskin.learn.finetune)",
    )
    p.add_argument(
        "--extra-train",
        metavar="FILE",
        nargs="+",
        default=(),
        help="recordings whose trials join the training split only (validation and test stay "
        "DATA's), each calibrated against its own rest readouts: e.g. the twin's coverage trials "
        "(ectskin simulate OUT --coverage; ectskin.learn.extra_train)",
    )
    p.add_argument(
        "--finger-mix",
        type=float,
        default=None,
        metavar="P",
        help="contact: each training window takes another training finger's signal with "
        "probability P (a hovering finger, or a second touch labelled as one; default 0; "
        "ectskin.learn.tasks.contact_mix)",
    )
    p.add_argument(
        "--batch-size", type=integer(1), default=None, help="override the profile's batch size"
    )
    p.add_argument(
        "--window", type=integer(1), default=10, help="track: frames per window (default 10)"
    )
    p.add_argument(
        "--no-prior",
        action="store_true",
        help="track ablation: absolute calibration, no initial marker coordinates",
    )
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA if available)")
    p.add_argument(
        "--threads",
        type=integer(1),
        default=None,
        help="torch CPU threads (default 1: results depend on the thread count)",
    )
    add_overwrite(
        p,
        help="start the run over, replacing the run in -o/--out (default: resume it; a run made "
        "with other settings or data is refused)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    # imported on use, for start-up speed: it loads torch, and every ``ectskin`` call imports
    # all subcommand modules to build its parser
    from ectskin.learn.train import TrainConfig, train_from_recording

    if args.epochs == 0 and args.init_from is None:
        raise EctskinError(
            "argument --epochs: must be an integer >= 1, got '0' (0 epochs only with "
            "--init-from: the base run's weights as they are)"
        )
    out = Path(resolve_out(args, "a run directory"))
    config = TrainConfig(
        profile=args.profile,
        seed=args.seed,
        epochs=args.epochs,
        batch_size=args.batch_size,
        window=args.window,
        prior=not args.no_prior,
        resume=not args.overwrite,
        device=args.device,
        progress=not args.no_progress,
        threads=args.threads,
        model=args.model,
        init_from=args.init_from,
        reference=args.reference,
        extra_train=tuple(args.extra_train),
        settings=None if args.finger_mix is None else {"finger_mix": args.finger_mix},
    )
    summary = train_from_recording(args.task, args.data, out, config)
    if int(os.environ.get("RANK", "0")) != 0:
        return 0
    if "best_epoch" in summary:
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
    if "selected_model" in summary:
        contact = args.task == "contact"
        scores = ", ".join(
            f"{k} {v:.3f} mm" if contact else f"{k} {100 * v:.2f} %"
            for k, v in summary["candidates"].items()
            if v is not None
        )
        log.info(
            "%s: selected %s (%s); validation %s: %s -> %s",
            args.task,
            summary["selected_model"],
            summary["selected_because"],
            "point error" if contact else "accuracy",
            scores,
            out / "candidates.json",
        )
    return 0
