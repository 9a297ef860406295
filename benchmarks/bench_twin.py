"""Benchmark: the full paper protocol in the digital twin (189 trials x 900 frames).

Target (issue 2): <= 90 s on a 2-core machine (>= 2,000 frames/s), peak memory < 2 GB.
Prints a table and writes JSON (``--out``). Run: ``.venv/bin/python benchmarks/bench_twin.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time

import numpy as np

from ectskin.layout import default_layout
from ectskin.twin import Protocol, SensorModel, Touch, simulate_experiment


def _peak_rss_mb() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, children) / 1024.0  # Linux: kB


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--levels", default="0,10,20")
    ap.add_argument("--out", default=None, help="write results as JSON here")
    args = ap.parse_args()

    sensor = SensorModel(default_layout())
    solve = []
    for _ in range(5):
        t0 = time.perf_counter()
        sensor.capacitance([10, 20, 0], Touch("front", (0.0, 60.0)), [1.0])
        solve.append(time.perf_counter() - t0)

    proto = Protocol(levels_ml=tuple(float(v) for v in args.levels.split(",")))
    t0 = time.perf_counter()
    rec = simulate_experiment(proto, workers=args.workers, progress=False)
    wall = time.perf_counter() - t0
    res = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "python": platform.python_version(),
        "workers": args.workers,
        "trials": rec.n_trials,
        "frames": rec.n_frames,
        "wall_s": round(wall, 2),
        "frames_per_s": round(rec.n_frames / wall, 1),
        "mom_solves": int(sum(t.meta["mom_solves"] for t in rec.trials)),
        "touch_solve_ms_median": round(1000 * float(np.median(solve)), 1),
        "panels_with_finger": int(
            sensor.electrode_panels([0, 0, 0], None, [0.0])[0].n_panels
            + sensor.finger_panels([0, 0, 0], Touch("front", (0.0, 60.0)), [1.0])[0].n_panels
        ),
        "peak_rss_mb": round(_peak_rss_mb(), 1),
        "load_avg_1min": os.getloadavg()[0],
    }
    for k, v in res.items():
        print(f"{k:24s} {v}")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
