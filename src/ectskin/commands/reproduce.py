"""``ectskin reproduce -o OUT_DIR``: the paper end to end (simulate, characterise, train,
evaluate, report). Thin wrapper over :func:`ectskin.pipeline.reproduce`.

Finished steps in OUT_DIR are reused (and reported as such), interrupted trainings resume;
results made with other settings are never overwritten without ``--overwrite`` (alias
``--force``), which redoes those steps. OUT_DIR may also be given as the first argument.
"""

from __future__ import annotations

import argparse
import shlex
import sys

from ectskin._check import EctskinError
from ectskin.commands._options import (
    add_figure_options,
    add_out,
    add_overwrite,
    add_seed,
    integer,
    resolve_out,
)
from ectskin.commands.train import MODELS as TOUCH_MODEL_CHOICES
from ectskin.report import results_table

HELP = (
    "reproduce the paper: simulate, characterise, train both models + ablations, evaluate, report"
)
EXAMPLES = """\
  ectskin reproduce -o paper-run                  # the paper's settings (hours; GPU advised)
  ectskin reproduce -o quick-run --profile quick --workers 2
  ectskin reproduce -o paper-run                  # again: finished steps are reused
  ectskin reproduce -o paper-run --epochs 5 --overwrite   # redo the steps whose settings changed
  ectskin reproduce -o paper-run --format svg --overwrite # figures as SVG
"""
OUT_HELP = "output folder (data.h5, runs/, figures/, metrics.json, report.md/.html)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_out(p, help=OUT_HELP, positional=True)
    add_common_arguments(p, default_profile="paper")


def add_common_arguments(p: argparse.ArgumentParser, *, default_profile: str) -> None:
    """Options shared by ``reproduce`` and ``demo``."""
    p.add_argument(
        "--profile",
        choices=("quick", "paper"),
        default=default_profile,
        help=f"training settings (default {default_profile}; 'paper' needs a GPU to be quick)",
    )
    p.add_argument(
        "--workers", type=integer(1), default=None, help="simulation processes (default: all cores)"
    )
    add_seed(p, help="seed of simulation, splits and training (default 0)")
    p.add_argument(
        "--epochs", type=integer(1), default=None, help="override the epochs of every training"
    )
    p.add_argument("--no-ablations", action="store_true", help="skip the two tracking ablations")
    p.add_argument(
        "--touch-model",
        default="mlp",
        choices=TOUCH_MODEL_CHOICES,
        help="model of the touch run: mlp (the paper's TouchMLP, default) or a choice of "
        "docs/model-choice.md (auto: every candidate, selected on the validation split)",
    )
    p.add_argument(
        "--no-contact",
        action="store_true",
        help="skip the contact experiment, the contact model and the ECT images (docs/contact.md)",
    )
    p.add_argument(
        "--contact-response",
        choices=("field", "solve"),
        default="field",
        help="how the contact experiment is read: from the states' response fields (default: "
        "dense, a new point every 0.5 s; the fields are built once and cached) or solved per "
        "point (4 trials per state of 2 points each)",
    )
    p.add_argument(
        "--field-grid",
        choices=("quick", "fine"),
        default="quick",
        help="the response fields' grid: quick (default, minutes to build) or fine (meets the "
        "field's accuracy bar, about 4x the build time); docs/field.md",
    )
    p.add_argument(
        "--field-states",
        choices=("contact", "all"),
        default="contact",
        help="the states whose response fields the bound and the inversion read: the contact "
        "experiment's (default) or every state of the contact run's data (the paper's 10-ml "
        "states too: the inversion then answers every test frame; 19 more fields to build)",
    )
    p.add_argument(
        "--bound-push-columns",
        choices=("untouched", "finger"),
        default="untouched",
        help="the bound's columns of the hand's push: from the untouched state (default, "
        "seconds) or from a table of direct solves with the finger pressing (about 2 min a "
        "state on one core; beyond the wire ends the default's bound is several times too "
        "low); docs/bound.md",
    )
    p.add_argument(
        "--inversion-finger",
        choices=("auto", "on", "off"),
        default="auto",
        help="the inversion fits each pressing finger's pulp modulus and radius (tables from "
        "coarse response fields, built into the field cache) and pools them over each trial, one "
        "person's: where the validation point error is lower (auto, default), always, or never; "
        "docs/inversion.md",
    )
    p.add_argument(
        "--field-cache",
        metavar="DIR",
        default=None,
        help="where response fields are cached (default $ECTSKIN_CACHE/fields or "
        "~/.cache/ectskin/fields)",
    )
    p.add_argument(
        "--no-robust",
        action="store_true",
        help="skip the TouchMLP trained with the robust recipe (runs/touch_robust)",
    )
    p.add_argument(
        "--no-coverage",
        action="store_true",
        help="train the robust recipe without the twin's coverage trials (every region in every "
        "inflation state, coverage.h5; ectskin.twin.coverage)",
    )
    p.add_argument("--no-baselines", action="store_true", help="skip the baselines")
    p.add_argument("--device", default=None, help="training device (default: CUDA if available)")
    p.add_argument(
        "--threads",
        default="auto",
        help="torch CPU threads of training and evaluation: a number, 'auto' (default: 1 on "
        "machines with <= 4 cores, where more gain nothing for these small models) or 'torch' "
        "(one per core)",
    )
    add_overwrite(
        p,
        help="redo the steps whose earlier results in the folder were made with other settings, "
        "replacing them (default: refuse; finished steps with the same settings are reused)",
    )
    add_figure_options(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def threads_option(text: str) -> int | str | None:
    """``--threads`` as the pipeline takes it: a number, "auto", or None for "torch"."""
    if text in ("auto", "torch"):
        return {"auto": "auto", "torch": None}[text]
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise EctskinError(f"--threads must be a number >= 1, 'auto' or 'torch', got {text!r}")
    return n


def run_reproduce(args: argparse.Namespace, out_dir: str) -> int:
    # imported here, not at the top: the pipeline imports torch, which `ectskin --help` and the
    # other commands should not wait for
    from ectskin.pipeline import ReproduceConfig, reproduce

    config = ReproduceConfig(
        out_dir,
        profile=args.profile,
        seed=args.seed,
        workers=args.workers,
        force=args.overwrite,
        epochs=args.epochs,
        ablations=not args.no_ablations,
        robust=not args.no_robust,
        coverage=not args.no_coverage,
        touch_model=args.touch_model,
        contact=not args.no_contact,
        baselines=not args.no_baselines,
        device=args.device,
        threads=threads_option(args.threads),
        progress=not args.no_progress,
        command=" ".join(["ectskin", *map(shlex.quote, sys.argv[1:])]) if sys.argv[1:] else None,
        figure_format=args.figure_format,
        dpi=args.dpi,
        contact_response=args.contact_response,
        field_grid=args.field_grid,
        field_states=args.field_states,
        bound_push_columns=args.bound_push_columns,
        inversion_finger=args.inversion_finger,
        field_cache=args.field_cache,
    )
    m = reproduce(config)
    for metric, paper, this, base in results_table(m):
        print(f"{metric}: {this} (paper {paper}; baselines: {base})")
    if m.get("reused"):
        print(f"reused finished steps: {', '.join(m['reused'])}")
    print(f"total {m['timings_s']['total']:.0f} s; report: {out_dir}/report.html")
    return 0


def run(args: argparse.Namespace) -> int:
    return run_reproduce(args, resolve_out(args, "an output folder"))
