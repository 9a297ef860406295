"""``ectskin demo [-o DIR]``: ``reproduce`` with the quick profile into ``./demo-output``.

Simulates the paper's 189-trial experiment in the twin, trains TouchMLP and C2DT (and the two
ablations) with the quick settings, evaluates them against the baselines and writes report.html.
Meant for a laptop CPU; the report lists the time each step took.
"""

from __future__ import annotations

import argparse

from ectskin.commands._options import add_out
from ectskin.commands.reproduce import add_common_arguments, run_reproduce

HELP = (
    "run the whole reproduction with quick settings into ./demo-output (the paper's experiment "
    "simulated in full on the CPU: its time on a 2-core machine is in BENCHMARKS.md)"
)
EXAMPLES = """\
  ectskin demo                         # ./demo-output/report.html
  ectskin demo -o my-demo --workers 2  # another folder, 2 simulation processes
  ectskin demo --format pdf --overwrite # the same folder again, figures as PDF
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_out(p, help="output folder (default ./demo-output)", default="demo-output")
    add_common_arguments(p, default_profile="quick")


def run(args: argparse.Namespace) -> int:
    return run_reproduce(args, args.out)
