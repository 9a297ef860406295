"""``ectskin variability OUT``: how models trained on the nominal skin fare on fabricated skins,
and what recovers them (:mod:`ectskin.design.variability`).

The library is imported inside :func:`run`: ``ectskin --help`` imports every command module, and
should not load torch and the twin for that.
"""

from __future__ import annotations

import argparse
import logging

from ectskin._check import EctskinError, parse_floats
from ectskin.commands._options import add_seed, integer

HELP = "degradation of the touch and contact models on fabricated skins, and their recoveries"
EXAMPLES = """\
  ectskin variability var/                    # 4 sampled skins, the fault cases, ~10-15 min
  ectskin variability var/ --skins 8 --seed 1 # more skins on the curve
  ectskin variability var/                    # again: resumes, redoing only what is missing
"""
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", metavar="OUT", help="folder for the data, runs and results (resumed)")
    p.add_argument(
        "--skins", type=integer(1), default=4, help="fabricated skins on the curve (default 4)"
    )
    p.add_argument(
        "--dr-skins",
        type=integer(0),
        default=2,
        help="extra skins for domain-randomisation training (default 2)",
    )
    p.add_argument(
        "--scales",
        default="0.5,2",
        metavar="LOW,HIGH",
        help="perturbation scales of the curve's skins, x the assumed spreads (default 0.5,2)",
    )
    p.add_argument(
        "--finetune",
        default="0,100,1000",
        metavar="N,...",
        help="labelled frames of each skin to fine-tune on (default 0,100,1000)",
    )
    p.add_argument("--no-faults", action="store_true", help="skip the dead and shorted cases")
    p.add_argument("--layout", help="layout JSON file (default: the paper's layout)")
    add_seed(p, help="seed of the skins, simulations and training (default 0)")
    p.add_argument(
        "--workers", type=integer(1), default=None, help="simulation processes (default: all cores)"
    )
    p.add_argument("--threads", default=None, help="torch threads (an integer or 'auto')")
    p.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    from ectskin.design.variability import VariabilityConfig, run_variability
    from ectskin.layout import load_layout

    scales = parse_floats("--scales", args.scales)
    if len(scales) != 2:
        raise EctskinError(f"--scales must be LOW,HIGH, got {args.scales!r}")
    frames = parse_floats("--finetune", args.finetune)
    if any(f != int(f) for f in frames):
        raise EctskinError(f"--finetune must be whole frame counts, got {args.finetune!r}")
    threads = args.threads
    if threads is not None and threads != "auto":
        try:
            threads = int(threads)
        except ValueError:
            threads = 0
        if threads < 1:
            raise EctskinError(
                f"--threads must be an integer >= 1 or 'auto', got {args.threads!r}"
            )
    config = VariabilityConfig(
        skins=args.skins,
        seed=args.seed,
        scale_range=(scales[0], scales[1]),
        dr_skins=args.dr_skins,
        finetune_frames=tuple(int(f) for f in frames),
        faults=not args.no_faults,
        layout=load_layout(args.layout) if args.layout else None,
        workers=args.workers,
        threads=threads,
        progress=not args.no_progress,
    )
    doc = run_variability(args.out, config)
    for task, s in doc["summary"].items():
        log.info("%s, mean over sampled skins: %s", task, s["sampled_mean"])
    return 0
