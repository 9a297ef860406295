"""``ectskin live --source SPEC``: touch recognition, tracking, contact, ECT imaging and the
physical inversion (``--fields``) live.

Prints a status line every second (or serves the web dashboard with ``--dashboard``), optionally
records every frame (``--record``) and writes every output as JSON lines (``--jsonl``). Every
check that needs no source (outputs, ``--reference-markers``) runs before the source is opened,
so a mistake costs no connection attempt. Neither output may be a file the source reads. Ctrl-C,
SIGTERM and SIGHUP stop the run and close the recording complete.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.commands._options import add_overwrite
from ectskin.dashboard import serve
from ectskin.layout import SensorLayout, default_layout, load_layout
from ectskin.live.engine import POLICIES, LiveEngine
from ectskin.live.inversion_head import (
    BOUND_ERROR_FIRST,
    PERSONS,
    READOUTS,
    InversionHead,
    load_fields,
)
from ectskin.live.output import JsonLinesWriter, status_line
from ectskin.live.recorder import Recorder
from ectskin.live.reference import reference_line
from ectskin.live.signals import stop_on_signals
from ectskin.live.sources import SOURCE_SPECS, check_not_input, open_source

HELP = "run the trained models on a live source (optionally with the web dashboard)"
EXAMPLES = """\
  ectskin live --source sim --dashboard --duration 60
  ectskin live --source replay:session.h5 --touch-model runs/touch --track-model runs/track \\
      --dashboard
  ectskin live --source tcp:192.168.1.20:5000 --touch-model runs/touch --record rig.h5 \\
      --jsonl rig.jsonl
  ectskin live --source replay:crashed.h5 --allow-partial --jsonl - --max-frames 100
  ectskin live --source sim --contact-model runs/contact --ect --ect-every 3 --dashboard
  ectskin live --source replay:session.h5 --fields ~/.cache/ectskin/fields --jsonl out.jsonl
  ectskin live --source tcp:192.168.1.20:5000 --fields field_rest/ --state 0 0 0

the reference: the first --reference-frames frames (default 30 = 1 s) are the reference that
every later frame is calibrated against (paper Eq. 2). Keep the skin UNTOUCHED and UNINFLATED
while they are captured. A capture window with a touched or inflated frame (when the source
knows: replay, sim, a line with label=) is refused and the capture starts again; markers that
move or readouts that drift during it are warned about. Re-capture at any time with the
dashboard's "Capture reference" button.
"""
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--source", required=True, metavar="SPEC", help=f"one of {SOURCE_SPECS}")
    p.add_argument("--touch-model", metavar="RUN", help="run dir (or model.pt) of a TouchMLP")
    p.add_argument("--track-model", metavar="RUN", help="run dir (or model.pt) of a C2DT")
    p.add_argument(
        "--contact-model",
        metavar="RUN",
        help="run dir (or model.pt) of a ContactNet: finger count, points, forces, hover",
    )
    p.add_argument(
        "--ect",
        action="store_true",
        help="image the skin by ECT (an imager built from the layout at the uninflated state)",
    )
    p.add_argument(
        "--ect-every",
        type=int,
        default=3,
        metavar="N",
        help="--ect: image every N-th processed frame (default 3: 10 images/s at 30 fps)",
    )
    p.add_argument(
        "--fields",
        nargs="+",
        metavar="DIR",
        help="the physical inversion (no trained model): response fields, one per inflation "
        "state the skin visits (field folders, field.npz files, or a folder of cached fields); "
        "each frame is fitted through the field of its state",
    )
    p.add_argument(
        "--state",
        nargs="+",
        type=float,
        metavar="ML",
        help="--fields: the inflation (ml per chamber) of frames that carry none (a source "
        "without the pump's state); a frame's own state wins",
    )
    p.add_argument(
        "--inversion-every",
        type=int,
        default=1,
        metavar="N",
        help="--fields: fit every N-th processed frame (default 1)",
    )
    p.add_argument(
        "--inversion-readout",
        choices=READOUTS,
        default="reference",
        help="--fields: fit the raw frame in pF with the touch reference as the skin's untouched "
        "readout (reference, default: the reproduction's untouched='auto'), the raw frame "
        "against the field's untouched readout (absolute: a source calibrated like the field's "
        "mesh) or its change against the touch reference (difference)",
    )
    p.add_argument(
        "--inversion-press-check",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="--fields: refit a hovering finger pressing and keep that when it fits about as "
        "well (default: on, as the reproduction)",
    )
    p.add_argument(
        "--inversion-finger-sd",
        type=float,
        default=None,
        metavar="SD",
        help="--fields: the prior sd of each finger's relative signal scale (people's "
        "fingertips differ from the field's); 0 turns it off (default: the reproduction's, "
        "ectskin.inversion.fit.FINGER_SCALE_SD)",
    )
    p.add_argument(
        "--inversion-fingers",
        type=int,
        choices=(0, 1, 2),
        default=2,
        help="--fields: the most fingers fitted (default 2)",
    )
    p.add_argument(
        "--inversion-person",
        choices=PERSONS,
        default="off",
        help="--fields: pool what the frames tell of the person's finger (pulp modulus, "
        "fingertip radius) and fit each frame with it: one person for the whole stream "
        "(session), a new one at each trial of a replay (trial), or none (off, default). Needs "
        "coarse finger fields of the states: read from --finger-fields, built there first "
        "where missing (minutes)",
    )
    p.add_argument(
        "--inversion-bound-error",
        default="session",
        metavar="session|off|A,R",
        help="--fields: the model error the standard errors of points, forces and heights "
        "carry: learnt from the session's own fits, no labels (session, default: the noise "
        f"alone for the first {BOUND_ERROR_FIRST} fitted frames), none (off: the readout "
        "noise alone, too small on a real skin), or a known floor A pF and share R of the "
        "signal (the reproduction's inversion.model_error)",
    )
    p.add_argument(
        "--finger-fields",
        metavar="DIR",
        default=None,
        help="--inversion-person: the field cache of the finger fields (default: ectskin's field "
        "cache, $ECTSKIN_CACHE/fields or ~/.cache/ectskin/fields)",
    )
    p.add_argument("--dashboard", action="store_true", help="serve the web dashboard")
    p.add_argument("--port", type=int, default=8765, help="dashboard port (default 8765)")
    p.add_argument(
        "--keep-serving",
        action="store_true",
        help="dashboard: keep serving the last frame after the source ends or --duration "
        "passes, until Ctrl-C (default: stop then)",
    )
    p.add_argument(
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help="dashboard: also accept requests addressed to this host name (default: loopback "
        "names only; protects against DNS rebinding); repeatable",
    )
    p.add_argument("--record", metavar="OUT.h5", help="record every frame to this HDF5 file")
    p.add_argument(
        "--jsonl", metavar="PATH", help="write every output as a JSON line ('-' = stdout)"
    )
    add_overwrite(
        p, help="replace an existing --record or --jsonl file (never a file the source reads)"
    )
    p.add_argument(
        "--allow-partial",
        action="store_true",
        help="replay: accept a recording left incomplete (a crash, a killed recorder)",
    )
    p.add_argument("--layout", help="layout JSON for lsl/serial/tcp sources (default: the paper's)")
    p.add_argument("--speed", type=float, default=1.0, help="replay speed factor (default 1)")
    p.add_argument("--loop", action="store_true", help="replay: start again at the end")
    p.add_argument(
        "--reference-frames",
        type=int,
        default=30,
        help="frames averaged into the calibration reference (default 30 = 1 s); keep the skin "
        "untouched and uninflated meanwhile",
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
    p.add_argument(
        "--runtime",
        choices=("onnx", "torch"),
        default="onnx",
        help="what runs the models on each frame (default onnx: each model is exported once at "
        "start, a few seconds, and checked against PyTorch; several times faster per frame "
        "than torch, which runs them eagerly)",
    )
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--max-frames", type=int, metavar="N", help="stop after N frames")


# ---------------------------------------------------------------------------- checks at the door
def _outputs(args: argparse.Namespace) -> list[tuple[str, str]]:
    """(option, path) of the files this run writes."""
    outs = [("--record", args.record)]
    if args.jsonl != "-":
        outs.append(("--jsonl", args.jsonl))
    return [(opt, path) for opt, path in outs if path]


def _check_outputs(args: argparse.Namespace) -> None:
    """No output onto the source's own file, not both onto one file, none replaced without
    ``--overwrite``."""
    outs = _outputs(args)
    for opt, path in outs:
        check_not_input(path, args.source, opt)
    if len(outs) == 2 and Path(outs[0][1]).resolve() == Path(outs[1][1]).resolve():
        raise EctskinError(f"--record and --jsonl name the same file {outs[0][1]!r}")
    for opt, path in outs:
        if Path(path).exists() and not args.overwrite:
            raise EctskinError(f"{opt} {path} exists; pass --overwrite to replace it")


def _known_layout(args: argparse.Namespace) -> SensorLayout | None:
    """The layout the source will use, when it is known before the source is opened (a replay
    brings its own)."""
    if args.layout:
        return load_layout(args.layout)
    return None if args.source.strip().startswith("replay:") else default_layout()


def _load_markers(path: str) -> np.ndarray:
    """``--reference-markers``: (n_markers, 3) finite coordinates in mm."""
    try:
        m = np.load(path) if path.endswith(".npy") else np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise EctskinError(f"--reference-markers {path}: cannot read ({exc})") from None
    m = np.asarray(m, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != 3:
        raise EctskinError(
            f"--reference-markers {path}: expected (n_markers, 3) marker coordinates in mm, "
            f"got shape {m.shape}"
        )
    if not np.isfinite(m).all():
        raise EctskinError(f"--reference-markers {path}: holds non-finite coordinates")
    return m


def _check_markers(m: np.ndarray, path: str, layout: SensorLayout | None) -> None:
    """``--reference-markers`` must have one row per marker of ``layout`` (when known)."""
    if layout is not None and m.shape[0] != layout.n_markers:
        raise EctskinError(
            f"--reference-markers {path}: expected ({layout.n_markers}, 3) marker coordinates "
            f"in mm for layout {layout.name!r}, got shape {m.shape}"
        )


def run(args: argparse.Namespace) -> int:
    if args.threads < 1:
        raise EctskinError(f"--threads must be >= 1, got {args.threads}")
    if args.ect_every < 1:
        raise EctskinError(f"--ect-every must be >= 1 (frames), got {args.ect_every}")
    if args.inversion_every < 1:
        raise EctskinError(f"--inversion-every must be >= 1 (frames), got {args.inversion_every}")
    sd = args.inversion_finger_sd
    if sd is not None and not 0 <= sd < float("inf"):  # NaN too
        raise EctskinError(f"--inversion-finger-sd must be a number >= 0 (0: off), got {sd}")
    if not args.fields and args.state is not None:
        raise EctskinError("--state is the inflation state of the inversion's frames: give --fields")
    if not args.fields and (args.inversion_person != "off" or args.finger_fields is not None):
        raise EctskinError("--inversion-person and --finger-fields pool the inversion's person's "
                           "finger: give --fields")
    args.inversion_bound_error = _bound_error(args.inversion_bound_error)
    if args.finger_fields is not None and args.inversion_person == "off":
        raise EctskinError("--finger-fields is where --inversion-person reads the finger fields: "
                           "give --inversion-person session or trial")
    _check_outputs(args)
    ref_markers = None
    if args.reference_markers:
        ref_markers = _load_markers(args.reference_markers)
        _check_markers(ref_markers, args.reference_markers, _known_layout(args))
    # the fields are read (and the --state checked against them) before the source is opened
    fields = load_fields(args.fields) if args.fields else None
    with contextlib.ExitStack() as stack:
        if fields is not None:  # the inversion's products are tiny: BLAS threads only cost
            stack.enter_context(threadpool_limits(limits=1))
        touch = track = contact = None
        if args.touch_model or args.track_model or args.contact_model:
            # torch is imported only when a model is given: a run without models, and every
            # other `ectskin` command, starts without it
            from ectskin.learn.predict import ContactPredictor, TouchPredictor, TrackPredictor
            from ectskin.learn.threads import torch_threads

            stack.enter_context(torch_threads(args.threads))
            layout = _known_layout(args)  # a model for another skin is refused before it is built
            touch = (
                TouchPredictor.from_run(args.touch_model, layout=layout)
                if args.touch_model
                else None
            )
            _check_touch_reference(touch, args.touch_model)
            track = (
                TrackPredictor.from_run(args.track_model, layout=layout)
                if args.track_model
                else None
            )
            if args.contact_model:
                contact = ContactPredictor.from_run(args.contact_model, layout=layout)
            _use_runtime(args.runtime, [touch, track, contact])
        with stop_on_signals("closing the recording" if args.record else "stopping"):
            return _run(
                args, {"touch": touch, "track": track, "contact": contact}, ref_markers, fields
            )


def _check_touch_reference(touch: Any, source: Any) -> None:
    """Refuse a touch run calibrated against each inflation state's rest readout: the live
    stream is calibrated against one rest readout (the rest state's), so its frames would not be
    the frames the run learnt from."""
    from ectskin.learn.data.touch import FOLLOWS_INFLATION

    mode = getattr(touch, "reference_mode", None)
    if touch is not None and mode in FOLLOWS_INFLATION:
        raise EctskinError(
            f"--touch-model {source}: the run calibrates each frame against the rest readout at "
            f"its own inflation (reference {mode!r}); the live engine calibrates against the rest "
            "state's readout only. Use a run trained with --reference rest (the paper's recipe) "
            "for live use"
        )


def _use_runtime(runtime: str, predictors: list) -> None:
    """``--runtime``: export each model once (ONNX), saying so, since it takes seconds."""
    for p in predictors:
        if p is None or runtime == "torch" or p.runtime == "skops":
            continue
        t0 = time.perf_counter()
        p.use_runtime(runtime)
        took = time.perf_counter() - t0
        print(f"{p.source}: answers with ONNX Runtime (exported in {took:.1f} s)", file=sys.stderr)


def _ect_imager(layout: SensorLayout):
    """``--ect``: the ECT imager of ``layout`` at the uninflated state (the touch reference's)."""
    try:
        from ectskin.twin.ect import EctImager
    except ImportError:
        raise EctskinError(
            "--ect needs the ECT imager (ectskin.twin.ect.EctImager), missing from this install"
        ) from None
    return EctImager(layout, (0.0, 0.0, 0.0))  # ml per chamber: the rest state


# ---------------------------------------------------------------------------- the run
def _inversion(args: argparse.Namespace, fields, layout: SensorLayout) -> InversionHead | None:
    """``--fields``: the inversion head over the loaded fields, bound to the source's layout."""
    if fields is None:
        return None
    sd = args.inversion_finger_sd
    tables = None
    if args.inversion_person != "off":
        from ectskin.pipeline.field import field_cache_dir
        from ectskin.twin.field_finger import finger_tables

        cache = field_cache_dir(args.finger_fields)
        log.info("inversion: the finger fields of %d state(s) from %s (built there where "
                 "missing)", len(fields), cache)
        tables = finger_tables([f.spec for f in fields.values()], cache, progress=False)
    return InversionHead.from_fields(
        fields, layout, max_fingers=args.inversion_fingers, state=args.state,
        every=args.inversion_every, readout=args.inversion_readout,
        press_check=args.inversion_press_check,
        finger_scale_sd="reproduction" if sd is None else sd,
        finger_tables=tables, person=args.inversion_person,
        bound_error=args.inversion_bound_error,
    )


def _bound_error(text: str) -> str | tuple[float, float]:
    """``--inversion-bound-error``: "session", "off" or "A,R" (two numbers >= 0)."""
    if text in ("session", "off"):
        return text
    try:
        a, r = (float(x) for x in text.split(","))
    except ValueError:
        a = r = float("nan")
    if not (0 <= a < float("inf") and 0 <= r < float("inf")):
        raise EctskinError(f"--inversion-bound-error must be session, off or A,R (a floor A pF "
                           f"and a share R of the signal, numbers >= 0), got {text!r}")
    return a, r


def _run(args: argparse.Namespace, models: dict, ref_markers, fields=None) -> int:
    """The command with its models loaded (``models``: touch, track, contact; each may be
    None) and its response fields (``fields``: state → field, or None)."""
    layout = load_layout(args.layout) if args.layout else None
    source = open_source(
        args.source,
        layout=layout,
        speed=args.speed,
        loop=args.loop,
        allow_partial=args.allow_partial,
    )
    recorder = None
    jsonl = None
    ended = "the source ended"
    try:
        if ref_markers is not None:  # a replay's layout is known only now
            _check_markers(ref_markers, args.reference_markers, source.layout)
        inversion = _inversion(args, fields, source.layout)
        if args.record:
            recorder = Recorder(
                args.record,
                source.layout,
                source.frame_rate_hz or 30.0,
                overwrite=args.overwrite,
                meta={
                    "source": args.source,
                    "touch_model": args.touch_model,
                    "track_model": args.track_model,
                    "contact_model": args.contact_model,
                    "ect_every": args.ect_every if args.ect else None,
                    "fields": list(args.fields) if args.fields else None,
                    "inversion": None if inversion is None else inversion.meta(),
                    "state": args.state,
                    "runtime": args.runtime,
                },
                trial_info=getattr(source, "trial_info", None),
            )
        engine = LiveEngine(
            source,
            source.layout,
            **models,
            imager=_ect_imager(source.layout) if args.ect else None,
            ect_every=args.ect_every,
            inversion=inversion,
            policy=args.policy,
            reference_frames=args.reference_frames,
            recorder=recorder,
            reference_markers=ref_markers,
        )
        run_kwargs = {"max_frames": args.max_frames, "duration_s": args.duration}
        if args.jsonl:
            jsonl = JsonLinesWriter(
                sys.stdout if args.jsonl == "-" else args.jsonl,
                overwrite=args.overwrite,
                on_error=engine.stop,
                name=f"--jsonl {args.jsonl}",
            )
        t0 = time.monotonic()
        if args.dashboard:
            stats, interrupted = _serve(engine, args, run_kwargs, jsonl)
        else:
            stats, interrupted = _console(engine, run_kwargs, jsonl, status=args.jsonl != "-")
        if interrupted:
            ended = "interrupted"
        elif args.duration is not None and time.monotonic() - t0 >= args.duration:
            ended = f"--duration {args.duration:g} s passed"
        elif args.max_frames is not None and stats.get("frames") == args.max_frames:
            ended = f"--max-frames {args.max_frames} reached"
    finally:
        source.close()
        if recorder is not None:
            recorder.close()
        if jsonl is not None:
            jsonl.close()
    _summary(engine, stats, recorder, args, ended)
    return 0


def _summary(engine: LiveEngine, stats: dict, recorder, args, ended: str) -> None:
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
    print(f"final ({ended}): " + ", ".join(f"{k} {stats.get(k)}" for k in keys), file=sys.stderr)
    refs = engine.reference_state()
    used = {"touch"} | {h.reference for h in engine.heads}
    for name in ("touch", "tracking"):
        if name in used:
            print(f"{name} reference: {reference_line(refs[name])}", file=sys.stderr)
    if recorder is not None:
        print(f"recorded {recorder.frames_written} frames to {args.record}", file=sys.stderr)


def _console(engine, run_kwargs, jsonl, status: bool) -> tuple[dict, bool]:
    """Run in this thread; one status line per second on stderr. Returns (stats, interrupted)."""
    last = [0.0]

    def on_output(out) -> None:
        if jsonl is not None:
            jsonl(out)
        now = time.monotonic()
        if status and now - last[0] >= 1.0:
            last[0] = now
            print(status_line(out), file=sys.stderr)

    try:
        return engine.run(on_output=on_output, **run_kwargs), False
    except KeyboardInterrupt:
        log.info("interrupted")
        engine.stop()
        return engine.stats, True


def _serve(engine, args, run_kwargs, jsonl) -> tuple[dict, bool]:
    """Serve the dashboard until the engine ends (or Ctrl-C). Returns (stats, interrupted)."""

    def ready(url: str) -> None:
        until = (
            "until Ctrl-C"
            if args.keep_serving
            else "until the source ends"
            + (f" or {args.duration:g} s pass" if args.duration else "")
            + " (or Ctrl-C)"
        )
        print(f"dashboard at {url}, serving {until}", file=sys.stderr)

    try:
        serve(
            engine,
            "127.0.0.1",
            args.port,
            run_kwargs=run_kwargs,
            on_ready=ready,
            on_output=jsonl,
            keep_serving=args.keep_serving,
            allowed_hosts=args.allow_host,
        )
    except KeyboardInterrupt:
        log.info("interrupted")
        return engine.stats, True
    print("live engine finished; dashboard stopped", file=sys.stderr)
    return engine.stats, False
