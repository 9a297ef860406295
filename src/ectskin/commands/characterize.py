"""``ectskin characterize OUT_DIR``: the paper's §2.2 in the twin (Fig. 3, Fig. 4, JSON)."""

from __future__ import annotations

import argparse
import logging

from ectskin._check import parse_floats
from ectskin.layout import default_layout, load_layout

HELP = "characterise the e-skin on the twin: inflation and touch responses (paper Fig. 3, 4)"
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "out_dir", help="folder for fig3_inflation.png, fig4_touch.png, characterize.json"
    )
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


def run(args: argparse.Namespace) -> int:
    # imported here, not at the top: the twin (electrostatics, matplotlib) takes about a second
    # to import, which `ectskin --help` and the other commands should not wait for
    from ectskin.twin.characterize import characterize

    layout = load_layout(args.layout) if args.layout else default_layout()
    if args.region is not None:
        layout.region(args.region)  # clear error for an unknown region
    res = characterize(
        args.out_dir,
        inflation=parse_floats("--inflation", args.inflation),
        touch_inflation=parse_floats("--touch-inflation", args.touch_inflation),
        force_n=args.force_n,
        figure_region=args.region,
        layout=layout,
    )
    log.info(
        "max |change| at %s ml: %.1f %%; written to %s",
        res["inflation_ml"],
        100 * res["inflation_change_max_abs"],
        args.out_dir,
    )
    return 0
