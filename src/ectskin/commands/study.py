"""``ectskin study STUDY ...``: the studies of :mod:`ectskin.study`, one subcommand each.

Each study module exposes ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; this
command lists them in :data:`SUBCOMMANDS` and imports each when the parser is built. A study
module that is not installed is left out of the listing.
"""

from __future__ import annotations

import argparse
import importlib
from types import ModuleType

HELP = "studies of the twin's reading of the paper (ablation, unseen inflation, few-shot)"
EXAMPLES = """\
  ectskin study reading --out study-reading --seeds 0 1 2   # the reading ablation
  ectskin study reading --out study-reading --table-only    # its table and figure again
  ectskin study few-shot runs/contact new.h5 -o fewshot      # contact few-shot curves
  ectskin study few-shot-touch runs/touch new.h5 -o fst      # touch few-shot curves
"""

#: (subcommand, module) in the order ``ectskin study --help`` lists them
SUBCOMMANDS = (
    ("reading", "ectskin.study.reading"),
    ("unseen-inflation", "ectskin.study.inflation"),
    ("few-shot", "ectskin.study.fewshot"),
    ("few-shot-touch", "ectskin.study.fewshot_touch"),
)


def study_modules() -> list[tuple[str, ModuleType]]:
    """(subcommand, module) of every study module that is there; a module that is missing
    itself is skipped (an import error inside one is raised)."""
    found = []
    for name, module_name in SUBCOMMANDS:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue
            raise
        found.append((name, module))
    return found


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="study", metavar="STUDY")
    for name, module in study_modules():
        sp = sub.add_parser(
            name,
            help=module.HELP,
            description=module.HELP,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(sp)
        sp.set_defaults(_study_run=module.run)
    p.set_defaults(_study_parser=p)


def run(args: argparse.Namespace) -> int:
    study_run = getattr(args, "_study_run", None)
    if study_run is None:
        args._study_parser.print_help()
        return 2
    return int(study_run(args) or 0)
