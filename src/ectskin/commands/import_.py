"""``ectskin import``: turn instrument files into an HDF5 recording.

Subcommands (thin wrappers over :mod:`ectskin.io.capmeter`, :mod:`ectskin.io.motive`,
:mod:`ectskin.io.align`, :mod:`ectskin.io.generic` and :mod:`ectskin.io.hdf5`)::

    ectskin import capacitance readout.csv                 # check a readout export, report masks
    ectskin import capacitance readout.csv -o rec.h5 --region 7 --inflation 0,10,20
    ectskin import mocap take.csv                          # check a Motive take, report occlusions
    ectskin import build --capacitance readout.csv --mocap take.csv -o rec.h5 --region 7
    ectskin import build --manifest trials.json -o rec.h5  # many trials into one file
    ectskin import generic data.npz -o rec.h5              # NPZ / CSV in the generic format

The file formats are described in ``docs/instrument-import.md`` and ``docs/import-format.md``.
The library is imported inside the functions that use it: ``ectskin --help`` imports every command
module, and should not load h5py and the readers for that.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from ectskin._check import EctskinError, parse_floats
from ectskin.commands._options import add_out, add_overwrite, integer, number

#: the fastest resampling grid and the widest delay search the import options take (a
#: capacitance meter or a camera beyond 10 kHz, or a clock offset beyond a minute, is a typo)
MAX_RESAMPLE_HZ = 1e4
MAX_DELAY_SEARCH_S = 60.0

HELP = "import instrument files (capacitance CSV, Motive CSV, generic NPZ/CSV) into HDF5"
EXAMPLES = """\
  ectskin import capacitance readout.csv                # check a readout export
  ectskin import capacitance readout.csv -o rec.h5 --region 7 --inflation 0,10,20
  ectskin import mocap take.csv --markers M1,M2,M3,M4,M5
  ectskin import build --capacitance readout.csv --mocap take.csv -o rec.h5 --region 7
  ectskin import build --manifest trials.json -o rec.h5 --overwrite
  ectskin import generic data.npz -o rec.h5             # docs/import-format.md
"""
#: Examples of each kind, at the end of ``ectskin import KIND --help``.
KIND_EXAMPLES = {
    "capacitance": """\
  ectskin import capacitance readout.csv                      # report channels and masks
  ectskin import capacitance readout.csv -o rec.h5 --region 7 --inflation 0,10,20
  ectskin import capacitance export.csv --delimiter semicolon --time-unit ms --no-strict
  ectskin import capacitance export.csv --time-order sort --resample-hz 30
""",
    "mocap": """\
  ectskin import mocap take.csv                               # markers, rate, occlusions
  ectskin import mocap take.csv --markers M1,M2,M3 --length-units Meters
""",
    "build": """\
  ectskin import build --capacitance readout.csv --mocap take.csv -o rec.h5 --region 7
  ectskin import build --capacitance readout.csv --mocap take.csv -o rec.h5 --delay 0.05
  ectskin import build --manifest trials.json -o rec.h5 --overwrite
""",
    "generic": """\
  ectskin import generic data.npz -o rec.h5
  ectskin import generic frames.csv -o rec.h5 --frame-rate 30 --layout my_layout.json
""",
}

log = logging.getLogger(__name__)

_DELIMITERS = {"comma": ",", "semicolon": ";", "tab": "\t"}


def _add_capacitance_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("capacitance-meter CSV")
    g.add_argument("--time-unit", choices=("s", "ms", "hh:mm:ss"), default=None,
                   help="unit of a time column that states none")
    g.add_argument("--value-unit", choices=("aF", "fF", "pF", "nF"), default=None,
                   help="capacitance unit of channel columns that state none")
    g.add_argument("--delimiter", choices=tuple(_DELIMITERS), default=None,
                   help="cell delimiter (default: detected from the data lines)")
    g.add_argument("--pair-order", choices=("auto", "file"), default="auto",
                   help="auto: put channels named like C12 / E1-E2 into the ECT pair order")
    g.add_argument("--no-strict", dest="strict", action="store_false",
                   help="skip malformed rows and mask unparseable cells (reported) instead of "
                        "stopping at the first")
    g.add_argument("--time-order", choices=("file", "sort", "strict"), default="file",
                   help="time stamps that repeat or step back: file (default): keep the rows in "
                        "the file's order and re-derive their times; sort: sort the rows by time "
                        "stamp; strict: refuse the row (docs/instrument-import.md)")
    g.add_argument("--resample-hz", type=number(0, MAX_RESAMPLE_HZ, above=True), default=None,
                   metavar="F",
                   help="resample the readouts onto a uniform grid of F frames/s, at most "
                        f"{MAX_RESAMPLE_HZ:g} (linear interpolation of each channel; default: "
                        "keep the file's frames)")


def _add_mocap_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("OptiTrack Motive CSV")
    g.add_argument("--markers", default=None,
                   help="comma-separated marker names to keep, in order (default: every "
                        "labelled marker of Type 'Marker')")
    g.add_argument("--length-units", choices=("Meters", "Centimeters", "Millimeters"),
                   default=None, help="for exports whose header lacks 'Length Units'")
    g.add_argument("--include-unlabeled", action="store_true",
                   help="also keep Motive's 'Unlabeled ...' markers")


def _add_trial_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("trial")
    g.add_argument("--layout", default=None, help="layout JSON (default: the paper's layout)")
    g.add_argument("--trial-name", default=None, help="default: the capacitance file's name")
    g.add_argument("--inflation", default="", help="chamber volumes in ml, e.g. 0,10,20")
    g.add_argument("--region", type=int, default=0,
                   help="touched region for the whole trial (0 = no touch)")
    add_overwrite(g, help="replace an existing output file (default: refuse)")


def _kind(sub, name: str, **kw) -> argparse.ArgumentParser:
    return sub.add_parser(name, epilog=f"examples:\n{KIND_EXAMPLES[name].rstrip()}",
                          formatter_class=argparse.RawDescriptionHelpFormatter, **kw)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="import_kind", metavar="KIND", required=True)

    p = _kind(sub, "capacitance", help="read a capacitance-meter CSV: report, or write -o",
              description="Read a capacitance-meter CSV export, report its channels, masked "
                          "cells and skipped rows; with -o write a one-trial recording without "
                          "markers.")
    p.add_argument("file", help="the CSV export")
    add_out(p, help="HDF5 recording to write (default: only report)")
    _add_capacitance_options(p)
    _add_trial_options(p)

    p = _kind(sub, "mocap", help="read an OptiTrack Motive CSV and report it",
              description="Read an OptiTrack Motive CSV export and report its markers, frame "
                          "rate and occlusions.")
    p.add_argument("file", help="the Motive CSV export")
    p.add_argument("--no-strict", dest="strict", action="store_false",
                   help="skip malformed rows (reported) instead of stopping at the first")
    _add_mocap_options(p)

    p = _kind(sub, "build", help="align readout + Motive files and write a recording",
              description="Read a capacitance export and a Motive take, estimate their delay, "
                          "resample the markers onto the readout frames and write an HDF5 "
                          "recording; or do that for every trial of a JSON manifest "
                          "(docs/instrument-import.md).")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--capacitance", default=None, help="capacitance-meter CSV (one trial)")
    src.add_argument("--manifest", default=None, help="JSON manifest of trials")
    p.add_argument("--mocap", default=None, help="Motive CSV of the same trial (optional)")
    add_out(p, help="HDF5 recording to write (required)")
    p.add_argument("--delay", default="auto",
                   help="'auto' (estimate) or the delay in s; > 0 means the markers lag")
    p.add_argument("--max-delay", type=number(0, MAX_DELAY_SEARCH_S, above=True), default=0.5,
                   help="search the delay within ±this many seconds (default 0.5, at most "
                        f"{MAX_DELAY_SEARCH_S:g})")
    p.add_argument("--delay-method", choices=("regression", "energy"), default="regression",
                   help="how 'auto' finds the delay (docs/instrument-import.md)")
    p.add_argument("--clock", choices=("start", "file"), default="start",
                   help="start: both files count from their first sample; file: the files' "
                        "times share one clock")
    p.add_argument("--max-gap-frames", type=integer(0), default=1,
                   help="occluded Motive frames that interpolation may bridge (default 1)")
    _add_capacitance_options(p)
    _add_mocap_options(p)
    _add_trial_options(p)

    p = _kind(sub, "generic", help="import a generic NPZ/CSV recording (docs/import-format.md)",
              description="Import a recording in the generic NPZ/CSV format and write it as "
                          "HDF5.")
    p.add_argument("file", help="the .npz or .csv file")
    add_out(p, help="HDF5 recording to write (required)")
    p.add_argument("--layout", default=None,
                   help="layout JSON the channels come from (default: a virtual layout built "
                        "from the data)")
    p.add_argument("--frame-rate", type=float, default=None,
                   help="frames/s, overriding the file's (default: the file's, else the "
                        "timestamps')")
    p.add_argument("--readouts", choices=("absolute", "difference"), default="absolute",
                   help="absolute readouts (default: Eq. 2 divides by a reference) or readouts "
                        "that are already differences (difference imaging: Eq. 2 is the "
                        "identity on them, no reference)")
    add_overwrite(p, help="replace an existing output file (default: refuse)")


# --------------------------------------------------------------------------- helpers
def _layout(args):
    from ectskin.layout import default_layout, load_layout

    return load_layout(args.layout) if args.layout else default_layout()


def _read_capacitance(args, path, n_pairs=None):
    from ectskin.io.capmeter import read_capmeter_csv

    delim = _DELIMITERS[args.delimiter] if args.delimiter else None
    return read_capmeter_csv(
        path, n_pairs=n_pairs, strict=args.strict, time_unit=args.time_unit,
        value_unit=args.value_unit, delimiter=delim, pair_order=args.pair_order,
        time_order=args.time_order, resample_hz=args.resample_hz,
    )


def _read_mocap(args, path):
    from ectskin.io.motive import read_motive_csv

    names = [n.strip() for n in args.markers.split(",") if n.strip()] if args.markers else None
    return read_motive_csv(
        path, names, strict=args.strict, length_units=args.length_units,
        include_unlabeled=args.include_unlabeled,
    )


def _check_out(args) -> None:
    """Refuse an existing output before any work, naming the flag."""
    if args.out and Path(args.out).exists() and not args.overwrite:
        raise EctskinError(f"{args.out}: file exists; use --overwrite to replace it")


def _write(rec, args) -> None:
    from ectskin.io.hdf5 import write_recording

    _check_out(args)
    path = write_recording(rec, args.out, overwrite=args.overwrite)
    print(f"wrote {path}: {rec.n_trials} trial(s), {rec.n_frames} frames, {rec.n_pairs} pairs, "
          f"{rec.frame_rate_hz:.3f} frames/s")


def _inflation(args) -> tuple[float, ...]:
    return tuple(parse_floats("--inflation", args.inflation)) if args.inflation.strip() else ()


def _print_capacitance(cap) -> None:
    print(f"{cap.path}: {cap.n_frames} frames, {cap.n_channels} channels, "
          f"{cap.frame_rate_hz:.3f} frames/s, time unit {cap.time_unit}, "
          f"units {', '.join(sorted(set(cap.units)))} (converted to pF)")
    print("channels: " + ", ".join(cap.channels))
    print(cap.mask_report.summary())


def _print_mocap(mc) -> None:
    print(f"{mc.path}: {mc.n_frames} frames, {mc.n_markers} markers, {mc.frame_rate_hz:.3f} "
          f"frames/s, length units {mc.units} (converted to mm)")
    print("markers: " + ", ".join(mc.marker_names))
    print(mc.summary())


# --------------------------------------------------------------------------- run
def _run_capacitance(args: argparse.Namespace) -> None:
    from ectskin.io.align import build_recording

    cap = _read_capacitance(args, args.file)
    _print_capacitance(cap)
    if args.out:
        rec = build_recording(cap, None, _layout(args), trial_name=args.trial_name,
                              inflation=_inflation(args), region=args.region)
        _write(rec, args)


def _run_mocap(args: argparse.Namespace) -> None:
    _print_mocap(_read_mocap(args, args.file))


def _build_from_manifest(args: argparse.Namespace):
    from ectskin.io.align import build_recording_from_manifest

    per_trial = {"--mocap": args.mocap, "--trial-name": args.trial_name,
                 "--region": args.region or None, "--inflation": args.inflation.strip(),
                 "--markers": args.markers,
                 "--time-order": args.time_order if args.time_order != "file" else None,
                 "--resample-hz": args.resample_hz}
    given = [k for k, v in per_trial.items() if v]
    if given:
        raise EctskinError(
            f"{', '.join(given)} describe one trial; with --manifest give them per trial "
            f"in the manifest (docs/instrument-import.md)"
        )
    layout = _layout(args) if args.layout else None
    rec = build_recording_from_manifest(
        args.manifest, layout, strict=None if args.strict else False
    )
    for t in rec.trials:
        d = t.meta.get("delay_s")
        extra = f", delay {d * 1e3:+.1f} ms ({t.meta['delay_source']})" if d is not None else ""
        print(f"trial {t.name}: {t.n_frames} frames{extra}")
    return rec


def _build_one_trial(args: argparse.Namespace):
    from ectskin.io.align import build_recording

    layout = _layout(args)
    cap = _read_capacitance(args, args.capacitance, n_pairs=layout.n_pairs)
    _print_capacitance(cap)
    mocap = None
    if args.mocap:
        mocap = _read_mocap(args, args.mocap)
        _print_mocap(mocap)
    delay = args.delay
    if delay != "auto":
        try:
            delay = float(delay)
        except ValueError:
            raise EctskinError(
                f"--delay must be 'auto' or a number of seconds, got {args.delay!r}"
            ) from None
    rec = build_recording(
        cap, mocap, layout, delay=delay, trial_name=args.trial_name,
        inflation=_inflation(args), region=args.region, max_delay_s=args.max_delay,
        delay_method=args.delay_method, clock=args.clock, max_gap_frames=args.max_gap_frames,
    )
    t = rec.trials[0]
    if "delay_s" in t.meta:
        score = t.meta.get("delay_score")
        how = (
            f"estimated by {t.meta['delay_method']}, score {score:.3f}, contrast "
            f"{t.meta['delay_contrast']:.3f}"
            if score is not None
            else "given"
        )
        print(f"delay {t.meta['delay_s'] * 1e3:+.1f} ms ({how}); markers lag when > 0")
    return rec


def _run_build(args: argparse.Namespace) -> None:
    rec = _build_from_manifest(args) if args.manifest else _build_one_trial(args)
    _write(rec, args)


def _run_generic(args: argparse.Namespace) -> None:
    from ectskin.io.generic import load_generic

    rec = load_generic(
        args.file, frame_rate_hz=args.frame_rate, layout=args.layout, readouts=args.readouts
    )
    _write(rec, args)


_RUNS = {
    "capacitance": _run_capacitance,
    "mocap": _run_mocap,
    "build": _run_build,
    "generic": _run_generic,
}


def _require_out(args: argparse.Namespace) -> None:
    if not args.out:
        raise EctskinError(f"import {args.import_kind} needs the recording to write: give -o/--out PATH")


def run(args: argparse.Namespace) -> int:
    kind = args.import_kind
    if kind not in _RUNS:
        raise EctskinError(f"unknown import kind {kind!r}")
    if kind in ("build", "generic"):
        _require_out(args)
    if kind != "mocap":
        _check_out(args)
    _RUNS[kind](args)
    return 0
