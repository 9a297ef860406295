"""A second finger's ground truth: checks at the door, HDF5 format version 3, version-2 files.

``tests/data/recording_v2.h5`` was written by the format-version-2 code (the commit before the
second finger) with :func:`v2_fixture_recording` below, so that reading version-2 files is tested
against a real old file.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import require_ground_truth
from ectskin.io.hdf5 import (
    FORMAT_VERSION,
    RecordingWriter,
    list_trials,
    read_recording,
    write_recording,
)
from ectskin.io.recording import SECOND_FINGER_FIELDS, Recording, Trial
from ectskin.layout import default_layout

V2_FILE = Path(__file__).resolve().parents[1] / "data" / "recording_v2.h5"
N = 6


@pytest.fixture(scope="module")
def layout():
    return default_layout()


def v2_fixture_recording(layout) -> Recording:
    """What ``tests/data/recording_v2.h5`` holds (written by ``write_recording``, version 2)."""
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


def first(n: int = N) -> dict:
    """The first finger on the skin throughout."""
    return {
        "contact": np.ones(n, dtype=bool),
        "finger_uv_mm": np.tile([0.0, 60.0], (n, 1)),
        "finger_height_mm": np.zeros(n),
        "force": np.linspace(0.5, 1.0, n),
        "finger_surface": "front",
    }


def second(n: int = N) -> dict:
    """A second finger on the skin in frames 2..3 only."""
    on = np.zeros(n, dtype=bool)
    on[2:4] = True
    uv = np.full((n, 2), np.nan)
    uv[on] = [[-15.0, 20.0], [-15.5, 20.25]]
    return {
        "contact2": on,
        "finger2_uv_mm": uv,
        "force2": np.where(on, 0.8, 0.0),
        "finger2_surface": "back",
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


def test_a_trial_counts_its_fingers():
    t = trial(**first(), **second())
    assert t.has_second_finger and t.n_contacts.tolist() == [1, 1, 2, 2, 1, 1]
    one = trial(**first())
    assert not one.has_second_finger and one.n_contacts.tolist() == [1] * N
    assert (one.contact2, one.finger2_uv_mm, one.force2, one.finger2_surface) == (None,) * 4
    assert trial().n_contacts is None


def _with(**change) -> dict:
    d = {**first(), **second()}
    d.update(change)
    return d


def _uv_nan_in_contact():
    uv = second()["finger2_uv_mm"].copy()
    uv[2] = np.nan
    return uv


def _uv_set_off_contact():
    uv = second()["finger2_uv_mm"].copy()
    uv[0] = [1.0, 2.0]
    return uv


@pytest.mark.parametrize(
    "kw, match",
    [
        (
            _with(force2=None),
            r"trial 't': a second finger needs all of contact2, finger2_uv_mm, "
            r"force2; force2 missing",
        ),
        (_with(finger2_surface=None), r"finger2_surface is None; a second finger needs its face"),
        (
            {**first(), "finger2_surface": "back"},
            r"finger2_surface is 'back' but the trial has no "
            r"second finger",
        ),
        (_with(finger2_surface="top"), r"'finger2_surface'.*got 'top'"),
        (
            _with(finger2_uv_mm=_uv_nan_in_contact()),
            r"finger2_uv_mm\[2\] is \[nan, nan\] with "
            r"contact2 True, expected two finite numbers",
        ),
        (
            _with(finger2_uv_mm=_uv_set_off_contact()),
            r"finger2_uv_mm\[0\] is \[1.0, 2.0\] with "
            r"contact2 False, expected two NaN",
        ),
        (
            _with(force2=np.array([0, 0, -1.0, 0.8, 0, 0])),
            r"force2\[2\] is -1.0 with contact2 "
            r"True, expected a force >= 0 N or NaN",
        ),
        (
            _with(force2=np.array([0.3, 0, 0.8, 0.8, 0, 0])),
            r"force2\[0\] is 0.3 with contact2 "
            r"False, expected 0 or NaN",
        ),
        (
            _with(contact2=np.array([0, 0, 2, 1, 0, 0])),
            r"contact2 must be bool \(or 0/1\), found 2",
        ),
        (_with(finger2_uv_mm=np.zeros((N, 3))), r"finger2_uv_mm"),
    ],
)
def test_trial_refuses_a_bad_second_finger(kw, match):
    with pytest.raises(EctskinError, match=match):
        trial(**kw)


def test_unknown_second_force_is_allowed():
    t = trial(**_with(force2=np.array([np.nan, 0, np.nan, 0.8, np.nan, 0])))
    assert np.isnan(t.force2[2])


def _same(a: Trial, b: Trial) -> None:
    for field in (*SECOND_FINGER_FIELDS, "contact", "finger_uv_mm", "force"):
        x, y = getattr(a, field), getattr(b, field)
        assert (x is None) == (y is None), (a.name, field)
        if x is not None:
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), (a.name, field)
    assert a.finger2_surface == b.finger2_surface and a.finger_surface == b.finger_surface


def test_write_recording_round_trips_the_second_finger(tmp_path, layout):
    rec = Recording(
        layout,
        [
            trial("two", layout, **first(), **second()),
            trial("one", layout, **first()),
            trial("none", layout, n=3),
        ],
        30.0,
    )
    back = read_recording(write_recording(rec, tmp_path / "r.h5"))
    assert back.format_version == FORMAT_VERSION == 3
    for a, b in zip(rec.trials, back.trials):
        _same(a, b)
    assert back.trials[0].contact2.dtype == np.bool_
    rows = list_trials(tmp_path / "r.h5")
    assert [r["has_contact2"] for r in rows] == [True, False, False]
    assert [r["finger2_surface"] for r in rows] == ["back", None, None]
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert int(f.attrs["format_version"]) == 3
        assert list(f["trials/finger2_surface"].asstr()[()]) == ["back", "", ""]
        assert f["frames/finger2_uv_mm"].shape == (2 * N + 3, 2)
    # one finger only: no second-finger datasets at all, and the ground truth is still complete
    solo = read_recording(
        write_recording(Recording(layout, rec.trials[1:], 30.0), tmp_path / "s.h5")
    )
    with h5py.File(tmp_path / "s.h5", "r") as f:
        assert "contact2" not in f["frames"]
    assert not solo.trials[0].has_second_finger
    require_ground_truth(Recording(layout, solo.trials[:1], 30.0))


def test_the_live_writer_records_a_second_finger(tmp_path, layout):
    two = trial("two", layout, **first(), **second())
    path = tmp_path / "live.h5"
    with RecordingWriter(path, layout, 30.0) as w:
        w.start_trial("two", finger_surface="front", finger2_surface="back")
        for rows in (slice(0, 3), slice(3, N)):  # two appends
            w.append(
                two.capacitance[rows],
                two.timestamps[rows],
                force=two.force[rows],
                contact=two.contact[rows],
                finger_uv_mm=two.finger_uv_mm[rows],
                finger_height_mm=two.finger_height_mm[rows],
                contact2=two.contact2[rows],
                finger2_uv_mm=two.finger2_uv_mm[rows],
                force2=two.force2[rows],
            )
        w.start_trial("one", finger_surface="front")
        w.append(
            two.capacitance[:2],
            two.timestamps[:2],
            contact=True,
            finger_uv_mm=[[0.0, 60.0]] * 2,
            finger_height_mm=0.0,
        )
        w.start_trial("scalar", finger2_surface="left")
        w.append(two.capacitance[0], 0.0, contact2=True, finger2_uv_mm=[1.0, 2.0], force2=0.5)
        with pytest.raises(EctskinError, match=r"trial 'scalar'.*force2 missing"):
            w.append(two.capacitance[0], 1.0, contact2=True, finger2_uv_mm=[1.0, 2.0])
        with pytest.raises(EctskinError, match=r"finger2_surface is None; a second finger needs"):
            w.start_trial("bad")
            w.append(two.capacitance[0], 0.0, contact2=False, finger2_uv_mm=[np.nan] * 2, force2=0)
    back = read_recording(path)
    _same(two, back.trial("two"))
    assert not back.trial("one").has_second_finger
    s = back.trial("scalar")
    assert (
        s.finger2_surface == "left" and s.force2.tolist() == [0.5] and s.contact2.tolist() == [True]
    )


def test_v2_file_reads_without_a_second_finger(layout, tmp_path):
    with h5py.File(V2_FILE, "r") as f:  # really a file of the version-2 code
        assert f.attrs["format_version"] == 2
        assert "finger2_surface" not in f["trials"] and "has_contact2" not in f["trials"]
    rec = read_recording(V2_FILE)
    assert rec.format_version == 2
    want = v2_fixture_recording(layout)
    for got, exp in zip(rec.trials, want.trials, strict=True):
        for field in (
            "capacitance",
            "markers",
            "force",
            "contact",
            "finger_uv_mm",
            "finger_height_mm",
        ):
            a, b = getattr(got, field), getattr(exp, field)
            assert (a is None) == (b is None) and (a is None or a.tobytes() == b.tobytes()), field
        assert got.finger_surface == exp.finger_surface
        for field in (*SECOND_FINGER_FIELDS, "finger2_surface"):
            assert getattr(got, field) is None, field
    rows = list_trials(V2_FILE)
    assert [r["has_contact2"] for r in rows] == [False, False]
    assert [r["finger2_surface"] for r in rows] == [None, None]
    # written again: the current version, still without a second finger
    again = read_recording(write_recording(rec, tmp_path / "again.h5"))
    assert again.format_version == 3 and not any(t.has_second_finger for t in again.trials)


def test_a_v3_file_without_its_second_finger_columns_is_damaged(tmp_path, layout):
    path = write_recording(
        Recording(layout, [trial("t", layout, **first())], 30.0), tmp_path / "x.h5"
    )
    with h5py.File(path, "a") as f:
        del f["trials/finger2_surface"]
    with pytest.raises(
        EctskinError,
        match=r"missing dataset /trials/finger2_surface \(required "
        r"by ectskin.recording version 3\)",
    ):
        read_recording(path)
