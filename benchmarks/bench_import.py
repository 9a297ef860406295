"""Benchmark: import time of a large capacitance-meter export and a large Motive take.

Writes two synthetic files (``--rows`` rows each) into a temporary folder: a readout export with
a time column in s, 28 channels in fF and their relative-change columns (a few ``OL`` and empty
cells, one dead channel), and a Motive take (a rigid body, five markers, an unlabeled marker, some
occlusions). Times ``read_capmeter_csv`` and ``read_motive_csv`` (best of ``--repeat``) and prints
JSON (and writes it with ``--out``). Run: ``.venv/bin/python benchmarks/bench_import.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from ectskin.io.capmeter import read_capmeter_csv
from ectskin.io.motive import read_motive_csv

N_CHANNELS = 28
MARKERS = ("Skin:M1", "Skin:M2", "Skin:M3", "Skin:M4", "Skin:M5")


def write_capmeter(path: Path, n_rows: int, seed: int = 0) -> None:
    """Time [s], then per channel ``Cij [fF]`` and ``Cij dC/C [%]``; a few masked cells."""
    rng = np.random.default_rng(seed)
    names = [f"C{i}-{j}" for i in range(1, 9) for j in range(i + 1, 9)][:N_CHANNELS]
    ref = rng.uniform(500.0, 1500.0, N_CHANNELS)
    vals = ref * (1 + 0.01 * rng.standard_normal((n_rows, N_CHANNELS)))
    rel = 100 * (vals / ref - 1)
    header = "Time [s]," + ",".join(f"{n} [fF],{n} dC/C [%]" for n in names)
    out = ["Instrument,bench,", "Exported,2024-01-01 00:00:00,", header]
    masked = rng.random((n_rows, N_CHANNELS)) < 1e-3
    for k in range(n_rows):
        cells = [f"{k / 30:.5f}"]
        for j in range(N_CHANNELS):
            if j == 5:
                cells += ["OL", "OL"]  # a dead channel
            elif masked[k, j]:
                cells += ["", ""]
            else:
                cells += [f"{vals[k, j]:.4f}", f"{rel[k, j]:.4f}"]
        out.append(",".join(cells))
    path.write_text("\n".join(out) + "\n", encoding="utf-8")


def write_motive(path: Path, n_rows: int, seed: int = 0) -> None:
    """A Motive 1.23 export at 120 frames/s in meters; markers occluded now and then."""
    rng = np.random.default_rng(seed)
    types = ["Rigid Body"] * 7 + ["Marker"] * (3 * len(MARKERS) + 3)
    names = ["Base"] * 7 + [m for m in MARKERS for _ in range(3)] + ["Unlabeled 7"] * 3
    comps = ["Rotation"] * 4 + ["Position"] * (len(names) - 4)
    axes = ["X", "Y", "Z", "W", "X", "Y", "Z"] + ["X", "Y", "Z"] * (len(MARKERS) + 1)
    out = [
        "Format Version,1.23,Take Name,bench,Capture Frame Rate,120.000000,Export Frame Rate,"
        "120.000000,Length Units,Meters",
        "",
        ",Type," + ",".join(types),
        ",Name," + ",".join(names),
        ",," + ",".join(comps),
        "Frame,Time (Seconds)," + ",".join(axes),
    ]
    pos = rng.uniform(-0.1, 0.1, (n_rows, len(names)))
    occluded = rng.random((n_rows, len(MARKERS) + 1)) < 0.01
    for k in range(n_rows):
        cells = [str(k), f"{k / 120:.6f}"] + [f"{v:.6f}" for v in pos[k]]
        for m in range(len(MARKERS) + 1):
            if occluded[k, m]:
                cells[9 + 3 * m : 12 + 3 * m] = ["", "", ""]
        out.append(",".join(cells))
    path.write_text("\r\n".join(out) + "\r\n", encoding="utf-8")


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000, help="data rows per file")
    ap.add_argument("--repeat", type=int, default=3, help="timed reads per file (best kept)")
    ap.add_argument("--out", default=None, help="write results as JSON here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        cap, mocap = Path(d) / "readout.csv", Path(d) / "take.csv"
        write_capmeter(cap, args.rows)
        write_motive(mocap, args.rows)
        result = {
            "rows": args.rows,
            "capmeter_MB": round(cap.stat().st_size / 1e6, 1),
            "motive_MB": round(mocap.stat().st_size / 1e6, 1),
            "read_capmeter_csv_s": round(best_of(lambda: read_capmeter_csv(cap), args.repeat), 3),
            "read_motive_csv_s": round(best_of(lambda: read_motive_csv(mocap), args.repeat), 3),
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load_avg": os.getloadavg()[0],
        }
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
