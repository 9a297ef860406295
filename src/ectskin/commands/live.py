"""``ectskin live --source SPEC``: touch recognition and tracking on a live source.

Prints a status line every second (or serves the web dashboard with ``--dashboard``), optionally
records every frame (``--record``) and writes every output as JSON lines (``--jsonl``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

from ectskin._check import EctskinError
from ectskin.dashboard import serve
from ectskin.layout import load_layout
from ectskin.live.engine import POLICIES, LiveEngine
from ectskin.live.recorder import Recorder
from ectskin.live.sources import SOURCE_SPECS, open_source

HELP = "run the trained models on a live source (optionally with the web dashboard)"
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--source", required=True, metavar="SPEC", help=f"one of {SOURCE_SPECS}")
    p.add_argument("--touch-model", metavar="RUN", help="run dir (or model.pt) of a TouchMLP")
    p.add_argument("--track-model", metavar="RUN", help="run dir (or model.pt) of a C2DT")
    p.add_argument("--dashboard", action="store_true", help="serve the web dashboard")
    p.add_argument("--port", type=int, default=8765, help="dashboard port (default 8765)")
    p.add_argument("--record", metavar="OUT.h5", help="record every frame to this HDF5 file")
    p.add_argument("--force", action="store_true", help="overwrite the --record file")
    p.add_argument(
        "--jsonl", metavar="PATH", help="write every output as a JSON line ('-' = stdout)"
    )
    p.add_argument("--layout", help="layout JSON for lsl/serial/tcp sources (default: the paper's)")
    p.add_argument("--speed", type=float, default=1.0, help="replay speed factor (default 1)")
    p.add_argument("--loop", action="store_true", help="replay: start again at the end")
    p.add_argument(
        "--reference-frames",
        type=int,
        default=30,
        help="frames averaged into the calibration reference (default 30 = 1 s)",
    )
    p.add_argument(
        "--reference-markers",
        metavar="FILE",
        help="initial marker coordinates (n_markers x 3 mm, .npy or text) for sources "
        "without markers",
    )
    p.add_argument(
        "--policy",
        choices=POLICIES,
        default="skip-to-newest",
        help="when inference falls behind (default skip-to-newest)",
    )
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads for inference (default 1: the models are tiny, and more "
        "threads compete with the reader and recorder threads, causing stalls)",
    )
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--max-frames", type=int, metavar="N", help="stop after N frames")


def _load_markers(path: str) -> np.ndarray:
    try:
        return np.load(path) if path.endswith(".npy") else np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise EctskinError(f"--reference-markers {path}: cannot read ({exc})") from None


def run(args: argparse.Namespace) -> int:
    if args.threads < 1:
        raise EctskinError(f"--threads must be >= 1, got {args.threads}")
    with contextlib.ExitStack() as stack:
        touch = track = None
        if args.touch_model or args.track_model:
            # torch is imported only when a model is given: a run without models, and every
            # other `ectskin` command, starts without it
            from ectskin.learn.predict import TouchPredictor, TrackPredictor
            from ectskin.learn.threads import torch_threads

            stack.enter_context(torch_threads(args.threads))
            touch = TouchPredictor.from_run(args.touch_model) if args.touch_model else None
            track = TrackPredictor.from_run(args.track_model) if args.track_model else None
        return _run(args, touch, track)


def _run(args: argparse.Namespace, touch, track) -> int:
    """The command with its models loaded (``touch``/``track`` may be None)."""
    if args.record and Path(args.record).exists() and not args.force:
        raise EctskinError(f"{args.record} exists; pass --force to overwrite it")
    ref_markers = _load_markers(args.reference_markers) if args.reference_markers else None
    layout = load_layout(args.layout) if args.layout else None
    source = open_source(args.source, layout=layout, speed=args.speed, loop=args.loop)
    recorder = None
    jsonl = None
    try:
        if args.record:
            recorder = Recorder(
                args.record,
                source.layout,
                source.frame_rate_hz or 30.0,
                overwrite=args.force,
                meta={
                    "source": args.source,
                    "touch_model": args.touch_model,
                    "track_model": args.track_model,
                },
                trial_info=getattr(source, "trial_info", None),
            )
        engine = LiveEngine(
            source,
            source.layout,
            touch=touch,
            track=track,
            policy=args.policy,
            reference_frames=args.reference_frames,
            recorder=recorder,
            reference_markers=ref_markers,
        )
        run_kwargs = {"max_frames": args.max_frames, "duration_s": args.duration}
        if args.jsonl:
            jsonl = sys.stdout if args.jsonl == "-" else open(args.jsonl, "w", encoding="utf-8")
        if args.dashboard:
            stats = _serve(engine, args, run_kwargs, jsonl)
        else:
            stats = _console(engine, run_kwargs, jsonl, status=args.jsonl != "-")
    finally:
        source.close()
        if recorder is not None:
            recorder.close()
        if jsonl is not None and jsonl is not sys.stdout:
            jsonl.close()
    keys = (
        "frames",
        "processed",
        "dropped",
        "malformed",
        "wrong_channels",
        "disconnects",
        "reconnects",
        "latency_ms_p50",
        "latency_ms_p99",
    )
    print("final: " + ", ".join(f"{k} {stats.get(k)}" for k in keys), file=sys.stderr)
    if recorder is not None:
        print(f"recorded {recorder.frames_written} frames to {args.record}", file=sys.stderr)
    return 0


def _writer(jsonl):
    if jsonl is None:
        return None
    # to_json_dict() already applies the JSON policy (non-finite -> None): dump it as is
    return lambda out: jsonl.write(json.dumps(out.to_json_dict(), allow_nan=False) + "\n")


def _console(engine, run_kwargs, jsonl, status: bool) -> dict:
    """Run in this thread; one status line per second on stderr."""
    write = _writer(jsonl)
    last = [0.0]

    def on_output(out) -> None:
        if write is not None:
            write(out)
        now = time.monotonic()
        if status and now - last[0] >= 1.0:
            last[0] = now
            s = out.stats
            touch = "-" if out.touch_cls is None else f"class {out.touch_cls:2d}"
            moved = "-"
            if out.markers_pred is not None and out.markers_reference is not None:
                d = np.linalg.norm(out.markers_pred - out.markers_reference, axis=1)
                moved = f"{np.nanmax(d):5.2f} mm"
            print(
                f"t {out.t:9.3f} s | touch {touch} | markers moved {moved} | "
                f"{s['fps_out']:5.1f} fps | latency p50 {s['latency_ms_p50']} ms "
                f"p99 {s['latency_ms_p99']} ms | dropped {s['dropped']} malformed "
                f"{s['malformed']} reconnects {s['reconnects']}",
                file=sys.stderr,
            )

    try:
        return engine.run(on_output=on_output, **run_kwargs)
    except KeyboardInterrupt:
        log.info("interrupted")
        engine.stop()
        return engine.stats


def _serve(engine, args, run_kwargs, jsonl) -> dict:

    if jsonl is not None:
        log.warning("--jsonl is ignored with --dashboard (the dashboard consumes the outputs)")

    def ready(url: str) -> None:
        print(f"dashboard at {url} (Ctrl-C to stop)", file=sys.stderr)

    try:
        serve(engine, "127.0.0.1", args.port, run_kwargs=run_kwargs, on_ready=ready)
    except KeyboardInterrupt:
        log.info("interrupted")
    return engine.stats
