"""The data sets' base class (ectskin.learn.data.base.SampleData) on hand-built cases: the declared
fields, select, take, concat, and the checks at the door.

What each test catches: a field cut or joined by guessing from its shape (a shared array that
happens to have one row per sample, like the electrode descriptors of a data set with as many
samples as electrodes, was cut with the samples); groups of a joined data set not renumbered
(samples of the second recording counted as the first's trials); a per-sample field added to a
data class but not declared (select would keep all its rows).
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.learn.data import ContactData, TouchData, TrackData, contact_dataset, touch_dataset


def _touch(n=6, groups=(0, 0, 1, 1, 2, 2), names=("a", "b", "c"), offset=0.0) -> TouchData:
    return TouchData(
        x=np.arange(n * 2, dtype=np.float32).reshape(n, 2) + offset,
        y=np.arange(n, dtype=np.int64) % 3,
        group=np.array(groups, dtype=np.int64),
        group_names=list(names),
        n_classes=3,
        pair_names=["p0", "p1"],
        group_region=np.arange(len(names), dtype=np.int64),
    )


def _track(n=4) -> TrackData:
    """Four samples of two trials, and four electrodes: ``electrode_desc`` has one row per
    sample by coincidence, but is shared."""
    return TrackData(
        x=np.arange(n * 3 * 2, dtype=np.float32).reshape(n, 3, 2),
        init=np.zeros((n, 1, 3), np.float32),
        y=np.arange(n * 3, dtype=np.float32).reshape(n, 1, 3),
        group=np.array([0, 0, 1, 1]),
        frame=np.array([0, 1, 0, 1]),
        group_names=["t0", "t1"],
        electrode_desc=np.arange(n * 5, dtype=np.float32).reshape(n, 5),
        pairs=np.array([[0, 1], [2, 3]]),
        prior=True,
        pair_names=["a", "b"],
    )


def test_select_by_groups_keeps_ids_names_and_shared_fields():
    d = _touch()
    sub = d.select([2, 0])
    np.testing.assert_array_equal(sub.group, [0, 0, 2, 2])  # data order, ids kept
    np.testing.assert_array_equal(sub.x, d.x[[0, 1, 4, 5]])
    np.testing.assert_array_equal(sub.y, d.y[[0, 1, 4, 5]])
    assert sub.group_names == d.group_names and sub.n_groups == 3 and sub.n_samples == 4
    np.testing.assert_array_equal(sub.group_region, d.group_region)
    assert d.select([]).n_samples == 0
    with pytest.raises(EctskinError, match=r"group ids must be integers in 0..2, got \[3\]"):
        d.select([3])
    with pytest.raises(EctskinError, match="group ids must be integers"):
        d.select([0.5])


def test_take_cuts_the_declared_sample_fields_only():
    d = _track()
    sub = d.take([3, 1])
    np.testing.assert_array_equal(sub.x, d.x[[3, 1]])
    np.testing.assert_array_equal(sub.frame, [1, 1])
    np.testing.assert_array_equal(sub.group, [1, 0])
    # shared, although it has one row per sample here (guessing by shape cut it to 2 rows)
    np.testing.assert_array_equal(sub.electrode_desc, d.electrode_desc)
    np.testing.assert_array_equal(sub.pairs, d.pairs)
    with pytest.raises(EctskinError, match=r"sample indices must be integers in 0..3, got \[4\]"):
        d.take([4])
    with pytest.raises(EctskinError, match="sample indices must be integers"):
        d.take([-1])


def test_concat_then_take_returns_the_original_rows():
    a = _touch()
    b = _touch(n=4, groups=(0, 1, 1, 1), names=("c", "d"), offset=100.0)
    m = TouchData.concat([a, b])
    assert m.n_samples == 10 and m.n_groups == 5
    assert m.group_names == ["0/a", "0/b", "0/c", "1/c", "1/d"]  # the same trial twice: 2 groups
    np.testing.assert_array_equal(m.group, [0, 0, 1, 1, 2, 2, 3, 4, 4, 4])
    np.testing.assert_array_equal(m.group_region, [0, 1, 2, 0, 1])
    back_a, back_b = m.take(np.arange(6)), m.take(np.arange(6, 10))
    for f in ("x", "y"):
        np.testing.assert_array_equal(getattr(back_a, f), getattr(a, f))
        np.testing.assert_array_equal(getattr(back_b, f), getattr(b, f))
    np.testing.assert_array_equal(back_b.group - a.n_groups, b.group)
    # a trial of the second part is found under its new name
    np.testing.assert_array_equal(m.select(m.group_ids(["1/d"])).x, b.select([1]).x)


def test_concat_keeps_the_first_parts_shared_arrays_and_checks_the_matching_ones():
    a, b = _track(), _track()
    b.electrode_desc = b.electrode_desc + 1.0  # another skin's geometry: the first one's is kept
    m = TrackData.concat([a, b])
    np.testing.assert_array_equal(m.electrode_desc, a.electrode_desc)
    np.testing.assert_array_equal(m.frame, [0, 1, 0, 1] * 2)
    b.pair_names = ["a", "c"]
    with pytest.raises(EctskinError, match="part 1 differs from part 0 in 'pair_names'"):
        TrackData.concat([a, b])
    with pytest.raises(EctskinError, match="part 1 is a TouchData, not a TrackData"):
        TrackData.concat([a, _touch()])
    wide = _track()
    wide.x = np.zeros((4, 2, 2), np.float32)
    with pytest.raises(EctskinError, match=r"part 1 has x samples of shape \(2, 2\), part 0"):
        TrackData.concat([a, wide])
    with pytest.raises(EctskinError, match="no data sets"):
        TrackData.concat([])


def test_a_field_of_the_wrong_length_is_refused_naming_it():
    d = _touch()
    with pytest.raises(EctskinError, match=r"TouchData.y must have one row per sample \(6"):
        TouchData(d.x, d.y[:5], d.group, d.group_names, 3, d.pair_names)
    with pytest.raises(EctskinError, match=r"TouchData.group_region must have one row per group"):
        TouchData(d.x, d.y, d.group, d.group_names, 3, d.pair_names, np.zeros(2, np.int64))
    with pytest.raises(EctskinError, match="TouchData.y must be a numpy array"):
        TouchData(d.x, d.y.tolist(), d.group, d.group_names, 3, d.pair_names)
    t = _track()
    with pytest.raises(EctskinError, match=r"TrackData.frame must have one row per sample"):
        TrackData(
            t.x, t.init, t.y, t.group, t.frame[:3], t.group_names, t.electrode_desc, t.pairs, True
        )
    # per-group fields may be left empty (not recorded)
    assert TouchData(d.x, d.y, d.group, d.group_names, 3, d.pair_names).group_region.size == 0


def test_group_ids_by_name():
    d = _touch()
    np.testing.assert_array_equal(d.group_ids(["c", "a"]), [2, 0])
    with pytest.raises(EctskinError, match=r"skin 2: lacks trial\(s\) \['x'\]"):
        d.group_ids(["a", "x"], source="skin 2")


def test_declared_fields_cover_every_per_sample_array(layout, make_recording, contact_recording):
    """Every array field of a built data set with one row per sample is declared per sample (or
    is a shared field with another first axis); the classes declare their own fields only."""
    built = [
        touch_dataset(make_recording(), reference="rest"),
        contact_dataset(contact_recording(layout, n_frames=5, n_trials=2), window=3),
    ]
    for d in built:
        for f in fields(d):
            v = getattr(d, f.name)
            if isinstance(v, np.ndarray) and v.shape[:1] == (d.n_samples,):
                assert f.name in type(d).SAMPLE_FIELDS, (type(d).__name__, f.name)
    for cls in (TouchData, TrackData, ContactData):
        names = {f.name for f in fields(cls)}
        assert set(cls.SAMPLE_FIELDS) | set(cls.GROUP_FIELDS) | set(cls.MATCH_FIELDS) <= names
        assert cls.SAMPLE_FIELDS[0] == "x" and "group" in cls.SAMPLE_FIELDS


def test_concat_of_recordings_renumbers_groups(make_recording):
    a = touch_dataset(make_recording(seed=0), reference="rest")
    b = touch_dataset(make_recording(seed=1), reference="rest")
    m = TouchData.concat([a, b])
    np.testing.assert_array_equal(m.x, np.concatenate([a.x, b.x]))
    np.testing.assert_array_equal(m.y, np.concatenate([a.y, b.y]))
    np.testing.assert_array_equal(m.group[: len(a.group)], a.group)
    np.testing.assert_array_equal(m.group[len(a.group) :], b.group + a.n_groups)
    assert m.n_groups == a.n_groups + b.n_groups == len(set(m.group_names))
    np.testing.assert_array_equal(m.group_region, np.r_[a.group_region, b.group_region])
    g = a.n_groups + 2
    np.testing.assert_array_equal(m.select([g]).x, b.select([2]).x)
