"""HDF5 recordings: bit-exact round trips, atomic writes, malformed files, crash-safe live writing."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io.hdf5 import (
    FORMAT_VERSION,
    RecordingWriter,
    list_trials,
    read_layout,
    read_recording,
    write_recording,
)
from ectskin.io.hdf5 import write as hdf5_write
from ectskin.io.recording import GROUND_TRUTH_FIELDS, Recording, Trial

DOCS = Path(__file__).resolve().parents[2] / "docs" / "recording-format.md"


NAN_PAYLOAD = np.frombuffer(b"\x01\x00\x00\x00\x00\x00\xf8\x7f", "<f8")[0]


def finger_truth(n: int, rng) -> dict[str, np.ndarray]:
    """Finger ground truth of ``n`` frames: no finger (NaN, one with a payload), hovering, contact."""
    contact = np.zeros(n, dtype=bool)
    contact[n // 2 :] = True
    uv = rng.uniform(-20, 80, size=(n, 2))
    height = np.where(contact, 0.0, rng.uniform(0.5, 30.0, size=n))
    if n:
        uv[:3] = np.nan
        height[:3] = np.nan
        height[1] = NAN_PAYLOAD  # no finger, stored bit for bit
    return {"contact": contact, "finger_uv_mm": uv, "finger_height_mm": height}


def special_recording(layout, seed: int = 0) -> Recording:
    """Four trials: markers with occlusions, an empty trial, one without markers, one with force.

    The capacitance holds values that only a bit-exact store keeps: NaN with a payload, -0.0,
    +-inf, a subnormal and the largest float. The finger ground truth: all of it on the first
    two trials (NaN where there is no finger), none on the third, only ``contact`` on the last.
    """
    rng = np.random.default_rng(seed)
    specs = [  # (n_frames, markers, force, inflation, region, ground truth, finger surface)
        (40, True, False, (0.0, 10.0, 20.0), 0, GROUND_TRUTH_FIELDS, "front"),
        (0, True, False, (10.0, 10.0, 10.0), 4, GROUND_TRUTH_FIELDS, "back"),
        (25, False, True, (), 11, (), None),
        (13, True, True, (20.0, 0.0, 20.0, 5.5), 18, ("contact",), None),
    ]
    trials = []
    for k, (n, with_markers, with_force, inflation, region, truth, surface) in enumerate(specs):
        cap = rng.normal(1.0, 0.2, size=(n, layout.n_pairs))
        if n:
            special = np.array(
                [
                    NAN_PAYLOAD,
                    -0.0,
                    np.inf,
                    -np.inf,
                    5e-324,
                    np.finfo(np.float64).max,
                ]
            )
            cap[0, : special.size] = special
        markers = None
        if with_markers:
            markers = rng.normal(0, 50, size=(n, layout.n_markers, 3))
            markers[::4, 2] = np.nan  # occluded marker
        timestamps = np.cumsum(rng.uniform(0.02, 0.05, size=n))
        labels = rng.integers(0, layout.n_regions + 1, size=n).astype(np.int16)
        force = rng.uniform(0, 2, size=n) if with_force else None
        fingers = {f: v for f, v in finger_truth(n, rng).items() if f in truth}
        if force is not None and "contact" in fingers:  # no force off the skin
            force = np.where(fingers["contact"], force, 0.0)
        trials.append(
            Trial(
                name=f"trial_{k:04d}",
                capacitance=cap,
                timestamps=timestamps,
                labels=labels,
                inflation=inflation,
                region=region,
                markers=markers,
                force=force,
                **fingers,
                finger_surface=surface,
                meta={"index": k, "note": "Berührung ✓", "nested": {"list": [1, 2.5, None, True]}},
            )
        )
    meta = {
        "protocol": {"states": 27, "levels_ml": [0, 10, 20], "seed": seed},
        "source": "unit test",
        "events": [
            {"t_s": 0.5, "trial": "trial_0000", "text": "inflation set to (0, 10, 20)"},
            {"t_s": 0.1, "trial": None, "text": "session start"},
        ],
    }
    return Recording(layout, trials, 30.0, meta)


def assert_same_recording(a: Recording, b: Recording) -> None:
    assert a.layout.to_dict() == b.layout.to_dict()
    assert a.frame_rate_hz == b.frame_rate_hz
    assert a.meta == b.meta
    assert [t.name for t in a.trials] == [t.name for t in b.trials]
    for ta, tb in zip(a.trials, b.trials):
        assert (ta.inflation, ta.region, ta.meta) == (tb.inflation, tb.region, tb.meta), ta.name
        assert ta.finger_surface == tb.finger_surface, ta.name
        for field in (
            "capacitance",
            "timestamps",
            "labels",
            "markers",
            "force",
            *GROUND_TRUTH_FIELDS,
        ):
            xa, xb = getattr(ta, field), getattr(tb, field)
            assert (xa is None) == (xb is None), (ta.name, field)
            if xa is not None:
                assert xa.dtype == xb.dtype and xa.shape == xb.shape, (ta.name, field)
                assert xa.tobytes() == xb.tobytes(), f"{ta.name}.{field} differs bitwise"


# ------------------------------------------------------------------------------- round trip
def test_round_trip_is_bit_exact(tmp_path, layout):
    rec = special_recording(layout)
    path = write_recording(rec, tmp_path / "rec.h5")
    assert path == tmp_path / "rec.h5"
    back = read_recording(path)
    assert_same_recording(rec, back)
    assert back.trials[1].n_frames == 0
    assert back.layout.source == f"{path}:/layout"
    # the NaN payload survived: not just "some NaN"
    assert back.trials[0].capacitance[0, :1].tobytes() == b"\x01\x00\x00\x00\x00\x00\xf8\x7f"
    assert back.trials[0].finger_height_mm[1:2].tobytes() == NAN_PAYLOAD.tobytes()
    assert back.trials[0].has_ground_truth and back.trials[1].has_ground_truth
    assert back.trials[0].contact.dtype == np.bool_
    assert back.format_version == FORMAT_VERSION == 4 and back.source == str(path)
    with h5py.File(path, "r") as f:  # a closed file opens in any HDF5 tool
        assert f.attrs["complete"] and f.attrs["format"] == "ectskin.recording"
        assert f.attrs["format_version"] == 4
        assert f["frames/capacitance"].compression == "gzip"
        assert list(f["frames/capacitance"].attrs["pair_names"])[:2] == list(layout.pair_names[:2])


def test_docs_snippet_reads_the_file_without_ectskin(tmp_path, layout):
    """The h5py-only reader in docs/recording-format.md agrees with read_recording."""
    text = DOCS.read_text(encoding="utf-8")
    section = text[text.index("## Reading without ectskin") :]
    code = re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)
    namespace: dict = {}
    exec(compile(code, str(DOCS), "exec"), namespace)  # noqa: S102 (our own docs)
    rec = special_recording(layout, seed=1)
    path = write_recording(rec, tmp_path / "rec.h5")
    trials, layout_dict, pair_names = namespace["load"](path)
    assert layout_dict == layout.to_dict()
    assert pair_names == list(layout.pair_names)
    assert list(trials) == [t.name for t in rec.trials]
    for t in rec.trials:
        got = trials[t.name]
        assert got["capacitance"].tobytes() == t.capacitance.tobytes()
        assert np.array_equal(got["timestamps"], t.timestamps)
        assert np.array_equal(got["labels"], t.labels)
        assert (got["markers"] is None) == (t.markers is None)
        if t.markers is not None:
            assert np.array_equal(got["markers"], t.markers, equal_nan=True)
        for field in ("force", *GROUND_TRUTH_FIELDS):  # on the fingers axis
            assert (got[field] is None) == (getattr(t, field) is None), (t.name, field)
            if got[field] is not None:
                assert got[field].shape == getattr(t, field).shape, (t.name, field)
                assert got[field].tobytes() == getattr(t, field).tobytes(), (t.name, field)
        assert got["finger_surface"] == list(t.finger_surface)
        assert got["n_fingers"] == t.n_fingers
        assert tuple(got["inflation_ml"]) == t.inflation
        assert got["region"] == t.region and got["meta"] == t.meta


def test_list_trials_and_read_layout_load_no_frames(tmp_path, layout, monkeypatch):
    rec = special_recording(layout)
    path = write_recording(rec, tmp_path / "rec.h5")
    read_names: list[str] = []
    original = h5py.Dataset.__getitem__

    def spy(self, *args, **kwargs):
        read_names.append(self.name)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(h5py.Dataset, "__getitem__", spy)
    rows = list_trials(path)
    got_layout = read_layout(path)
    assert not [n for n in read_names if n.startswith("/frames/")]
    assert got_layout.to_dict() == layout.to_dict()
    assert [r["name"] for r in rows] == [t.name for t in rec.trials]
    assert [r["n_frames"] for r in rows] == [40, 0, 25, 13]
    assert [r["start_frame"] for r in rows] == [0, 40, 40, 65]
    assert [r["region"] for r in rows] == [0, 4, 11, 18]
    assert [r["inflation"] for r in rows] == [t.inflation for t in rec.trials]
    assert [r["has_markers"] for r in rows] == [True, True, False, True]
    assert [r["has_force"] for r in rows] == [False, False, True, True]
    assert [r["has_contact"] for r in rows] == [True, True, False, True]
    assert [r["has_finger_uv_mm"] for r in rows] == [True, True, False, False]
    assert [r["has_finger_height_mm"] for r in rows] == [True, True, False, False]
    assert [r["n_fingers"] for r in rows] == [1, 1, 1, 1]  # (the last two: force only)
    assert [r["finger_surface"] for r in rows] == [("front",), ("back",), (None,), (None,)]


def test_read_selected_trials_in_requested_order(tmp_path, layout):
    rec = special_recording(layout)
    path = write_recording(rec, tmp_path / "rec.h5")
    sub = read_recording(path, trials=["trial_0003", "trial_0000"])
    assert [t.name for t in sub.trials] == ["trial_0003", "trial_0000"]
    assert sub.trials[0].capacitance.tobytes() == rec.trials[3].capacitance.tobytes()
    with pytest.raises(EctskinError, match="no trial named 'nope'"):
        read_recording(path, trials=["nope"])


def test_meta_with_numpy_values_is_stored_as_json(tmp_path, layout):
    rec = special_recording(layout)
    rec.meta = {"n": np.int64(3), "p": np.array([0.0, 10.0]), "x": np.float32(0.5)}
    back = read_recording(write_recording(rec, tmp_path / "rec.h5"))
    assert back.meta == {"n": 3, "p": [0.0, 10.0], "x": 0.5}


def test_meta_keeps_non_finite_floats_and_refuses_other_objects(tmp_path, layout):
    """Metadata round-trips exactly: NaN and +-inf come back as those floats (JSON's NaN /
    Infinity extension), not as null as in the result files of ectskin._files; a value that is
    not JSON (a path, a dataclass) is refused, naming its key, not turned into text."""
    rec = special_recording(layout)
    rec.meta = {"a": float("nan"), "b": [np.inf, -np.inf], "c": {"d": np.float64("nan")}}
    back = read_recording(write_recording(rec, tmp_path / "rec.h5"))
    assert np.isnan(back.meta["a"]) and np.isnan(back.meta["c"]["d"])
    assert back.meta["b"] == [np.inf, -np.inf]
    for bad in (Path("x.h5"), layout.skins[0]):
        rec.meta = {"ok": 1, "where": bad}
        with pytest.raises(EctskinError, match=r"recording meta must hold JSON-able values .*"
                           r"\(at \['where'\]\)"):
            write_recording(rec, tmp_path / "bad.h5")


# ------------------------------------------------------------------------ writing safely
def test_write_refuses_to_overwrite_unless_asked(tmp_path, layout):
    path = write_recording(special_recording(layout, seed=0), tmp_path / "rec.h5")
    before = path.read_bytes()
    with pytest.raises(EctskinError, match=re.escape(str(path)) + ".*overwrite=True"):
        write_recording(special_recording(layout, seed=1), path)
    assert path.read_bytes() == before
    write_recording(special_recording(layout, seed=1), path, overwrite=True)
    assert_same_recording(read_recording(path), special_recording(layout, seed=1))


@pytest.mark.parametrize("existing", [False, True])
def test_write_is_atomic_when_it_fails_midway(tmp_path, layout, monkeypatch, existing):
    path = tmp_path / "rec.h5"
    if existing:
        write_recording(special_recording(layout, seed=5), path)
    before = path.read_bytes() if existing else None
    original = hdf5_write._write_frames
    calls = []

    def crash(fds, lay, trials, starts):
        original(fds, lay, trials[:1], starts[:1])  # some frames are on disk already
        calls.append(1)
        raise RuntimeError("simulated crash while writing frames")

    monkeypatch.setattr(hdf5_write, "_write_frames", crash)
    with pytest.raises(RuntimeError, match="simulated crash"):
        write_recording(special_recording(layout), path, overwrite=True)
    assert calls, "the failure was not injected"
    assert sorted(p.name for p in tmp_path.iterdir()) == (["rec.h5"] if existing else [])
    if existing:
        assert path.read_bytes() == before
        assert_same_recording(read_recording(path), special_recording(layout, seed=5))


def test_write_refuses_bad_metadata_before_touching_disk(tmp_path, layout):
    rec = special_recording(layout)
    rec.trials[2].meta = {"fn": object()}
    with pytest.raises(EctskinError, match="trial 'trial_0002': meta must hold JSON-able"):
        write_recording(rec, tmp_path / "rec.h5")
    rec = special_recording(layout)
    rec.meta["events"] = [{"t_s": 1.0, "trial": "nope", "text": "x"}]
    with pytest.raises(EctskinError, match=r"events.*names no trial.*'nope'"):
        write_recording(rec, tmp_path / "rec.h5")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------- malformed files
def _edit(path: Path, fn) -> None:
    with h5py.File(path, "r+") as f:
        fn(f)


def _replace(f, name, data):
    del f[name]
    f[name] = data


MALFORMED = {
    "text file": (lambda p: p.write_text("time,c1\n0,1\n" * 50), r"not an HDF5 file"),
    "truncated": (
        lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
        r"not an HDF5 file \(or truncated\): the file is shorter",
    ),
    "missing dataset": (
        lambda p: _edit(p, lambda f: f.__delitem__("frames/timestamps")),
        r"missing dataset /frames/timestamps",
    ),
    "wrong shape": (
        lambda p: _edit(
            p, lambda f: _replace(f, "frames/capacitance", f["frames/capacitance"][:, :27])
        ),
        (
            r"/frames/capacitance has shape \(78, 27\), expected \(n_frames, 28\) for layout "
            r"'paper-2x4-wires'"
        ),
    ),
    "wrong format": (
        lambda p: _edit(p, lambda f: f.attrs.__setitem__("format", "someone.else")),
        r"not an ectskin recording: root attribute 'format' is 'someone.else'",
    ),
    "newer version": (
        lambda p: _edit(p, lambda f: f.attrs.__setitem__("format_version", FORMAT_VERSION + 1)),
        rf"format_version {FORMAT_VERSION + 1} is newer than this ectskin reads \({FORMAT_VERSION}\)",
    ),
    "missing ground-truth column": (
        lambda p: _edit(p, lambda f: f.__delitem__("trials/has_contact")),
        r"missing dataset /trials/has_contact \(required by ectskin.recording version 4\)",
    ),
    "missing ground-truth dataset": (
        lambda p: _edit(p, lambda f: f.__delitem__("frames/finger_uv_mm")),
        r"missing dataset /frames/finger_uv_mm: trial 'trial_0000' has has_finger_uv_mm=True",
    ),
    "float contact": (
        lambda p: _edit(p, lambda f: _replace(f, "frames/contact", f["frames/contact"][()] * 0.5)),
        r"/frames/contact has dtype float64, expected a boolean",
    ),
    "contact not 0/1": (
        lambda p: _edit(
            p, lambda f: _replace(f, "frames/contact", f["frames/contact"][()].astype(np.int8) * 2)
        ),
        r"/frames/contact\[0:40\] does not fit bool losslessly",
    ),
    "unknown finger surface": (
        lambda p: _edit(p, lambda f: f["trials/finger_surface"].__setitem__(0, "top")),
        r"/trials/finger_surface\[0\] \(trial 'trial_0000'\) is 'top', expected '' \(none\) or "
        r"one of front, back, right, left",
    ),
    "uv and height disagree": (
        lambda p: _edit(p, lambda f: f["frames/finger_height_mm"].__setitem__(0, 3.0)),
        r"/frames rows 0:40: trial 'trial_0000': frame 0, finger 0 has finger_uv_mm \[nan, nan\] "
        r"but finger_height_mm 3.0",
    ),
    "incomplete": (
        lambda p: _edit(p, lambda f: f.attrs.__setitem__("complete", False)),
        r"incomplete recording \(complete=False\).*allow_partial=True",
    ),
    "rows disagree with commit record": (
        lambda p: _edit(p, lambda f: f["committed"].__setitem__(0, 50)),
        r"/frames/capacitance has 78 rows, but /committed says the recording holds 50 frames",
    ),
    "label out of range": (
        lambda p: _edit(p, lambda f: f["frames/labels"].__setitem__(3, 99)),
        r"trial 'trial_0000': frame 3 has label 99, expected 0..18",
    ),
    "timestamps go back": (
        lambda p: _edit(p, lambda f: f["frames/timestamps"].__setitem__(41, 0.0)),
        r"/frames rows 40:65: trial 'trial_0002': timestamps must increase",
    ),
    "broken layout": (
        lambda p: _edit(p, lambda f: f["layout"].attrs.__setitem__("json", '{"schema": 1}')),
        r"invalid layout in attribute 'json'",
    ),
    "float labels": (
        lambda p: _edit(p, lambda f: _replace(f, "frames/labels", f["frames/labels"][()] * 1.0)),
        r"/frames/labels has dtype float64, expected an integer",
    ),
    "trial starts out of order": (
        lambda p: _edit(p, lambda f: f["trials/start"].__setitem__(2, 10)),
        r"/trials/start\[2\] \(trial 'trial_0002'\) is 10, before the start 40",
    ),
    "bad meta json": (
        lambda p: _edit(p, lambda f: f.attrs.__setitem__("meta_json", "{oops")),
        r"attribute 'meta_json' on / is not valid JSON",
    ),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_file_gives_one_clear_error(tmp_path, layout, case):
    damage, message = MALFORMED[case]
    path = write_recording(special_recording(layout), tmp_path / "bad.h5")
    damage(path)
    with pytest.raises(EctskinError) as info:
        read_recording(path)
    text = str(info.value)
    assert text.startswith(f"{path}: "), text
    assert re.search(message, text), text
    frame_content = ("label out of range", "timestamps go back", "uv and height disagree")
    if case not in ("incomplete", "contact not 0/1", *frame_content):
        with pytest.raises(EctskinError, match=re.escape(str(path))):
            list_trials(path, allow_partial=True)


@pytest.mark.parametrize(
    "volumes, shown",
    [([np.nan, 0.0, 0.0], "nan"), ([-1e9], "-1000000000.0"), ([0.0, np.inf, 0.0], "inf")],
)
def test_reader_refuses_a_non_finite_or_negative_inflation(tmp_path, layout, volumes, shown):
    """Chamber volumes are >= 0 ml (the twin's 0..30 ml): NaN, inf or a negative volume in
    /trials/inflation_ml is one error naming the trial and the value, from read_recording and
    list_trials alike. (A NaN in the rest trial was reported later, by the calibration, as a
    recording without a rest-state trial.)"""
    P = layout.n_pairs
    rest = Trial("rest", np.ones((3, P)), np.arange(3.0), np.zeros(3, np.int16),
                 inflation=(0.0, 0.0, 0.0), meta={"kind": "no_contact"})
    touch = Trial("touch", np.ones((3, P)), np.arange(3.0), np.full(3, 2, np.int16),
                  inflation=(0.0, 0.0, 0.0), region=2, meta={"kind": "touch"})
    path = write_recording(Recording(layout, [touch, rest], 30.0), tmp_path / "x.h5")
    with h5py.File(path, "a") as f:
        f["trials/inflation_ml"][1] = np.asarray(volumes, dtype=np.float64)
    want = (
        rf"^{re.escape(str(path))}: /trials/inflation_ml\[1\] \(trial 'rest'\) holds {shown} "
        r"in \[.*\], expected finite chamber volumes >= 0 ml$"
    )
    with pytest.raises(EctskinError, match=want):
        read_recording(path)
    with pytest.raises(EctskinError, match=want):
        list_trials(path)


def test_missing_file_and_directory(tmp_path, layout):
    with pytest.raises(EctskinError, match="no such file"):
        read_recording(tmp_path / "nope.h5")
    with pytest.raises(EctskinError, match="is a directory"):
        read_recording(tmp_path)
    with pytest.raises(EctskinError, match="does not exist"):
        write_recording(special_recording(layout), tmp_path / "no" / "dir.h5")


def test_partial_file_returns_committed_rows_only(tmp_path, layout):
    """Rows beyond /committed (an interrupted flush) are not part of the recording."""
    rec = special_recording(layout)
    path = write_recording(rec, tmp_path / "rec.h5")
    # As if the writer was killed after committing 45 frames and 3 trials: trial_0002 (starts at
    # frame 40) has 5 committed frames, trial_0003 was never committed.
    _edit(path, lambda f: f.attrs.__setitem__("complete", False))
    _edit(path, lambda f: f["committed"].__setitem__(slice(0, 3), [45, 3, 1]))
    back = read_recording(path, allow_partial=True)
    assert [t.name for t in back.trials] == ["trial_0000", "trial_0001", "trial_0002"]
    assert [t.n_frames for t in back.trials] == [40, 0, 5]
    assert back.trials[2].capacitance.tobytes() == rec.trials[2].capacitance[:5].tobytes()
    assert back.meta["events"] == rec.meta["events"][:1]
    # a commit record at the start of a trial leaves that trial with 0 frames
    _edit(path, lambda f: f["committed"].__setitem__(slice(0, 3), [40, 3, 0]))
    back = read_recording(path, allow_partial=True)
    assert [t.n_frames for t in back.trials] == [40, 0, 0]
    assert "events" not in back.meta


# ------------------------------------------------------------------------ append-mode writer
def test_writer_round_trip_equals_write_recording(tmp_path, layout):
    """Frames appended one by one and in batches read back bit-exactly, like write_recording."""
    rec = special_recording(layout)
    path = tmp_path / "live.h5"
    with RecordingWriter(
        path,
        layout,
        rec.frame_rate_hz,
        meta={"protocol": rec.meta["protocol"], "source": "unit test"},
    ) as w:
        w.add_event(0.1, "session start")  # before the first trial
        for k, t in enumerate(rec.trials):
            w.start_trial(
                t.name,
                inflation=t.inflation,
                region=t.region,
                finger_surface=t.finger_surface,
                meta=t.meta,
            )
            if k == 0:
                w.add_event(0.5, "inflation set to (0, 10, 20)")
            split = t.n_frames // 3
            for i in range(split):  # single frames
                w.append(
                    t.capacitance[i],
                    t.timestamps[i],
                    int(t.labels[i]),
                    markers=None if t.markers is None else t.markers[i],
                    force=None if t.force is None else t.force[i],
                    **{
                        f: getattr(t, f)[i]
                        for f in GROUND_TRUTH_FIELDS
                        if getattr(t, f) is not None
                    },
                )
            # then one batch (empty for the empty trial: it declares what it carries)
            rows = slice(split, None)
            w.append(
                t.capacitance[rows],
                t.timestamps[rows],
                t.labels[rows],
                markers=None if t.markers is None else t.markers[rows],
                force=None if t.force is None else t.force[rows],
                **{
                    f: getattr(t, f)[rows] for f in GROUND_TRUTH_FIELDS if getattr(t, f) is not None
                },
            )
        assert w.n_frames == rec.n_frames and w.n_trials == rec.n_trials
    assert w.closed
    expected = Recording(
        layout,
        rec.trials,
        rec.frame_rate_hz,
        {**rec.meta, "events": rec.meta["events"][::-1]},  # logged in time order here
    )
    assert_same_recording(read_recording(path), expected)
    with h5py.File(path, "r") as f:  # closed properly: no SWMR flag left, plain h5py opens it
        assert bool(f.attrs["complete"]) and f.attrs["writer"] == "RecordingWriter"
    # and the two writers produce the same recording
    other = write_recording(expected, tmp_path / "batch.h5")
    assert_same_recording(read_recording(other), read_recording(path))


def test_writer_rejects_bad_input_and_stays_usable(tmp_path, layout):
    path = tmp_path / "live.h5"
    n = layout.n_pairs
    w = RecordingWriter(path, layout, 30.0)
    with pytest.raises(EctskinError, match=r"call start_trial\(\) before append"):
        w.append(np.ones(n), 0.0)
    w.start_trial("a", region=2)
    w.append(np.ones((2, n)), [0.0, 0.1], markers=np.zeros((2, layout.n_markers, 3)))
    bad = [
        (lambda: w.append(np.ones(n - 1), 0.2), r"capacitance must have shape \(n, 28\)"),
        (lambda: w.append(np.ones(n), 0.1), r"timestamps must increase.*0.1 comes after 0.1"),
        (lambda: w.append(np.ones((2, n)), [0.3, 0.3]), r"timestamps must increase"),
        (lambda: w.append(np.ones(n), np.nan), r"timestamps must be finite"),
        (
            lambda: w.append(np.ones(n), 0.2, labels=19),
            r"labels\[0\] is 19.0, expected an integer 0..18",
        ),
        (
            lambda: w.append(np.ones(n), 0.2),
            r"markers missing here, but the trial's earlier frames had",
        ),
        (
            lambda: w.append(np.ones((2, n)), [0.2, 0.3], markers=np.zeros((layout.n_markers, 3))),
            r"markers must have shape \(2, 5, 3\)",
        ),
        (lambda: w.append([[1, 2], [3]], 0.2), r"capacitance must be numeric"),
        (lambda: w.start_trial("a"), r"trial 'a' already exists"),
        (lambda: w.start_trial("b", region=19), r"region 19 is not 0..18"),
        (lambda: w.start_trial("b", meta={"x": object()}), r"meta must hold JSON-able"),
        (lambda: w.add_event(float("inf"), "x"), r"event time must be a finite number"),
    ]
    for call, message in bad:
        with pytest.raises(EctskinError, match=message):
            call()
    w.append(np.full(n, 2.0), 0.2, markers=np.zeros((layout.n_markers, 3)))
    w.close()
    w.close()  # idempotent
    with pytest.raises(EctskinError, match="closed"):
        w.append(np.ones(n), 0.3)
    back = read_recording(path)
    assert [t.name for t in back.trials] == ["a"]
    assert back.trials[0].n_frames == 3 and np.array_equal(back.trials[0].timestamps, [0, 0.1, 0.2])
    assert back.trials[0].region == 2 and back.trials[0].markers.shape == (3, layout.n_markers, 3)


def test_writer_refuses_existing_file(tmp_path, layout):
    path = tmp_path / "live.h5"
    path.write_bytes(b"precious")
    with pytest.raises(EctskinError, match=re.escape(str(path)) + ".*overwrite=True"):
        RecordingWriter(path, layout, 30.0)
    assert path.read_bytes() == b"precious"
    with RecordingWriter(path, layout, 30.0, overwrite=True) as w:
        w.start_trial("t")
    assert read_recording(path).n_trials == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["live.h5"]  # no temp file left


def test_writer_flushes_on_its_interval(tmp_path, layout):
    """Frames reach the file once flush_interval_s has passed, not before."""
    clock = [100.0]
    path = tmp_path / "live.h5"
    w = RecordingWriter(path, layout, 30.0, flush_interval_s=1.0, clock=lambda: clock[0])
    w.start_trial("t")

    def on_disk():
        return read_recording(path, allow_partial=True).n_frames

    for k in range(10):
        clock[0] += 0.09
        w.append(np.full(layout.n_pairs, k), k / 30)
    assert on_disk() == 0  # 0.9 s since the last flush
    clock[0] += 0.1
    w.append(np.full(layout.n_pairs, 10), 10 / 30)  # 1.0 s: this append flushes
    assert on_disk() == 11
    with pytest.raises(EctskinError, match="incomplete recording"):
        read_recording(path)
    w.flush()
    w.close()
    assert read_recording(path).n_frames == 11


def test_writer_trial_row_written_before_its_first_frame_is_updated(tmp_path, layout):
    """With a flush between start_trial and the first append, the trial's flags are rewritten."""
    path = tmp_path / "live.h5"
    with RecordingWriter(path, layout, 30.0, flush_interval_s=0.0) as w:  # flush on every call
        w.start_trial("t0", inflation=(1, 2, 3), region=5, meta={"a": 1})
        assert list_trials(path, allow_partial=True)[0]["has_markers"] is False
        markers = np.arange(2 * layout.n_markers * 3, dtype=float).reshape(2, layout.n_markers, 3)
        w.append(np.ones((2, layout.n_pairs)), [0.0, 1.0], markers=markers, force=[0.5, 0.7])
    (t,) = read_recording(path).trials
    assert np.array_equal(t.markers, markers) and np.array_equal(t.force, [[0.5], [0.7]])
    assert (t.inflation, t.region, t.meta) == ((1.0, 2.0, 3.0), 5, {"a": 1})


def test_writer_left_by_an_exception_is_partial_but_readable(tmp_path, layout):
    path = tmp_path / "live.h5"
    with pytest.raises(KeyError), RecordingWriter(path, layout, 30.0, flush_interval_s=60) as w:
        w.start_trial("t")
        w.append(np.ones((5, layout.n_pairs)), np.arange(5.0))
        raise KeyError("source died")
    with pytest.raises(EctskinError, match="incomplete recording"):
        read_recording(path)
    assert read_recording(path, allow_partial=True).n_frames == 5


# ----------------------------------------------------------------------------- SIGKILL
_CHILD = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from ectskin.layout import default_layout
    from ectskin.io.hdf5 import RecordingWriter

    path, rate, interval, frames_per_trial = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), 100
    layout = default_layout()

    def frame(k):  # deterministic: the test recomputes it
        return np.sin(0.01 * k + np.arange(layout.n_pairs)) + 2.0

    w = RecordingWriter(path, layout, rate, flush_interval_s=interval, meta={"child": True})
    print("ready", flush=True)
    k = 0
    while True:
        if k % frames_per_trial == 0:
            w.start_trial(f"trial_{k // frames_per_trial:04d}", inflation=(k // frames_per_trial,),
                          region=1)
            w.add_event(k / rate, f"trial {k // frames_per_trial}")
        w.append(frame(k), k / rate, labels=1,
                 markers=np.full((layout.n_markers, 3), float(k)))
        k += 1
        print(k, flush=True)
        time.sleep(1.0 / rate)
    """
)


def _run_child(tmp_path: Path, path: Path, rate: float, interval: float) -> subprocess.Popen:
    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    return subprocess.Popen(
        [sys.executable, str(script), str(path), str(rate), str(interval)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _check_killed_file(path: Path, layout, appended: int, rate: float, interval: float) -> int:
    with pytest.raises(EctskinError, match="incomplete recording"):
        read_recording(path)
    rec = read_recording(path, allow_partial=True)
    n = rec.n_frames
    assert rec.meta["child"] is True
    cap = np.concatenate([t.capacitance for t in rec.trials] + [np.empty((0, layout.n_pairs))])
    ts = np.concatenate([t.timestamps for t in rec.trials] + [np.empty(0)])
    k = np.arange(n)
    expect = np.sin(0.01 * k[:, None] + np.arange(layout.n_pairs)) + 2.0
    assert cap.tobytes() == expect.tobytes()  # every saved frame, bit for bit
    assert np.all(np.diff(ts) > 0) and np.array_equal(ts, k / rate)
    assert all(t.n_frames == 100 for t in rec.trials[:-1])
    # one event per trial, logged just after start_trial (a kill may fall in between)
    assert len(rec.meta.get("events", [])) in (rec.n_trials - 1, rec.n_trials)
    # `appended` is the last count the child printed; it may have saved one more frame unprinted
    lost = appended - n
    assert -1 <= lost <= rate * interval + 2, f"lost {lost} frames at {rate} fps"
    return n


def test_sigkill_loses_at_most_the_last_flush_interval(tmp_path, layout):
    rate, interval = 100.0, 1.0
    path = tmp_path / "killed.h5"
    proc = _run_child(tmp_path, path, rate, interval)
    try:
        assert proc.stdout.readline().strip() == "ready", proc.stderr.read()
        time.sleep(1.4)
        live = read_recording(path, allow_partial=True)  # readable while being written
        assert live.n_frames > 0
        time.sleep(1.1)
        os.kill(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    appended = int(out.split()[-1])
    n = _check_killed_file(path, layout, appended, rate, interval)
    assert n >= live.n_frames and n >= rate * 1.0  # two flushes happened in 2.5 s


@pytest.mark.slow
def test_sigkill_at_random_moments_never_corrupts_the_file(tmp_path, layout):
    """Flushing after every frame, kills land mid-flush; every file must still read."""
    rng = np.random.default_rng(0)
    for it in range(15):
        path = tmp_path / f"killed_{it}.h5"
        proc = _run_child(tmp_path, path, 1000.0, 0.0)
        try:
            assert proc.stdout.readline().strip() == "ready"
            time.sleep(rng.uniform(0.05, 0.5))
            os.kill(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        lines = out.split()
        appended = int(lines[-1]) if len(lines) > 1 else 0
        _check_killed_file(path, layout, appended, 1000.0, 0.0)


def test_an_event_time_that_is_not_finite_is_refused_by_the_reader(tmp_path, make_recording):
    """Found by the fuzz suite: the reader accepted an event at t = NaN, which no writer writes
    (and write_recording refuses), so a read file could not be written back."""
    rec = make_recording(n_frames=4)
    rec.meta["events"] = [{"t_s": 0.5, "trial": rec.trials[0].name, "text": "x"}]
    p = write_recording(rec, tmp_path / "e.h5")
    with h5py.File(p, "r+") as f:
        f["events/t_s"][0] = np.nan
    with pytest.raises(EctskinError, match=r"/events/t_s\[0\] is nan, expected a finite time"):
        read_recording(p)
