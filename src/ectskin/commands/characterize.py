"""``ectskin characterize -o OUT_DIR``: the paper's §2.2 in the twin (Fig. 3, Fig. 4, JSON).

OUT_DIR may also be given as the first argument. Files of an earlier characterisation there are
replaced only with ``--overwrite`` (this command has no ``--force`` alias: ``--force`` has always
been short for ``--force-n``).
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

from ectskin._check import EctskinError, parse_floats
from ectskin.commands._options import OVERWRITE_HELP, add_figure_options, add_out, resolve_out
from ectskin.layout import default_layout, load_layout

HELP = "characterise the e-skin on the twin: inflation and touch responses (paper Fig. 3, 4)"
EXAMPLES = """\
  ectskin characterize -o char                       # fig3_inflation.png, fig4_touch.png, JSON
  ectskin characterize -o char --region 5 --overwrite   # touch region 5 in Fig. 4, same folder
  ectskin characterize -o char10 --inflation 10,10,10 --force-n 0.5
  ectskin characterize -o char-pdf --format pdf      # vector figures for a paper
"""
#: the files a characterisation writes into its folder (figures in the chosen format)
OUTPUTS = ("fig3_inflation", "fig4_touch", "characterize.json")
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_out(p, help=f"folder for {', '.join(OUTPUTS)}", positional=True)
    p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    p.add_argument("--inflation", default="20,20,20", help="inflation state, ml (default 20,20,20)")
    p.add_argument(
        "--touch-inflation",
        default="0,20,20",
        help="inflation before the touch, ml (default 0,20,20)",
    )
    p.add_argument("--force-n", type=float, default=1.0, help="touch force, N (default 1)")
    p.add_argument(
        "--region", type=int, default=None, help="region touched in Fig. 4 (default: first front)"
    )
    p.add_argument("--layout", help="layout JSON file (default: the paper's layout)")
    add_figure_options(p)


def run(args: argparse.Namespace) -> int:
    # imported here, not at the top: the twin (electrostatics, matplotlib) takes about a second
    # to import, which `ectskin --help` and the other commands should not wait for
    from ectskin.twin.characterize import characterize
    from ectskin.twin.protocol import MAX_FINGER_FORCE_N

    out = Path(resolve_out(args, "an output folder"))
    # before any work: Fig. 3 is drawn before the touch of Fig. 4, whose force wanders up to
    # 1.5 x --force-n and a finger presses at most MAX_FINGER_FORCE_N
    highest = MAX_FINGER_FORCE_N / 1.5
    if not (math.isfinite(args.force_n) and 0 < args.force_n <= highest):
        raise EctskinError(
            f"--force-n must be a touch force > 0 and at most {highest:.1f} N (the press wanders "
            f"up to 1.5 x it; a finger presses at most {MAX_FINGER_FORCE_N:g} N), got "
            f"{args.force_n}"
        )
    layout = load_layout(args.layout) if args.layout else default_layout()
    if args.region is not None:
        layout.region(args.region)  # clear error for an unknown region
    names = [n if n.endswith(".json") else f"{n}.{args.figure_format}" for n in OUTPUTS]
    existing = [out / name for name in names if (out / name).exists()]
    if existing and not args.overwrite:
        more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
        raise EctskinError(
            f"{existing[0]}{more}: written by an earlier characterisation; pass --overwrite to "
            "replace them, or choose another folder with -o/--out"
        )
    res = characterize(
        out,
        inflation=parse_floats("--inflation", args.inflation),
        touch_inflation=parse_floats("--touch-inflation", args.touch_inflation),
        force_n=args.force_n,
        figure_region=args.region,
        layout=layout,
        figure_format=args.figure_format,
        dpi=args.dpi,
    )
    log.info(
        "max |change| at %s ml: %.1f %%; written to %s",
        res["inflation_ml"],
        100 * res["inflation_change_max_abs"],
        out,
    )
    return 0
