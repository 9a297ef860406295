"""Instrument import: capacitance-meter CSV, OptiTrack Motive CSV, clock alignment, CLI.

Fixtures in tests/data/instruments are hand-made; the expected values below were written down
from the files by hand (see the comments in each test), not produced by the reader.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from ectskin import cli
from ectskin._check import EctskinError
from ectskin.io import hdf5
from ectskin.io.align import (
    build_recording,
    build_recording_from_manifest,
    estimate_delay,
    interp_linear,
    lagged_fit,
    normalised_xcorr,
    resample_markers,
)
from ectskin.io.capmeter import (
    canonical_pair_order,
    parse_clock,
    parse_pair_name,
    read_capmeter_csv,
)
from ectskin.io.motive import read_motive_csv
from ectskin.io.text import parse_number
from ectskin.layout import default_layout

DATA = Path(__file__).parents[1] / "data" / "instruments"
CAP_BOM = DATA / "capmeter_bom_fF.csv"
CAP_SEMI = DATA / "capmeter_semicolon_clock.csv"
CAP_TWO_ROW = DATA / "capmeter_two_row_header.csv"
MOTIVE = DATA / "motive_meters_30fps.csv"


def _copy_with(tmp_path: Path, src: Path, old: str, new: str, count: int = 1) -> Path:
    """A copy of ``src`` with the first ``count`` occurrences of ``old`` replaced by ``new``."""
    raw = src.read_bytes()
    text = raw.decode("utf-8-sig")
    assert old in text, f"fixture {src.name} lacks {old!r}"
    out = tmp_path / src.name
    bom = raw.startswith(b"\xef\xbb\xbf")
    out.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.replace(old, new, count).encode())
    return out


# =========================================================================== capacitance meter
def test_capmeter_bom_multirow_header_fF_and_masks():
    d = read_capmeter_csv(CAP_BOM, n_pairs=3)
    assert d.channels == ("C12", "C13", "C23")
    assert d.units == ("fF", "fF", "fF")
    assert d.meta["Instrument"] == "ECT-Eval 8ch (fw 2.4)"
    # Time [ms] column: 0, 33.3, 66.7, 100, 133.3, 166.7, 200, 233.3 ms
    np.testing.assert_allclose(
        d.timestamps, [0, 0.0333, 0.0667, 0.1, 0.1333, 0.1667, 0.2, 0.2333], rtol=0, atol=1e-12
    )
    # fF -> pF: 1520.4 fF = 1.5204 pF (line 5), 985.9 fF = 0.9859 pF (line 12, padded cells)
    assert d.values[0, 0] == pytest.approx(1.5204, abs=1e-12)
    assert d.values[0, 1] == pytest.approx(0.9802, abs=1e-12)
    assert d.values[7, 1] == pytest.approx(0.9859, abs=1e-12)
    # masked cells, by hand from the file: C12 empty on line 10; C13 OL on lines 7 and 11, NaN on
    # line 8; C23 '-' on line 9 (frames are lines 5..12)
    expect = np.zeros((8, 3), dtype=bool)
    expect[5, 0] = True
    expect[[2, 3, 6], 1] = True
    expect[4, 2] = True
    np.testing.assert_array_equal(np.isnan(d.values), expect)
    assert not np.any(d.values[~expect] == 0.0)  # never turned into zeros
    rep = d.mask_report.channels
    assert rep["C12"].counts == {"empty": 1} and rep["C12"].first_lines == [10]
    assert rep["C13"].counts == {"OL": 2, "NaN": 1} and rep["C13"].first_lines == [7, 8, 11]
    assert rep["C23"].counts == {"-": 1} and rep["C23"].first_lines == [9]
    assert d.mask_report.n_masked == 5
    summary = d.mask_report.summary()
    assert "C13: 3 masked (OL: 2, NaN: 1), first at line(s) 7, 8, 11" in summary
    # the dC/C columns agree with the values: cross-checked, no mismatch
    assert all(c.relative_checked and c.relative_mismatch == 0 for c in rep.values())
    np.testing.assert_array_equal(d.pairs, [[1, 2], [1, 3], [2, 3]])
    np.testing.assert_array_equal(d.lines, np.arange(5, 13))


def test_capmeter_semicolon_decimal_comma_units_row_clock_midnight_and_pair_order():
    d = read_capmeter_csv(CAP_SEMI)
    # file order E1-E2;E3-E4;E1-E3;E2-E4;E1-E4;E2-E3 -> ECT order (1,2),(1,3),(1,4),(2,3)...
    assert d.channels == ("E1-E2", "E1-E3", "E1-E4", "E2-E3", "E2-E4", "E3-E4")
    np.testing.assert_array_equal(d.pairs, [[1, 2], [1, 3], [1, 4], [2, 3], [2, 4], [3, 4]])
    # first data row (line 5): E1-E2 1,5204  E3-E4 1,4877  E1-E3 0,4012  E2-E4 0,3988 ...
    np.testing.assert_allclose(d.values[0], [1.5204, 0.4012, 0.2110, 0.6021, 0.3988, 1.4877])
    # 23:59:59,900 .. 00:00:00.033 crosses midnight: 0, 33, 67, 100, 133 ms
    np.testing.assert_allclose(d.timestamps, [0, 0.033, 0.067, 0.100, 0.133], atol=1e-9)
    assert d.meta["clock_start"] == "23:59:59,900"
    assert d.mask_report.channels["E1-E3"].counts == {"OL": 1}
    assert d.mask_report.channels["E1-E3"].first_lines == [7]
    assert d.mask_report.channels["E1-E4"].first_lines == [8]
    assert np.isnan(d.values[2, 1]) and np.isnan(d.values[3, 2])
    # pair_order="file" keeps the columns as written
    f = read_capmeter_csv(CAP_SEMI, pair_order="file")
    assert f.channels[:3] == ("E1-E2", "E3-E4", "E1-E3")
    assert f.pairs is None
    np.testing.assert_array_equal(f.values[:, 1], d.values[:, 5])


def test_capmeter_utf16_and_cp1252_text(tmp_path):
    text = CAP_BOM.read_bytes().decode("utf-8-sig")
    p16 = tmp_path / "u16.csv"
    p16.write_bytes(text.encode("utf-16"))  # with BOM, as Excel's "Unicode text" export
    d16 = read_capmeter_csv(p16)
    ref = read_capmeter_csv(CAP_BOM)
    np.testing.assert_array_equal(d16.values, ref.values)
    # Windows-1252 with a temperature column (°C): the column is not a capacitance and is ignored
    rows = ["Gerät;Messbrücke", "Zeit [s];T [°C];C12 [pF]", "0,0;21,5;1,25", "0,1;21,5;1,26"]
    pcp = tmp_path / "cp.csv"
    pcp.write_bytes("\r\n".join(rows).encode("cp1252"))
    d = read_capmeter_csv(pcp)
    assert d.channels == ("C12",)
    np.testing.assert_allclose(d.values[:, 0], [1.25, 1.26])
    np.testing.assert_allclose(d.timestamps, [0.0, 0.1])


def test_parse_helpers_against_hand_cases():
    assert parse_number("  980.2 ", False) == 980.2
    assert parse_number("1 520.4", False) == 1520.4  # thousands grouped with a space
    assert parse_number("12 34", False) is None  # not a thousands grouping
    assert parse_number("1,5", True) == 1.5 and parse_number("1,5", False) is None
    assert parse_number("1.234,5", True) is None
    assert parse_number("OL", False) is None
    assert parse_number("-1.5e-3", False) == -1.5e-3
    assert parse_clock("23:59:59.900")[0] == pytest.approx(86399.9)
    assert parse_clock("00:00:01,5")[0] == pytest.approx(1.5)
    assert parse_clock("2024-03-02 01:00:00.000")[1].day == 2
    assert parse_clock("25:00:00") is None and parse_clock("12.5") is None
    assert parse_pair_name("C12") == (1, 2)
    assert parse_pair_name("E3-E1") == (1, 3)
    assert parse_pair_name("C 1_10") == (1, 10)
    assert parse_pair_name("CH1") is None and parse_pair_name("C11") is None
    assert canonical_pair_order(["C13", "C12", "C23"])[1].tolist() == [1, 0, 2]
    assert canonical_pair_order(["C12", "C13"]) is None  # not all pairs of 3 electrodes
    assert canonical_pair_order(["CH01", "CH02", "CH03"]) is None


def test_capmeter_relative_change_mismatch_is_reported_not_fatal(tmp_path):
    # line 8: C12 = 1525.0 fF with dC/C 0.302 %; make it 3.302 % (inconsistent with C/C_ref)
    p = _copy_with(tmp_path, CAP_BOM, "100.0,1525.0,0.302,", "100.0,1525.0,3.302,")
    d = read_capmeter_csv(p)
    c = d.mask_report.channels["C12"]
    assert c.relative_mismatch == 1 and c.relative_first_lines == [8]
    assert "relative-change column disagrees" in d.mask_report.summary()
    assert d.values[3, 0] == pytest.approx(1.525)  # the value column is kept


def test_capmeter_ms_time_without_unit_needs_time_unit(tmp_path):
    p = _copy_with(tmp_path, CAP_BOM, "Time [ms],", "Time,")
    with pytest.raises(EctskinError, match=r"states no unit.*time_unit"):
        read_capmeter_csv(p)
    d = read_capmeter_csv(p, time_unit="ms")
    assert d.timestamps[1] == pytest.approx(0.0333)
    with pytest.raises(EctskinError, match="time_unit='s' was passed"):
        read_capmeter_csv(CAP_BOM, time_unit="s")


@pytest.mark.parametrize(
    ("old", "new", "pattern"),
    [
        # a row with a missing cell: file, line and the expected count
        ("66.7,1523.4,0.197,OL,OL,1208.8,-0.099,", "66.7,1523.4,0.197,OL,1208.8,-0.099",
         r"capmeter_bom_fF\.csv: line 7: expected 8 cells \(as in the header on line 4\), found 6"),
        # a garbage cell: file, line, column and channel
        ("133.3,1526.1,0.375,983.4,", "133.3,1526.1,0.375,98x3.4,",
         (r"capmeter_bom_fF\.csv: line 9: column 4 \(channel 'C13', 'C13 \[fF\]'\): expected a "
         r"number or a missing-value marker .* found '98x3.4'")),
        # an unparseable time
        ("233.3,1530.2", "2x3.3,1530.2", r"line 12: time column 'Time \[ms\]': expected a number"),
        # a channel column with no unit
        ("C23 [fF],", "C23,", r"column 6 'C23' \(header line 4\) has no unit.*value_unit"),
        # a relative-change column whose channel has no value column
        ("C23 [fF],C23 dC/C [%]", "C23 [V],C24 dC/C [%]",
         r"column 7 'C24 dC/C \[%\]' is a relative change of channel 'C24', but no capacitance"),
        # two columns for one channel
        ("C23 [fF]", "C12 [fF]", r"channel 'C12' appears twice \(columns 2 and 6\)"),
        # no header at all
        ("Time [ms]", "Zeitpunkt", r"no header row found"),
    ],
)
def test_capmeter_malformed_inputs_name_file_line_and_channel(tmp_path, old, new, pattern):
    p = _copy_with(tmp_path, CAP_BOM, old, new)
    with pytest.raises(EctskinError, match=pattern):
        read_capmeter_csv(p)


def test_capmeter_time_going_backwards_is_refused_with_time_order_strict(tmp_path):
    """time_order="strict" keeps the error that was the only behaviour before (the default,
    "file", now imports such a file: tests/io/test_capmeter_time_order.py)."""
    p = _copy_with(tmp_path, CAP_BOM, "200.0,1528.8", "150.0,1528.8")
    with pytest.raises(EctskinError, match=(
        r"line 11: time column 'Time \[ms\]': time '150.0' does not increase \(previous frame, "
        r"line 10: '166.7'\)")):
        read_capmeter_csv(p, time_order="strict")


def test_capmeter_non_strict_skips_and_reports(tmp_path):
    p = _copy_with(tmp_path, CAP_BOM, "66.7,1523.4,0.197,OL,OL,1208.8,-0.099,",
                   "66.7,1523.4,0.197,OL,1208.8,-0.099")
    p.write_text(p.read_text(encoding="utf-8-sig").replace("983.4", "98x3.4"), encoding="utf-8")
    d = read_capmeter_csv(p, strict=False)
    assert d.n_frames == 7  # line 7 skipped
    assert [line for line, _ in d.mask_report.skipped_rows] == [7]
    assert "expected 8 cells" in d.mask_report.skipped_rows[0][1]
    c13 = d.mask_report.channels["C13"]
    # the OL of the skipped line 7 is not counted; line 9's garbage is masked as 'invalid'
    assert c13.counts == {"NaN": 1, "invalid": 1, "OL": 1}
    assert c13.first_lines == [8, 9, 11]
    assert "line 7 skipped" in d.mask_report.summary()


def test_capmeter_channel_count_check_and_empty_file(tmp_path):
    with pytest.raises(EctskinError, match=r"expected 28 capacitance channels .* found 3: C12"):
        read_capmeter_csv(CAP_BOM, n_pairs=28)
    empty = tmp_path / "empty.csv"
    empty.write_bytes(b"\xef\xbb\xbf\r\n")
    with pytest.raises(EctskinError, match=r"empty\.csv: the file is empty"):
        read_capmeter_csv(empty)
    with pytest.raises(EctskinError, match="cannot read capacitance-meter"):
        read_capmeter_csv(tmp_path / "missing.csv")
    nodata = _copy_with(tmp_path, CAP_BOM, "0,1520.4", "x")
    text = nodata.read_text(encoding="utf-8-sig").splitlines()[:4]
    nodata.write_text("\r\n".join(text), encoding="utf-8")
    with pytest.raises(EctskinError, match="no data rows after the header on line 4"):
        read_capmeter_csv(nodata)


def test_capmeter_metadata_row_starting_with_time_is_not_the_header(tmp_path):
    p = tmp_path / "tz.csv"
    p.write_text("Time zone,UTC+1\nTime [s],C12 [pF]\n0.0,1.0\n0.1,1.1\n", encoding="utf-8")
    d = read_capmeter_csv(p)
    assert d.meta == {"Time zone": "UTC+1"} and d.channels == ("C12",)


# =========================================================================== Motive
def test_motive_meters_occlusions_and_type_selection():
    d = read_motive_csv(MOTIVE)
    # Type == Marker, labelled only (Unlabeled 1042 and the rigid body are left out)
    assert d.marker_names == ("Skin:M1", "Skin:M2", "Skin:M3")
    assert d.units == "Meters" and d.frame_rate_hz == 30.0
    assert d.meta["Take Name"] == "touch_017"
    np.testing.assert_allclose(d.timestamps, np.round(np.arange(10) / 30, 6), atol=1e-12)
    np.testing.assert_array_equal(d.frame_numbers, np.arange(10))
    # frame 0 (line 8): 0.025,0.000000,0.024 m etc. -> mm
    np.testing.assert_allclose(d.positions[0], [[25, 0, 24], [25, 0, 48], [25, 0, 72]], atol=1e-9)
    # frame 9, Skin:M3 y = 0.004500 m = 4.5 mm
    assert d.positions[9, 2, 1] == pytest.approx(4.5, abs=1e-9)
    # occluded (empty cells): Skin:M2 at frames 3, 4 (lines 11, 12), Skin:M3 at frame 7 (line 15)
    occluded = np.zeros((10, 3), dtype=bool)
    occluded[[3, 4], 1] = True
    occluded[7, 2] = True
    np.testing.assert_array_equal(np.isnan(d.positions).any(axis=2), occluded)
    np.testing.assert_array_equal(np.isnan(d.positions).all(axis=2), occluded)
    assert d.occlusions["Skin:M2"].first_lines == [11, 12]
    assert d.occlusions["Skin:M3"].n_occluded == 1
    assert "Skin:M2: occluded in 2 of 10 frames, first at line(s) 11, 12" in d.summary()


def test_motive_select_by_name_and_unlabeled():
    d = read_motive_csv(MOTIVE, marker_names=["M3", "Base:Marker1"])
    assert d.marker_names == ("Skin:M3", "Base:Marker1")
    # the rigid-body marker: 0.001250,-0.002080,0.000010 m
    np.testing.assert_allclose(d.positions[0, 1], [1.25, -2.08, 0.01], atol=1e-9)
    with pytest.raises(EctskinError, match=r"marker 'M9' is not in the file; markers with "
                                           r"positions: Base, Base:Marker1, Skin:M1"):
        read_motive_csv(MOTIVE, marker_names=["M9"])
    u = read_motive_csv(MOTIVE, include_unlabeled=True)
    assert u.marker_names[-1] == "Unlabeled 1042"
    assert np.isnan(u.positions[5:, 3]).all() and not np.isnan(u.positions[:5, 3]).any()


def test_motive_length_units(tmp_path):
    ref = read_motive_csv(MOTIVE)
    cm = read_motive_csv(
        _copy_with(tmp_path, MOTIVE, "Length Units,Meters", "Length Units,Centimeters")
    )
    np.testing.assert_allclose(cm.positions, ref.positions / 100, equal_nan=True)
    p = _copy_with(tmp_path, MOTIVE, ",Length Units,Meters", "")
    with pytest.raises(EctskinError, match=r"no 'Length Units' field; give the unit "
                                           r"\(length_units='Meters'.*--length-units"):
        read_motive_csv(p)
    np.testing.assert_allclose(
        read_motive_csv(p, length_units="Meters").positions, ref.positions, equal_nan=True
    )
    with pytest.raises(EctskinError, match="Length Units 'Inches' is not supported"):
        read_motive_csv(_copy_with(tmp_path, MOTIVE, "Length Units,Meters", "Length Units,Inches"))


def test_motive_partly_empty_marker_counts_as_occluded(tmp_path):
    # frame 2 (line 10): blank only Skin:M1's X
    line10 = MOTIVE.read_bytes().decode().split("\r\n")[9]
    cells = line10.split(",")
    cells[14] = ""  # Skin:M1 X is column 15
    p = _copy_with(tmp_path, MOTIVE, line10, ",".join(cells))
    d = read_motive_csv(p)
    assert np.isnan(d.positions[2, 0]).all()
    assert d.occlusions["Skin:M1"].n_partial == 1 and d.occlusions["Skin:M1"].first_lines == [10]


@pytest.mark.parametrize(
    ("old", "new", "pattern"),
    [
        ("0.025000,0.000500,0.072000", "0.025000,abc,0.072000",
         (r"motive_meters_30fps\.csv: line 9: column 22 \(marker 'Skin:M3', Y\): expected a number "
         r"or an empty cell \(occluded\), found 'abc'")),
        ("\r\n5,0.166667,", "\r\n5,0.166667,0,", (r"line 13: expected 26 cells \(as in the column "
                                                   r"header on line 7\), found 27")),
        ("\r\n4,0.133333,", "\r\n4,0.033333,", (r"line 12: column 2 \(Time \(Seconds\)\): time "
                                               r"0.033333 s does not increase")),
        ("\r\n4,0.133333,", "\r\nfour,0.133333,",
         r"line 12: column 1 \(Frame\): expected an integer"),
        ("Format Version", "Format", (r"not a Motive CSV export: line 1 should start with 'Format "
                                     r"Version'")),
        ("Frame,Time (Seconds)", "Fr,Time (Seconds)", r"no column header row starting with 'Frame"),
        (",Name,", ",Label,", r"no ',Name,\.\.\.' row"),
        ("Export Frame Rate,30.000000", "Export Frame Rate,fast",
         r"Export Frame Rate must be a number"),
    ],
)
def test_motive_malformed_inputs_name_file_line_and_column(tmp_path, old, new, pattern):
    with pytest.raises(EctskinError, match=pattern):
        read_motive_csv(_copy_with(tmp_path, MOTIVE, old, new))


def test_motive_non_strict_skips_bad_rows(tmp_path):
    p = _copy_with(tmp_path, MOTIVE, "0.025000,0.000500,0.072000", "0.025000,abc,0.072000")
    d = read_motive_csv(p, strict=False)
    assert d.n_frames == 9 and [ln for ln, _ in d.skipped_rows] == [9]
    np.testing.assert_array_equal(d.frame_numbers, [0, 2, 3, 4, 5, 6, 7, 8, 9])
    assert "line 9 skipped" in d.summary()


# =========================================================================== alignment
def _reference_resample(mt, mp, ft, delay, max_gap):
    """Slow, obvious version of resample_markers: loops over frames and markers."""
    out = np.full((len(ft), mp.shape[1], 3), np.nan)
    for f, t in enumerate(ft):
        tau = t + delay
        for m in range(mp.shape[1]):
            vis = [k for k in range(len(mt)) if np.all(np.isfinite(mp[k, m]))]
            on = [k for k in vis if abs(mt[k] - tau) <= 1e-9]
            if on:
                out[f, m] = mp[on[0], m]
                continue
            before = [k for k in vis if mt[k] < tau]
            after = [k for k in vis if mt[k] > tau]
            if not before or not after:
                continue
            a, b = before[-1], after[0]
            if b - a - 1 > max_gap:
                continue
            w = (tau - mt[a]) / (mt[b] - mt[a])
            out[f, m] = (1 - w) * mp[a, m] + w * mp[b, m]
    return out


def test_resample_markers_exact_on_linear_trajectory():
    rng = np.random.default_rng(1)
    mt = 0.37 + np.arange(240) / 120.0  # 2 s at 120 Hz, its own start
    a = rng.normal(0, 50, (1, 4, 3))
    b = rng.normal(0, 20, (1, 4, 3))
    mp = a + b * mt[:, None, None]
    ft = np.sort(rng.uniform(0.2, 2.6, 50))  # irregular readout frames, some outside the take
    delay = 0.0123
    got = resample_markers(mt, mp, ft, delay)
    tau = ft + delay
    inside = (tau >= mt[0]) & (tau <= mt[-1])
    np.testing.assert_allclose(got[inside], (a + b * tau[:, None, None])[inside], rtol=0, atol=1e-9)
    assert np.isnan(got[~inside]).all() and (~inside).any() and inside.sum() > 30


def test_resample_markers_gaps_match_slow_reference():
    rng = np.random.default_rng(2)
    mt = np.arange(60) / 30.0
    mp = rng.normal(0, 10, (60, 3, 3))
    mp[10, 0] = np.nan  # a one-frame gap: bridged with max_gap_frames=1
    mp[20:23, 1] = np.nan  # three frames: never bridged
    mp[40, 2, 1] = np.nan  # one coordinate missing: the marker counts as occluded there
    ft = np.concatenate([mt[5:50], np.sort(rng.uniform(0, 2, 40))])
    ft = np.unique(ft)
    for delay in (0.0, 0.05, -1 / 30):
        for gap in (0, 1, 3):
            got = resample_markers(mt, mp, ft, delay, max_gap_frames=gap)
            ref = _reference_resample(mt, mp, ft, delay, gap)
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12, equal_nan=True)
    # spot checks by hand: at the occluded sample time itself
    t10 = np.array([mt[10]])
    assert np.isnan(resample_markers(mt, mp, t10, 0.0, max_gap_frames=0)[0, 0]).all()
    np.testing.assert_allclose(
        resample_markers(mt, mp, t10, 0.0, max_gap_frames=1)[0, 0], (mp[9, 0] + mp[11, 0]) / 2
    )
    assert np.isnan(resample_markers(mt, mp, np.array([mt[21]]), 0.0, max_gap_frames=1)[0, 1]).all()


def test_interp_linear_and_xcorr_against_references():
    t = np.array([0.0, 1.0, 2.0, 4.0])
    y = np.array([0.0, 10.0, np.nan, 40.0])
    got = interp_linear(t, y, np.array([-1, 0.0, 0.5, 1.0, 1.5, 3.0, 4.0, 5.0]))
    np.testing.assert_array_equal(got[[1, 2, 3, 6]], [0.0, 5.0, 10.0, 40.0])
    assert np.isnan(got[[0, 4, 5, 7]]).all()
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=200), rng.normal(size=200)
    a[rng.random(200) < 0.1] = np.nan
    lags, r, counts = normalised_xcorr(a, b, 7, 8)
    for lag, rv, c in zip(lags, r, counts):
        x = a[max(0, -lag): 200 - max(0, lag)]
        y2 = b[max(0, lag): 200 + min(0, lag)]
        ok = np.isfinite(x) & np.isfinite(y2)
        assert c == ok.sum()
        assert rv == pytest.approx(np.corrcoef(x[ok], y2[ok])[0, 1], abs=1e-12)


def _synthetic_session(delay_s, *, mocap_hz=30.0, seed=0, noise_mm=0.2, duration_s=30.0,
                       occlude=True):
    """Readout (28 channels) and markers (5) of one touch trial; the markers lag by ``delay_s``.

    A smooth random press force f(t) moves some channels (gain per channel) and bends the body
    (tip displacement up to ~10 mm), seen by the markers ``delay_s`` later.
    """
    rng = np.random.default_rng(seed)
    fine = np.arange(-2, duration_s + 2, 0.001)
    force = np.zeros_like(fine)
    for _ in range(8):
        force += rng.uniform(0.1, 0.5) * np.sin(
            2 * np.pi * rng.uniform(0.05, 0.8) * fine + rng.uniform(0, 2 * np.pi)
        )
    force = np.maximum(force, 0.0)
    cap_t = np.arange(0, duration_s, 1 / 30)
    gains = rng.normal(0, 1, 28) * (rng.random(28) < 0.5)  # half the pairs see the touch
    base = rng.uniform(0.2, 2.0, 28)
    cap = base * (1 + 0.02 * gains * np.interp(cap_t, fine, force)[:, None])
    cap += base * 1e-3 * rng.normal(size=cap.shape)  # 60 dB
    mk_t = np.arange(0, duration_s, 1 / mocap_hz)
    z = np.array([24.0, 48.0, 72.0, 96.0, 120.0])
    bend = 5.0 * np.interp(mk_t - delay_s, fine, force)  # what the readout saw delay_s earlier
    truth = np.zeros((len(mk_t), 5, 3))
    truth[:, :, 0] = 25.0
    truth[:, :, 1] = bend[:, None] * (z / 120.0) ** 2
    truth[:, :, 2] = z
    pos = truth + noise_mm * rng.normal(size=truth.shape)
    if occlude:
        pos[100:130, 4] = np.nan
        pos[rng.random(len(mk_t)) < 0.02, 2] = np.nan
    return cap_t, cap, mk_t, pos, truth


def test_lagged_fit_matches_lstsq_reference():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(120, 4))
    y = rng.normal(size=(120, 2, 3))
    y[:, 0] += x[:, :3] @ rng.normal(size=(3, 3))  # marker 0 depends on x
    x[rng.random(120) < 0.05, 1] = np.nan
    y[rng.random(120) < 0.05, 1] = np.nan
    lags, r, counts = lagged_fit(x, y, 3, 10, ridge=0.0)
    for lag, rv, c in zip(lags, r, counts):
        sse = sst = 0.0
        n_max = 0
        for m in range(2):
            rows = [n for n in range(120) if 0 <= n + lag < 120
                    and np.isfinite(x[n]).all() and np.isfinite(y[n + lag, m]).all()]
            a = np.column_stack([np.ones(len(rows)), x[rows]])
            b = y[[n + lag for n in rows], m]
            beta = np.linalg.lstsq(a, b, rcond=None)[0]
            sse += ((b - a @ beta) ** 2).sum()
            sst += ((b - b.mean(0)) ** 2).sum()
            n_max = max(n_max, len(rows))
        assert c == n_max
        assert rv == pytest.approx(np.sqrt(1 - sse / sst), abs=1e-10)


@pytest.mark.parametrize("method", ["regression", "energy"])
@pytest.mark.parametrize(
    ("delay_s", "mocap_hz"),
    [(0.1, 30.0), (-0.1, 30.0), (0.05, 120.0), (0.2, 120.0), (0.0, 30.0)],
)
def test_estimate_delay_recovers_injected_delay_within_half_a_frame(delay_s, mocap_hz, method):
    cap_t, cap, mk_t, pos, _ = _synthetic_session(delay_s, mocap_hz=mocap_hz, seed=7)
    est = estimate_delay(cap_t, cap, mk_t, pos, max_delay_s=0.5, method=method)
    assert abs(est.delay_s - delay_s) < 0.5 / 30, est
    assert est.method == method and est.score > 0.3 and est.contrast > 0.2 and not est.at_bound
    # the score curve peaks where the estimate says
    assert abs(est.lags_s[np.nanargmax(est.scores)] - est.delay_s) <= est.grid_dt_s


@pytest.mark.parametrize("method", ["regression", "energy"])
def test_estimate_delay_sub_frame_resolution(method):
    # 0.0123 s is 0.37 frame at 30 fps: the integer-lag peak alone would be 12.3 ms off; the
    # parabolic refinement must get within 4 ms on signals without marker noise
    cap_t, cap, mk_t, _pos, truth = _synthetic_session(0.0123, seed=3, noise_mm=0.0, occlude=False)
    est = estimate_delay(cap_t, cap, mk_t, truth, max_delay_s=0.3, method=method)
    assert abs(est.delay_s - 0.0123) < 0.004, est


def test_estimate_delay_contrast_is_low_when_markers_do_not_move():
    cap_t, cap, mk_t, _pos, truth = _synthetic_session(0.1, seed=5)
    still = truth[:1] + 0.2 * np.random.default_rng(0).normal(size=truth.shape)
    est = estimate_delay(cap_t, cap, mk_t, still, max_delay_s=0.5)
    assert est.contrast < 0.2


def test_estimate_delay_flags_bound_and_refuses_flat_signals():
    cap_t, cap, mk_t, pos, _ = _synthetic_session(0.4, seed=1)
    est = estimate_delay(cap_t, cap, mk_t, pos, max_delay_s=0.2)
    assert est.at_bound
    with pytest.raises(EctskinError, match="readouts never change"):
        estimate_delay(cap_t, np.ones_like(cap), mk_t, pos, max_delay_s=0.2)
    with pytest.raises(EctskinError, match="no marker is visible"):
        estimate_delay(cap_t, cap, mk_t, np.full_like(pos, np.nan), max_delay_s=0.2)
    with pytest.raises(EctskinError, match="Invalid value for 'method'"):
        estimate_delay(cap_t, cap, mk_t, pos, max_delay_s=0.2, method="psychic")
    with pytest.raises(EctskinError, match=r"cap_values must have shape"):
        estimate_delay(cap_t, cap[:-1], mk_t, pos, max_delay_s=0.2)
    with pytest.raises(EctskinError, match="max_delay_s must be > 0"):
        estimate_delay(cap_t, cap, mk_t, pos, max_delay_s=0)


# =========================================================================== building recordings
def _write_capmeter(path: Path, t: np.ndarray, values_pf: np.ndarray, names: list[str]) -> None:
    """A readout export in the documented layout: metadata, header with units, fF values."""
    lines = ["Instrument,synthetic", "Time [s]," + ",".join(f"{n} [fF]" for n in names)]
    for k in range(len(t)):
        cells = ["" if np.isnan(v) else f"{v * 1e3:.4f}" for v in values_pf[k]]
        lines.append(f"{t[k]:.6f}," + ",".join(cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _write_motive(path: Path, t: np.ndarray, pos_mm: np.ndarray, names: list[str]) -> None:
    """A Motive 1.23 export in Millimeters with the given marker names (Type Marker)."""
    meta = ("Format Version,1.23,Take Name,synthetic,Capture Frame Rate,30.000000,Export Frame "
            "Rate,30.000000,Rotation Type,Quaternion,Length Units,Millimeters,Coordinate Space,"
            "Global")
    rows = [meta, "", ",Type," + ",".join(["Marker"] * 3 * len(names)),
            ",Name," + ",".join(n for n in names for _ in range(3)),
            ",ID," + ",".join(str(k + 1) for k in range(len(names)) for _ in range(3)),
            ",," + ",".join(["Position"] * 3 * len(names)),
            "Frame,Time (Seconds)," + ",".join(["X,Y,Z"] * len(names))]
    for f in range(len(t)):
        cells = []
        for m in range(len(names)):
            p = pos_mm[f, m]
            cells += ["", "", ""] if np.isnan(p).any() else [f"{v:.6f}" for v in p]
        rows.append(f"{f},{t[f]:.6f}," + ",".join(cells))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


LAYOUT = default_layout()
PAIR_NAMES = [f"C{i + 1}{j + 1}" for i, j in LAYOUT.pairs]


def _session_files(tmp_path, delay_s, name="t0", seed=0):
    cap_t, cap, mk_t, pos, truth = _synthetic_session(delay_s, seed=seed, duration_s=20.0)
    cap[50, 3] = np.nan  # one masked cell
    cap_t = cap_t + 12.5  # the meter's clock started earlier: clock='start' removes it
    cp, mp = tmp_path / f"{name}_cap.csv", tmp_path / f"{name}_mocap.csv"
    _write_capmeter(cp, cap_t, cap, PAIR_NAMES)
    order = [2, 0, 1, 4, 3]  # file order M3, M1, M2, M5, M4: build_recording reorders by name
    _write_motive(mp, mk_t, pos[:, order], [f"Skin:M{k + 1}" for k in order])
    return cp, mp, cap_t - 12.5, truth, mk_t


def test_build_recording_end_to_end_from_files(tmp_path):
    cp, mp, cap_t, truth, mk_t = _session_files(tmp_path, 0.1)
    cap = read_capmeter_csv(cp, n_pairs=28)
    mocap = read_motive_csv(mp)
    rec = build_recording(cap, mocap, LAYOUT, trial_name="s1_touch", inflation=(0, 10, 20),
                          region=7)
    t = rec.trials[0]
    assert rec.n_trials == 1 and rec.frame_rate_hz == pytest.approx(30.0, rel=1e-4)
    assert t.name == "s1_touch" and t.region == 7 and t.inflation == (0.0, 10.0, 20.0)
    assert (t.labels == 7).all() and t.meta["kind"] == "touch"
    assert abs(t.meta["delay_s"] - 0.1) < 0.5 / 30 and t.meta["delay_source"] == "estimated"
    assert t.meta["delay_method"] == "regression" and t.meta["delay_contrast"] > 0.2
    np.testing.assert_allclose(t.timestamps, cap_t - cap_t[0], atol=1e-6)
    assert np.isnan(t.capacitance[50, 3]) and t.meta["masked"]["masked"]["C15"]["n"] == 1
    # markers in layout order M1..M5, sampled at frame time + delay: compare with the noise-free
    # truth resampled with the true delay (difference = marker noise 0.2 mm + delay error)
    assert t.meta["mocap_markers"] == ["Skin:M1", "Skin:M2", "Skin:M3", "Skin:M4", "Skin:M5"]
    want = resample_markers(mk_t, truth, t.timestamps, 0.1)
    ok = np.isfinite(t.markers) & np.isfinite(want)
    err = np.abs(t.markers - want)[ok]
    assert ok.mean() > 0.9 and np.median(err) < 0.3 and err.max() < 2.0
    # the occlusion of marker M5 (mocap samples 100..129) reaches the recording as NaN
    assert np.isnan(t.markers[105:125, 4]).all()
    assert t.meta["occluded_frames"]["Skin:M5"] >= 30


def test_build_recording_orders_channels_by_layout_pair_names(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(10) / 30
    vals = rng.uniform(0.5, 1.5, (10, 28))
    names = list(LAYOUT.pair_names)  # "E1-E2", ... but written in reverse column order
    p = tmp_path / "rev.csv"
    _write_capmeter(p, t, vals[:, ::-1], names[::-1])
    cap = read_capmeter_csv(p, pair_order="file")
    assert cap.channels[0] == "E7-E8"
    rec = build_recording(cap, None, LAYOUT)
    np.testing.assert_allclose(rec.trials[0].capacitance, vals, rtol=0, atol=1e-7)  # 0.1 aF


def test_build_recording_given_delay_no_mocap_and_errors(tmp_path):
    cp, mp, *_ = _session_files(tmp_path, 0.0)
    cap = read_capmeter_csv(cp)
    mocap = read_motive_csv(mp)
    rec = build_recording(cap, mocap, LAYOUT, delay=0.0667, trial_name="x")
    assert rec.trials[0].meta["delay_s"] == 0.0667 and rec.trials[0].meta["delay_source"] == "given"
    assert rec.trials[0].meta["kind"] == "no_contact"
    bare = build_recording(cap, None, LAYOUT)
    assert bare.trials[0].markers is None and bare.trials[0].name == "t0_cap"
    small = read_capmeter_csv(CAP_BOM)
    with pytest.raises(EctskinError, match=r"3 capacitance channels \(C12, C13, C23\), but layout "
                                           r"'paper-2x4-wires' has 8 electrodes = 28 pairs"):
        build_recording(small, None, LAYOUT)
    with pytest.raises(EctskinError, match="unknown region 19"):
        build_recording(cap, None, LAYOUT, region=19)
    with pytest.raises(EctskinError, match="delay must be 'auto' or a number"):
        build_recording(cap, mocap, LAYOUT, delay="soon")
    three = read_motive_csv(MOTIVE)
    with pytest.raises(EctskinError, match=r"missing from the take: M4, M5\. Markers are matched"):
        build_recording(cap, three, LAYOUT)


def _take_with(tmp_path, names, file_name="take.csv"):
    """A Motive take of the session whose markers carry ``names``; a name ending in digit k holds
    the trajectory of layout marker Mk (M6: a sixth trajectory)."""
    _, _, mk_t, pos, _ = _synthetic_session(0.0, seed=3, duration_s=5.0)
    pos = np.concatenate([pos, pos[:, :1] + 50.0], axis=1)  # a sixth marker for "M6"
    cols = [int(n[-1]) - 1 for n in names]
    path = tmp_path / file_name
    _write_motive(path, mk_t, pos[:, cols], names)
    return read_motive_csv(path)


def test_build_recording_matches_markers_by_name_or_refuses(tmp_path):
    """Issue 12, defect 6: a take of Skin:M1, M2, M4, M5, M6 gave layout M3 the data of M4 and
    M5 that of M6 (matched by order, logged at INFO). Now by name, or one error naming them."""
    cp, *_ = _session_files(tmp_path, 0.0)
    cap = read_capmeter_csv(cp)
    gap = _take_with(tmp_path, ["Skin:M1", "Skin:M2", "Skin:M4", "Skin:M5", "Skin:M6"])
    with pytest.raises(EctskinError) as info:
        build_recording(cap, gap, LAYOUT, delay=0.0)
    msg = str(info.value)
    assert "missing from the take: M3" in msg and "not in the layout: Skin:M6" in msg
    assert "never by their order" in msg and "--markers" in msg
    # names without any match (the old fallback took them in file order)
    other = _take_with(tmp_path, ["Skin:X1", "Skin:X2", "Skin:X3", "Skin:X4", "Skin:X5"], "o.csv")
    with pytest.raises(EctskinError, match="missing from the take: M1, M2, M3, M4, M5; not in "
                                           "the layout: Skin:X1"):
        build_recording(cap, other, LAYOUT, delay=0.0)
    # an extra marker (say, on the finger) is refused too, until the take's markers are selected
    six = ["Skin:M6", "Skin:M2", "Skin:M1", "Skin:M3", "Skin:M5", "Skin:M4"]
    extra = _take_with(tmp_path, six, "six.csv")
    with pytest.raises(EctskinError, match="not in the layout: Skin:M6"):
        build_recording(cap, extra, LAYOUT, delay=0.0)
    picked = read_motive_csv(tmp_path / "six.csv", ["M2", "M1", "M3", "M5", "M4"])
    t = build_recording(cap, picked, LAYOUT, delay=0.0).trials[0]
    assert t.meta["mocap_markers"] == [f"Skin:M{k}" for k in range(1, 6)]  # layout order
    in_order = _take_with(tmp_path, [f"Skin:M{k}" for k in range(1, 6)], "ok.csv")
    want = build_recording(cap, in_order, LAYOUT, delay=0.0).trials[0]
    np.testing.assert_array_equal(t.markers, want.markers)


def test_cli_build_refuses_markers_that_do_not_match(tmp_path, capsys):
    cp, *_ = _session_files(tmp_path, 0.0)
    _take_with(tmp_path, ["Skin:M1", "Skin:M2", "Skin:M4", "Skin:M5", "Skin:M6"], "gap.csv")
    code = cli.main(["import", "build", "--capacitance", str(cp), "--mocap",
                     str(tmp_path / "gap.csv"), "-o", str(tmp_path / "r.h5"), "--region", "3"])
    err = capsys.readouterr().err
    assert code == 2 and "missing from the take: M3" in err and "Traceback" not in err
    assert not (tmp_path / "r.h5").exists()


def test_build_recording_from_manifest(tmp_path):
    cp0, mp0, *_ = _session_files(tmp_path, 0.1, name="a", seed=1)
    cp1, _, *_ = _session_files(tmp_path, 0.0, name="b", seed=2)
    manifest = {
        "max_delay_s": 0.4,
        "trials": [
            {"name": "a_touch", "capacitance": cp0.name, "mocap": mp0.name,
             "inflation": [0, 0, 10], "region": 12},
            {"name": "b_rest", "capacitance": cp1.name, "inflation": [0, 0, 10]},
        ],
    }
    mf = tmp_path / "trials.json"
    mf.write_text(json.dumps(manifest), encoding="utf-8")
    rec = build_recording_from_manifest(mf)
    assert [t.name for t in rec.trials] == ["a_touch", "b_rest"]
    assert abs(rec.trials[0].meta["delay_s"] - 0.1) < 0.5 / 30
    assert rec.trials[1].markers is None and rec.trials[0].markers is not None
    manifest["trials"][1]["regoin"] = 3
    mf.write_text(json.dumps(manifest), encoding="utf-8")
    with pytest.raises(EctskinError, match=r"trials\[1\]: unknown field\(s\) \['regoin'\]"):
        build_recording_from_manifest(mf)
    del manifest["trials"][1]["regoin"]
    manifest["trials"][1]["capacitance"] = "nope.csv"
    mf.write_text(json.dumps(manifest), encoding="utf-8")
    with pytest.raises(EctskinError, match=r"trials\[1\] \(b_rest\): cannot read capacitance"):
        build_recording_from_manifest(mf)


# =========================================================================== CLI
def _cli(argv):
    from ectskin.commands import import_

    parser = argparse.ArgumentParser(prog="ectskin import")
    import_.add_arguments(parser)
    return import_.run(parser.parse_args(argv))


def test_cli_reports_and_builds_hdf5(tmp_path, capsys):
    assert _cli(["capacitance", str(CAP_BOM)]) == 0
    out = capsys.readouterr().out
    assert "8 frames, 3 channels" in out and "C13: 3 masked (OL: 2, NaN: 1)" in out
    assert _cli(["mocap", str(MOTIVE), "--markers", "M1,M3"]) == 0
    assert "markers: Skin:M1, Skin:M3" in capsys.readouterr().out
    cp, mp, *_ = _session_files(tmp_path, 0.1)
    out_h5 = tmp_path / "rec.h5"
    argv = ["build", "--capacitance", str(cp), "--mocap", str(mp), "-o", str(out_h5),
            "--region", "4", "--inflation", "0,10,20", "--trial-name", "s1"]
    assert _cli(argv) == 0
    assert "delay +" in capsys.readouterr().out
    back = hdf5.read_recording(out_h5)
    t = back.trials[0]
    assert t.name == "s1" and t.region == 4 and t.inflation == (0.0, 10.0, 20.0)
    assert abs(t.meta["delay_s"] - 0.1) < 0.5 / 30
    assert t.markers.shape == (t.n_frames, 5, 3)
    with pytest.raises(EctskinError, match="exist"):
        _cli(argv)  # refuses to overwrite without --overwrite
    assert _cli([*argv, "--overwrite", "--delay", "0.05"]) == 0
    assert hdf5.read_recording(out_h5).trials[0].meta["delay_s"] == 0.05
    with pytest.raises(EctskinError, match="--delay must be 'auto' or a number"):
        _cli([*argv, "--overwrite", "--delay", "later"])


def test_cli_manifest_refuses_per_trial_flags(tmp_path):
    with pytest.raises(EctskinError, match=r"--mocap, --region describe one trial"):
        _cli(["build", "--manifest", str(tmp_path / "m.json"), "--mocap", "x.csv", "--region",
              "3", "-o", str(tmp_path / "o.h5")])


def test_cli_main_prints_clear_error_for_bad_file(tmp_path, capsys):
    bad = _copy_with(tmp_path, CAP_BOM, "133.3,1526.1,0.375,983.4,", "133.3,1526.1,0.375,98x3.4,")
    code = cli.main(["import", "capacitance", str(bad)])
    err = capsys.readouterr().err
    assert code == 2
    assert "ectskin import: error:" in err and "line 9" in err and "'C13'" in err
    assert "Traceback" not in err


def test_cli_generic_calls_load_generic_and_writer(tmp_path, capsys, monkeypatch):
    written = {}

    def fake_write(rec, path, *, overwrite=False):  # the writer has its own tests
        written.update(rec=rec, path=path, overwrite=overwrite)
        return Path(path)

    monkeypatch.setattr(hdf5, "write_recording", fake_write)
    src = tmp_path / "g.csv"
    src.write_text(
        "# frame_rate_hz: 30\ngroup,label,c:E1-E2,c:E1-E3,c:E2-E3\n"
        "rest,0,1.20,0.81,0.95\nrest,0,1.21,0.82,0.96\npress,2,1.30,0.80,0.97\n"
        "press,2,1.31,0.79,0.98\n",
        encoding="utf-8",
    )
    assert _cli(["generic", str(src), "-o", str(tmp_path / "g.h5"), "--overwrite"]) == 0
    rec = written["rec"]
    assert written["overwrite"] is True and rec.n_trials == 2 and rec.n_pairs == 3
    assert rec.frame_rate_hz == 30.0
    assert "wrote" in capsys.readouterr().out


# ============================================================ issue 12: cut, dead and huge values
def _fixed_capmeter(path, last_value="983.4021", newline=False):
    """Three channels in fF with 4 decimals in every row; the last row ends with ``last_value``."""
    rows = ["Time [s],C12 [fF],C13 [fF],C23 [fF]"]
    rows += [f"{k / 30:.4f},1525.{k:04d},983.{k:04d},1207.{k:04d}" for k in range(12)]
    rows.append(f"{12 / 30:.4f},1525.0012,983.0012,{last_value}")
    path.write_text("\n".join(rows) + ("\n" if newline else ""), encoding="utf-8")
    return path


def test_capmeter_last_line_cut_short_is_left_out_and_reported(tmp_path, caplog):
    """Issue 12, defect 15 (capacitance CSV): '1207.0239' cut to '1207.0' in a file without a
    final newline was stored as is. Now the line is skipped, reported, the rows before kept."""
    p = _fixed_capmeter(tmp_path / "cut.csv", last_value="1207.0")
    with caplog.at_level("WARNING"):
        cap = read_capmeter_csv(p, strict=True)
    assert cap.n_frames == 12
    assert "line 14 is cut short (its last number '1207.0' has 1 decimal" in caplog.text
    (line, why), = cap.mask_report.skipped_rows
    assert line == 14 and "cut short" in why and "truncated" in why
    assert "line 14 skipped: cut short" in cap.mask_report.summary()
    # cut inside a cell separator: fewer cells
    p = tmp_path / "cut2.csv"
    p.write_text(_fixed_capmeter(tmp_path / "x.csv").read_text()[:-10], encoding="utf-8")
    assert read_capmeter_csv(p).n_frames == 12
    # complete last lines are kept, with or without the final newline
    for newline in (False, True):
        cap = read_capmeter_csv(_fixed_capmeter(tmp_path / "ok.csv", newline=newline))
        assert cap.n_frames == 13 and cap.values[-1, 2] == pytest.approx(983.4021e-3)
        assert cap.mask_report.skipped_rows == []


def test_capmeter_huge_value_is_refused(tmp_path):
    p = _fixed_capmeter(tmp_path / "huge.csv", last_value="1.7e308", newline=True)
    with pytest.raises(EctskinError, match=r"line 14, column 4 \(channel 'C23'\): 1.7e\+305 pF "
                                           r"is beyond ±1e\+30 pF"):
        read_capmeter_csv(p)


def test_build_recording_leaves_out_an_all_zero_channel(tmp_path, caplog):
    """Before: a channel reading 0 pF in every frame imported silently and failed at training."""
    rng = np.random.default_rng(0)
    t = np.arange(20) / 30
    vals = rng.uniform(0.5, 1.5, (20, 28))
    vals[:, 5] = 0.0
    p = tmp_path / "dead.csv"
    _write_capmeter(p, t, vals, PAIR_NAMES)
    with caplog.at_level("WARNING"):
        rec = build_recording(read_capmeter_csv(p), None, LAYOUT)
    assert rec.meta["unmeasured_pairs"] == [5]
    assert np.isnan(rec.trials[0].capacitance[:, 5]).all()
    assert rec.trials[0].meta["dropped_channels"] == [LAYOUT.pair_names[5]]
    assert f"channel {LAYOUT.pair_names[5]} reads 0 pF" in caplog.text
    manifest = {"trials": [{"name": "a", "capacitance": "dead.csv"},
                           {"name": "b", "capacitance": "alive.csv"}]}
    _write_capmeter(tmp_path / "alive.csv", t, rng.uniform(0.5, 1.5, (20, 28)), PAIR_NAMES)
    (tmp_path / "m.json").write_text(json.dumps(manifest), encoding="utf-8")
    both = build_recording_from_manifest(tmp_path / "m.json")
    assert both.meta["unmeasured_pairs"] == [5]  # dead in one trial: left out of all
    assert np.isfinite(both.trials[1].capacitance).all()


def test_capmeter_two_row_header_channel_row_over_units_row():
    """Issue 10, item 5: ``,Ch1,,Ch2,,...`` over ``Time (s),C (pF),ΔC/C0 (%),...`` failed with
    "channel 'C' appears twice". Values from the fixture by hand: row 1 (line 5) reads
    10.000 pF, 12.500 pF, OL, 850.0 fF; the last row (line 24, t = 0.95 s) 10.190, 12.405, OL,
    859.5 fF. Line 11's Ch1 relative change (55 %) disagrees with its value: ignored, not checked.
    """
    d = read_capmeter_csv(CAP_TWO_ROW)
    assert d.channels == ("Ch1", "Ch2", "Ch3", "Ch4")
    assert d.units == ("pF", "pF", "pF", "fF")
    assert d.n_frames == 20 and d.time_unit == "s"
    assert d.lines[0] == 5 and d.lines[-1] == 24
    np.testing.assert_allclose(d.timestamps[[0, 1, -1]], [0.0, 0.05, 0.95])
    np.testing.assert_allclose(d.values[0, [0, 1, 3]], [10.0, 12.5, 0.85], rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.values[-1, [0, 1, 3]], [10.19, 12.405, 0.8595], rtol=0,
                               atol=1e-12)
    assert d.meta == {"Instrument": "LCR logger 4ch", "Exported": "2024-05-14 10:12:00"}
    rep = d.mask_report
    # the relative-change columns are ignored (not read, not cross-checked), and the report says so
    assert not any(c.relative_checked or c.relative_mismatch for c in rep.channels.values())
    assert any("relative-change column(s) 3 (Ch1" in n and "ignored" in n for n in rep.notes)
    # Ch3 reads OL in every row: all NaN, with a note that a built recording leaves it out
    assert np.isnan(d.values[:, 2]).all() and rep.channels["Ch3"].counts == {"OL": 20}
    assert any("'Ch3' has no readout in any frame (OL in every row)" in n for n in rep.notes)
    assert "note: channel 'Ch3'" in rep.summary() and rep.to_dict()["notes"] == rep.notes
    # one-row files carry no layout notes
    assert read_capmeter_csv(CAP_BOM).mask_report.notes == []


def test_capmeter_two_row_header_needs_one_name_per_capacitance_column(tmp_path):
    """A channel row that does not name exactly the capacitance columns is no channel row: the
    old error stands (two columns named 'C')."""
    p = _copy_with(tmp_path, CAP_TWO_ROW, ",Ch1,,Ch2,,Ch3,,Ch4,", ",Ch1,,,,Ch3,,Ch4,")
    with pytest.raises(EctskinError, match="channel 'C' appears twice"):
        read_capmeter_csv(p)


def test_build_recording_leaves_out_an_all_overload_channel_of_a_two_row_file(tmp_path, caplog):
    """A channel reading OL in every row is left out like an all-zero one (unmeasured_pairs)."""
    rng = np.random.default_rng(1)
    vals = rng.uniform(0.5, 1.5, (20, 28))
    lines = ["," + ",".join(f"{n}," for n in PAIR_NAMES),
             "Time (s)," + ",".join(["C (pF),ΔC/C0 (%)"] * 28)]
    for k in range(20):
        cells = ["OL,OL" if j == 7 else f"{vals[k, j]:.5f},0.0" for j in range(28)]
        lines.append(f"{k / 30:.5f}," + ",".join(cells))
    p = tmp_path / "ol.csv"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    cap = read_capmeter_csv(p, n_pairs=28)
    assert cap.channels == tuple(PAIR_NAMES)
    with caplog.at_level("WARNING"):
        rec = build_recording(cap, None, LAYOUT)
    assert rec.meta["unmeasured_pairs"] == [7]
    assert rec.trials[0].meta["dropped_channels"] == [LAYOUT.pair_names[7]]
    keep = [j for j in range(28) if j != 7]
    np.testing.assert_allclose(rec.trials[0].capacitance[:, keep], vals[:, keep], atol=1e-5)


def test_motive_empty_length_units_is_like_none(tmp_path):
    """Found by the fuzz suite: 'Length Units,' with an empty value gave an AttributeError."""
    p = _copy_with(tmp_path, MOTIVE, ",Length Units,Meters", ",Length Units,")
    with pytest.raises(EctskinError, match="no 'Length Units' field"):
        read_motive_csv(p)
    assert read_motive_csv(p, length_units="Meters").units == "Meters"


def test_motive_huge_coordinate_is_a_bad_row(tmp_path):
    t = np.arange(5) / 30
    pos = np.ones((5, 1, 3))
    p = tmp_path / "m.csv"
    _write_motive(p, t, pos, ["Skin:M1"])
    p.write_text(p.read_text().replace("1.000000,1.000000,1.000000\n", "1.000000,1.7e308,1.0\n",
                                       1), encoding="utf-8")
    with pytest.raises(EctskinError, match=r"'1.7e308' is beyond ±1e\+30 mm"):
        read_motive_csv(p)
