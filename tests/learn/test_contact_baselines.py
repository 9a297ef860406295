"""The contact baselines on data as it comes: one touch class (the region classifier has one
class to learn), and a virtual layout (no physical regions: the region centre is left out with a
note, the other baselines give their numbers)."""

from __future__ import annotations

import numpy as np
import pytest
from press_data import press_npz  # tests/learn/press_data.py

from ectskin.io import read_recording, write_recording
from ectskin.io.generic import is_virtual_layout, load_generic
from ectskin.learn.baselines.contact import contact_baselines, left_out, region_centre_baseline
from ectskin.learn.data.contact import contact_dataset
from ectskin.learn.tasks import get_task
from ectskin.learn.tasks.contact import contact_report


def test_region_centre_with_one_class_answers_that_region_centre(layout, contact_recording):
    """Training frames of presses in one region only (no rest trial): every frame is class r.
    Logistic regression cannot be fit on one class; the baseline answers r's centre."""
    rec = contact_recording(layout, n_frames=6, n_trials=28)
    d = contact_dataset(rec, window=1)
    r = int(d.group_region[1])
    same = np.flatnonzero(d.group_region == r)  # touch trials of region r
    assert same.size >= 3 and d.regions_physical
    tr, te = d.select(same[:-1]), d.select(same[-1:])
    pred = region_centre_baseline(tr, te, tr.region_centre)
    face, u, v = d.region_centre[r]
    assert (pred[:, 0] == 1).all() and (pred[:, 1] == 1.0).all()  # count 1, p_contact 1
    np.testing.assert_array_equal(pred[:, 3], face)
    np.testing.assert_array_equal(pred[:, 4], u)
    np.testing.assert_array_equal(pred[:, 5], v)
    np.testing.assert_allclose(pred[:, 7], tr.force[:, 0].mean())  # the mean training force
    # its error is the distance from each true point to r's centre (one face: in the plane)
    want = np.hypot(te.uv[:, 0, 0] - u, te.uv[:, 0, 1] - v).mean()
    got = contact_report(te, pred, with_maps=False)["loc_mm_mean"]
    assert got == pytest.approx(want, rel=1e-9)
    # and the whole set of baselines runs on it (it crashed here before)
    assert set(contact_baselines(tr, te, tr.region_centre)) == {"region_centre", "knn", "ridge"}


def test_a_virtual_layout_leaves_the_region_centre_out_with_a_note(tmp_path):
    rec = load_generic(press_npz(tmp_path / "p.npz", n_presses=20, n_channels=10))
    assert rec.meta["virtual_layout"] is True and is_virtual_layout(rec)
    write_recording(rec, tmp_path / "p.h5")
    back = read_recording(tmp_path / "p.h5")
    assert is_virtual_layout(back)
    d = contact_dataset(back, window=1)
    assert not d.regions_physical
    tr, te = d.select(np.arange(0, d.n_groups, 2)), d.select(np.arange(1, d.n_groups, 2))
    out = contact_baselines(tr, te, tr.region_centre)
    assert set(out) == {"knn", "ridge"}
    for pred, _ in out.values():  # the others give a point error, well under the face's size
        assert contact_report(te, pred, with_maps=False)["loc_mm_mean"] < 10.0
    note = get_task("contact").baselines_left_out(tr)
    assert set(note) == {"region_centre"} and "virtual layout" in note["region_centre"]
    # a recording imported before the flag was stored: known by the virtual layout's name
    back.meta.pop("virtual_layout")
    assert is_virtual_layout(back)


def test_a_physical_layout_keeps_every_baseline(layout, contact_recording):
    d = contact_dataset(contact_recording(layout, n_frames=4, n_trials=8), window=1)
    assert d.regions_physical and left_out(d) == {}
    assert not is_virtual_layout(contact_recording(layout, n_frames=4, n_trials=2))
