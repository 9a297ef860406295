"""Benchmark: training-free ECT images — Jacobian per deformation state, reconstruction per frame.

Prints JSON (and writes it with ``--out``). Run: ``.venv/bin/python benchmarks/bench_ect.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np

from ectskin.electrostatics import METHODS, Reconstructor
from ectskin.layout import default_layout
from ectskin.twin import EctImager, SensorModel, ect_grid, sensitivity


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=3, help="inflation states timed")
    ap.add_argument("--frames", type=int, default=2000, help="frames reconstructed per method")
    ap.add_argument("--out", default=None, help="write results as JSON here")
    args = ap.parse_args()

    layout = default_layout()
    sensor = SensorModel(layout)
    grid = ect_grid(layout)
    states = [[0.0, 0.0, 0.0], [10.0, 20.0, 0.0], [20.0, 20.0, 20.0]][: max(1, args.states)]
    jac = []
    for s in states:
        t0 = time.perf_counter()
        sens = sensitivity(sensor, grid, s, kind="conductor")
        jac.append(time.perf_counter() - t0)
    rng = np.random.default_rng(0)
    dc = -np.abs(rng.normal(scale=0.01, size=(args.frames, layout.n_pairs)))
    per_frame = {}
    batched = {}
    for m in METHODS:
        r = Reconstructor.build(sens.jacobian, m, row_scale=sens.readout, response_sign=1)
        n = min(args.frames, 200 if m == "landweber" else args.frames)
        t0 = time.perf_counter()
        for k in range(n):
            r.image(dc[k])
        per_frame[m] = 1e6 * (time.perf_counter() - t0) / n
        t0 = time.perf_counter()
        r.image(dc)
        batched[m] = 1e6 * (time.perf_counter() - t0) / args.frames
    imager = EctImager(layout, states[0], sensor=sensor, grid=grid)
    t0 = time.perf_counter()
    for k in range(args.frames):
        imager.locate(dc[k])
    locate_us = 1e6 * (time.perf_counter() - t0) / args.frames
    res = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "python": platform.python_version(),
        "n_voxels": grid.n_voxels,
        "n_pixels": grid.n_pixels,
        "jacobian_s_per_state": [round(t, 3) for t in jac],
        "reconstruct_us_per_frame": {m: round(v, 1) for m, v in per_frame.items()},
        "reconstruct_us_per_frame_batched": {m: round(v, 2) for m, v in batched.items()},
        "imager_locate_us_per_frame": round(locate_us, 1),
        "load_avg_1min": os.getloadavg()[0],
    }
    print(json.dumps(res, indent=1))
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
