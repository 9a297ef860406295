"""Benchmark: a small design sweep on a Dask LocalCluster of 1 and of 2 workers (wall time).

Each run scores the same layouts (the paper's and ``--layouts`` - 1 members of the family) from
scratch into a fresh folder; the machine's load average before and after each run is printed
with it, since the sweep competes with whatever else the machine runs. Prints JSON (and writes
it with ``--out``). Run: ``.venv/bin/python benchmarks/bench_design.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from ectskin.design.family import FaceDesign, LayoutDesign, build_layout
from ectskin.design.score import ScoreConfig, design_protocol
from ectskin.design.sweep import score_layouts

CANDIDATES = (
    LayoutDesign(FaceDesign(3), FaceDesign(3)),
    LayoutDesign(FaceDesign(5, 36.0, routing="fan"), FaceDesign(3)),
    LayoutDesign(FaceDesign(2, 20.0), FaceDesign(6, 36.0, routing="fan")),
    LayoutDesign(FaceDesign(4, order="outside_in"), FaceDesign(4, order="inside_out")),
    LayoutDesign(FaceDesign(6, 36.0, routing="fan"), FaceDesign(2, 20.0)),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--layouts", type=int, default=4, help="layouts per sweep, the paper's included"
    )
    ap.add_argument("--workers", default="1,2", help="worker counts timed")
    ap.add_argument("--out", default=None, help="write results as JSON here")
    args = ap.parse_args()
    n = max(1, min(args.layouts, len(CANDIDATES) + 1))
    named = [(f"cand{k}", build_layout(d, f"cand{k}")) for k, d in enumerate(CANDIDATES[: n - 1])]
    protocol = design_protocol(0, touch_trials=2, duration_s=2.0, touch_dwells=1, force_nodes=2)
    config = ScoreConfig(protocol=protocol, epochs={"touch": 5, "contact": 3, "track": 1})
    runs = []
    for w in (int(x) for x in args.workers.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            load0 = os.getloadavg()
            t0 = time.perf_counter()
            design = score_layouts(named, Path(tmp), config, n_workers=w, report=False)
            wall = time.perf_counter() - t0
            runs.append(
                {
                    "workers": w,
                    "layouts": len(design["layouts"]),
                    "wall_s": round(wall, 1),
                    "per_layout_s": [round(e["seconds"]["total"], 1) for e in design["layouts"]],
                    "load_before": [round(x, 2) for x in load0],
                    "load_after": [round(x, 2) for x in os.getloadavg()],
                }
            )
            print(json.dumps(runs[-1]), flush=True)
    result = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "protocol": {"trials": protocol.n_trials, "frames_per_trial": protocol.n_frames},
        "runs": runs,
    }
    if len(runs) >= 2:
        result["speedup"] = round(runs[0]["wall_s"] / runs[-1]["wall_s"], 2)
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()
