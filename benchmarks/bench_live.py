"""Live engine benchmark: end-to-end throughput and latency on one CPU core, and a soak test.

Throughput (default)::

    python benchmarks/bench_live.py --frames 20000 --out bench_live.json

replays a synthetic recording as fast as possible (``speed=inf``) through the whole engine
(reference capture → Eq. 2 calibration → TouchMLP → C2DT window + C2DT → Output) with policy
``block`` (every frame processed), with ``torch.set_num_threads(1)`` and the process pinned to one
CPU core. It reports frames/s sustained and the per-frame latency (frame arrival → output) p50 /
p99 / max, plus the cost of each stage measured alone. The target is >= 300 frames/s. At
saturation the latency includes waiting behind the previous frame (``--queue-size 1`` keeps that
to about one frame); the ``paced`` section gives the live latency, with frames arriving at
``--paced-rate`` (below capacity) under the live policy ``skip-to-newest``, with every head.

Heads: ``end_to_end`` runs touch + tracking; ``all_heads`` adds the contact head (ContactNet on
its window) and the ECT image head every ``--ect-every`` frames (default 1: every frame). With
``--fields`` (response fields, or ``synthetic``) the replayed readouts are a field's (one finger,
none, two fingers in turn) and ``all_heads_inversion`` adds the physical-inversion head
(:mod:`ectskin.live.inversion_head`, every ``--inversion-every`` frames) to every head,
``inversion_only`` runs it alone::

    python benchmarks/bench_live.py --frames 5000 --fields synthetic --out bench_live.json

The ``stages_ms`` section also times the frame's JSON message with the ECT image (what ``--jsonl``
and the dashboard encode, outside the inference loop).

Soak::

    python benchmarks/bench_live.py --soak-seconds 600 --rate 300 --out soak.json

paces the replay at ``--rate`` frames/s with the live policy ``skip-to-newest`` and a recorder
attached (as ``ectskin live --record``), and checks zero lost frames (nothing skipped by the
engine, no sequence gaps, every frame recorded) and flat memory (RSS sampled every
``--rss-every`` seconds; start / end / max reported).

Runtime: ``--runtime onnx`` (default, as ``ectskin live``) answers each frame with ONNX Runtime
exports of the models (:mod:`ectskin.learn.runtime`); ``--runtime torch`` runs them eagerly. With
onnx the per-stage costs are measured both ways in the same run (``stages_ms_torch`` beside
``stages_ms``), and ``export_s`` gives each model's one-off export time.

Models: the run directories given with ``--touch-run`` / ``--track-run`` / ``--contact-run``
(``model.pt`` from ``ectskin train``), else randomly initialised TouchMLP and C2DT of the paper's
size and a ContactNet of the ``ectskin train contact`` default size (window 10; latency is what
matters). The ECT imager is ``ectskin.twin.ect.EctImager`` of the layout at rest when that module
is installed, else :class:`MatrixImager`, a stand-in with the same work per frame as its
Tikhonov path (one precomputed pixel × pair matrix times Δc, the per-face reshape, then peak and
centroid); ``result["models"]["ect"]`` says which ran. Results are printed and written as JSON
to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import platform
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_inversion (--fields)


def _rss_mb() -> float:
    """Resident set size of this process, MiB (Linux /proc)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _pin_one_core() -> int | None:
    try:
        cpu = sorted(os.sched_getaffinity(0))[0]
        os.sched_setaffinity(0, {cpu})
        return cpu
    except (AttributeError, OSError):
        return None


class MatrixImager:
    """ECT imager stand-in (the interface the live engine uses) with the work of a linear
    reconstruction: a fixed random (n_pix, n_pairs) matrix on a grid of ``pixel_mm`` (assumed 4 mm)
    pixels per face; ``locate`` takes the peak pixel and the weighted centroid of the pixels of at
    least half the peak within two pixels of it. Its images mean nothing; its cost is the point."""

    def __init__(self, layout, pixel_mm: float = 4.0, seed: int = 0):
        self.faces, self.grid_extent, self._shapes, uv, face = [], {}, [], [], []
        for k, skin in enumerate(layout.skins):
            nu = max(1, round((skin.u_mm[1] - skin.u_mm[0]) / pixel_mm))
            nv = max(1, round((skin.v_mm[1] - skin.v_mm[0]) / pixel_mm))
            u = np.linspace(*skin.u_mm, nu + 1)
            v = np.linspace(*skin.v_mm, nv + 1)
            vv, uu = np.meshgrid((v[1:] + v[:-1]) / 2, (u[1:] + u[:-1]) / 2, indexing="ij")
            self.faces.append(skin.surface)
            self.grid_extent[skin.surface] = [list(skin.u_mm), list(skin.v_mm)]
            self._shapes.append((nv, nu))
            uv.append(np.column_stack([uu.ravel(), vv.ravel()]))
            face.append(np.full(nu * nv, k))
        self._uv, self._face = np.concatenate(uv), np.concatenate(face)
        rng = np.random.default_rng(seed)
        self._matrix = rng.standard_normal((len(self._uv), layout.n_pairs))
        self._radius = 2 * pixel_mm

    def _pixels(self, dc):
        return self._matrix @ dc

    def image(self, dc):
        y, out, a = self._pixels(dc), {}, 0
        for name, (nv, nu) in zip(self.faces, self._shapes):
            out[name] = y[a : a + nv * nu].reshape(nv, nu)
            a += nv * nu
        return out

    def locate(self, dc):
        y = self._pixels(dc)
        k = int(np.argmax(y))
        peak = y[k]
        sel = (self._face == self._face[k]) & (
            np.linalg.norm(self._uv - self._uv[k], axis=1) <= self._radius
        )
        sel &= y >= 0.5 * peak
        w = y[sel] - 0.5 * peak
        u, v = (w[:, None] * self._uv[sel]).sum(0) / w.sum() if w.sum() > 0 else self._uv[k]
        return self.faces[self._face[k]], float(u), float(v), float(peak)


def _imager(layout):
    """(imager, description): the real EctImager when installed, else :class:`MatrixImager`."""
    try:
        from ectskin.twin.ect import EctImager
    except ImportError:
        return MatrixImager(layout), "MatrixImager stand-in (ectskin.twin.ect not installed)"
    return EctImager(layout, (0.0, 0.0, 0.0)), "ectskin.twin.ect.EctImager at rest"


def _contact(layout, contact_run, tmp: Path):
    """ContactPredictor from a run dir, or a random ContactNet of the default training size."""
    import torch

    from ectskin.learn.checkpoint import save_checkpoint
    from ectskin.learn.models.contact import ContactNet, ContactNetConfig
    from ectskin.learn.predict import ContactPredictor

    if contact_run is None:
        torch.manual_seed(0)
        extent = {s.surface: [list(s.u_mm), list(s.v_mm)] for s in layout.skins}
        extra = {
            "pair_names": list(layout.pair_names),
            "faces": list(extent),
            "face_extent": extent,
        }
        contact_run = tmp / "contact"
        model = ContactNet(ContactNetConfig(n_pairs=layout.n_pairs, window=10))
        save_checkpoint(contact_run / "model.pt", model, extra=extra)
    return ContactPredictor.from_run(contact_run)


def _predictors(layout, touch_run, track_run, tmp: Path):
    """TouchPredictor / TrackPredictor from run dirs, or random paper-size models saved and
    loaded through the same checkpoint path a trained run uses."""
    import torch

    from ectskin.learn.checkpoint import save_checkpoint
    from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP, TouchMLPConfig
    from ectskin.learn.predict import TouchPredictor, TrackPredictor

    extra = {"pair_names": list(layout.pair_names)}
    torch.manual_seed(0)
    if touch_run is None:
        cfg = TouchMLPConfig(n_pairs=layout.n_pairs, n_classes=layout.n_classes)
        touch_run = tmp / "touch"
        save_checkpoint(touch_run / "model.pt", TouchMLP(cfg), extra=extra)
    if track_run is None:
        cfg = C2DTConfig(
            n_pairs=layout.n_pairs, n_markers=layout.n_markers, n_electrodes=layout.n_electrodes
        )
        model = C2DT(cfg, desc=layout.electrode_descriptors(), pairs=layout.pairs)
        track_run = tmp / "track"
        save_checkpoint(track_run / "model.pt", model, extra=extra)
    return TouchPredictor.from_run(touch_run), TrackPredictor.from_run(track_run)


def _recording(layout, n_frames: int, frame_rate_hz: float, seed: int = 0, field=None):
    """A synthetic recording: one trial of slowly varying readouts with markers, after one second
    at rest (where the engine captures its reference, as a session should begin). With a
    ``field`` the readouts are the field's (``bench_inversion.field_readouts``), of its state."""
    from ectskin.io.recording import Recording, Trial

    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / frame_rate_hz
    moving = np.clip(t - 1.0, 0.0, None)  # 0 during the first second
    base = 0.05 + 0.2 * rng.random(layout.n_pairs)
    cap = base * (
        1
        + 0.1 * np.sin(2 * np.pi * 0.3 * moving)[:, None]
        + 0.001 * rng.standard_normal((n_frames, layout.n_pairs))
    )
    state: tuple[float, ...] = ()
    if field is not None:
        from bench_inversion import field_readouts

        cap = field_readouts(field, n_frames, frame_rate_hz, rng)
        state = tuple(field.spec.inflation_ml)
    markers = np.zeros((n_frames, layout.n_markers, 3))
    markers[:, :, 2] = np.linspace(24, 120, layout.n_markers)
    markers[:, :, 0] = 25 + np.sin(2 * np.pi * 0.2 * moving)[:, None]
    labels = (np.arange(n_frames) // 90) % layout.n_classes
    trial = Trial("bench", cap, t, labels, markers=markers, inflation=state)
    return Recording(layout, [trial], frame_rate_hz)


def _pct(a: np.ndarray) -> dict[str, float]:
    return {
        "p50": float(np.percentile(a, 50)),
        "p99": float(np.percentile(a, 99)),
        "max": float(a.max()),
        "mean": float(a.mean()),
    }


def _stage_costs(heads, layout, n: int = 2000) -> dict[str, dict[str, float]]:
    """Each predictor called alone (ms per call) with realistic inputs, and the JSON message of
    a frame with every head's output (the ECT image quantised)."""
    from ectskin.live.heads import EctHead
    from ectskin.live.output import Output

    touch, track, contact, imager = (
        heads["touch"],
        heads["track"],
        heads["contact"],
        heads["imager"],
    )
    rng = np.random.default_rng(1)
    x = (0.01 * rng.standard_normal(layout.n_pairs)).astype(np.float32)
    w = (0.01 * rng.standard_normal((track.window, layout.n_pairs))).astype(np.float32)
    wc = (0.01 * rng.standard_normal((contact.window, layout.n_pairs))).astype(np.float32)
    init = rng.normal(size=(layout.n_markers, 3)).astype(np.float32) * 20
    raw = 1 + 0.01 * rng.random(layout.n_pairs)
    c0 = np.ones(layout.n_pairs)
    ect = EctHead(imager, layout)
    out_msg = Output(seq=1, t=0.0, raw=raw, calibrated=raw - 1, touch_probs=touch.predict(x))
    out_msg.touch_cls = int(np.argmax(out_msg.touch_probs))
    out_msg.markers_pred = out_msg.markers_reference = init.astype(np.float64)
    out_msg.contact = contact.read(wc)
    out_msg.ect = ect(raw, c0)
    out = {}
    for name, fn in (
        ("touch_predict", lambda: touch.predict(x)),
        ("track_predict", lambda: track.predict(w, init)),
        ("contact_read", lambda: contact.read(wc)),
        ("ect_image_locate", lambda: ect(raw, c0)),
        ("message_json", lambda: json.dumps(out_msg.to_json_dict(), allow_nan=False)),
    ):
        for _ in range(50):
            fn()
        t = np.empty(n)
        cpu0 = time.thread_time()
        for i in range(n):
            t0 = time.perf_counter()
            fn()
            t[i] = time.perf_counter() - t0
        out[name] = _pct(t * 1e3)
        out[name]["cpu_mean"] = 1e3 * (time.thread_time() - cpu0) / n
    return out


def throughput(args, layout, heads, inversion=None) -> dict:
    """``inversion``: (fields, rest field) or None; with it every configuration replays the rest
    field's readouts, and ``all_heads_inversion`` / ``inversion_only`` add the inversion head."""
    from ectskin.live import InversionHead, LiveEngine, ReplaySource

    field = None if inversion is None else inversion[1]
    rec = _recording(layout, args.frames, 30.0, field=field)
    result = {"mode": "throughput", "frames": args.frames, "ect_every": args.ect_every}
    paper = {"touch": heads["touch"], "track": heads["track"]}
    configs: list[tuple[str, dict]] = [("engine_only", {}), ("end_to_end", paper), ("all_heads", heads)]
    if inversion is not None:
        configs += [("all_heads_inversion", {**heads, "inversion": True}),
                    ("inversion_only", {"inversion": True})]

    def head(models: dict) -> dict:
        """A fresh inversion head per engine (a head keeps its stream's last answer)."""
        if not models.get("inversion"):
            return {k: v for k, v in models.items() if k != "inversion"}
        return {**models, "inversion": InversionHead.from_fields(
            inversion[0], layout, every=args.inversion_every, **args.inversion_options)}

    for label, models in configs:
        src = ReplaySource(rec, speed=math.inf)
        eng = LiveEngine(
            src,
            **head(models),
            ect_every=args.ect_every,
            policy="block",
            queue_size=args.queue_size,
            reference_frames=30,
        )
        lat = np.empty(args.frames)
        n = [0]

        def on_output(o, lat=lat, n=n):
            lat[n[0]] = o.latency_ms
            n[0] += 1

        t0, cpu0 = time.perf_counter(), time.process_time()
        stats = eng.run(on_output=on_output)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        lat = lat[: n[0]]
        result[label] = {
            "heads": [h.key for h in eng.heads],
            "fps": stats["processed"] / wall,
            "wall_s": wall,
            # CPU time of the whole process (reader, engine, this callback) per frame: what one
            # core can sustain when it is not shared (wall-clock fps drops when it is)
            "cpu_ms_per_frame": 1e3 * cpu / max(stats["processed"], 1),
            "fps_cpu_bound": stats["processed"] / cpu if cpu > 0 else float("nan"),
            "processed": stats["processed"],
            "dropped": stats["dropped"],
            "errors": stats["errors"],
            "latency_ms": _pct(lat),
        }
        logging.info(
            "%s: %.0f frames/s (%.0f CPU-bound), latency p50 %.3f ms p99 %.3f ms",
            label,
            result[label]["fps"],
            result[label]["fps_cpu_bound"],
            result[label]["latency_ms"]["p50"],
            result[label]["latency_ms"]["p99"],
        )
    # live latency: frames paced at --paced-rate (below capacity), live policy skip-to-newest
    n_paced = int(args.paced_rate * args.paced_seconds)
    src = ReplaySource(_recording(layout, n_paced, 30.0, field=field),
                       speed=args.paced_rate / 30.0)
    every = {**heads, "inversion": inversion is not None}
    eng = LiveEngine(src, **head(every), ect_every=args.ect_every, policy="skip-to-newest")
    lat = []
    stats = eng.run(on_output=lambda o: lat.append(o.latency_ms))
    result["paced"] = {
        "rate_hz": args.paced_rate,
        "frames": stats["frames"],
        "processed": stats["processed"],
        "dropped": stats["dropped"],
        "latency_ms": _pct(np.asarray(lat)),
        "heads": [h.key for h in eng.heads],
    }
    logging.info(
        "paced %.0f frames/s: %d dropped of %d, latency p50 %.3f ms p99 %.3f ms",
        args.paced_rate,
        stats["dropped"],
        stats["frames"],
        result["paced"]["latency_ms"]["p50"],
        result["paced"]["latency_ms"]["p99"],
    )
    result["stages_ms"] = _stage_costs(heads, layout)
    result["target_fps"] = 300
    result["meets_target"] = result["end_to_end"]["fps"] >= 300
    result["all_heads_meet_target"] = result["all_heads"]["fps"] >= 300
    if inversion is not None:
        result["all_heads_inversion_meet_target"] = result["all_heads_inversion"]["fps"] >= 300
    return result


def soak(args, layout, heads) -> dict:
    from ectskin.live import LiveEngine, Recorder, ReplaySource

    rate = float(args.rate)
    # a 60 s loop at 30 fps, replayed rate/30 times faster: frames arrive every 1/rate s
    rec = _recording(layout, 1800, 30.0)
    src = ReplaySource(rec, speed=rate / 30.0, loop=True)
    tmp = Path(args.record_dir or tempfile.mkdtemp(prefix="ectskin-soak-"))
    path = tmp / "soak.h5"
    if path.exists():
        path.unlink()
    recorder = None if args.no_record else Recorder(path, layout, rate)
    models = heads if args.all_heads else {"touch": heads["touch"], "track": heads["track"]}
    eng = LiveEngine(
        src,
        **models,
        ect_every=args.ect_every,
        policy="skip-to-newest",
        recorder=recorder,
        max_lag_ms=args.max_lag_ms,
    )
    cap = int(rate * args.soak_seconds * 1.2) + 1000
    lat = np.empty(cap)  # preallocated: the benchmark's own bookkeeping does not grow
    n = [0]

    def on_output(o):
        if n[0] < cap:
            lat[n[0]] = o.latency_ms
        n[0] += 1

    rss: list[tuple[float, float]] = []
    done = threading.Event()

    def sample():
        t0 = time.perf_counter()
        while not done.wait(args.rss_every):
            rss.append((time.perf_counter() - t0, _rss_mb()))
            s = eng.stats
            logging.info(
                "t=%4.0f s rss %.1f MiB frames %d dropped %d recorded %d p99 %.2f ms",
                rss[-1][0],
                rss[-1][1],
                s["frames"],
                s["dropped"],
                s.get("recorded", 0),
                s["latency_ms_p99"] or float("nan"),
            )

    rss.append((0.0, _rss_mb()))
    th = threading.Thread(target=sample, daemon=True)
    th.start()
    stats = eng.run(duration_s=args.soak_seconds, on_output=on_output)
    done.set()
    th.join()
    rss.append((args.soak_seconds, _rss_mb()))
    if recorder is not None:
        recorder.close()
        from ectskin.io.hdf5 import list_trials

        recorded = sum(t["n_frames"] for t in list_trials(path))
    else:
        recorded = stats["frames"]  # nothing to lose on the recording side
    lat = lat[: min(n[0], cap)]
    mem = np.array([m for _, m in rss])
    # growth over the second half (after warm-up: caches, allocator pools)
    half = [m for t, m in rss if t >= args.soak_seconds / 2]
    lost = stats["dropped"] + stats["seq_gaps"] + (stats["frames"] - recorded)
    result = {
        "mode": "soak",
        "rate_hz": rate,
        "max_lag_ms": args.max_lag_ms,
        "recording_on": recorder is not None,
        "heads": "all" if args.all_heads else "touch+track",
        "seconds": args.soak_seconds,
        "frames": stats["frames"],
        "processed": stats["processed"],
        "dropped": stats["dropped"],
        "seq_gaps": stats["seq_gaps"],
        "recorded": recorded,
        "lost": lost,
        "zero_lost": lost == 0,
        "fps_in_mean": stats["frames"] / args.soak_seconds,
        "latency_ms": _pct(lat) if lat.size else None,
        "rss_mib": {
            "start": float(mem[0]),
            "end": float(mem[-1]),
            "max": float(mem.max()),
            "second_half_growth": float(half[-1] - half[0]) if len(half) > 1 else 0.0,
        },
        "rss_samples": [[round(t, 1), round(m, 2)] for t, m in rss],
    }
    result["recording"] = None if recorder is None else str(path)
    if recorder is not None and not args.keep_recording:
        path.unlink()
        result["recording"] = "deleted"
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=20000, help="throughput: frames to replay")
    ap.add_argument(
        "--queue-size",
        type=int,
        default=1,
        help="throughput: engine queue (1 = latency without queueing delay)",
    )
    ap.add_argument(
        "--paced-rate",
        type=float,
        default=300.0,
        help="throughput: also measure latency with frames paced at this rate",
    )
    ap.add_argument("--paced-seconds", type=float, default=5.0)
    ap.add_argument("--touch-run", type=Path, help="run dir of a trained TouchMLP")
    ap.add_argument("--track-run", type=Path, help="run dir of a trained C2DT")
    ap.add_argument("--contact-run", type=Path, help="run dir of a trained ContactNet")
    ap.add_argument(
        "--ect-every",
        type=int,
        default=1,
        help="ECT image every N-th frame (default 1: every frame)",
    )
    ap.add_argument(
        "--all-heads",
        action="store_true",
        help="soak: run contact and ECT too (default: touch+track)",
    )
    ap.add_argument("--soak-seconds", type=float, help="run the soak test for this long")
    ap.add_argument("--rate", type=float, help="soak: frames per second")
    ap.add_argument("--rss-every", type=float, default=5.0, help="soak: RSS sampling period, s")
    ap.add_argument("--record-dir", type=Path, help="soak: where the recording goes (tmp)")
    ap.add_argument("--keep-recording", action="store_true")
    ap.add_argument("--no-record", action="store_true", help="soak without the recorder")
    ap.add_argument(
        "--max-lag-ms", type=float, default=50.0, help="soak: engine max_lag_ms (default 50)"
    )
    ap.add_argument(
        "--runtime",
        choices=("onnx", "torch"),
        default="onnx",
        help="what runs the models on each frame (default onnx, as ectskin live)",
    )
    ap.add_argument(
        "--fields",
        nargs="+",
        metavar="DIR",
        help="throughput: add the physical-inversion head over these response fields (field "
        "folders, field.npz files or a folder of cached fields; one must be of the rest state), "
        "replaying the rest field's readouts of one and two fingers; 'synthetic': "
        "bench_inversion.py's field of the contact experiment's size",
    )
    ap.add_argument("--inversion-every", type=int, default=1, help="--fields: fit every N-th frame")
    ap.add_argument("--inversion-options", type=json.loads, default={}, metavar="JSON", help=(
        '--fields: InversionHead.from_fields options, e.g. {"press_check": false}'))
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    ap.add_argument("--out", type=Path, help="write the results as JSON here")
    args = ap.parse_args(argv)
    if args.fields and args.soak_seconds is not None:
        ap.error("--fields is for the throughput run, not the soak")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    if args.soak_seconds is not None and not args.rate:
        ap.error("--soak-seconds needs --rate")

    import torch

    torch.set_num_threads(1)
    cpu = None if args.no_pin else _pin_one_core()
    from ectskin.layout import default_layout

    layout = default_layout()
    with tempfile.TemporaryDirectory() as tmp:
        touch, track = _predictors(layout, args.touch_run, args.track_run, Path(tmp))
        imager, ect_name = _imager(layout)
        heads = {
            "touch": touch,
            "track": track,
            "contact": _contact(layout, args.contact_run, Path(tmp)),
            "imager": imager,
        }
        stages_torch, export_s = None, {}
        if args.runtime == "onnx":
            if args.soak_seconds is None:
                stages_torch = _stage_costs(heads, layout)
            for name in ("touch", "track", "contact"):
                t0 = time.perf_counter()
                heads[name].use_runtime("onnx")
                export_s[name] = time.perf_counter() - t0
        if args.soak_seconds is not None:
            result = soak(args, layout, heads)
        else:
            inversion = None
            if args.fields:
                from bench_inversion import live_fields

                inversion = live_fields(args.fields, layout)
            with threadpool_limits(limits=1):  # as `ectskin live --fields`
                result = throughput(args, layout, heads, inversion)
    result["runtime"] = args.runtime
    if stages_torch is not None:
        result["stages_ms_torch"] = stages_torch
    if export_s:
        result["export_s"] = export_s
    result["machine"] = {
        "python": sys.version.split()[0],
        "torch": torch.__version__,
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "pinned_cpu": cpu,
        "torch_threads": torch.get_num_threads(),
    }
    result["models"] = {
        "touch": str(args.touch_run or "random TouchMLP (paper size)"),
        "track": str(args.track_run or "random C2DT (paper size)"),
        "contact": str(args.contact_run or "random ContactNet (train default size, window 10)"),
        "ect": ect_name,
        "inversion": args.fields and " ".join([*args.fields, json.dumps(args.inversion_options)]),
    }
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
