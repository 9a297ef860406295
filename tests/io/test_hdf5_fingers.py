"""The fingers axis: checks at the door, HDF5 format version 4, files of versions 2 and 3.

``tests/data/recording_v2.h5`` was written by the format-version-2 code (the commit before the
second finger) with :func:`v2_fixture_recording` below; ``tests/data/recording_v3.h5`` by the
format-version-3 code (second finger in suffixed columns) with the same two trials plus
``trial_0002`` of :func:`v3_two_finger_expected`. Reading old files is so tested against real
old files.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from test_ground_truth import assert_snippet_agrees  # the docs' h5py-only reader

from ectskin import EctskinError
from ectskin.io import require_ground_truth
from ectskin.io.hdf5 import (
    FORMAT_VERSION,
    RecordingWriter,
    list_trials,
    read_recording,
    write_recording,
)
from ectskin.io.recording import FINGER_FRAME_FIELDS, Recording, Trial
from ectskin.layout import default_layout

DATA = Path(__file__).resolve().parents[1] / "data"
V2_FILE = DATA / "recording_v2.h5"
V3_FILE = DATA / "recording_v3.h5"
N = 6
NAN2 = [np.nan, np.nan]


@pytest.fixture(scope="module")
def layout():
    return default_layout()


def v2_fixture_recording(layout) -> Recording:
    """What ``tests/data/recording_v2.h5`` holds (written by ``write_recording``, version 2),
    and the first two trials of ``recording_v3.h5``."""
    P, M = layout.n_pairs, layout.n_markers
    touch = Trial(
        "trial_0000",
        capacitance=1.0 + 0.01 * np.arange(5 * P).reshape(5, P),
        timestamps=np.arange(5) / 30.0,
        labels=np.array([0, 0, 4, 4, 4], dtype=np.int16),
        inflation=(0.0, 10.0, 20.0),
        region=4,
        markers=np.arange(5 * M * 3, dtype=np.float64).reshape(5, M, 3),
        force=np.array([0.0, 0.0, 0.5, 1.0, 1.5]),
        contact=np.array([False, False, True, True, True]),
        finger_uv_mm=np.array(
            [[np.nan, np.nan], [1.0, 50.0], [1.0, 50.0], [1.5, 50.5], [2.0, 51.0]]
        ),
        finger_height_mm=np.array([np.nan, 3.0, 0.0, 0.0, 0.0]),
        finger_surface="front",
        meta={"kind": "touch"},
    )
    none = Trial(
        "trial_0001",
        capacitance=2.0 + 0.01 * np.arange(3 * P).reshape(3, P),
        timestamps=np.arange(3) / 30.0,
        labels=np.zeros(3, dtype=np.int16),
        inflation=(20.0, 0.0, 10.0),
        meta={"kind": "no_contact"},
    )
    return Recording(layout, [touch, none], 30.0, meta={"source": "format version 2 fixture"})


def v3_two_finger_expected() -> dict:
    """``trial_0002`` of ``recording_v3.h5`` on the fingers axis, written out by hand from what
    the format-3 code stored: the first finger on the front throughout (u, v) = (0, 60) with a
    force rising 0.5 → 1.0 N; a second finger on the back in frames 2 and 3 only, at (-15, 20)
    then (-15.5, 20.25), 0.8 N there and 0 elsewhere. Version 3 kept no height for the second
    finger (it existed only on the skin): 0 in contact, NaN (away) elsewhere."""
    return {
        "contact": [[True, False], [True, False], [True, True], [True, True], [True, False],
                    [True, False]],
        "finger_uv_mm": [
            [[0.0, 60.0], NAN2],
            [[0.0, 60.0], NAN2],
            [[0.0, 60.0], [-15.0, 20.0]],
            [[0.0, 60.0], [-15.5, 20.25]],
            [[0.0, 60.0], NAN2],
            [[0.0, 60.0], NAN2],
        ],
        "finger_height_mm": [[0.0, np.nan], [0.0, np.nan], [0.0, 0.0], [0.0, 0.0], [0.0, np.nan],
                             [0.0, np.nan]],
        "force": [[0.5, 0.0], [0.6, 0.0], [0.7, 0.8], [0.8, 0.8], [0.9, 0.0], [1.0, 0.0]],
        "finger_surface": ("front", "back"),
    }


def two_fingers(n: int = N) -> dict:
    """Finger 0 on the skin throughout; finger 1 away, then on the skin in frames 2..3, then
    hovering 5 mm above it."""
    on = np.zeros((n, 2), dtype=bool)
    on[:, 0] = True
    on[2:4, 1] = True
    uv = np.full((n, 2, 2), np.nan)
    uv[:, 0] = [0.0, 60.0]
    uv[2:4, 1] = [[-15.0, 20.0], [-15.5, 20.25]]
    uv[4:, 1] = [-15.5, 20.25]
    height = np.where(on, 0.0, np.nan)
    height[4:, 1] = 5.0
    force = np.where(on, 0.8, 0.0)
    force[:, 0] = np.linspace(0.5, 1.0, n)
    return {
        "contact": on,
        "finger_uv_mm": uv,
        "finger_height_mm": height,
        "force": force,
        "finger_surface": ("front", "back"),
    }


def trial(name="t", layout=None, n=N, **kw) -> Trial:
    P = (layout or default_layout()).n_pairs
    return Trial(
        name,
        capacitance=np.full((n, P), 1.0),
        timestamps=np.arange(n) / 30.0,
        labels=np.zeros(n, dtype=np.int16),
        **kw,
    )


# ------------------------------------------------------------------------ the Trial
def test_a_trial_counts_its_fingers_and_gives_each_alone():
    t = trial(**two_fingers(), finger_radius_mm=[8.0, np.nan], finger_modulus_mpa=[0.05, 0.07])
    assert t.n_fingers == 2 and t.n_contacts.tolist() == [1, 1, 2, 2, 1, 1]
    assert t.contact.shape == (N, 2) and t.finger_uv_mm.shape == (N, 2, 2)
    f1 = t.finger(1)
    assert (f1.index, f1.surface, np.isnan(f1.radius_mm), f1.modulus_mpa) == (1, "back", True, 0.07)
    assert f1.contact.tolist() == [False, False, True, True, False, False]
    assert f1.uv_mm[3].tolist() == [-15.5, 20.25] and f1.height_mm[5] == 5.0
    assert f1.force.tolist() == [0.0, 0.0, 0.8, 0.8, 0.0, 0.0]
    assert t.finger(0).force.tolist() == np.linspace(0.5, 1.0, N).tolist()
    with pytest.raises(EctskinError, match=r"trial 't' has 2 finger\(s\), so no finger 2"):
        t.finger(2)
    bare = trial()
    assert bare.n_fingers == 0 and bare.n_contacts is None and bare.finger_surface == ()
    assert bare.finger_radius_mm is None and bare.force is None


def test_one_finger_without_the_axis_is_finger_0():
    d = two_fingers()
    flat = {k: v[:, 0] for k, v in d.items() if k in FINGER_FRAME_FIELDS}
    a = trial(**flat, finger_surface="front")
    b = trial(**{k: v[:, :1] for k, v in d.items() if k in FINGER_FRAME_FIELDS},
              finger_surface=("front",))
    assert a.n_fingers == b.n_fingers == 1 and a.finger_surface == ("front",)
    for k in FINGER_FRAME_FIELDS:
        x, y = getattr(a, k), getattr(b, k)
        assert x.shape == y.shape == (N, 1, 2)[: 2 + (k == "finger_uv_mm")]
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), k
    assert a.finger_radius_mm is None and np.isnan(a.finger(0).radius_mm)  # unknown


def _with(**change) -> dict:
    d = two_fingers()
    d.update(change)
    return d


def _set(field: str, index: tuple, value) -> dict:
    d = two_fingers()
    arr = np.array(d[field], dtype=int if field == "contact" else float)
    arr[index] = value
    d[field] = arr
    return d


@pytest.mark.parametrize(
    "kw, match",
    [
        (  # a field that misses a finger
            _with(force=two_fingers()["force"][:, 0]),
            r"trial 't': the finger fields disagree on the number of fingers \(force 1, "
            r"contact 2, finger_uv_mm 2, finger_height_mm 2, finger_surface 2\)",
        ),
        (_with(finger_surface=("front",)), r"disagree on the number of fingers.*finger_surface 1"),
        (
            _with(finger_surface=("front", "back", "left")),
            r"disagree on the number of fingers.*finger_surface 3",
        ),
        (_with(finger_surface=("front", "top")), r"'finger_surface\[1\]'.*got 'top'"),
        (
            _with(finger_radius_mm=[8.0, 8.0, 8.0]),
            r"disagree on the number of fingers.*finger_radius_mm 3",
        ),
        (  # in contact, but away (no point, no height)
            {**_set("finger_uv_mm", (2, 1), np.nan),
             "finger_height_mm": _set("finger_height_mm", (2, 1), np.nan)["finger_height_mm"]},
            r"finger_uv_mm\[2, 1\] is \[nan, nan\] in contact, expected two finite numbers",
        ),
        (  # a point for a finger that is away (no height)
            _set("finger_uv_mm", (0, 1), [1.0, 2.0]),
            r"frame 0, finger 1 has finger_uv_mm \[1.0, 2.0\] but finger_height_mm nan",
        ),
        (
            _set("finger_uv_mm", (1, 0), [np.nan, 60.0]),
            r"finger_uv_mm\[1, 0\] is \[nan, 60.0\], expected two finite numbers \(mm\) or two NaN",
        ),
        (
            _set("finger_height_mm", (3, 1), 1.0),
            r"finger_height_mm\[3, 1\] is 1.0 in contact, expected 0",
        ),
        (
            _set("finger_height_mm", (5, 1), -2.0),
            r"finger_height_mm\[5, 1\] is -2.0, expected a height >= 0 mm",
        ),
        (
            _set("force", (2, 1), -1.0),
            r"force\[2, 1\] is -1.0, expected a force >= 0 N or NaN",
        ),
        (_set("force", (1, 0), -0.1), r"force\[1, 0\] is -0.1, expected a force >= 0 N"),
        (_set("force", (3, 0), np.inf), r"force\[3, 0\] is inf, expected a force >= 0 N"),
        (
            _set("force", (0, 1), 0.3),
            r"force\[0, 1\] is 0.3 without contact \(contact\[0, 1\] False\), expected 0 or NaN",
        ),
        (
            _set("contact", (2, 1), 2),
            r"contact must be bool \(or 0/1\), found 2 at index \(2, 1\)",
        ),
        (_with(finger_uv_mm=np.zeros((N, 2, 3))), r"finger_uv_mm must have shape \(6, n_fingers, 2\)"),
        (_with(contact=np.ones(N + 1, bool)), r"contact must have shape .* one finger, \(6,\); got \(7,\)"),
        (_with(finger_radius_mm=[8.0, -8.0]), r"finger_radius_mm\[1\] is -8.0, expected a radius"),
        (_with(finger_modulus_mpa=[0.0, 1.0]), r"finger_modulus_mpa\[0\] is 0.0, expected a modulus"),
        (_with(inflation=(0.0, np.nan)), r"trial 't': inflation\[1\] is nan ml, expected a finite"),
        (_with(inflation=(-1e9,)), r"inflation\[0\] is -1000000000.0 ml, expected a finite volume"),
    ],
)
def test_trial_refuses_bad_fingers(kw, match):
    with pytest.raises(EctskinError, match=match):
        trial(**kw)


def test_unknown_forces_and_finger_properties_are_allowed():
    t = trial(**_set("force", (slice(None), 1), np.nan), finger_radius_mm=[np.nan, 9.0])
    assert np.isnan(t.force[:, 1]).all() and t.finger_radius_mm[1] == 9.0


# ------------------------------------------------------------------------ format 4
def _same(a: Trial, b: Trial) -> None:
    for field in (*FINGER_FRAME_FIELDS, "finger_radius_mm", "finger_modulus_mpa"):
        x, y = getattr(a, field), getattr(b, field)
        assert (x is None) == (y is None), (a.name, field)
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape, (a.name, field)
            assert x.tobytes() == y.tobytes(), (a.name, field)
    assert a.finger_surface == b.finger_surface and a.n_fingers == b.n_fingers


def _three_fingers(layout) -> Trial:
    on = np.array([[1, 1, 0], [1, 1, 1], [0, 0, 0]], dtype=bool)
    uv = np.where(on[..., None], np.full((3, 3, 2), 1.5), np.nan)
    uv[2, 2] = [4.0, 5.0]  # hovering
    height = np.where(on, 0.0, np.nan)
    height[2, 2] = 7.5
    return trial(
        "three", layout, n=3, contact=on, finger_uv_mm=uv, finger_height_mm=height,
        force=np.where(on, 1.0, 0.0), finger_surface=("front", None, "left"),
        finger_radius_mm=[7.0, 8.0, 9.0],
    )


def test_write_recording_round_trips_the_fingers(tmp_path, layout):
    trials = [
        trial("two", layout, **two_fingers(), finger_radius_mm=[8.0, 7.0],
              finger_modulus_mpa=[np.nan, 0.1]),
        _three_fingers(layout),
        trial("one", layout, **{k: v[:, 0] for k, v in two_fingers().items() if k != "finger_surface"}),
        trial("none", layout, n=3),
    ]
    rec = Recording(layout, trials, 30.0)
    back = read_recording(write_recording(rec, tmp_path / "r.h5"))
    assert back.format_version == FORMAT_VERSION == 4
    for a, b in zip(rec.trials, back.trials, strict=True):
        _same(a, b)
    assert back.trial("two").contact.dtype == np.bool_
    rows = list_trials(tmp_path / "r.h5")
    assert [r["n_fingers"] for r in rows] == [2, 3, 1, 0]
    assert [r["finger_surface"] for r in rows] == [
        ("front", "back"), ("front", None, "left"), (None,), ()
    ]
    assert rows[1]["finger_radius_mm"] == (7.0, 8.0, 9.0)
    with h5py.File(tmp_path / "r.h5", "r") as f:  # the axis as such, as wide as the widest trial
        assert int(f.attrs["format_version"]) == 4
        assert f["frames/contact"].shape == (N + 3 + N + 3, 3)
        assert f["frames/finger_uv_mm"].shape[1:] == (3, 2) and f["frames/force"].shape[1] == 3
        assert f["trials/n_fingers"][()].tolist() == [2, 3, 1, 0]
        assert f["trials/finger_surface"].asstr()[0].tolist() == ["front", "back", ""]
        assert f["frames/contact"][N : N + 3].tolist() == trials[1].contact.tolist()
        assert not f["frames/contact"][:N, 2].any()  # the columns a trial does not use
        assert "contact2" not in f["frames"] and "finger2_surface" not in f["trials"]
    # one finger only: a one-wide axis, and the ground truth is complete
    solo = read_recording(
        write_recording(Recording(layout, trials[2:], 30.0), tmp_path / "s.h5")
    )
    with h5py.File(tmp_path / "s.h5", "r") as f:
        assert f["frames/contact"].shape == (N + 3, 1)
    assert solo.trials[0].n_fingers == 1
    require_ground_truth(Recording(layout, solo.trials[:1], 30.0))


def test_the_live_writer_records_fingers_and_widens_its_axis(tmp_path, layout):
    two = trial("two", layout, **two_fingers())
    three = _three_fingers(layout)
    path = tmp_path / "live.h5"
    with RecordingWriter(path, layout, 30.0, flush_interval_s=0.0) as w:
        w.start_trial("one", finger_surface="front")  # one finger: the file's axis is 1 wide
        w.append(two.capacitance[:2], two.timestamps[:2], contact=True,
                 finger_uv_mm=[[0.0, 60.0]] * 2, finger_height_mm=0.0, force=[0.5, 0.6])
        w.start_trial("two", finger_surface=("front", "back"))
        for rows in (slice(0, 3), slice(3, N)):  # two appends
            w.append(
                two.capacitance[rows],
                two.timestamps[rows],
                force=two.force[rows],
                contact=two.contact[rows],
                finger_uv_mm=two.finger_uv_mm[rows],
                finger_height_mm=two.finger_height_mm[rows],
            )
        part = read_recording(path, allow_partial=True)  # widened while recording
        _same(two, part.trial("two"))
        w.start_trial("three", finger_radius_mm=[7.0, 8.0, 9.0])  # faces from the appends: none
        w.append(three.capacitance, three.timestamps, contact=three.contact,
                 finger_uv_mm=three.finger_uv_mm, finger_height_mm=three.finger_height_mm,
                 force=three.force)
        w.start_trial("scalar")  # one frame of two fingers
        w.append(two.capacitance[0], 0.0, contact=[[True, True]], force=[[0.5, 0.25]])
        with pytest.raises(EctskinError, match=r"trial 'scalar'.*1 finger\(s\) here, but the "
                           r"trial's earlier frames had 2; a trial keeps its fingers"):
            w.append(two.capacitance[0], 1.0, contact=True, force=0.5)
        w.start_trial("faces", finger_surface=("front", "back"))
        with pytest.raises(EctskinError, match=r"trial 'faces'.*disagree on the number of "
                           r"fingers \(force 1, contact 1, finger_surface 2\)"):
            w.append(two.capacitance[0], 0.0, contact=True, force=0.5)
        with pytest.raises(EctskinError, match=r"trial 'bad'.*'finger_surface\[0\]'.*got 'top'"):
            w.start_trial("bad", finger_surface="top")
        with pytest.raises(EctskinError, match=r"trial 'nan'.*inflation\[0\] is nan ml"):
            w.start_trial("nan", inflation=(np.nan, 0.0))
    back = read_recording(path)
    _same(two, back.trial("two"))
    got = back.trial("three")
    assert got.finger_surface == (None, None, None) and got.finger_radius_mm.tolist() == [7, 8, 9]
    assert got.finger_uv_mm.tobytes() == three.finger_uv_mm.tobytes()
    assert back.trial("one").n_fingers == 1 and back.trial("one").force.tolist() == [[0.5], [0.6]]
    s = back.trial("scalar")
    assert s.force.tolist() == [[0.5, 0.25]] and s.contact.tolist() == [[True, True]]
    with h5py.File(path, "r") as f:
        assert f["frames/contact"].shape[1] == 3 and f["trials/finger_surface"].shape[1] == 3


def test_a_v4_trial_beyond_the_fingers_axis_is_damaged(tmp_path, layout):
    path = write_recording(Recording(layout, [trial("t", layout, **two_fingers())], 30.0),
                           tmp_path / "x.h5")
    with h5py.File(path, "a") as f:
        f["trials/n_fingers"][0] = 3
    with pytest.raises(EctskinError, match=r"/trials/n_fingers\[0\] \(trial 't'\) is 3, "
                       r"expected 0..2 \(the fingers axis"):
        read_recording(path)


# ------------------------------------------------------------------------ older files
def test_v2_file_reads_with_one_finger(layout, tmp_path):
    with h5py.File(V2_FILE, "r") as f:  # really a file of the version-2 code
        assert f.attrs["format_version"] == 2 and "n_fingers" not in f["trials"]
        assert f["frames/contact"].shape == (8,)
    rec = read_recording(V2_FILE)
    assert rec.format_version == 2
    want = v2_fixture_recording(layout)
    for got, exp in zip(rec.trials, want.trials, strict=True):
        for field in ("capacitance", "markers", *FINGER_FRAME_FIELDS):
            a, b = getattr(got, field), getattr(exp, field)
            assert (a is None) == (b is None) and (a is None or a.tobytes() == b.tobytes()), field
            assert a is None or a.shape == b.shape, field  # (n, 1, ...): one finger on the axis
        assert got.finger_surface == exp.finger_surface and got.n_fingers == exp.n_fingers
    assert [t.n_fingers for t in rec.trials] == [1, 0]
    rows = list_trials(V2_FILE)
    assert [r["n_fingers"] for r in rows] == [1, 0]
    assert [r["finger_surface"] for r in rows] == [("front",), ()]
    # written again: the current version, with the same one finger
    again = read_recording(write_recording(rec, tmp_path / "again.h5"))
    assert again.format_version == 4
    for a, b in zip(rec.trials, again.trials, strict=True):
        _same(a, b)


def test_v3_file_reads_its_second_finger_as_finger_1(layout, tmp_path):
    with h5py.File(V3_FILE, "r") as f:  # really a file of the version-3 code
        assert f.attrs["format_version"] == 3
        assert list(f["trials/finger2_surface"].asstr()[()]) == ["", "", "back"]
        assert f["frames/contact2"].shape == (14,) and f["frames/finger2_uv_mm"].shape == (14, 2)
    rec = read_recording(V3_FILE)
    assert rec.format_version == 3 and [t.name for t in rec.trials][:2] == ["trial_0000",
                                                                           "trial_0001"]
    for got, exp in zip(rec.trials[:2], v2_fixture_recording(layout).trials, strict=True):
        _same(exp, got)  # the one-finger trials as in version 2
    t = rec.trial("trial_0002")
    want = v3_two_finger_expected()
    assert t.n_fingers == 2 and t.finger_surface == want["finger_surface"]
    for field in FINGER_FRAME_FIELDS:
        got = getattr(t, field)
        exp = np.array(want[field], dtype=got.dtype)
        assert got.shape == exp.shape, field
        np.testing.assert_array_equal(got, exp, err_msg=field)  # NaN where NaN, every value
    assert t.finger_radius_mm is None and t.finger_modulus_mpa is None  # unknown in version 3
    assert t.n_contacts.tolist() == [1, 1, 2, 2, 1, 1]
    P = layout.n_pairs
    np.testing.assert_array_equal(t.capacitance, 3.0 + 0.01 * np.arange(N * P).reshape(N, P))
    assert (t.inflation, t.region, t.labels.tolist()) == ((10.0, 10.0, 0.0), 12, [12] * N)
    rows = list_trials(V3_FILE)
    assert [r["n_fingers"] for r in rows] == [1, 0, 2]
    assert rows[2]["finger_surface"] == ("front", "back") and "has_contact2" not in rows[2]
    # written again: format 4 with the second finger on the axis
    again = read_recording(write_recording(rec, tmp_path / "again.h5"))
    assert again.format_version == 4
    _same(t, again.trial("trial_0002"))


def test_docs_snippet_reads_versions_2_3_and_4_onto_the_axis(tmp_path, layout):
    assert_snippet_agrees(V2_FILE)
    assert_snippet_agrees(V3_FILE)
    rec = Recording(layout, [trial("two", layout, **two_fingers()), _three_fingers(layout),
                             trial("none", layout, n=2)], 30.0)
    assert_snippet_agrees(write_recording(rec, tmp_path / "v4.h5"))


def _damaged_v3(tmp_path: Path, edit) -> Path:
    path = tmp_path / "v3.h5"
    shutil.copyfile(V3_FILE, path)
    with h5py.File(path, "a") as f:
        edit(f)
    return path


@pytest.mark.parametrize(
    "edit, match",
    [
        (
            lambda f: f.__delitem__("trials/finger2_surface"),
            r"missing dataset /trials/finger2_surface \(required by ectskin.recording version 3\)",
        ),
        (
            lambda f: f["trials/has_force2"].__setitem__(2, False),
            r"trial 'trial_0002' has has_contact2=True, has_finger2_uv_mm=True, "
            r"has_force2=False; a second finger \(version 3\) gives all three or none",
        ),
        (
            lambda f: f["trials/has_finger_height_mm"].__setitem__(2, False),
            r"trial 'trial_0002' has a second finger but not the first finger's contact",
        ),
    ],
)
def test_a_damaged_v3_second_finger_is_one_clear_error(tmp_path, edit, match):
    with pytest.raises(EctskinError, match=match):
        read_recording(_damaged_v3(tmp_path, edit))
