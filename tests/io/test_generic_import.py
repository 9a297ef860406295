"""Generic NPZ / CSV import (ectskin.io.generic, docs/import-format.md)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import hdf5
from ectskin.io.generic import load_generic, virtual_layout
from ectskin.layout import default_layout
from ectskin.learn.data import touch_dataset, track_dataset


def _data(n_channels=5, n_markers=2, seed=0):
    """Three groups of 15 frames in the file order 7, 3, 5 (group 7: no contact)."""
    rng = np.random.default_rng(seed)
    group = np.repeat([7, 3, 5], 15)
    labels = np.repeat([0, 2, 1], 15)
    readouts = rng.uniform(1.0, 2.0, (45, n_channels))
    markers = 10 * np.arange(n_markers)[None, :, None] + rng.normal(0, 1, (45, n_markers, 3))
    t = np.tile(np.arange(15) / 30.0, 3) + np.repeat([0.0, 100.0, 200.0], 15)
    return group, labels, readouts, markers, t


def _write_csv(path, group, labels, readouts, markers=None, t=None, refs=None, extra_header=""):
    m = readouts.shape[1]
    cols = ["group"] + (["time_s"] if t is not None else []) + ["label"]
    cols += [f"c:ch{j}" for j in range(m)]
    if refs is not None:
        cols += [f"ref:ch{j}" for j in range(m)]
    if markers is not None:
        cols += [f"m:mk{k}.{a}" for k in range(markers.shape[1]) for a in "xyz"]
    lines = [extra_header, ",".join(cols)] if extra_header else [",".join(cols)]
    for i in range(len(group)):
        cells = [str(group[i])] + ([repr(float(t[i]))] if t is not None else []) + [str(labels[i])]
        cells += [repr(float(v)) for v in readouts[i]]
        if refs is not None:
            cells += [repr(float(v)) for v in refs[i]]
        if markers is not None:
            cells += ["" if np.isnan(v) else repr(float(v)) for v in markers[i].ravel()]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


# --------------------------------------------------------------------------- round trips
def test_npz_round_trip_odd_channel_count(tmp_path):
    group, labels, readouts, markers, t = _data(n_channels=5)
    p = tmp_path / "rec.npz"
    np.savez(p, readouts=readouts, group=group, labels=labels, markers=markers, timestamps=t)
    rec = load_generic(p)
    # 5 channels: 4 virtual electrodes (6 pairs), pair 5 unmeasured
    assert rec.layout.n_electrodes == 4 and rec.n_pairs == 6
    assert rec.meta["unmeasured_pairs"] == [5]
    assert rec.meta["channel_names"] == [f"ch{j + 1}" for j in range(5)]
    assert [tr.name for tr in rec.trials] == ["group_7", "group_3", "group_5"]
    assert rec.frame_rate_hz == pytest.approx(30.0)
    for k, tr in enumerate(rec.trials):
        rows = slice(15 * k, 15 * (k + 1))
        np.testing.assert_array_equal(tr.capacitance[:, :5], readouts[rows])
        assert np.all(np.isnan(tr.capacitance[:, 5]))
        np.testing.assert_array_equal(tr.markers, markers[rows])
        np.testing.assert_array_equal(tr.labels, labels[rows])
        np.testing.assert_allclose(tr.timestamps, np.arange(15) / 30.0, atol=1e-9)
        assert tr.meta["t0_s"] == pytest.approx(100.0 * k)
    assert rec.trials[0].meta["kind"] == "no_contact" and rec.trials[1].region == 2


def test_npz_coordinates_as_labels_and_no_timestamps(tmp_path):
    group, _, readouts, markers, _ = _data(n_channels=3)
    p = tmp_path / "track.npz"
    np.savez(
        p,
        readouts=readouts,
        group=group.astype(np.float64),
        labels=markers,
        frame_rate_hz=np.array(60.0),
    )
    rec = load_generic(p)
    assert rec.layout.n_electrodes == 3 and "unmeasured_pairs" not in rec.meta
    assert rec.frame_rate_hz == 60.0
    assert all(tr.meta["kind"] == "tracking" for tr in rec.trials)
    np.testing.assert_allclose(rec.trials[0].timestamps, np.arange(15) / 60.0)
    d = track_dataset(rec, window=4)
    assert d.x.shape == (45, 4, 3) and d.n_markers == 2
    np.testing.assert_array_equal(d.pairs, [[0, 1], [0, 2], [1, 2]])


@pytest.mark.parametrize("n_channels, n_el, unmeasured", [(6, 4, None), (7, 5, [7, 8, 9])])
def test_csv_round_trip(tmp_path, n_channels, n_el, unmeasured):
    group, labels, readouts, markers, t = _data(n_channels=n_channels)
    markers[3, 1, 2] = np.nan  # an occluded cell (empty)
    p = _write_csv(tmp_path / "rec.csv", group, labels, readouts, markers, t)
    rec = load_generic(p)
    assert rec.layout.n_electrodes == n_el
    assert rec.meta.get("unmeasured_pairs") == unmeasured
    assert rec.meta["marker_names"] == ["mk0", "mk1"]
    assert rec.meta["channel_names"] == [f"ch{j}" for j in range(n_channels)]
    for k, tr in enumerate(rec.trials):
        rows = slice(15 * k, 15 * (k + 1))
        np.testing.assert_array_equal(tr.capacitance[:, :n_channels], readouts[rows])  # repr exact
        np.testing.assert_array_equal(tr.markers, markers[rows])
    assert rec.trials[0].has_occlusion
    # the learning side works on the import: touch (against the no-contact group) and tracking
    d = touch_dataset(rec)
    assert d.n_pairs == n_channels and d.pair_names == [f"ch{j}" for j in range(n_channels)]
    ref = readouts[:15].mean(0)
    np.testing.assert_allclose(d.x, (readouts - ref) / ref, rtol=1e-5, atol=1e-6)
    assert d.n_classes == 3
    tr = track_dataset(rec)
    assert tr.group_names == ["group_3", "group_5"] and tr.n_pairs == n_channels


def test_csv_text_groups_bom_comments_and_frame_rate(tmp_path):
    _, labels, readouts, _, _ = _data(n_channels=3)
    names = np.array(["rest", "touch-a", "touch-b"])[np.repeat([0, 1, 2], 15)]
    p = _write_csv(tmp_path / "r.csv", names, labels, readouts, extra_header="# frame_rate_hz: 25")
    p.write_bytes("\ufeff".encode() + b"# exported by hand\n" + p.read_bytes())
    rec = load_generic(p)
    assert [tr.name for tr in rec.trials] == ["rest", "touch-a", "touch-b"]
    assert rec.frame_rate_hz == 25.0
    assert rec.trials[1].meta["group"] == "touch-a"
    assert load_generic(p, frame_rate_hz=10.0).frame_rate_hz == 10.0


def test_reference_per_trial_and_per_frame(tmp_path):
    group, labels, readouts, _, _ = _data(n_channels=4)
    ref_g = np.array(
        [[1.0, 2.0, 3.0, 4.0], [2.0, 2.0, 2.0, 2.0], [4.0, 3.0, 2.0, 1.0]]
    )  # groups 3, 5, 7
    p = tmp_path / "a.npz"
    np.savez(p, readouts=readouts, group=group, labels=labels, reference=ref_g, frame_rate_hz=30.0)
    d = touch_dataset(load_generic(p))
    # file order 7, 3, 5 → sorted-order references rows 2, 0, 1
    want = np.concatenate(
        [(readouts[15 * k : 15 * (k + 1)] - ref_g[r]) / ref_g[r] for k, r in enumerate([2, 0, 1])]
    )
    np.testing.assert_allclose(d.x, want, rtol=1e-6)
    # a per-frame reference that varies inside a group: Eq. 2 frame by frame
    ref_f = np.random.default_rng(3).uniform(0.5, 1.5, readouts.shape)
    p2 = _write_csv(
        tmp_path / "b.csv", group, labels, readouts, refs=ref_f, extra_header="# frame_rate_hz=30"
    )
    rec = load_generic(p2)
    assert rec.trials[0].meta["reference_kind"] == "per_frame_ratio"
    np.testing.assert_allclose(
        touch_dataset(rec).x, (readouts - ref_f) / ref_f, rtol=1e-5, atol=1e-6
    )


def test_given_layout(tmp_path):
    lay = default_layout()
    rng = np.random.default_rng(0)
    p = tmp_path / "paper.npz"
    np.savez(
        p,
        readouts=rng.uniform(1, 2, (20, 28)),
        group=np.repeat([0, 1], 10),
        labels=np.repeat([0, 18], 10),
        timestamps=np.tile(np.arange(10) / 30, 2),
    )
    rec = load_generic(p, layout=lay)
    assert rec.layout is lay and "unmeasured_pairs" not in rec.meta
    np.savez(
        p,
        readouts=rng.uniform(1, 2, (20, 27)),
        group=np.repeat([0, 1], 10),
        labels=np.repeat([0, 18], 10),
        frame_rate_hz=30,
    )
    with pytest.raises(EctskinError, match="27 readout channels.*28 pairs"):
        load_generic(p, layout=lay)


def test_virtual_layout_sizes():
    for m, n in [(1, 2), (3, 3), (4, 4), (28, 8), (29, 9), (1000, 46)]:
        lay = virtual_layout(m, n_regions=3, n_markers=2)
        assert lay.n_electrodes == n and lay.n_pairs >= m > (n - 1) * (n - 2) // 2
        assert lay.n_regions == 3 and lay.n_markers == 2


def test_hdf5_round_trip_of_an_import(tmp_path):
    group, labels, readouts, markers, t = _data(n_channels=5)
    p = tmp_path / "rec.npz"
    np.savez(
        p,
        readouts=readouts,
        group=group,
        labels=labels,
        markers=markers,
        timestamps=t,
        reference=np.ones(5),
    )
    rec = load_generic(p)
    h5 = hdf5.write_recording(rec, tmp_path / "rec.h5")
    back = hdf5.read_recording(h5)
    assert back.meta["unmeasured_pairs"] == [5]
    np.testing.assert_array_equal(touch_dataset(back).x, touch_dataset(rec).x)


# --------------------------------------------------------------------------- bad files
def _csv(tmp_path, text, name="bad.csv"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


GOOD_HEADER = "group,time_s,label,c:a,c:b,c:c\n"


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("time_s,label,c:a\n0,0,1\n", "missing column 'group'"),
        ("group,label\n0,0\n", "no readout columns"),
        ("group,label,c:a,foo\n0,0,1,2\n", "unknown column 'foo'"),
        ("group,c:a,c:a,label\n0,1,1,0\n", "duplicate column 'c:a'"),
        (GOOD_HEADER + "0,0,0,1,2,3\n0,0.1,0,1,abc,3\n", r"line 3, column 'c:b'.*'abc'"),
        (GOOD_HEADER + "0,0,0,1,2,3\n0,0.1,0,1,2\n", "line 3 has 5 cells.*has 6"),
        (GOOD_HEADER + "0,0,0,1,2,3\n,0.1,0,1,2,3\n", "line 3, column 'group': empty"),
        (GOOD_HEADER + "0,0,0,1,2,3\n0,0.1,1.5,1,2,3\n", "line 3 is 1.5"),
        (GOOD_HEADER + "0,0,0,1,2,3\n0,0.1,-1,1,2,3\n", "line 3 is -1"),
        (
            GOOD_HEADER + "0,0,0,1,2,3\n0,0.0,0,1,2,3\n",
            r"timestamps must increase.*line 3 has 0.0 s",
        ),
        (GOOD_HEADER, "no data rows"),
        ("", "empty file"),
        ("group,c:a,m:tip.x,m:tip.y\n0,1,2,3\n", r"lacks column\(s\) m:tip.z"),
        ("group,c:a,c:b,ref:a\n0,1,2,3\n", "reference columns must match"),
        ("group,c:a,c:b,ref:a,ref:b,label\n0,1,2,1,0,0\n", "'b' is 0.0"),
        ("group,c:a,c:b\n0,1,2\n", "no labels"),
        ("group,label,c:a,c:b\n0,0,1,2\n0,0,1,2\n", "no timestamps and no frame rate"),
        ("# frame_rate_hz: fast\ngroup,label,c:a\n0,0,1\n", "frame_rate_hz' must be a number"),
        (GOOD_HEADER + "0,0,0,1,inf,3\n", "line 2, column 'c:b' is inf"),
    ],
)
def test_bad_csv(tmp_path, text, pattern):
    p = _csv(tmp_path, text)
    with pytest.raises(EctskinError, match=pattern) as e:
        load_generic(p)
    assert str(p) in str(e.value)


def _npz(tmp_path, **fields):
    p = tmp_path / "bad.npz"
    np.savez(p, **fields)
    return p


@pytest.mark.parametrize(
    "fields, pattern",
    [
        ({"group": np.zeros(3), "labels": np.zeros(3)}, "missing field 'readouts'"),
        ({"readouts": np.ones((3, 2)), "labels": np.zeros(3)}, "missing field 'group'"),
        (
            {"readouts": np.ones((3, 2)), "group": np.zeros(4), "labels": np.zeros(3)},
            r"'group' must have shape \(3,\).*\(4,\)",
        ),
        (
            {"readouts": np.ones((3, 2)), "group": np.zeros(3), "labels": np.zeros(2)},
            r"'labels' must have shape \(3,\)",
        ),
        (
            {"readouts": np.ones(3), "group": np.zeros(3), "labels": np.zeros(3)},
            "n_frames, n_channels",
        ),
        (
            {"readouts": np.array([["a", "b"]]), "group": np.zeros(1), "labels": np.zeros(1)},
            "must be numeric",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.zeros(3),
                "refrence": np.ones(2),
            },
            r"unknown field\(s\) \['refrence'\]",
        ),
        (
            {"readouts": np.ones((3, 2)), "group": np.array([0, 0.5, 1]), "labels": np.zeros(3)},
            "row 1 is 0.5",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.zeros(3),
                "markers": np.ones((3, 2, 2)),
            },
            r"\(3, n_markers, 3\)",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.zeros(3),
                "reference": np.ones((2, 2)),
            },
            "reference has 2 rows",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.zeros(3),
                "reference": np.array([1.0, 0.0]),
            },
            "channel 'ch2' is 0.0",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.array([0, 7, 2000]),
                "frame_rate_hz": 1.0,
            },
            "row 2 is 2000",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.zeros(3),
                "frame_rate_hz": -3.0,
            },
            "frame_rate_hz must be a number > 0",
        ),
        (
            {
                "readouts": np.ones((3, 2)),
                "group": np.zeros(3),
                "labels": np.zeros(3),
                "frame_rate_hz": 1.0,
                "channel_names": np.array(["a"]),
            },
            "must hold 2 names",
        ),
    ],
)
def test_bad_npz(tmp_path, fields, pattern):
    p = _npz(tmp_path, **fields)
    with pytest.raises(EctskinError, match=pattern) as e:
        load_generic(p)
    assert str(p) in str(e.value)


def test_npz_object_array_is_refused_without_pickle(tmp_path):
    p = tmp_path / "obj.npz"
    np.savez(
        p, readouts=np.ones((2, 1)), group=np.array(["a", 1], dtype=object), labels=np.zeros(2)
    )
    with pytest.raises(EctskinError, match="'group' cannot be read without pickle"):
        load_generic(p)


def test_not_an_npz_missing_file_and_unknown_suffix(tmp_path):
    p = _csv(tmp_path, "hello", name="fake.npz")
    with pytest.raises(EctskinError, match="not a readable .npz"):
        load_generic(p)
    np.save(tmp_path / "single.npy", np.ones(3))
    (tmp_path / "single.npz").write_bytes((tmp_path / "single.npy").read_bytes())
    with pytest.raises(EctskinError, match="single array"):
        load_generic(tmp_path / "single.npz")
    with pytest.raises(EctskinError, match="file not found"):
        load_generic(tmp_path / "none.csv")
    with pytest.raises(EctskinError, match="expected .npz or .csv"):
        load_generic(tmp_path / "x.h5")
    bad = tmp_path / "latin.csv"
    bad.write_bytes(b"group,c:\xe9\n")
    with pytest.raises(EctskinError, match="not UTF-8"):
        load_generic(bad)


# ------------------------------------------------------------- issue 12: defects 11, 12, 15
@pytest.mark.parametrize("fmt", ["csv", "npz"])
def test_nul_byte_in_a_group_id_is_one_clear_error(tmp_path, fmt):
    """Before: an h5py ValueError traceback at writing ("VLEN strings do not support embedded
    NULLs"). Now the importer names the row."""
    group = np.array(["a", "a\x00b", "a\x00b"])
    p = tmp_path / f"nul.{fmt}"
    if fmt == "csv":
        _csv(tmp_path, "# frame_rate_hz: 30\ngroup,label,c:a\na,0,1\na\x00b,0,1\na\x00b,1,2\n",
             name="nul.csv")
        where = "line 4, column 'group'"
    else:
        np.savez(p, readouts=np.ones((3, 1)), group=group, labels=np.zeros(3), frame_rate_hz=30.0)
        where = "group id at row 1"
    with pytest.raises(EctskinError, match="NUL byte") as e:
        load_generic(p)
    assert where in str(e.value) and str(p) in str(e.value)


def test_empty_group_id_is_refused_at_import(tmp_path):
    """Before: an NPZ with an empty group id imported, and the reader refused the file written."""
    for group in (["", ""], ["  ", "  "], ["a", ""]):
        p = _npz(tmp_path, readouts=np.ones((2, 1)), group=np.array(group), labels=np.zeros(2),
                 frame_rate_hz=30.0)
        with pytest.raises(EctskinError, match="group id at row [01] is empty"):
            load_generic(p)
    p = _csv(tmp_path, "# frame_rate_hz: 30\ngroup,label,c:a\n\"\",0,1\n")
    with pytest.raises(EctskinError, match="line 3, column 'group': empty"):
        load_generic(p)


def test_trial_names_hdf5_cannot_store_are_refused_at_the_door(tmp_path, layout):
    from ectskin.io.recording import Trial

    for name, pattern in (("", "must not be empty"), ("a\x00b", "NUL byte")):
        with pytest.raises(EctskinError, match=pattern):
            Trial(name, np.ones((1, layout.n_pairs)), [0.0], [0])


FIXED = "# frame_rate_hz: 30\ngroup,label,c:a,c:b\n" + "".join(
    f"g,0,1.50000,1.00{k:03d}\n" for k in range(230, 240)
)


@pytest.mark.parametrize(
    "tail, why",
    [
        ("g,1,1.50000,1.0", "its last number '1.0' has 1 decimal, the 10 rows before it have 5"),
        ("g,1,1.50000,1.", "its last number '1.' has 0 decimals"),
        ("g,1,1.500", "it has 3 of the header's 4 cells"),
        ("g,1,1.50000,", "it ends with an empty cell"),
        ("g,1,1.50000,1.00239e", "its last cell '1.00239e' is not a number"),
    ],
)
def test_last_line_cut_short_is_left_out_with_a_warning(tmp_path, caplog, tail, why):
    """Issue 12, defect 15: before, '1.00239' cut to '1.0' at the end of a file without a final
    newline was stored as 1.0. Now the cut line is left out, said so, and the rows before kept."""
    p = _csv(tmp_path, FIXED + tail, name="cut.csv")
    with caplog.at_level("WARNING"):
        rec = load_generic(p)
    assert rec.n_frames == 10  # the rows before it
    np.testing.assert_array_equal(rec.trials[0].capacitance[:, 1], 1.0 + np.arange(230, 240) / 1e5)
    assert "line 13 is cut short" in caplog.text and why in caplog.text
    assert "file looks truncated" in caplog.text
    assert rec.meta["import_notes"] == [n for n in rec.meta["import_notes"] if "line 13" in n]


@pytest.mark.parametrize(
    "text",
    [
        FIXED + "g,1,1.50000,1.00239",  # complete, only the final newline missing
        FIXED + "g,1,1.50000,1.00239\n",
        "# frame_rate_hz: 30\ngroup,label,c:a\ng,0,1.25\ng,0,1.5\ng,1,2.0",  # mixed decimals
    ],
)
def test_complete_last_line_is_kept(tmp_path, caplog, text):
    p = _csv(tmp_path, text, name="ok.csv")
    with caplog.at_level("WARNING"):
        rec = load_generic(p)
    assert rec.n_frames == text.count("\ng,")
    assert "cut short" not in caplog.text and "import_notes" not in rec.meta


# ------------------------------------------------------------- issue 12: dead and huge readouts
def test_all_zero_channel_is_left_out_with_a_note(tmp_path, caplog):
    """Before: a channel reading 0 in every frame imported silently and failed training (Eq. 2
    divides by its reference of 0). Now it is stored as NaN, listed as unmeasured and noted."""
    group, labels, readouts, _, t = _data(n_channels=6)
    readouts[:, 2] = 0.0
    readouts[:, 4] = np.nan  # never read at all
    p = _write_csv(tmp_path / "dead.csv", group, labels, readouts, t=t)
    with caplog.at_level("WARNING"):
        rec = load_generic(p)
    assert rec.meta["unmeasured_pairs"] == [2, 4]
    assert rec.meta["dropped_channels"] == ["ch2", "ch4"]
    assert rec.meta["channel_names"] == ["ch0", "ch1", "ch3", "ch5"]
    assert "channel 'ch2' reads 0 in every frame" in caplog.text
    assert "channel 'ch4' has no readout in any frame" in caplog.text
    assert len(rec.meta["import_notes"]) == 2
    assert all(np.isnan(tr.capacitance[:, [2, 4]]).all() for tr in rec.trials)
    d = touch_dataset(rec)  # training data: the dead channels are left out, nothing fails
    assert d.pair_names == ["ch0", "ch1", "ch3", "ch5"] and np.isfinite(d.x).all()
    readouts[:, :] = 0.0
    p = _write_csv(tmp_path / "all.csv", group, labels, readouts, t=t)
    with pytest.raises(EctskinError, match="no channel has a usable readout"):
        load_generic(p)


@pytest.mark.parametrize(
    "where, pattern",
    [
        ("readouts", r"line 3, column 'c:ch1': readout 1.7e\+308 is beyond ±1e\+30"),
        ("markers", r"line 3, column 'm:mk0.y': marker coordinate -1.7e\+308"),
        ("time", r"line 3, column 'time_s': time 1.7e\+308"),
    ],
)
def test_huge_numbers_are_refused_at_import_csv(tmp_path, where, pattern):
    """Before: 1.7e308 imported and overflowed later (calibration, statistics)."""
    group, labels, readouts, markers, t = _data(n_channels=3, n_markers=1)
    if where == "readouts":
        readouts[1, 1] = 1.7e308
    elif where == "markers":
        markers[1, 0, 1] = -1.7e308
    else:
        t[1] = 1.7e308
    p = _write_csv(tmp_path / "huge.csv", group, labels, readouts, markers, t)
    with pytest.raises(EctskinError, match=pattern):
        load_generic(p)


def test_huge_numbers_are_refused_at_import_npz(tmp_path):
    group, labels, readouts, markers, t = _data(n_channels=3, n_markers=1)
    readouts[5, 2] = -1.7e308
    p = _npz(tmp_path, readouts=readouts, group=group, labels=labels, timestamps=t)
    with pytest.raises(EctskinError, match=r"'readouts' row 5, channel 2: readout -1.7e\+308"):
        load_generic(p)
    readouts[5, 2] = 1.0
    p = _npz(tmp_path, readouts=readouts, group=group, labels=labels, timestamps=t,
             reference=np.full(3, 1.7e308))
    with pytest.raises(EctskinError, match="reference 1.7e\\+308 is beyond"):
        load_generic(p)


def test_names_with_a_nul_byte_are_refused_before_hdf5(tmp_path):
    """Found by the fuzz suite: a marker name with a NUL byte imported and then failed in h5py
    (ValueError) when the recording was written."""
    group, labels, readouts, markers, t = _data(n_channels=3, n_markers=2)
    p = _npz(tmp_path, readouts=readouts, group=group, labels=labels, markers=markers,
             timestamps=t, marker_names=np.array(["tip", "a\x00b"]))
    with pytest.raises(EctskinError, match="field 'marker_names' entry 1 is 'a\\\\x00b'"):
        load_generic(p)
    p = _csv(tmp_path, "# frame_rate_hz: 30\ngroup,label,c:a,m:a\x00b.x,m:a\x00b.y,m:a\x00b.z\n"
                       "1,0,1,2,3,4\n")
    with pytest.raises(EctskinError, match="column name 'm:a\\\\x00b.x' contains a NUL byte"):
        load_generic(p)
    # a layout built in Python with such a name is refused where it is made
    with pytest.raises(EctskinError, match="marker name 'a\\\\x00b' must be non-empty text without NUL"):
        virtual_layout(3, 2, 2, ["tip", "a\x00b"])


def test_group_ids_that_do_not_fit_int64_are_refused(tmp_path):
    """Found by the fuzz suite: float ids like 1e300 were cast to int64 (undefined, one value for
    all), so different groups could merge into one trial."""
    p = _npz(tmp_path, readouts=np.ones((2, 1)), group=np.array([1e300, 2e300]),
             labels=np.zeros(2), frame_rate_hz=30.0)
    with pytest.raises(EctskinError, match="row 0 is 1e\\+300, expected an integer id"):
        load_generic(p)
    p = _npz(tmp_path, readouts=np.ones((2, 1)), group=np.array([1, 2**64 - 1], dtype=np.uint64),
             labels=np.zeros(2), frame_rate_hz=30.0)
    with pytest.raises(EctskinError, match="row 1 is 18446744073709551615, beyond the int64"):
        load_generic(p)
