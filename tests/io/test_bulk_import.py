"""The importers' bulk reads against their per-line reference, the one rule for a cut last row,
and the shared frame-rate checks.

The bulk read of a data block (``capmeter.rows.bulk_rows``, ``motive.read._bulk_take``) must give
exactly what the per-line reader gives (``parse_rows``, ``_parse_rows``: the readers before the
bulk read, kept to report faults); each comparison below also checks that the bulk read ran.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

import ectskin.io.capmeter.read as cap_read
import ectskin.io.capmeter.rows as cap_rows
import ectskin.io.motive.read as mot_read
from ectskin._check import EctskinError
from ectskin.io.capmeter import read_capmeter_csv
from ectskin.io.frame_rate import frame_rate, stated_rate
from ectskin.io.generic import load_generic
from ectskin.io.motive import read_motive_csv
from ectskin.io.text import cut_last_row, data_cells, float_cells, parse_float, parse_number

DATA = Path(__file__).parents[1] / "data" / "instruments"
CAP_BOM = DATA / "capmeter_bom_fF.csv"
CAP_SEMI = DATA / "capmeter_semicolon_clock.csv"
CAP_TWO_ROW = DATA / "capmeter_two_row_header.csv"
MOTIVE = DATA / "motive_meters_30fps.csv"


def _write_motive(path: Path, t: np.ndarray, pos_mm: np.ndarray, names: list[str]) -> None:
    """A Motive 1.23 export in Millimeters, markers of Type Marker; NaN → three empty cells."""
    rows = [
        "Format Version,1.23,Take Name,synthetic,Export Frame Rate,120.000000,Length Units,"
        "Millimeters",
        "",
        ",Type," + ",".join(["Marker"] * 3 * len(names)),
        ",Name," + ",".join(n for n in names for _ in range(3)),
        ",," + ",".join(["Position"] * 3 * len(names)),
        "Frame,Time (Seconds)," + ",".join(["X,Y,Z"] * len(names)),
    ]
    for f in range(len(t)):
        cells = []
        for m in range(len(names)):
            p = pos_mm[f, m]
            cells += ["", "", ""] if np.isnan(p).any() else [f"{v:.6f}" for v in p]
        rows.append(f"{f},{t[f]:.6f}," + ",".join(cells))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def _same(a, b):
    """Two reader results hold the same arrays and reports (NaN equal to NaN)."""
    da, db = vars(a), vars(b)
    assert da.keys() == db.keys()
    for key in da:
        x, y = da[key], db[key]
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, key
            np.testing.assert_array_equal(x, y, err_msg=key)
        elif hasattr(x, "__dict__"):
            assert vars(x) == vars(y), key
        elif isinstance(x, dict):
            assert {k: vars(v) if hasattr(v, "__dict__") else v for k, v in x.items()} == {
                k: vars(v) if hasattr(v, "__dict__") else v for k, v in y.items()
            }, key
        else:
            assert x == y, key


def _capmeter_both(monkeypatch, path, **kw):
    """(bulk result, per-line result) of read_capmeter_csv; fails unless the bulk read ran."""
    calls = []
    bulk = cap_read.bulk_rows

    def spy(*args, **kwargs):
        out = bulk(*args, **kwargs)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(cap_read, "bulk_rows", spy)
    fast = read_capmeter_csv(path, **kw)
    assert calls == [True], "the bulk read did not run"
    monkeypatch.setattr(cap_read, "bulk_rows", lambda *a, **k: None)
    slow = read_capmeter_csv(path, **kw)
    monkeypatch.setattr(cap_read, "bulk_rows", bulk)
    return fast, slow


def _semicolon_clock_file(path, n=700, seed=0):
    """Semicolon, decimal commas, a units row, clock times over midnight, masked cells of every
    kind, padded cells, thousands in spaces, 17-digit numbers, blank and delimiter-only lines."""
    rng = np.random.default_rng(seed)
    rows = ["# LCR log;;;;", "Operator;J. Doe;;;", "Timestamp;E1-E2;E1-E3;E2-E3;E1-E2 dC/C",
            "hh:mm:ss.fff;pF;pF;fF;%"]
    markers = ["OL", "ol", "", " ", "NaN", "-", "N/A", "inf", "--", "Overload"]
    for k in range(n):
        t = (86400 - 10.0 + k * 0.0333) % 86400
        clock = f"{int(t // 3600):02d}:{int(t % 3600 // 60):02d}:{t % 60:06.3f}"
        cells = [clock.replace(".", ",") if k % 3 else clock]
        for j in range(3):
            v = rng.uniform(0.1, 2.0) * (1000 if j == 2 else 1)
            r = rng.random()
            if r < 0.05:
                cells.append(markers[k % len(markers)])
            elif j == 0:
                cells.append(repr(float(v)).replace(".", ","))
            elif j == 2 and k % 5 == 0:
                cells.append(f"1 {int(v) % 1000:03d},5")
            else:
                cells.append(f" {v:.5f} ")
        cells.append(f"{rng.normal():.3f}".replace(".", ",") if k % 4 else "x")
        rows.append(";".join(cells))
        if k % 97 == 0:
            rows.append(";;;;" if k % 2 else "")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("kw", [{}, {"pair_order": "file"}, {"time_order": "sort"}])
def test_capmeter_bulk_read_equals_the_per_line_reader(tmp_path, monkeypatch, kw):
    monkeypatch.setattr(cap_rows, "CHUNK_LINES", 64)  # several chunks
    for path in (CAP_BOM, CAP_SEMI, CAP_TWO_ROW, _semicolon_clock_file(tmp_path / "semi.csv")):
        _same(*_capmeter_both(monkeypatch, path, **kw))


def test_capmeter_bulk_read_of_a_large_file(tmp_path, monkeypatch):
    """20 000 rows, 28 channels in fF with their relative changes, a dead channel (OL), gaps."""
    rng = np.random.default_rng(1)
    n, m = 20_000, 28
    vals = rng.uniform(500, 1500, (n, m))
    gaps = rng.random((n, m)) < 1e-3
    head = "Time [s]," + ",".join(f"C{j} [fF],C{j} dC/C [%]" for j in range(m))
    lines = [head]
    for k in range(n):
        cells = [f"{k / 30:.5f}"]
        for j in range(m):
            if j == 5:
                cells += ["OL", "OL"]
            elif gaps[k, j]:
                cells += ["", ""]
            else:
                cells += [f"{vals[k, j]:.4f}", f"{vals[k, j] / 1000 - 1:.4f}"]
        lines.append(",".join(cells))
    p = tmp_path / "big.csv"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    fast, slow = _capmeter_both(monkeypatch, p, relative_tolerance=10.0)
    _same(fast, slow)
    assert fast.mask_report.channels["C5"].counts == {"OL": n}


@pytest.mark.parametrize(
    "old, new, line",
    [
        ("133.3,1526.1,0.375,983.4,", "133.3,1526.1,0.375,98x3.4,", 9),  # garbage cell
        ("66.7,1523.4,0.197,OL,OL,1208.8,-0.099,", "66.7,1523.4,0.197,OL,1208.8,-0.099", 7),
        ("233.3,1530.2", "2x3.3,1530.2", 12),  # a time that is no number
    ],
)
def test_capmeter_a_fault_is_left_to_the_per_line_reader(tmp_path, monkeypatch, old, new, line):
    """The bulk read hands a faulty block over; the per-line reader names the line (strict) or
    skips / masks it and keeps the rest (not strict)."""
    text = CAP_BOM.read_text(encoding="utf-8-sig")
    p = tmp_path / "x.csv"
    p.write_text(text.replace(old, new), encoding="utf-8")
    calls = []
    bulk = cap_read.bulk_rows
    monkeypatch.setattr(
        cap_read, "bulk_rows", lambda *a, **k: calls.append(out := bulk(*a, **k)) or out
    )
    with pytest.raises(EctskinError, match=rf"x\.csv: line {line}: "):
        read_capmeter_csv(p)
    assert calls == [None]
    assert read_capmeter_csv(p, strict=False).n_frames >= 7


def test_data_cells_leaves_quotes_and_odd_rows_to_the_csv_reader():
    lines = ["1,2,3", "", " , ,", "4,5,6"]
    cells, line_no = data_cells(lines, 10, ",", 3)
    assert cells.tolist() == [["1", "2", "3"], ["4", "5", "6"]]
    assert line_no.tolist() == [10, 13]  # blank and delimiter-only lines left out
    assert data_cells(['1,"2",3'], 1, ",", 3) is None
    assert data_cells(["1,2"], 1, ",", 3) is None
    assert data_cells(["1,2,3,4"], 1, ",", 3) is None


def test_motive_bulk_read_equals_the_per_line_reader(tmp_path, monkeypatch):
    monkeypatch.setattr(mot_read, "CHUNK_LINES", 50)
    rng = np.random.default_rng(2)
    t = np.arange(400) / 120
    pos = rng.uniform(-50, 50, (400, 4, 3))
    pos[rng.random((400, 4)) < 0.05] = np.nan
    p = tmp_path / "take.csv"
    _write_motive(p, t, pos, ["Skin:M1", "Skin:M2", "Skin:M3", "Skin:M4"])
    text = p.read_text(encoding="utf-8").splitlines()
    text[40] = text[40].rsplit(",", 1)[0] + ","  # one partly empty marker
    p.write_text("\n".join(text) + "\n", encoding="utf-8")
    for path in (MOTIVE, p):
        calls = []
        bulk = mot_read._bulk_take

        def spy(*args, _bulk=bulk, _calls=calls, **kwargs):
            out = _bulk(*args, **kwargs)
            _calls.append(out is not None)
            return out

        monkeypatch.setattr(mot_read, "_bulk_take", spy)
        fast = read_motive_csv(path, include_unlabeled=True)
        assert calls == [True], "the bulk read did not run"
        monkeypatch.setattr(mot_read, "_bulk_take", lambda *a, **k: None)
        slow = read_motive_csv(path, include_unlabeled=True)
        monkeypatch.setattr(mot_read, "_bulk_take", bulk)
        _same(fast, slow)


def test_float_cells_read_as_the_cell_parsers_do():
    cells = np.array(
        ["1.5", " 2 ", "1_000", "nan", "-inf", "", "OL", "1 520.4", "1,5", "abc", "1e-320"],
        dtype=object,
    )
    for parse, comma in ((parse_float, False), (lambda c: parse_number(c, False), False),
                         (lambda c: parse_number(c, True), True)):
        want = [parse(c) for c in cells]
        got = float_cells(cells, parse, ("", "OL"), comma)
        want = np.array([np.nan if v is None else v for v in want])
        np.testing.assert_array_equal(got, want)


# --------------------------------------------------------------------------- cut last row
FIXED = [(k + 2, [f"{k / 30:.4f}", f"1.{k:04d}", f"2.{k:04d}"]) for k in range(10)]


@pytest.mark.parametrize(
    "last, why",
    [
        (["0.3333", "1.0010", "2.0"], "its last number '2.0' has 1 decimal, the 10 rows"),
        (["0.3333", "1.00"], "it has 2 of the header's 3 cells"),
        (["0.3333", "1.0010", ""], "it ends with an empty cell"),
        (["0.3333", "1.0010", "2.00e"], "its last cell '2.00e' is not a number"),
        (["0.3333", "1.0010", "2.0010"], None),
        (["", "", ""], None),  # a blank last row is no cut
    ],
)
def test_cut_last_row_against_hand_cases(last, why):
    got = cut_last_row([*FIXED, (12, last)], 3, lambda c: parse_float(c) is not None)
    assert got == why if why is None else why in got


def test_motive_last_row_cut_short_is_left_out_with_a_warning(tmp_path, caplog):
    """Before: a take whose copy stopped inside its last row was refused ("expected 5 cells")
    in strict mode. Now, like the other importers, the row is left out, said so, the rest kept."""
    t = np.arange(6) / 120
    p = tmp_path / "take.csv"  # data on lines 7 to 12
    _write_motive(p, t, np.full((6, 1, 3), 12.5), ["Skin:M1"])
    text = p.read_text(encoding="utf-8")
    for cut in (text[:-10], text[:-3]):  # fewer cells; a last number with fewer decimals
        p.write_text(cut, encoding="utf-8")
        with caplog.at_level(logging.WARNING):
            d = read_motive_csv(p)
        assert d.n_frames == 5
        assert "line 12 is cut short" in caplog.text
        assert d.skipped_rows[-1][0] == 12 and "cut short" in d.skipped_rows[-1][1]
        caplog.clear()
    p.write_text(text.rstrip("\n"), encoding="utf-8")  # complete, only the newline missing
    assert read_motive_csv(p).n_frames == 6


# --------------------------------------------------------------------------- frame rate
def test_stated_rate_accepts_a_finite_number_above_zero():
    assert stated_rate("120.000000", "f: Export Frame Rate") == 120.0
    assert stated_rate(np.array([30.0]), "f: frame_rate_hz") == 30.0
    for bad in ("fast", "0", "-1", "nan", "inf", None, np.array([1.0, 2.0])):
        with pytest.raises(EctskinError, match=r"^f: x must be a number > 0, got"):
            stated_rate(bad, "f: x")


def test_frame_rate_from_steps_and_a_contradicted_rate(caplog):
    assert frame_rate(None, np.array([0.1, 0.1, 0.2, -1.0, np.nan]), "f", no_rate="?") == 10.0
    with pytest.raises(EctskinError, match=r"^f: no rate here$"):
        frame_rate(None, np.array([0.0, -1.0]), "f", no_rate="no rate here")
    with caplog.at_level(logging.WARNING):
        assert frame_rate(30.0, np.full(5, 1 / 30), "f", no_rate="?") == 30.0
        assert not caplog.text
        assert frame_rate(25.0, np.full(5, 1 / 30), "f", no_rate="?") == 25.0
    assert "f: the time steps give 30.000 frames/s, the stated frame rate is 25.000" in caplog.text


def test_generic_csv_frame_rate_of_zero_is_refused_naming_the_comment(tmp_path):
    """Before: '# frame_rate_hz: 0' passed the reader and failed later without naming the
    comment line ("frame_rate_hz must be a number > 0, got 0.0")."""
    p = tmp_path / "g.csv"
    p.write_text("# frame_rate_hz: 0\ngroup,label,c:a\n0,0,1\n0,0,2\n", encoding="utf-8")
    with pytest.raises(EctskinError, match=r"g\.csv: '# frame_rate_hz' must be a number > 0, "
                                           r"got '0'"):
        load_generic(p)


def test_generic_frame_rate_contradicted_by_the_timestamps_is_logged(tmp_path, caplog):
    """Before: a stated rate that the timestamps contradict (here 30 Hz stated, 10 Hz steps) was
    taken silently; Motive's reader already logged it. Now both do."""
    p = tmp_path / "g.csv"
    p.write_text("# frame_rate_hz: 30\ngroup,time_s,label,c:a\n0,0.0,0,1\n0,0.1,0,2\n"
                 "0,0.2,0,3\n", encoding="utf-8")
    with caplog.at_level(logging.WARNING):
        rec = load_generic(p)
    assert rec.frame_rate_hz == 30.0
    assert "give 10.000 frames/s, the stated frame rate is 30.000" in caplog.text
