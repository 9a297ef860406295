"""Classical touch models answering one frame (the live engine's path) and a batch (evaluation).

Usage::

    python benchmarks/bench_candidates.py --out bench_candidates.json [--calls 2000]

Each classical candidate (``gbt``, ``random_forest``, ``logreg``, ``knn``) is fit with its
default settings (:data:`ectskin.learn.candidates.SETTINGS`; gradient boosting: 19 classes x 100
iterations = 1 900 trees) on synthetic frames of the paper's size (28 pairs, 19 classes, up to
:data:`~ectskin.learn.candidates.MAX_TRAIN` training frames; ``--noise`` sets how much the classes
overlap, hence the trees' size), then, with one thread and the process pinned to one CPU core:

* ``first_frame_s``: the first ``ClassicalModel.predict_proba`` of one frame of a fresh model:
  it includes the one-off cost of the single-frame path (the ONNX export, which
  ``TouchPredictor`` makes when it loads the model, before the live engine's first frame);
* ``frame``: ``ClassicalModel.predict_proba`` of one float32 frame, as ``TouchPredictor`` calls
  it live: median / p99 over ``--calls`` calls on held-out frames;
* ``sklearn_frame``: scikit-learn's own ``estimator.predict_proba`` of one frame, the public
  API the single-frame path is measured against;
* ``batch_s``: ``ClassicalModel.predict_proba`` of ``--batch`` held-out frames at once;
* ``max_abs_diff``: the largest difference of the one-frame probabilities from scikit-learn's.

``path`` says what answered one frame. Run it at another commit (same command) to compare the
single-frame path of that commit. Numbers on a shared machine depend on what else runs; the JSON
records the load average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin.layout import default_layout
from ectskin.learn.candidates import CLASSICAL, fit_classical
from ectskin.learn.data import TouchData


def touch_data(n: int, seed: int, noise: float) -> TouchData:
    """``n`` frames of 19 classes around fixed centres (28 pairs, spread 0.2) with Gaussian
    ``noise``, in groups of 900 frames."""
    rng = np.random.default_rng(seed)
    centres = np.random.default_rng(0).normal(0, 0.2, size=(19, 28))
    y = rng.integers(0, 19, n)
    x = centres[y] + noise * rng.standard_normal((n, 28))
    group = np.arange(n) // 900
    return TouchData(
        x.astype(np.float32),
        y.astype(np.int64),
        group.astype(np.int64),
        [f"t{g}" for g in range(group.max() + 1)],
        19,
        list(default_layout().pair_names),
    )


def _pin_one_core() -> int | None:
    try:
        cpu = sorted(os.sched_getaffinity(0))[0]
        os.sched_setaffinity(0, {cpu})
        return cpu
    except (AttributeError, OSError):
        return None


def _latency(fn, frames: np.ndarray, calls: int) -> dict[str, float]:
    """``fn(frame)`` on one frame at a time (cycling through ``frames``): median / p99 ms."""
    for i in range(min(50, calls)):
        fn(frames[i % len(frames)][None])
    t = np.empty(calls)
    for i in range(calls):
        f = frames[i % len(frames)][None]
        t0 = time.perf_counter()
        fn(f)
        t[i] = time.perf_counter() - t0
    return {
        "median_ms": float(np.median(t) * 1e3),
        "p99_ms": float(np.percentile(t, 99) * 1e3),
        "calls": calls,
    }


def _path(model) -> str:
    """What answers one frame of ``model``."""
    single = getattr(model, "single_frame", None)
    if single is None:
        return "ClassicalModel.predict_proba (no single_frame at this commit)"
    return "onnxruntime" if single() is not None else "scikit-learn"


def bench_candidate(name: str, train: TouchData, held_out: np.ndarray, args) -> dict:
    model, used, fit_s = fit_classical(name, train, seed=0, max_train=args.max_train)
    t0 = time.perf_counter()
    model.predict_proba(held_out[:1])
    first = time.perf_counter() - t0
    frames = held_out[: min(len(held_out), 1000)]
    frame = _latency(model.predict_proba, frames, args.calls)
    x64 = held_out.astype(np.float64)
    sk_frame = _latency(lambda f: model.estimator.predict_proba(f.astype(np.float64)), frames, 200)
    one = np.concatenate([model.predict_proba(f[None]) for f in frames[:200]])
    want = model.estimator.predict_proba(x64[:200])
    diff = float(np.abs(one[:, model.estimator.classes_] - want).max())
    t0 = time.perf_counter()
    model.predict_proba(held_out[: args.batch])
    batch_s = time.perf_counter() - t0
    return {
        "path": _path(model),
        "n_train": used,
        "fit_s": fit_s,
        "first_frame_s": first,
        "frame": frame,
        "sklearn_frame": sk_frame,
        "batch_frames": int(min(args.batch, len(held_out))),
        "batch_s": batch_s,
        "max_abs_diff": diff,
    }


def _versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for pkg in ("scikit-learn", "skl2onnx", "onnxruntime", "onnx", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, help="write the results as JSON here")
    p.add_argument("--calls", type=int, default=2000, help="single-frame calls per model")
    p.add_argument("--batch", type=int, default=28_800, help="frames of the batch call")
    p.add_argument(
        "--max-train", type=int, default=None, help="training frames (default: MAX_TRAIN)"
    )
    p.add_argument(
        "--noise",
        type=float,
        default=0.2,
        help="noise of the synthetic frames (default 0.2: classes overlap, so the boosted trees "
        "grow to about their 31 leaves; 0.05 gives trees of about 18)",
    )
    p.add_argument("--only", nargs="*", choices=CLASSICAL, help="these candidates only")
    args = p.parse_args(argv)
    cpu = _pin_one_core()
    res: dict = {
        "machine": {
            "cpu_count": os.cpu_count(),
            "pinned_cpu": cpu,
            "python": platform.python_version(),
            "processor": platform.processor() or platform.machine(),
            "versions": _versions(),
            "loadavg_start": os.getloadavg(),
        },
        "args": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        "candidates": {},
    }
    train = touch_data(50_000, 1, args.noise)
    held_out = touch_data(max(args.batch, 1000), 2, args.noise).x
    with threadpool_limits(1):
        for name in args.only or CLASSICAL:
            r = bench_candidate(name, train, held_out, args)
            res["candidates"][name] = r
            print(
                f"{name:<14} one frame median {r['frame']['median_ms']:.3f} ms, "
                f"p99 {r['frame']['p99_ms']:.3f} ms ({r['path']}; first {r['first_frame_s']:.2f} s)"
                f" | scikit-learn {r['sklearn_frame']['median_ms']:.3f} ms"
                f" | batch of {r['batch_frames']} {r['batch_s']:.2f} s"
                f" | max |dp| {r['max_abs_diff']:.1e}",
                flush=True,
            )
    res["machine"]["loadavg_end"] = os.getloadavg()
    if args.out:
        args.out.write_text(json.dumps(res, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
