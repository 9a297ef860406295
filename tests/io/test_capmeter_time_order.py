"""Capacitance-meter exports whose time stamps repeat or step back (``time_order``), and
resampling onto a uniform grid (``resample_hz``).

The files are built in each test; the expected times are worked out by hand in the comments.
Before ``time_order``, every such file was refused ("time ... does not increase").
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io.align import build_recording
from ectskin.io.capmeter import read_capmeter_csv
from ectskin.io.capmeter.timing import monotone_times
from ectskin.layout import default_layout

# Rows 0..8 on lines 2..10. Row 4 (line 6) steps back from 0.3 to 0.2; row 6 (line 8) repeats 0.4.
T_FILE = [0.0, 0.1, 0.2, 0.3, 0.2, 0.4, 0.4, 0.5, 0.6]


def _write(path, times, values=None, *, header="Time [s],C12 [pF],C13 [pF]"):
    """One row per time stamp; C12 = 1 + row / 10 tells the rows apart, C13 = 2 + row / 100."""
    n = len(times)
    if values is None:
        values = np.stack([1 + np.arange(n) / 10, 2 + np.arange(n) / 100], axis=1)
    rows = [header] + [
        f"{t}," + ",".join("" if np.isnan(v) else repr(float(v)) for v in vals)
        for t, vals in zip(times, values)
    ]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_default_file_order_rederives_repeats_and_steps_back(tmp_path, caplog):
    """time_order="file": row 4 (0.2 after 0.3) lies between the new maxima 0.3 (row 3) and 0.4
    (row 5): 0.35; row 6 (0.4 again) between 0.4 (row 5) and 0.5 (row 7): 0.45. The other rows
    keep their stamps; the rows keep their order."""
    p = _write(tmp_path / "jitter.csv", T_FILE)
    with caplog.at_level("WARNING"):
        cap = read_capmeter_csv(p)
    np.testing.assert_allclose(
        cap.timestamps, [0.0, 0.1, 0.2, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6], rtol=0, atol=1e-12
    )
    np.testing.assert_array_equal(cap.lines, np.arange(2, 11))
    np.testing.assert_array_equal(cap.values[:, 0], 1 + np.arange(9) / 10)  # file order
    assert cap.timing == {
        "time_order": "file",
        "steps_back": 1,
        "repeats": 1,
        "first_lines": [6, 8],
        "retimed": 2,
    }
    assert "1 step(s) back and 1 repeat(s), first at line(s) 6, 8" in caplog.text
    assert any("time stamps out of order" in n for n in cap.mask_report.notes)
    assert cap.mask_report.to_dict()["notes"] == cap.mask_report.notes


def test_sort_orders_rows_by_time_stamp(tmp_path):
    """time_order="sort": the stable order of 0, .1, .2, .3, .2, .4, .4, .5, .6 is rows
    0, 1, 2, 4, 3, 5, 6, 7, 8; the stamps 0.2 (row 4) and 0.4 (row 6) then repeat the one before
    and are placed halfway to the next: 0.25 and 0.45."""
    p = _write(tmp_path / "jitter.csv", T_FILE)
    cap = read_capmeter_csv(p, time_order="sort")
    order = [0, 1, 2, 4, 3, 5, 6, 7, 8]
    np.testing.assert_allclose(
        cap.timestamps, [0.0, 0.1, 0.2, 0.25, 0.3, 0.4, 0.45, 0.5, 0.6], rtol=0, atol=1e-12
    )
    np.testing.assert_array_equal(cap.values[:, 0], 1 + np.array(order) / 10)
    np.testing.assert_array_equal(cap.lines, np.array(order) + 2)
    assert cap.timing["time_order"] == "sort" and cap.timing["retimed"] == 2
    assert cap.timing["steps_back"] == 1 and cap.timing["repeats"] == 1


def test_strict_refuses_or_skips_as_before(tmp_path):
    p = _write(tmp_path / "jitter.csv", T_FILE)
    with pytest.raises(
        EctskinError,
        match=r"jitter\.csv: line 6: time column 'Time \[s\]': time '0.2' does not increase "
        r"\(previous frame, line 5: '0.3'\)",
    ):
        read_capmeter_csv(p, time_order="strict")
    # not strict: lines 6 (0.2 ≤ 0.3) and 8 (0.4 ≤ 0.4) are skipped, the other 7 kept
    cap = read_capmeter_csv(p, time_order="strict", strict=False)
    np.testing.assert_array_equal(cap.lines, [2, 3, 4, 5, 7, 9, 10])
    assert [line for line, _ in cap.mask_report.skipped_rows] == [6, 8]
    assert cap.timing == {}


def test_rows_after_the_last_new_maximum_continue_at_the_median_interval(tmp_path):
    """Stamps 1.300, 1.377, 1.455, 1.377, 1.455 (the meter's clock stepped back 78 ms and the file
    ends before it catches up): the last two rows follow 1.455 at the median positive interval,
    median(0.077, 0.078, 0.078) = 0.078: 1.533, 1.611."""
    p = _write(tmp_path / "tail.csv", [1.300, 1.377, 1.455, 1.377, 1.455])
    cap = read_capmeter_csv(p)
    np.testing.assert_allclose(
        cap.timestamps, [1.300, 1.377, 1.455, 1.533, 1.611], rtol=0, atol=1e-12
    )
    assert cap.timing["steps_back"] == 1 and cap.timing["repeats"] == 0
    assert cap.timing["retimed"] == 2 and cap.timing["first_lines"] == [5]


def test_monotone_times_against_hand_cases():
    t, retimed = monotone_times(np.array([0.0, 0.1, 0.2]))
    np.testing.assert_array_equal(t, [0.0, 0.1, 0.2])
    assert not retimed.any()
    # two rows stuck at 1.0 between 1.0 and 1.3: 1.1 and 1.2
    t, retimed = monotone_times(np.array([0.9, 1.0, 1.0, 1.0, 1.3]))
    np.testing.assert_allclose(t, [0.9, 1.0, 1.1, 1.2, 1.3], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(retimed, [False, False, True, True, False])


def test_a_time_stamp_that_never_increases_is_refused(tmp_path):
    p = _write(tmp_path / "stuck.csv", [5.0, 5.0, 5.0])
    for order in ("file", "sort"):
        with pytest.raises(EctskinError, match=r"stuck\.csv: .*never increases \(lines 2 to 4\)"):
            read_capmeter_csv(p, time_order=order)


def test_unknown_time_order_and_bad_resample_rate_are_refused(tmp_path):
    p = _write(tmp_path / "ok.csv", [0.0, 0.1])
    with pytest.raises(EctskinError, match=r"'time_order': allowed values are 'file', 'sort'"):
        read_capmeter_csv(p, time_order="fix")
    for hz in (0, -5.0, float("nan")):
        with pytest.raises(EctskinError, match=r"resample_hz must be a number > 0"):
            read_capmeter_csv(p, resample_hz=hz)


def test_resampling_a_linear_ramp_gives_the_ramp(tmp_path):
    """Irregular stamps (and one step back, re-derived first): every channel a linear function
    of the frame time; on the 20 Hz grid t0 + k / 20 the result is the same function."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.02, 0.09, 60)) + 3.0
    t = np.round(t, 4)
    stamps = list(t)
    stamps[30] = stamps[28]  # a step back: re-derived as halfway between rows 29 and 31
    p = tmp_path / "ramp.csv"
    times = t.copy()
    times[30] = (t[29] + t[31]) / 2  # where the reader will put row 30
    values = np.stack([1.0 + 0.5 * times, 2.0 - 1.5 * times], axis=1)
    _write(p, stamps, values)
    cap = read_capmeter_csv(p, resample_hz=20.0)
    n = int(np.floor((t[-1] - t[0]) * 20 + 1e-9)) + 1
    grid = t[0] + np.arange(n) / 20.0
    np.testing.assert_allclose(cap.timestamps, grid, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cap.values[:, 0], 1.0 + 0.5 * grid, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(cap.values[:, 1], 2.0 - 1.5 * grid, rtol=1e-12, atol=1e-12)
    assert cap.frame_rate_hz == 20.0 and cap.timing["resampled_hz"] == 20.0
    assert cap.timing["retimed"] == 1
    # each grid frame names the line of the row at or before it
    src = np.searchsorted(times, grid, side="right") - 1
    np.testing.assert_array_equal(cap.lines, src + 2)


def test_resampling_does_not_bridge_a_masked_cell(tmp_path):
    """Rows at 0, 0.1, 0.2, 0.3 s; C13 masked on row 2. At 40 Hz the grid is 0, 0.025, ...,
    0.3: the grid times in (0.1, 0.3) draw on row 2 and are NaN; 0.1 and 0.3 are rows themselves
    and keep their values."""
    values = np.array([[1.0, 2.0], [1.1, 2.1], [1.2, np.nan], [1.3, 2.3]])
    p = _write(tmp_path / "gap.csv", [0.0, 0.1, 0.2, 0.3], values)
    cap = read_capmeter_csv(p, resample_hz=40.0)
    assert cap.n_frames == 13
    nan = np.isnan(cap.values[:, 1])
    np.testing.assert_array_equal(np.flatnonzero(nan), np.arange(5, 12))
    assert cap.values[4, 1] == pytest.approx(2.1) and cap.values[12, 1] == pytest.approx(2.3)
    assert np.isfinite(cap.values[:, 0]).all()


def test_recording_meta_records_the_repair(tmp_path):
    layout = default_layout()
    names = [f"C{i + 1}{j + 1}" for i, j in layout.pairs]
    n = 12
    times = [k / 30 for k in range(n)]
    times[6] = times[4]  # a step back of two frames
    values = 1.0 + np.arange(n * len(names)).reshape(n, -1) / 1000
    p = _write(tmp_path / "cap.csv", times, values, header="Time [s]," + ",".join(
        f"{nm} [pF]" for nm in names))
    rec = build_recording(read_capmeter_csv(p), None, layout)
    timing = rec.trials[0].meta["timing"]
    assert timing["steps_back"] == 1 and timing["first_lines"] == [8]
    assert np.all(np.diff(rec.trials[0].timestamps) > 0)


def _cli(argv):
    from ectskin.commands import import_

    parser = argparse.ArgumentParser(prog="ectskin import")
    import_.add_arguments(parser)
    return import_.run(parser.parse_args(argv))


def test_cli_time_order_and_resample(tmp_path, capsys):
    p = _write(tmp_path / "jitter.csv", T_FILE)
    assert _cli(["capacitance", str(p)]) == 0
    out = capsys.readouterr().out
    assert "9 frames" in out and "time stamps out of order: 1 step(s) back" in out
    assert _cli(["capacitance", str(p), "--time-order", "sort", "--resample-hz", "20"]) == 0
    out = capsys.readouterr().out
    assert "13 frames" in out and "20.000 frames/s" in out and "resampled to 13" in out
    with pytest.raises(EctskinError, match="does not increase"):
        _cli(["capacitance", str(p), "--time-order", "strict"])
    with pytest.raises(EctskinError, match="--time-order, --resample-hz describe one trial"):
        _cli(["build", "--manifest", str(tmp_path / "m.json"), "--time-order", "sort",
              "--resample-hz", "30", "-o", str(tmp_path / "o.h5")])
