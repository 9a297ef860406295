"""``ectskin live`` as a user runs it: outputs that never destroy the input, one clear line on a
full disk, checks before any connection, SIGTERM/SIGHUP closing the recording, the dashboard
stopping after ``--duration``, partial recordings on request, and the help's examples."""

from __future__ import annotations

import errno
import io
import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from ectskin.cli import main
from ectskin.io.hdf5 import RecordingWriter, read_recording, write_recording
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.live import output as live_output

LAYOUT = default_layout()
P, M = LAYOUT.n_pairs, LAYOUT.n_markers


def _replay(path, n=90) -> str:
    rng = np.random.default_rng(0)
    trial = Trial("rest", 10 + 1e-3 * rng.standard_normal((n, P)), np.arange(n) / 30, np.zeros(n))
    write_recording(Recording(LAYOUT, [trial], 30.0), path)
    return str(path)


def _fast(src: str, *extra: str) -> list[str]:
    return ["live", "--source", f"replay:{src}", "--speed", "inf", "--policy", "block", *extra]


# ---------------------------------------------------------------------------- outputs
def test_jsonl_refuses_an_existing_file_without_overwrite(tmp_path, capsys):
    """--jsonl once overwrote an existing file without a flag."""
    src = _replay(tmp_path / "c.h5")
    out = tmp_path / "out.jsonl"
    out.write_text("earlier results\n")
    assert main(_fast(src, "--jsonl", str(out))) == 2
    assert f"--jsonl {out} exists; pass --overwrite to replace it" in capsys.readouterr().err
    assert out.read_text() == "earlier results\n"
    assert main(_fast(src, "--jsonl", str(out), "--overwrite")) == 0
    lines = out.read_text().splitlines()
    assert len(lines) == 90 and json.loads(lines[-1])["seq"] == 89


@pytest.mark.parametrize("option", ["--jsonl", "--record"])
def test_no_output_onto_the_file_being_replayed(tmp_path, capsys, option):
    """`live --source replay:c.h5 --jsonl c.h5` once turned the recording into
    JSON, and `--record X --force` destroyed X. Refused, even with --overwrite/--force."""
    src = _replay(tmp_path / "c.h5")
    before = open(src, "rb").read()
    for flag in ([], ["--overwrite"], ["--force"]):
        assert main(_fast(src, option, src, *flag)) == 2
        err = capsys.readouterr().err
        assert f"{option} '{src}' is the file the source 'replay:{src}' reads" in err
        assert "Traceback" not in err
    assert open(src, "rb").read() == before
    assert read_recording(src).n_frames == 90


def test_record_and_jsonl_onto_one_file_is_refused(tmp_path, capsys):
    src = _replay(tmp_path / "c.h5")
    both = str(tmp_path / "same")
    assert main(_fast(src, "--record", both, "--jsonl", both)) == 2
    assert "--record and --jsonl name the same file" in capsys.readouterr().err


class _FullDisk(io.StringIO):
    """A text file on a disk that fills up after ``room`` writes."""

    def __init__(self, room: int):
        super().__init__()
        self.room = room

    def write(self, text: str) -> int:
        if self.room <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= 1
        return super().write(text)


def test_jsonl_on_a_full_disk_is_one_clear_message(tmp_path, capsys, caplog, monkeypatch):
    """A full disk once gave an OSError traceback. Now one line, exit code 2, no partial
    file, and the engine stopped (not 90 failing callbacks)."""
    src = _replay(tmp_path / "c.h5")
    out = tmp_path / "out.jsonl"
    real_open = open

    def open_on_full_disk(path, *args, **kwargs):
        if str(path) == str(out):
            real_open(path, *args, **kwargs).close()  # the file exists, as a real one would
            return _FullDisk(room=5)
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(live_output, "open", open_on_full_disk, raising=False)
    with caplog.at_level("WARNING"):
        rc = main(_fast(src, "--jsonl", str(out)))
    err = capsys.readouterr().err
    assert rc == 2
    assert (
        f"ectskin live: error: --jsonl {out}: cannot write (No space left on device); stopped "
        "after 5 lines; removed the incomplete file" in err
    )
    assert "Traceback" not in err and not out.exists()
    assert not [r for r in caplog.records if r.exc_info]  # no logged traceback either


# ---------------------------------------------------------------------------- checks first
def test_reference_markers_are_checked_before_any_connection(tmp_path, capsys):
    """A bad --reference-markers file was once found only after a 10-s connection attempt."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # nothing listens there
    bad = tmp_path / "markers.txt"
    np.savetxt(bad, np.zeros((4, 3)))  # the layout has 5 markers
    t0 = time.monotonic()
    rc = main(["live", "--source", f"tcp:127.0.0.1:{port}", "--reference-markers", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and time.monotonic() - t0 < 3
    assert f"--reference-markers {bad}: expected (5, 3) marker coordinates in mm" in err
    assert "cannot connect" not in err
    bad.write_text("1 2\n3 4\n")
    assert main(["live", "--source", f"tcp:127.0.0.1:{port}", "--reference-markers", str(bad)]) == 2
    assert "expected (n_markers, 3)" in capsys.readouterr().err


def test_a_recording_as_source_suggests_replay(tmp_path, capsys):
    src = _replay(tmp_path / "c.h5")
    assert main(["live", "--source", src]) == 2
    assert f"to replay a recording, write replay:{src}" in capsys.readouterr().err


def test_allow_partial_replays_an_incomplete_recording(tmp_path, capsys):
    path = tmp_path / "crashed.h5"
    w = RecordingWriter(path, LAYOUT, 30.0)
    w.start_trial("rest", inflation=(0, 0, 0))
    w.append(np.full((40, P), 10.0), np.arange(40) / 30)
    w.close(complete=False)  # as a killed recorder leaves it
    assert main(_fast(str(path))) == 2
    capsys.readouterr()
    assert main(_fast(str(path), "--allow-partial", "--jsonl", "-")) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("{")]
    assert len(lines) == 40


def test_help_has_examples_and_the_reference_rule(capsys):
    with pytest.raises(SystemExit):
        main(["live", "--help"])
    text = capsys.readouterr().out
    assert "examples:\n  ectskin live --source sim --dashboard" in text
    assert "UNTOUCHED and UNINFLATED" in text
    for flag in ("--overwrite, --force", "--allow-partial", "--keep-serving", "--allow-host"):
        assert flag in text


# ---------------------------------------------------------------------------- real processes
def _cli(argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "ectskin.cli", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_live_record_is_closed_complete_on_sigterm_and_sighup(tmp_path, sig, spawn_cli):
    """Once, the recording of `live --record` was left incomplete by a signal."""
    src = _replay(tmp_path / "c.h5")
    out = tmp_path / "live.h5"
    argv = ["live", "--source", f"replay:{src}", "--loop", "--record", str(out)]
    proc, lines, seen, reader = spawn_cli(argv, "| touch")  # the first status line: frames are flowing
    try:
        assert seen.wait(60), "".join(lines)
        time.sleep(1.0)
        os.kill(proc.pid, sig)
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(timeout=5)
    assert rc == 0, "".join(lines)
    assert read_recording(out).n_frames > 10  # complete: no allow_partial needed
    assert any(f"{signal.Signals(sig).name} received" in ln for ln in lines)
    assert any(ln.startswith("final (interrupted)") for ln in lines)


def test_dashboard_stops_after_duration(tmp_path):
    """With --dashboard, live once kept serving after --duration ended."""
    src = _replay(tmp_path / "c.h5")
    argv = [
        "live",
        "--source",
        f"replay:{src}",
        "--loop",
        "--dashboard",
        "--port",
        "0",
        "--duration",
        "1.5",
    ]
    proc = _cli(argv)
    t0 = time.monotonic()
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "serving until the source ends or 1.5 s pass" in err
    assert "final (--duration 1.5 s passed)" in err and "dashboard stopped" in err
    assert time.monotonic() - t0 < 45
