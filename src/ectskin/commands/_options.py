"""The CLI's one vocabulary: options every command spells the same way.

* ``-o/--out PATH``: where a command writes. Commands that took their output as a positional
  argument keep accepting it (an alias users already type).
* ``--overwrite``: replace what an earlier run wrote there (a file, a run folder, steps made with
  other settings). ``--force`` is kept as an alias where users already type it. Without it
  nothing recorded or trained is replaced: the command stops with a message that names the flag.
* Every command's ``--help`` ends with examples (the module's ``EXAMPLES``).
* Numbers are checked by argparse against their range (:func:`integer`, :func:`number`,
  ``--seed``: :func:`add_seed`): a value outside it is a usage error naming the option and the
  range, never a traceback from deep inside.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from ectskin._check import MAX_SEED, EctskinError
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


def integer(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An argparse ``type``: a whole number from ``low`` to ``high`` (None: unbounded)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"must be {_range('an integer', low, high)}, got {text!r}"
            ) from None
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(
                f"must be {_range('an integer', low, high)}, got {text!r}"
            )
        return value

    parse.__name__ = "integer"
    return parse


def number(
    low: float | None = None, high: float | None = None, *, above: bool = False
) -> Callable[[str], float]:
    """An argparse ``type``: a finite number from ``low`` to ``high`` (None: unbounded);
    ``above``: greater than ``low``, not equal to it. NaN and inf are refused."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value)
        if ok and low is not None:
            ok = value > low if above else value >= low
        if ok and high is not None:
            ok = value <= high
        if not ok:
            what = (
                f"a finite number > {_num(low)}"
                + (f" and <= {_num(high)}" if high is not None else "")
                if above and low is not None
                else _range("a finite number", low, high)
            )
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
        return value

    parse.__name__ = "number"
    return parse


def _range(what: str, low: float | None, high: float | None) -> str:
    if low is not None and high is not None:
        return f"{what} from {_num(low)} to {_num(high)}"
    if low is not None:
        return f"{what} >= {_num(low)}"
    if high is not None:
        return f"{what} <= {_num(high)}"
    return what


def _num(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def add_seed(p: argparse.ArgumentParser, *, help: str = "random seed (default 0)") -> None:
    """``--seed N`` → ``args.seed``: an integer from 0 to 2**32 − 1 (numpy, torch and
    scikit-learn all take these); anything else is a usage error naming the range."""
    p.add_argument("--seed", type=integer(0, MAX_SEED), default=0, help=help)
