"""The ``ectskin`` console script: dispatches to one module per subcommand (``ectskin.commands``)."""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin._malloc import keep_freed_memory
from ectskin.commands import COMMANDS


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ectskin",
        description="Touch and shape perception for soft robots from a sparse capacitive e-skin.",
    )
    parser.add_argument("--version", action="version", version=f"ectskin {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in COMMANDS:
        module = importlib.import_module(f"ectskin.commands.{module_name}")
        examples = getattr(module, "EXAMPLES", None)
        p = sub.add_parser(
            name,
            help=module.HELP,
            description=module.HELP,
            epilog=f"examples:\n{examples.rstrip()}" if examples else None,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _name=name)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
    )
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    keep_freed_memory()  # the solves' large arrays reused, not zero-filled anew (ectskin._malloc)
    try:
        return int(args._run(args) or 0)
    except EctskinError as exc:
        print(f"ectskin {args._name}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the machine refused (a full disk, permissions): one line, no trace
        where = f"{exc.filename}: " if exc.filename else ""
        reason = os.strerror(exc.errno) if exc.errno else (exc.strerror or str(exc))
        print(f"ectskin {args._name}: error: {where}{reason}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"ectskin {args._name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # python -m ectskin.cli (also under torchrun)
    sys.exit(main())
