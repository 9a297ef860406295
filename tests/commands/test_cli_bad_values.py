"""Numbers outside their range give one clear error before any work, never a traceback or a
runaway: ``--seed`` of every command, the size of a simulated experiment, and the other counts,
durations and rates a newcomer or a bad-input probe may type (0, negative, NaN, huge)."""

from __future__ import annotations

import time

import pytest

from ectskin.cli import main
from ectskin.io import write_recording


def _cli(capsys, argv: list[str]) -> tuple[int, str]:
    """(exit status, stderr) of ``ectskin ARGV``: argparse's usage errors exit with 2."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


SEED_ARGV = [
    ["simulate", "-o", "{d}/s.h5"],
    ["train", "touch", "{d}/data.h5", "-o", "{d}/run"],
    ["evaluate", "{d}/run"],
    ["reproduce", "-o", "{d}/out"],
    ["demo", "-o", "{d}/out"],
    ["design", "score", "--out", "{d}/out"],
    ["design", "search", "{d}/out"],
    ["variability", "{d}/out"],
]


@pytest.mark.parametrize("seed", ["-1", "4294967296", "1.5", "x"])
@pytest.mark.parametrize("argv", SEED_ARGV, ids=lambda a: " ".join(a[:2]))
def test_every_seed_is_checked_as_a_usage_error_naming_the_range(tmp_path, capsys, argv, seed):
    """Defect 1: ``simulate --seed -1`` ended in numpy's "expected non-negative integer"
    traceback (train's split and evaluate's baselines the same). Catches a ``--seed`` declared
    with a bare ``type=int`` anywhere."""
    argv = [a.format(d=tmp_path) for a in argv] + ["--seed", seed]
    code, err = _cli(capsys, argv)
    assert code == 2
    assert f"argument --seed: must be an integer from 0 to 4294967295, got '{seed}'" in err
    assert not any(tmp_path.iterdir())  # nothing started


def test_an_oversized_simulation_is_refused_at_once_naming_its_size(tmp_path, capsys):
    """Defect 2: ``simulate --levels 0 --touch-trials 100000000 --duration 1`` printed nothing
    and grew in memory until killed. Now a documented bound, checked before any work: the
    message gives the size (trials x frames x per-frame values x 8 bytes). Catches removing the
    check (the command then plans 10^8 trials: minutes and gigabytes)."""
    out = tmp_path / "x.h5"
    t0 = time.perf_counter()
    code, err = _cli(
        capsys,
        ["simulate", "-o", str(out), "--levels", "0", "--touch-trials", "100000000",
         "--duration", "1", "--workers", "1", "--no-progress"],
    )
    assert time.perf_counter() - t0 < 10
    assert code == 2 and not out.exists()
    assert "100000001 trials (1 inflation state(s) x 100000001) x 30 frames" in err
    assert "x 8 bytes = 1072.9 GiB, held in memory" in err
    assert "at most 100000 trials and 4.0 GiB" in err
    assert "--touch-trials, --levels, --duration, --fps" in err
    # the bound is on the size too: few trials of very many frames
    code, err = _cli(
        capsys,
        ["simulate", "-o", str(out), "--levels", "0", "--touch-trials", "1", "--duration",
         "90000", "--fps", "1000", "--workers", "1"],
    )
    assert code == 2 and "2 trials" in err and "GiB, held in memory" in err and not out.exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "{o}", "--touch-trials", "-1"],
         "argument --touch-trials: must be an integer >= 0, got '-1'"),
        (["simulate", "{o}", "--dwells", "0"], "argument --dwells: must be an integer >= 1"),
        (["simulate", "{o}", "--dwells", "7", "--duration", "0.2"],
         "touch_dwells must be a whole number from 1 to the frames of a trial (6), got 7"),
        (["simulate", "{o}", "--duration", "0.01"], "holds 0.3 frames; it needs at least one"),
        (["simulate", "{o}", "--duration", "nan"], "duration_s and frame_rate_hz must be finite"),
        (["simulate", "{o}", "--levels", "nan"], "levels_ml must be finite volumes"),
        (["simulate", "{o}", "--levels", "0,20,0"], "levels_ml must be distinct"),
        (["simulate", "{o}", "--workers", "0"], "argument --workers: must be an integer >= 1"),
        (["train", "touch", "{o}", "-o", "{d}/r", "--epochs", "0"],
         "argument --epochs: must be an integer >= 1, got '0'"),
        (["train", "touch", "{o}", "-o", "{d}/r", "--batch-size", "-3"],
         "argument --batch-size: must be an integer >= 1"),
        (["train", "track", "{o}", "-o", "{d}/r", "--window", "0"],
         "argument --window: must be an integer >= 1"),
        (["train", "touch", "{o}", "-o", "{d}/r", "--threads", "0"],
         "argument --threads: must be an integer >= 1"),
        (["reproduce", "{d}/r", "--epochs", "-1"], "argument --epochs: must be an integer >= 1"),
        (["characterize", "{d}/c", "--force-n", "nan"],
         "--force-n must be a touch force > 0 and at most 13.3 N"),
        (["characterize", "{d}/c", "--force-n", "-1"], "--force-n must be a touch force > 0"),
        (["import", "capacitance", "{o}", "--resample-hz", "1e12"],
         "argument --resample-hz: must be a finite number > 0 and <= 10000, got '1e12'"),
        (["import", "build", "--capacitance", "{o}", "-o", "{d}/b.h5", "--max-delay", "1e9"],
         "argument --max-delay: must be a finite number > 0 and <= 60"),
        (["variability", "{d}/v", "--threads", "0"],
         "--threads must be an integer >= 1 or 'auto', got '0'"),
        (["design", "score", "--out", "{d}/s", "--duration", "nan"],
         "argument --duration: must be a finite number > 0, got 'nan'"),
    ],
)
def test_bad_numbers_are_one_clear_error_before_any_work(tmp_path, capsys, argv, message):
    """Defect 7: among these, ``characterize --force-n nan`` drew Fig. 3 before failing in the
    rod solver, ``import --resample-hz 1e12`` and ``--max-delay 1e9`` ended in numpy's
    MemoryError traceback, ``variability --threads 0`` simulated every skin first, and
    ``simulate --dwells 100`` or ``--levels 0,0`` were accepted."""
    argv = [a.format(o=tmp_path / "o.h5", d=tmp_path) for a in argv]
    code, err = _cli(capsys, argv)
    assert code == 2 and message in err, err
    assert not any(tmp_path.iterdir())


def test_a_window_too_large_for_memory_is_refused_naming_its_size(tmp_path, capsys, make_recording):
    """Defect 7: ``train track --window 100000000`` built windows of the whole recording padded
    to 10^8 frames (numpy's MemoryError, or the machine swapping). Catches removing the bound."""
    data = tmp_path / "data.h5"
    write_recording(make_recording(n_frames=40, occluded=(), no_markers=()), data)
    for task in ("track", "contact"):
        code, err = _cli(
            capsys, ["train", task, str(data), "-o", str(tmp_path / task), "--window", "100000000"]
        )
        assert code == 2
        assert "--window 100000000: 320 frames x 100000000 frames per window x 28 pairs" in err
        assert "at most 8 GiB" in err and not (tmp_path / task).exists()
