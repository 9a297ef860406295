"""``ectskin demo [--out DIR]``: ``reproduce`` with the quick profile into ``./demo-output``.

About 10 minutes on a 2-core laptop: simulate the paper's 189-trial experiment in the twin, train
TouchMLP and C2DT (and the two ablations) with the quick settings, evaluate against the baselines
and write report.html.
"""

from __future__ import annotations

import argparse

from ectskin.commands.reproduce import add_common_arguments, run_reproduce

HELP = (
    "run the whole reproduction with quick settings into ./demo-output (about 10 min on a laptop)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="demo-output", help="output folder (default ./demo-output)")
    add_common_arguments(p, default_profile="quick")


def run(args: argparse.Namespace) -> int:
    return run_reproduce(args, args.out)
