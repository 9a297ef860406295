"""The CLI's one vocabulary: options every command spells the same way.

* ``-o/--out PATH``: where a command writes. Commands that took their output as a positional
  argument keep accepting it (an alias users already type).
* ``--overwrite``: replace what an earlier run wrote there (a file, a run folder, steps made with
  other settings). ``--force`` is kept as an alias where users already type it. Without it
  nothing recorded or trained is replaced: the command stops with a message that names the flag.
* Every command's ``--help`` ends with examples (the module's ``EXAMPLES``).
"""

from __future__ import annotations

import argparse

from ectskin._check import EctskinError
from ectskin.viz import DEFAULT_DPI, FIGURE_FORMATS

OVERWRITE_HELP = "replace what an earlier run wrote at the output (default: refuse)"


def add_overwrite(p: argparse.ArgumentParser, *, help: str = OVERWRITE_HELP) -> None:
    """``--overwrite`` (alias ``--force``) → ``args.overwrite``."""
    p.add_argument("--overwrite", "--force", dest="overwrite", action="store_true", help=help)


def add_out(
    p: argparse.ArgumentParser, *, help: str, default: str | None = None, positional: bool = False
) -> None:
    """``-o/--out`` → ``args.out``; with ``positional`` the old positional form is kept too."""
    if positional:
        p.add_argument("out_positional", nargs="?", metavar="OUT", help=f"{help} (or -o/--out)")
    p.add_argument("-o", "--out", default=default, help=help)


def resolve_out(args: argparse.Namespace, what: str = "an output path") -> str:
    """The output path from ``-o/--out`` or the positional alias; one clear error if neither or
    two different ones are given."""
    pos = getattr(args, "out_positional", None)
    if pos and args.out and pos != args.out:
        raise EctskinError(f"two outputs given ({pos!r} and --out {args.out!r}); give one")
    out = args.out or pos
    if not out:
        raise EctskinError(f"needs {what}: give -o/--out PATH")
    return out


def add_figure_options(p: argparse.ArgumentParser) -> None:
    """``--format png|pdf|svg`` and ``--dpi N`` → ``args.figure_format``, ``args.dpi``."""
    p.add_argument(
        "--format",
        dest="figure_format",
        choices=FIGURE_FORMATS,
        default="png",
        help="file format of the figures (default png; pdf and svg are vector graphics)",
    )
    p.add_argument(
        "--dpi",
        type=int,
        default=DEFAULT_DPI,
        help=f"resolution of the figures in dots per inch (default {DEFAULT_DPI}; in pdf and "
        "svg only raster parts use it)",
    )
