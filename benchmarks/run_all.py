"""Run every benchmark in turn and collect their JSON results (``make bench``).

Usage::

    python benchmarks/run_all.py [--out bench-results] [--quick]

Each benchmark runs in its own process (one at a time: they measure speed, so they must not share
the cores) and writes ``OUT/<name>.json``; ``OUT/summary.json`` lists what ran, its exit code and
its wall time. ``--quick`` passes smaller sizes, for checking that the benchmarks still run; the
figures in ``BENCHMARKS.md`` come from full runs. The exit code is non-zero if any benchmark
failed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: name → (script, extra arguments of a full run, extra arguments of a --quick run)
BENCHMARKS = {
    "bench_twin": ("bench_twin.py", [], ["--levels", "0", "--workers", "1"]),
    "bench_train": (
        "bench_train.py",
        [],
        ["--touch-epochs", "2", "--touch-frames", "5000", "--c2dt-steps", "3", "--calls", "50"],
    ),
    "bench_live": (
        "bench_live.py", [], ["--frames", "500", "--paced-seconds", "1", "--fields", "synthetic"]
    ),
    "bench_inversion": (
        "bench_inversion.py", [], ["--frames", "10", "--streams", "1", "--stream", "5"]
    ),
    "bench_ect": ("bench_ect.py", [], ["--states", "1", "--frames", "200"]),
    "bench_live_person": (
        "bench_live_person.py", ["--synthetic"], ["--synthetic", "--people", "2", "--frames", "15"]
    ),
    "bench_design": ("bench_design.py", [], ["--layouts", "1", "--workers", "1"]),
    "bench_candidates": (
        "bench_candidates.py",
        [],
        ["--calls", "200", "--batch", "2000", "--max-train", "2000"],
    ),
    "bench_import": ("bench_import.py", [], ["--rows", "2000", "--repeat", "1"]),
    "bench_field_grid": (
        "bench_field_grid.py",
        [],
        ["--v-window", "50,54", "--fine", "2,2", "--du", "2,4", "--dv", "2,4", "--nodes", "4",
         "--points", "3", "--workers", "1"],
    ),
    "bench_batched_solve": (
        "bench_batched_solve.py",
        ["--build"],
        ["--devices", "numpy,cpu", "--rows", "1", "--fine-v", "1", "--repeat", "1"],
    ),
    "bench_placement": ("bench_placement.py", ["--build"], ["--rows", "1"]),
    "bench_field": (
        "bench_field.py",
        [],
        ["--levels", "0", "--spacing", "4,4", "--window=-2,6,50,58", "--checks", "4",
         "--workers", "1", "--rigid-checks", "1"],
    ),
}


def run(out: Path, quick: bool, only: list[str] | None) -> int:
    out.mkdir(parents=True, exist_ok=True)
    summary = {}
    failed = 0
    for name, (script, full_args, quick_args) in BENCHMARKS.items():
        if only and name not in only:
            continue
        cmd = [sys.executable, str(HERE / script), "--out", str(out / f"{name}.json")]
        cmd += quick_args if quick else full_args
        print(f"== {name}: {' '.join(cmd[1:])}", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call(cmd)
        summary[name] = {"rc": rc, "seconds": round(time.perf_counter() - t0, 1), "cmd": cmd[1:]}
        failed += rc != 0
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("bench-results"))
    ap.add_argument("--quick", action="store_true", help="small sizes: check they run")
    ap.add_argument("--only", nargs="*", choices=sorted(BENCHMARKS), help="run only these")
    args = ap.parse_args(argv)
    return run(args.out, args.quick, args.only)


if __name__ == "__main__":
    sys.exit(main())
