"""``ectskin record -o OUT.h5 --source SPEC``: record a live source to a crash-safe HDF5 file.

Ctrl-C, SIGTERM and SIGHUP end the recording cleanly: the file is closed and marked complete.
The summary reports what the frames' timestamps say (seconds spanned, frames per second) next to
the nominal rate, and warns when the source delivered fewer frames than nominal.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from pathlib import Path

from ectskin._check import EctskinError
from ectskin.commands._options import add_out, add_overwrite, resolve_out
from ectskin.layout import load_layout
from ectskin.live.recorder import record_stream
from ectskin.live.signals import stop_on_signals
from ectskin.live.sources import SOURCE_SPECS, check_not_input

HELP = "record frames from a live source (replay, sim, lsl, serial, tcp) to HDF5"
EXAMPLES = """\
  ectskin record -o session.h5 --source sim --duration 20
  ectskin record -o rig.h5 --source tcp:192.168.1.20:5000 --layout my_layout.json
  ectskin record -o fast.h5 --source replay:session.h5 --speed inf --overwrite
  (the old form 'ectskin record session.h5 --source sim' still works)

Ctrl-C, SIGTERM (kill) and SIGHUP (a closed terminal) close the file complete. The summary
gives the seconds and frames per second that the timestamps show, and warns when the source
delivered fewer frames than its nominal rate.
"""
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_out(p, help="output HDF5 recording", positional=True)
    p.add_argument("--source", required=True, metavar="SPEC", help=f"one of {SOURCE_SPECS}")
    p.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after S seconds (default: until the source ends, Ctrl-C or SIGTERM)",
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
    add_overwrite(p, help="replace OUT if it exists (never the file being replayed)")


def run(args: argparse.Namespace) -> int:
    out = resolve_out(args, "an output recording")
    check_not_input(out, args.source, "the output")
    if Path(out).exists() and not args.overwrite:
        raise EctskinError(f"{out} exists; pass --overwrite to replace it")
    layout = load_layout(args.layout) if args.layout else None
    last = [time.monotonic(), 0]

    def progress(frame) -> None:
        last[1] += 1
        now = time.monotonic()
        if now - last[0] >= 10.0:
            log.info("%d frames recorded (t = %.1f s on the source clock)", last[1], frame.t)
            last[0] = now

    with stop_on_signals("closing the recording"):
        summary = record_stream(
            args.source,
            out,
            args.duration,
            layout=layout,
            overwrite=args.overwrite,
            speed=args.speed,
            loop=args.loop,
            frame_rate_hz=args.rate,
            on_frame=progress,
        )
    c = summary["counters"]
    problems = {k: v for k, v in c.items() if k != "frames" and v}
    rate = summary["rate_hz"]
    print(
        f"recorded {summary['frames']} frames in {len(summary['trials'])} trial(s) to "
        f"{summary['path']}: timestamps span {summary['timestamps_s']:.1f} s"
        + (f" at {rate:.1f} fps" if math.isfinite(rate) else "")
        + f" (nominal {summary['nominal_hz']:g} fps; {summary['seconds']:.1f} s wall clock)"
        + (f"; source problems: {problems}" if problems else "")
        + ("; stopped by a signal" if summary["interrupted"] else "")
    )
    return 0
