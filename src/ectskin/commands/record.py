"""``ectskin record OUT.h5 --source SPEC``: record a live source to a crash-safe HDF5 file."""

from __future__ import annotations

import argparse
import logging
import time

from ectskin.layout import load_layout
from ectskin.live.recorder import record_main
from ectskin.live.sources import SOURCE_SPECS

HELP = "record frames from a live source (replay, sim, lsl, serial, tcp) to HDF5"
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", help="output HDF5 recording (refuses to overwrite without --force)")
    p.add_argument("--source", required=True, metavar="SPEC", help=f"one of {SOURCE_SPECS}")
    p.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after S seconds (default: until the source ends or Ctrl-C)",
    )
    p.add_argument("--layout", help="layout JSON for lsl/serial/tcp sources (default: the paper's)")
    p.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="replay speed factor; 'inf' = as fast as possible (default 1)",
    )
    p.add_argument("--loop", action="store_true", help="replay: start again at the end")
    p.add_argument(
        "--rate",
        type=float,
        metavar="HZ",
        help="frame rate stored in the file when the source does not know it "
        "(default: the source's, else 30)",
    )
    p.add_argument(
        "--force",
        "--overwrite",
        action="store_true",
        dest="force",
        help="overwrite OUT if it exists",
    )


def run(args: argparse.Namespace) -> int:
    layout = load_layout(args.layout) if args.layout else None
    last = [time.monotonic(), 0]

    def progress(frame) -> None:
        last[1] += 1
        now = time.monotonic()
        if now - last[0] >= 10.0:
            log.info("%d frames recorded (t = %.1f s on the source clock)", last[1], frame.t)
            last[0] = now

    summary = record_main(
        args.source,
        args.out,
        args.duration,
        layout=layout,
        overwrite=args.force,
        speed=args.speed,
        loop=args.loop,
        frame_rate_hz=args.rate,
        on_frame=progress,
    )
    c = summary["counters"]
    problems = {k: v for k, v in c.items() if k != "frames" and v}
    print(
        f"recorded {summary['frames']} frames in {len(summary['trials'])} trial(s) to "
        f"{summary['path']} ({summary['seconds']:.1f} s)"
        + (f"; source problems: {problems}" if problems else "")
    )
    return 0
