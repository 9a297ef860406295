"""Generic imports of real data as it comes: readouts that are already differences (difference
imaging: Eq. 2 is the identity on them, no reference), and files with contact labels alone (one
touch class, no regions)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.io.calibration import calibrate, choose_reference, is_difference, touch_reference
from ectskin.io.generic import load_generic
from ectskin.learn.data.contact import contact_dataset
from ectskin.learn.data.touch import touch_dataset
from ectskin.learn.data.track import track_dataset


def _file(path, *, labels=True, reference=False, markers=False):
    """Two groups of differences (3 channels): "rest" (no finger) and "press" (a finger at a
    known point); the readouts are given to 9 digits, some negative, some zero."""
    rng = np.random.default_rng(7)
    n = 8
    d = np.round(rng.normal(0, 0.01, (2 * n, 3)), 9)
    d[0, 0] = 0.0
    contact = np.r_[np.zeros(n), np.ones(n)].astype(bool)
    pos = np.where(contact[:, None], [12.0, 20.0], np.nan)
    fields = {
        "readouts": d,
        "group": np.repeat(["rest", "press"], n),
        "contact": contact,
        "position_mm": pos,
        "force_n": np.where(contact, 1.5, 0.0),
        "surface": np.where(contact, "front", ""),
        "frame_rate_hz": 30.0,
    }
    if labels:
        fields["labels"] = contact.astype(int)
    if reference:
        fields["reference"] = np.ones(3)
    if markers:
        fields["markers"] = rng.normal(0, 1, (2 * n, 2, 3))
    np.savez(path, **fields)
    return path, d


def test_difference_readouts_are_calibrated_by_the_identity(tmp_path):
    src, d = _file(tmp_path / "diff.npz")
    rec = load_generic(src, readouts="difference")
    assert rec.meta["readouts"] == "difference" and is_difference(rec)
    write_recording(rec, tmp_path / "diff.h5")
    back = read_recording(tmp_path / "diff.h5")
    assert is_difference(back)
    refs = touch_reference(back)
    assert refs == {"rest": None, "press": None}
    data = contact_dataset(back, window=1)
    # the calibrated frames are the file's numbers themselves (float32), trial after trial
    np.testing.assert_array_equal(data.x[:, 0, :], d.astype(np.float32))
    t = touch_dataset(back)
    np.testing.assert_array_equal(t.x, d.astype(np.float32))
    # the same file taken as absolute readouts is divided by its rest state: not the identity
    absolute = contact_dataset(load_generic(src), window=1)
    assert not np.allclose(absolute.x[:, 0, :], d)
    # Eq. 2 against no reference: the identity, non-finite frames still refused
    np.testing.assert_array_equal(calibrate(d, None), d.astype(np.float32))
    with pytest.raises(EctskinError, match=r"frame 1, channel 2 is nan"):
        calibrate(np.where(np.arange(6).reshape(2, 3) == 5, np.nan, 1.0), None)


def test_difference_readouts_take_no_reference(tmp_path):
    src, _ = _file(tmp_path / "ref.npz", reference=True)
    with pytest.raises(EctskinError, match=r"ref\.npz: field 'reference' with readouts='diff"):
        load_generic(src, readouts="difference")
    rec = load_generic(_file(tmp_path / "d.npz")[0], readouts="difference")
    with pytest.raises(EctskinError, match="Eq. 2 takes no reference, expected none"):
        touch_reference(rec, reference=np.ones(rec.n_pairs))
    choice = choose_reference(rec)
    assert choice.value == "auto" and "differences" in choice.text
    with pytest.raises(EctskinError, match="--reference does not apply"):
        choose_reference(rec, given=rec)
    with pytest.raises(EctskinError, match="allowed values are 'absolute', 'difference'"):
        load_generic(src, readouts="ratio")


def test_tracking_with_prior_knowledge_refuses_differences(tmp_path):
    rec = load_generic(_file(tmp_path / "m.npz", markers=True)[0], readouts="difference")
    with pytest.raises(EctskinError, match=r"readouts are differences .*--no-prior"):
        track_dataset(rec, window=2, prior=True)


def test_contact_labels_alone_give_one_touch_class(tmp_path):
    src, _ = _file(tmp_path / "c.npz", labels=False)
    rec = load_generic(src)
    assert [t.region for t in rec.trials] == [0, 1] and rec.layout.n_regions == 1
    np.testing.assert_array_equal(rec.trial("press").labels, 1)
    np.testing.assert_array_equal(rec.trial("rest").labels, 0)
    d = contact_dataset(rec, window=1)
    assert d.count.tolist() == [0] * 8 + [1] * 8
    np.testing.assert_array_equal(d.uv[8:, 0], [[12.0, 20.0]] * 8)


def test_the_import_command_takes_difference_readouts(tmp_path):
    from ectskin.cli import main

    src, d = _file(tmp_path / "cli.npz")
    out = tmp_path / "cli.h5"
    assert main(["import", "generic", str(src), "-o", str(out), "--readouts", "difference"]) == 0
    rec = read_recording(out)
    assert is_difference(rec)
    np.testing.assert_array_equal(contact_dataset(rec, window=1).x[:, 0], d.astype(np.float32))
