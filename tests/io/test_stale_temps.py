"""Hidden ``.NAME.tmp-PID`` files left by killed runs are removed by later writes of the same
target, but only those whose process is gone (issue 12, smaller items)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from ectskin._files import remove_stale_temps, write_json_atomic
from ectskin.io.hdf5 import RecordingWriter, write_recording


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _temps(target):
    dead = target.with_name(f".{target.name}.tmp-{_dead_pid()}")
    alive = target.with_name(f".{target.name}.tmp-{os.getppid()}")  # the test runner's parent
    other = target.with_name(f".other.h5.tmp-{_dead_pid()}")  # another target's: not ours
    for p in (dead, alive, other):
        p.write_bytes(b"half a file")
    return dead, alive, other


def test_write_recording_removes_stale_temps_only(tmp_path, make_recording):
    out = tmp_path / "r.h5"
    dead, alive, other = _temps(out)
    write_recording(make_recording(n_frames=3), out)
    assert not dead.exists()
    assert alive.exists() and other.exists()


def test_recording_writer_removes_stale_temps(tmp_path, layout):
    out = tmp_path / "live.h5"
    dead, alive, _ = _temps(out)
    with RecordingWriter(out, layout, 30.0) as w:
        w.start_trial("t")
        w.append(np.ones(layout.n_pairs), 0.0)
    assert not dead.exists() and alive.exists()


def test_atomic_json_removes_stale_temps(tmp_path):
    out = tmp_path / "metrics.json"
    dead, alive, _ = _temps(out)
    write_json_atomic(out, {"a": 1})
    assert not dead.exists() and alive.exists()


def test_remove_stale_temps_ignores_odd_names(tmp_path):
    out = tmp_path / "r.h5"
    odd = tmp_path / ".r.h5.tmp-notapid"
    odd.write_text("x")
    assert remove_stale_temps(out) == []
    assert odd.exists()
    assert remove_stale_temps(tmp_path / "missing" / "r.h5") == []  # no folder: nothing to do
