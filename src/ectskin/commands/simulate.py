"""``ectskin simulate -o OUT.h5``: run the paper's experiment (or a variant) in the digital twin.

The twin and the HDF5 writer are imported inside :func:`run`: ``ectskin --help`` imports every
command module, and should not load them for that.

One recording is bounded (:func:`ectskin.twin.protocol.check_recording_size`: at most 100 000
trials and 4 GiB, frames x (pairs + 3 x markers + 5) x 8 bytes), checked before any work.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from ectskin._check import EctskinError, parse_floats
from ectskin.commands._options import (
    add_out,
    add_overwrite,
    add_seed,
    integer,
    resolve_out,
)

HELP = "simulate the experiment protocol in the digital twin and record it to HDF5"
EXAMPLES = """\
  ectskin simulate -o twin.h5                          # the paper's protocol, all cores
  ectskin simulate -o quick.h5 --levels 0,20 --touch-trials 2 --duration 5
  ectskin simulate -o twin.h5 --overwrite --workers 2  # replace an earlier twin.h5
  ectskin simulate -o two.h5 --second-finger 0.3       # 30 % of touch trials: two fingers
  ectskin simulate -o cover.h5 --coverage              # every region in every state, 3 s each
  ectskin simulate -o c.h5 --placement uniform --dwells 3 --lifts --hover  # contact training data
  ectskin simulate -o dense.h5 --response field --placement uniform --dwells 60 --slide 0.17
"""
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_out(p, help="HDF5 recording to write", positional=True)
    add_overwrite(p, help="replace OUT if it exists (default: refuse)")
    p.add_argument(
        "--levels", default="0,10,20", help="inflation levels per chamber, ml (default 0,10,20)"
    )
    p.add_argument(
        "--touch-trials",
        type=integer(0),
        default=6,
        help="touch trials per state (default 6; a recording holds at most 100 000 trials)",
    )
    p.add_argument("--duration", type=float, default=30.0, help="trial duration, s (default 30)")
    p.add_argument("--fps", type=float, default=30.0, help="frame rate, Hz (default 30)")
    p.add_argument(
        "--finger-radius",
        type=float,
        default=None,
        help="one fingertip radius for every finger, mm (default: each trial draws its fingers' "
        "radius, 7-10 mm, and pulp modulus)",
    )
    p.add_argument(
        "--snr-db",
        type=float,
        default=66.0,
        help="the readout's frame-to-frame gain noise as an SNR, dB (default 66; see twin/readout.py)",
    )
    p.add_argument(
        "--lifts", action="store_true", help="lift the finger now and then (per-frame labels)"
    )
    p.add_argument(
        "--placement",
        choices=("aimed", "uniform"),
        default="aimed",
        help="where the finger lands in its region: its centre with the experimenter's scatter "
        "(aimed, the paper's marked sub-regions) or anywhere in it (uniform; contact models)",
    )
    p.add_argument(
        "--dwells",
        type=integer(1),
        default=8,
        help="finger placements per touch trial: it moves to a new point of its region D-1 "
        "times (default 8, the twin's reading of the paper: docs/paper-reading.md; 1: one point "
        "held)",
    )
    p.add_argument(
        "--slide",
        type=float,
        default=None,
        metavar="S",
        help="seconds at the end of each dwell in which the finger slides, in contact, to the "
        "next point (default: the whole dwell, one continuous contact; 0: it jumps)",
    )
    p.add_argument(
        "--response",
        choices=("solve", "field"),
        default="solve",
        help="touch trials by method-of-moments solves per dwell (solve), or read from the "
        "states' response fields (field: many dwells cheaply; the fields are built once into "
        "--field-cache, see docs/field.md)",
    )
    p.add_argument(
        "--field-cache",
        metavar="DIR",
        help="response field cache for --response field (default $ECTSKIN_CACHE/fields or "
        "~/.cache/ectskin/fields)",
    )
    p.add_argument(
        "--field-grid",
        choices=("quick", "fine"),
        default="quick",
        help="the response fields' grid for --response field: quick (minutes to build) or fine "
        "(meets the field's accuracy bar, about 4x the build time); see docs/field.md",
    )
    p.add_argument("--hover", action="store_true", help="the finger hovers above the skin at times")
    p.add_argument(
        "--approach", action="store_true", help="each touch starts with the finger coming down"
    )
    p.add_argument(
        "--push-max",
        type=float,
        default=2.0,
        help="the experimenter's hand pushes the body with up to this force, N (0: no hand)",
    )
    p.add_argument(
        "--second-finger",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="fraction of touch trials in which a second finger also presses (default 0)",
    )
    p.add_argument(
        "--coverage",
        action="store_true",
        help="simulate the coverage trials of the experiment the other options describe instead "
        "of the experiment: every touch region once in every inflation state, one point held "
        "for 3 s, random streams of their own (training data for ectskin train --extra-train; "
        "ectskin.twin.coverage)",
    )
    p.add_argument("--layout", help="layout JSON file (default: the paper's layout)")
    add_seed(p, help="seed of every random draw of the experiment (default 0)")
    p.add_argument(
        "--workers", type=integer(1), default=None, help="parallel processes (default: all cores)"
    )
    p.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    from ectskin.io.hdf5 import write_recording
    from ectskin.layout import default_layout, load_layout
    from ectskin.twin import Manipulator, Protocol, ReadoutConfig, simulate_experiment
    from ectskin.twin.protocol import check_recording_size

    out = resolve_out(args, "the HDF5 recording to write")
    protocol = Protocol(
        levels_ml=tuple(parse_floats("--levels", args.levels)),
        touch_trials=args.touch_trials,
        duration_s=args.duration,
        frame_rate_hz=args.fps,
        finger_radius_mm=8.0 if args.finger_radius is None else args.finger_radius,
        finger_variability=args.finger_radius is None,
        lifts=args.lifts,
        touch_placement=args.placement,
        touch_dwells=args.dwells,
        dwell_slide_s=args.slide,
        response=args.response,
        hover=args.hover,
        approach=args.approach,
        push_max_n=args.push_max,
        second_finger=args.second_finger,
        seed=args.seed,
        readout=ReadoutConfig(gain_snr_db=args.snr_db),
    )
    layout = load_layout(args.layout) if args.layout else default_layout()
    if args.coverage:
        from ectskin.twin.coverage import coverage_protocol

        protocol = coverage_protocol(protocol, layout)
    try:
        check_recording_size(protocol, layout)
    except EctskinError as exc:
        raise EctskinError(f"{exc} (options --touch-trials, --levels, --duration, --fps)") from None
    for v in protocol.levels_ml:  # refuse impossible levels before any work
        Manipulator().check_inflation([v] * protocol.n_chambers)
    if Path(out).exists() and not args.overwrite:
        raise EctskinError(f"{out}: file exists; use --overwrite to replace it")
    fields = None
    if protocol.response == "field":
        from ectskin.pipeline.field import field_cache_dir, protocol_field_specs
        from ectskin.twin.field_build import build_fields, field_dir

        specs = protocol_field_specs(protocol, layout, grid=args.field_grid)
        cache = field_cache_dir(args.field_cache)
        t0 = time.perf_counter()
        build_fields(specs, cache, workers=args.workers, progress=not args.no_progress)
        log.info("%d response field(s) in %.1f s (%s)", len(specs), time.perf_counter() - t0, cache)
        fields = {s.inflation_ml: field_dir(s, cache) for s in specs}
    elif args.field_cache is not None or args.field_grid != "quick":
        raise EctskinError("--field-cache and --field-grid are for --response field")
    t0 = time.perf_counter()
    rec = simulate_experiment(
        protocol, layout=layout, workers=args.workers, progress=not args.no_progress,
        fields=fields,
    )
    dt = time.perf_counter() - t0
    write_recording(rec, out, overwrite=args.overwrite)
    log.info(
        "%d trials, %d frames in %.1f s (%.0f frames/s) -> %s",
        rec.n_trials,
        rec.n_frames,
        dt,
        rec.n_frames / dt,
        out,
    )
    return 0
