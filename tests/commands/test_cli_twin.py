"""`ectskin simulate` and `ectskin characterize`: files written, and one clear error for bad input."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ectskin.cli import main
from ectskin.io.hdf5 import read_recording


def test_simulate_writes_a_readable_recording(tmp_path, capsys):
    out = tmp_path / "d.h5"
    args = ["simulate", str(out), "--levels", "0,15", "--touch-trials", "2", "--duration", "1",
            "--dwells", "1", "--workers", "1", "--no-progress", "--seed", "4"]
    assert main(args) == 0
    rec = read_recording(out)
    assert rec.n_trials == 8 * 3 and rec.trials[0].n_frames == 30
    assert {t.inflation for t in rec.trials} >= {(0.0, 0.0, 0.0), (15.0, 15.0, 15.0)}
    assert rec.meta["protocol"]["seed"] == 4
    # nothing recorded is overwritten silently; the message names the flag
    assert main(args) == 2
    assert "file exists; use --overwrite" in capsys.readouterr().err


def test_simulate_output_and_overwrite_options(tmp_path, capsys):
    """-o/--out (the positional OUT kept as an alias) and --overwrite (alias --force)."""
    out = tmp_path / "d.h5"
    small = ["--levels", "0", "--touch-trials", "1", "--duration", "0.2", "--dwells", "1",
             "--workers", "1", "--no-progress"]
    assert main(["simulate", "-o", str(out), *small]) == 0
    first = out.read_bytes()
    assert main(["simulate", "--out", str(out), *small, "--seed", "1"]) == 2
    assert "use --overwrite" in capsys.readouterr().err and out.read_bytes() == first
    assert main(["simulate", str(out), "--force", *small, "--seed", "1"]) == 0  # old spellings
    assert out.read_bytes() != first
    assert main(["simulate", str(out), "-o", str(tmp_path / "x.h5"), *small]) == 2
    assert "two outputs given" in capsys.readouterr().err
    assert main(["simulate", *small]) == 2
    assert "give -o/--out PATH" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "{out}", "--levels", "0,45"], "impossible inflation for chamber 1: 45.0 ml"),
        (["simulate", "{out}", "--levels", "-5"], "impossible inflation"),
        (["simulate", "{out}", "--levels", "a,b"], "--levels must be comma-separated numbers"),
        (["simulate", "{out}", "--snr-db", "nan"], "readout: gain_snr_db must be a finite number"),
        (["simulate", "{out}", "--fps", "inf"], "frame_rate_hz"),
        (["simulate", "{out}", "--push-max", "-1"], "push_max_n must be a finite number >= 0"),
        (["simulate", "{out}", "--finger-radius", "0"], "finger_radius_mm"),
        (["simulate", "{out}", "--layout", "{bad}"], "not valid JSON"),
        (["characterize", "{dir}", "--region", "25"], "unknown region 25"),
        (["characterize", "{dir}", "--inflation", "20,20"], "one volume per chamber"),
    ],
)
def test_bad_input_gives_one_clear_error(tmp_path, capsys, argv, message):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    argv = [a.format(out=tmp_path / "o.h5", bad=bad, dir=tmp_path / "c") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err and err.count("\n") == 1


@pytest.mark.slow
def test_characterize_writes_figures_and_json(tmp_path):
    assert main(["characterize", str(tmp_path), "--region", "5"]) == 0
    assert (tmp_path / "fig3_inflation.png").stat().st_size > 10_000
    assert (tmp_path / "fig4_touch.png").stat().st_size > 10_000
    res = json.loads((tmp_path / "characterize.json").read_text())
    assert len(res["pairs"]) == 28 and len(res["touches"]) == 18
    pair = res["pairs"][0]
    assert set(pair) == {
        "pair", "electrodes", "same_face", "standing_pf", "noise_ff", "snr_db", "inflation_change"
    }
    assert min(p["snr_db"] for p in res["pairs"]) > 60.0  # the paper's readout, every pair
    assert res["readout"]["output_step_ff"] < min(p["noise_ff"] for p in res["pairs"])
    assert len(res["touches"][4]["change"]) == 28
    assert np.isfinite(res["inflation_change_max_abs"])


# ------------------------------------------------------------------ workers die with the driver
def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = open(f"/proc/{entry}/stat").read()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry))
    return out


def _running(pid: int) -> bool:
    """The process exists and is not a zombie (a zombie has ended; its parent did not reap it)."""
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_killed_simulate_leaves_no_worker_alive(tmp_path, sig):
    """Issue 12, defect 9: before, the two workers of a killed `simulate --workers 2` ran on
    for good (blocked on a task queue whose pipe they hold open themselves)."""
    argv = [sys.executable, "-m", "ectskin", "simulate", "-o", str(tmp_path / "s.h5"),
            "--workers", "2", "--duration", "30", "--no-progress"]
    # the driver gets SIGINT's default disposition, as from a terminal: a test earlier in the
    # same pytest process may leave SIGINT ignored, and a child inherits that
    proc = subprocess.Popen(
        argv,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            workers = _children(proc.pid)
        assert len(workers) >= 2, "the workers did not start"
        time.sleep(1.0)  # let them get to work
        os.kill(proc.pid, sig)
        proc.wait(timeout=60)
        deadline = time.monotonic() + 15
        while any(_running(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        alive = [w for w in workers if _running(w)]
        assert alive == [], f"workers {alive} outlived the killed driver"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for w in workers:  # never leave the workers this test started behind
            if _running(w):
                os.kill(w, signal.SIGKILL)
