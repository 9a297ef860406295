"""Training and inference speed of the paper's models on this machine.

(a) TouchMLP, profile ``paper`` (100 epochs, batch 256, validation every epoch) through
    :func:`ectskin.learn.train.train` on 112 500 synthetic training frames x 28 pairs (the demo
    data set's size) and 28 800 validation frames: wall time.
(b) C2DT training throughput (samples/s) with the ``paper`` settings (batch 255, Adam) through the
    real epoch loop :func:`ectskin.learn.train.train_one_epoch`, and evaluation throughput.
(c) Single-sample inference latency of TouchPredictor and TrackPredictor with
    ``torch.set_num_threads(1)``: median and p99 over ``--calls`` calls.

Usage::

    python benchmarks/bench_train.py --out bench_train.json [--threads 1] [--touch-epochs 100]

Numbers on a shared 2-core machine depend on what else runs; the JSON records the load average
before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from ectskin.layout import default_layout
from ectskin.learn.checkpoint import save_checkpoint
from ectskin.learn.data import TouchData
from ectskin.learn.distributed import Dist
from ectskin.learn.engine import Tensors, epoch_indices, evaluate, train_one_epoch
from ectskin.learn.models import C2DT, C2DTConfig, TouchMLP
from ectskin.learn.predict import TouchPredictor, TrackPredictor
from ectskin.learn.tasks import TrackCriterion
from ectskin.learn.threads import TRAIN_DEFAULT_THREADS, torch_threads
from ectskin.learn.train import TrainConfig, train


def touch_data(n: int, seed: int) -> TouchData:
    rng = np.random.default_rng(seed)
    centres = np.random.default_rng(0).normal(0, 0.2, size=(19, 28))
    y = rng.integers(0, 19, n)
    x = centres[y] + 0.05 * rng.standard_normal((n, 28))
    per = 900
    group = np.arange(n) // per
    return TouchData(
        x.astype(np.float32),
        y.astype(np.int64),
        group.astype(np.int64),
        [f"t{g}" for g in range(group.max() + 1)],
        19,
        list(default_layout().pair_names),
    )


def bench_touch_training(epochs: int, n_train: int, n_val: int, threads: int | None) -> dict:
    tr, va = touch_data(n_train, 1), touch_data(n_val, 2)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        s = train(
            "touch",
            tr,
            va,
            Path(tmp) / "run",
            TrainConfig(profile="paper", epochs=epochs, progress=False, threads=threads),
        )
        wall = time.perf_counter() - t0
    return {
        "epochs": epochs,
        "n_train": n_train,
        "n_val": n_val,
        "wall_s": wall,
        "train_loop_s": s["seconds_total"],
        "s_per_epoch": s["seconds_per_epoch"],
        "best_val_accuracy": s["best_val_metric"],
    }


def bench_c2dt_training(steps: int, batch: int = 255) -> dict:
    layout = default_layout()
    torch.manual_seed(0)
    model = C2DT(C2DTConfig(), layout.electrode_descriptors(), layout.pairs)
    n = steps * batch
    rng = np.random.default_rng(0)
    x = torch.from_numpy((0.05 * rng.standard_normal((n, 10, 28))).astype(np.float32))
    init = torch.from_numpy(rng.normal(0, 30, (n, 5, 3)).astype(np.float32))
    y = init + torch.from_numpy(rng.normal(0, 2, (n, 5, 3)).astype(np.float32))
    data = Tensors((x, init, y))
    opt = torch.optim.Adam(model.parameters(), lr=1e-3, fused=True)
    task = TrackCriterion(model)
    d = Dist()
    warm = epoch_indices(n, 0, 0)[: 3 * batch]
    train_one_epoch(model, task, opt, data, warm, batch, epoch=0, d=d)
    idx = epoch_indices(n, 1, 0)
    t0 = time.perf_counter()
    train_one_epoch(model, task, opt, data, idx, batch, epoch=1, d=d)
    dt = time.perf_counter() - t0
    t0 = time.perf_counter()
    evaluate(model, task, data, torch.arange(n), 2048, d)
    de = time.perf_counter() - t0
    return {
        "batch": batch,
        "samples": n,
        "train_samples_per_s": n / dt,
        "eval_samples_per_s": n / de,
        "paper_epoch_s_for_72000_windows": 72000 / (n / dt),
    }


def _latency(fn, calls: int) -> dict:
    for _ in range(50):
        fn()
    t = np.empty(calls)
    for i in range(calls):
        t0 = time.perf_counter()
        fn()
        t[i] = time.perf_counter() - t0
    return {
        "median_ms": float(np.median(t) * 1e3),
        "p99_ms": float(np.percentile(t, 99) * 1e3),
        "calls": calls,
    }


def bench_latency(calls: int) -> dict:
    layout = default_layout()
    with torch_threads(1):
        with tempfile.TemporaryDirectory() as tmp:
            save_checkpoint(Path(tmp) / "touch.pt", TouchMLP())
            save_checkpoint(
                Path(tmp) / "c2dt.pt",
                C2DT(C2DTConfig(), layout.electrode_descriptors(), layout.pairs),
            )
            touch = TouchPredictor.from_run(Path(tmp) / "touch.pt")
            track = TrackPredictor.from_run(Path(tmp) / "c2dt.pt")
        rng = np.random.default_rng(0)
        frame = rng.normal(0, 0.1, 28).astype(np.float32)
        window = rng.normal(0, 0.1, (10, 28)).astype(np.float32)
        init = rng.normal(0, 30, (5, 3)).astype(np.float32)
        return {
            "threads": 1,
            "touch_mlp": _latency(lambda: touch.predict(frame), calls),
            "c2dt": _latency(lambda: track.predict(window, init), calls),
        }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, help="write the results as JSON here")
    p.add_argument(
        "--threads",
        type=int,
        default=TRAIN_DEFAULT_THREADS,
        help=f"torch threads for training (default {TRAIN_DEFAULT_THREADS}, as ectskin.learn.train)",
    )
    p.add_argument("--touch-epochs", type=int, default=100)
    p.add_argument("--touch-frames", type=int, default=112_500)
    p.add_argument("--c2dt-steps", type=int, default=40, help="batches of 255 to time")
    p.add_argument("--calls", type=int, default=2000, help="inference calls per model")
    args = p.parse_args(argv)
    with torch_threads(args.threads):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    res = {
        "machine": {
            "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "torch": torch.__version__,
            "python": platform.python_version(),
            "processor": platform.processor() or platform.machine(),
            "loadavg_start": os.getloadavg(),
        },
    }
    print(
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"load average {os.getloadavg()[0]:.2f}",
        flush=True,
    )
    res["touch_training"] = bench_touch_training(
        args.touch_epochs, args.touch_frames, 28_800, args.threads
    )
    res["c2dt_training"] = bench_c2dt_training(args.c2dt_steps)
    res["latency"] = bench_latency(args.calls)
    res["machine"]["loadavg_end"] = os.getloadavg()
    t, c, lat = res["touch_training"], res["c2dt_training"], res["latency"]
    rows = [
        (
            "(a) TouchMLP paper profile",
            f"{t['epochs']} epochs x {t['n_train']} frames",
            f"{t['wall_s']:.1f} s wall ({t['s_per_epoch']:.2f} s/epoch)",
        ),
        (
            "(b) C2DT training, batch 255",
            f"{c['samples']} windows",
            f"{c['train_samples_per_s']:.0f} samples/s (eval {c['eval_samples_per_s']:.0f}/s)",
        ),
        (
            "(c) TouchMLP latency, 1 thread",
            f"{lat['touch_mlp']['calls']} calls",
            f"median {lat['touch_mlp']['median_ms']:.3f} ms, p99 {lat['touch_mlp']['p99_ms']:.3f} ms",
        ),
        (
            "(c) C2DT latency, 1 thread",
            f"{lat['c2dt']['calls']} calls",
            f"median {lat['c2dt']['median_ms']:.3f} ms, p99 {lat['c2dt']['p99_ms']:.3f} ms",
        ),
    ]
    w0, w1 = max(len(r[0]) for r in rows), max(len(r[1]) for r in rows)
    for a, b, cc in rows:
        print(f"{a:<{w0}}  {b:<{w1}}  {cc}")
    if args.out:
        args.out.write_text(json.dumps(res, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
