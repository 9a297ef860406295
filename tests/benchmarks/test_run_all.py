"""`make bench` runs benchmarks/run_all.py, which runs every benchmark (here with --quick sizes)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_make_bench_runs_a_script_that_exists():
    makefile = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^bench:.*\n((?:\t.*\n)+)", makefile, re.M)
    assert recipe, "Makefile has no bench target"
    scripts = re.findall(r"(benchmarks/\S+\.py)", recipe.group(1))
    assert scripts, f"the bench recipe names no benchmark script: {recipe.group(1)!r}"
    for s in scripts:
        assert (ROOT / s).is_file(), f"make bench runs {s}, which does not exist"


@pytest.mark.slow
def test_every_benchmark_runs_at_quick_sizes(tmp_path):
    out = tmp_path / "bench"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run_all.py"), "--quick", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    # every benchmark script in benchmarks/ is run (a new one left out of run_all.py fails here)
    assert set(summary) == {p.stem for p in (ROOT / "benchmarks").glob("bench_*.py")}
    for name in summary:
        assert json.loads((out / f"{name}.json").read_text()), f"{name} wrote no results"
