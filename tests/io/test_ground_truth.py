"""The finger's per-frame ground truth: checks at the door, HDF5 round trips, version-1 files.

One finger throughout (finger 0 of the fingers axis; several fingers: test_hdf5_fingers.py).

``tests/data/recording_v1.h5`` was written by the format-version-1 code (the commit before the
ground truth) with :func:`v1_fixture_recording` below, so that reading files of older ectskin is
tested against a real old file, not one edited to look old.
"""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import GROUND_TRUTH_FIELDS, require_ground_truth
from ectskin.io import read_recording as read_any
from ectskin.io.hdf5 import (
    FORMAT_VERSION,
    RecordingWriter,
    list_trials,
    read_recording,
    write_recording,
)
from ectskin.io.recording import Recording, Trial

V1_FILE = Path(__file__).resolve().parents[1] / "data" / "recording_v1.h5"
N = 6


def v1_fixture_recording(layout) -> Recording:
    """What ``tests/data/recording_v1.h5`` holds (written by ``write_recording``, version 1)."""
    P, M = layout.n_pairs, layout.n_markers
    t0 = Trial(
        "trial_0000",
        capacitance=1.0 + 0.01 * np.arange(6 * P).reshape(6, P),
        timestamps=np.arange(6) / 30.0,
        labels=np.zeros(6, dtype=np.int16),
        inflation=(0.0, 10.0, 20.0),
        markers=np.arange(6 * M * 3, dtype=np.float64).reshape(6, M, 3),
        meta={"kind": "no_contact"},
    )
    t1 = Trial(
        "trial_0001",
        capacitance=2.0 + 0.01 * np.arange(4 * P).reshape(4, P),
        timestamps=np.arange(4) / 30.0,
        labels=np.full(4, 3, dtype=np.int16),
        inflation=(20.0, 0.0, 10.0),
        region=3,
        force=np.array([0.0, 0.5, 1.0, 1.5]),
        meta={"kind": "touch"},
    )
    return Recording(layout, [t0, t1], 30.0, meta={"source": "format version 1 fixture"})


def truth(n: int = N) -> dict:
    """Off (no finger), hovering, then in contact; NaN where there is no finger."""
    contact = np.array([False, False, False, True, True, True])[:n]
    uv = np.array([[np.nan, np.nan], [10.0, 50.0], [11.0, 51.0], [12, 52], [13, 53], [14, 54]])
    height = np.array([np.nan, 8.5, 2.0, 0.0, 0.0, 0.0])
    return {"contact": contact, "finger_uv_mm": uv[:n], "finger_height_mm": height[:n]}


def trial(name: str = "t", n: int = N, layout=None, **fields) -> Trial:
    P = 28 if layout is None else layout.n_pairs
    return Trial(name, np.ones((n, P)), np.arange(n) / 30.0, np.zeros(n, dtype=np.int16), **fields)


# ------------------------------------------------------------------------ Trial checks
def test_trial_holds_the_ground_truth():
    t = trial(**truth(), finger_surface="front", force=np.zeros(N))
    assert t.has_ground_truth and t.missing_ground_truth == ()
    assert t.contact.dtype == np.bool_ and t.finger_uv_mm.shape == (N, 1, 2)  # one finger
    assert t.finger_height_mm.dtype == np.float64 and t.finger_surface == ("front",)
    bare = trial()
    assert not bare.has_ground_truth and bare.missing_ground_truth == GROUND_TRUTH_FIELDS
    assert (bare.contact, bare.finger_uv_mm, bare.finger_height_mm) == (None, None, None)
    assert bare.finger_surface == () and bare.n_fingers == 0
    partial = trial(contact=truth()["contact"])
    assert partial.missing_ground_truth == ("finger_uv_mm", "finger_height_mm")
    # contact as 0/1 numbers is accepted and stored as bool
    assert trial(contact=[0, 0, 0, 1, 1, 1]).contact.dtype == np.bool_
    assert trial(contact=[0, 0, 0, 1, 1, 1]).contact[:, 0].tolist() == [0, 0, 0, 1, 1, 1]


def _with(**change):
    fields = truth()
    fields.update(change)
    return fields


BAD_TRIALS = {
    "contact too long": (
        _with(contact=np.zeros(N + 1, dtype=bool)),
        r"trial 't': contact must have shape \(6, n_fingers\) or, one finger, \(6,\); got \(7,\)",
    ),
    "contact not 0/1": (_with(contact=[0, 0, 2, 1, 1, 1]), r"trial 't': contact must be bool"),
    "contact float": (
        _with(contact=np.full(N, 0.5)),
        r"contact must be bool \(or 0/1\), found 0.5",
    ),
    "contact text": (_with(contact=["yes"] * N), r"contact must be bool, found dtype <U3"),
    "uv 3 columns": (
        _with(finger_uv_mm=np.zeros((N, 3))),
        r"trial 't': finger_uv_mm must have shape \(6, n_fingers, 2\) or, one finger, \(6, 2\); "
        r"got \(6, 3\)",
    ),
    "uv flat": (
        _with(finger_uv_mm=np.zeros(N)),
        r"trial 't': finger_uv_mm must have shape \(6, n_fingers, 2\) .*; got \(6,\)",
    ),
    "height 3-D": (
        _with(finger_height_mm=np.zeros((N, 1, 1))),
        r"trial 't': finger_height_mm must have shape \(6, n_fingers\) or, one finger, \(6,\); "
        r"got \(6, 1, 1\)",
    ),
    "uv half NaN": (
        _with(finger_uv_mm=np.array([[np.nan, 1.0]] + [[1.0, 1.0]] * 5)),
        r"trial 't': finger_uv_mm\[0, 0\] is \[nan, 1.0\], expected two finite numbers \(mm\) or "
        r"two NaN",
    ),
    "uv inf": (
        _with(finger_uv_mm=np.array([[np.nan, np.nan]] + [[np.inf, 1.0]] * 5)),
        r"finger_uv_mm\[1, 0\] is \[inf, 1.0\]",
    ),
    "negative height": (
        _with(finger_height_mm=np.array([np.nan, -1.0, 2.0, 0, 0, 0])),
        r"trial 't': finger_height_mm\[1, 0\] is -1.0, expected a height >= 0 mm",
    ),
    "uv and height disagree": (
        _with(finger_height_mm=np.array([3.0, 8.5, 2.0, 0, 0, 0])),
        r"trial 't': frame 0, finger 0 has finger_uv_mm \[nan, nan\] but finger_height_mm 3.0",
    ),
    "contact without a finger": (
        _with(contact=np.ones(N, dtype=bool), finger_height_mm=None),
        r"trial 't': finger_uv_mm\[0, 0\] is \[nan, nan\] in contact, expected two finite numbers",
    ),
    "contact above the skin": (
        _with(contact=np.array([0, 1, 0, 1, 1, 1]), finger_uv_mm=None),
        r"trial 't': finger_height_mm\[1, 0\] is 8.5 in contact, expected 0",
    ),
    "unknown surface": (
        _with(finger_surface="top"),
        r"trial 't': 'finger_surface\[0\]'.*'front', 'back', 'right', 'left'; got 'top'",
    ),
}


@pytest.mark.parametrize("case", list(BAD_TRIALS))
def test_bad_ground_truth_gives_a_clear_error(case):
    fields, message = BAD_TRIALS[case]
    with pytest.raises(EctskinError, match=message):
        trial(**fields)


# ------------------------------------------------------------------- require_ground_truth
def test_require_ground_truth_names_file_version_and_trial(layout):
    rec = read_recording(V1_FILE)
    with pytest.raises(EctskinError) as info:
        require_ground_truth(rec, source="data.h5")
    assert str(info.value) == (
        "recording data.h5 (schema 1) has no per-frame finger ground truth (trial 'trial_0000' "
        "lacks contact, finger_uv_mm, finger_height_mm); record it again with ectskin simulate, "
        "or import labels (docs/import-format.md)"
    )
    with pytest.raises(EctskinError, match=re.escape(f"recording {V1_FILE} (schema 1)")):
        require_ground_truth(rec)  # the source defaults to the file read
    # a recording built in memory: no file, no version; the first trial lacking a field
    full = trial("a", layout=layout, **truth())
    part = trial("b", layout=layout, **{**truth(), "finger_uv_mm": None})
    built = Recording(layout, [full, part], 30.0)
    with pytest.raises(EctskinError, match=r"^recording has no .*trial 'b' lacks finger_uv_mm\)"):
        require_ground_truth(built)
    ok = Recording(layout, [full], 30.0)
    assert require_ground_truth(ok) is ok


# ----------------------------------------------------------------------- version-1 files
def test_v1_file_reads_with_the_ground_truth_none(layout):
    assert V1_FILE.stat().st_size < 100_000
    with h5py.File(V1_FILE, "r") as f:  # really a file of the old code
        assert f.attrs["format_version"] == 1
        assert "has_contact" not in f["trials"] and "contact" not in f["frames"]
    rec = read_recording(V1_FILE)
    assert rec.format_version == 1 and rec.source == str(V1_FILE)
    assert read_any(V1_FILE).format_version == 1
    expected = v1_fixture_recording(layout)
    assert [t.name for t in rec.trials] == ["trial_0000", "trial_0001"]
    for got, want in zip(rec.trials, expected.trials):
        for field in ("capacitance", "timestamps", "labels", "markers", "force"):
            a, b = getattr(got, field), getattr(want, field)
            assert (a is None) == (b is None) and (a is None or a.tobytes() == b.tobytes())
        for field in GROUND_TRUTH_FIELDS:
            assert getattr(got, field) is None, field
        assert not got.has_ground_truth
        assert got.finger_surface == want.finger_surface  # (), and (None,) for a force alone
    assert [t.n_fingers for t in rec.trials] == [0, 1] and rec.trials[1].force.shape == (4, 1)
    assert rec.meta == expected.meta
    rows = list_trials(V1_FILE)
    assert [r["has_contact"] for r in rows] == [False, False]
    assert [r["finger_surface"] for r in rows] == [(), (None,)]
    assert [r["has_force"] for r in rows] == [False, True]


def test_v1_file_written_again_is_the_current_version(tmp_path):
    out = write_recording(read_recording(V1_FILE), tmp_path / "new.h5")
    back = read_recording(out)
    assert back.format_version == FORMAT_VERSION == 4
    assert [t.has_ground_truth for t in back.trials] == [False, False]
    with h5py.File(out, "r") as f:
        assert int(f.attrs["format_version"]) == 4
        assert list(f["trials/has_contact"][()]) == [False, False]
        assert "contact" not in f["frames"]  # no trial has it: no dataset


# ------------------------------------------------------------------------- round trips
def _recording(layout) -> Recording:
    t = truth()
    t["finger_height_mm"][0] = np.frombuffer(b"\x01\x00\x00\x00\x00\x00\xf8\x7f", "<f8")[0]
    hover = {  # a trial that only hovers over the back, plus one without a finger
        "contact": np.zeros(N, dtype=bool),
        "finger_uv_mm": np.full((N, 2), -3.25),
        "finger_height_mm": np.linspace(1.0, 40.0, N),
    }
    return Recording(
        layout,
        [
            trial(
                "touch",
                layout=layout,
                **t,
                finger_surface="front",
                force=np.where(t["contact"], np.linspace(0, 1, N), 0.0),  # 0 off the skin
            ),
            trial("hover", layout=layout, **hover, finger_surface="back"),
            trial("none", layout=layout),
        ],
        30.0,
    )


def _assert_same_truth(a: Recording, b: Recording) -> None:
    for ta, tb in zip(a.trials, b.trials, strict=True):
        assert ta.finger_surface == tb.finger_surface, ta.name
        for field in GROUND_TRUTH_FIELDS:
            xa, xb = getattr(ta, field), getattr(tb, field)
            assert (xa is None) == (xb is None), (ta.name, field)
            if xa is not None:
                assert xa.dtype == xb.dtype and xa.shape == xb.shape, (ta.name, field)
                assert xa.tobytes() == xb.tobytes(), f"{ta.name}.{field} differs bitwise"


def test_batch_writer_round_trip_is_bit_exact(tmp_path, layout):
    rec = _recording(layout)
    back = read_recording(write_recording(rec, tmp_path / "rec.h5"))
    _assert_same_truth(rec, back)
    assert back.trials[0].finger_height_mm[:1].tobytes() == b"\x01\x00\x00\x00\x00\x00\xf8\x7f"
    assert [t.has_ground_truth for t in back.trials] == [True, True, False]


def test_append_writer_round_trip_and_checks(tmp_path, layout):
    rec = _recording(layout)
    path = tmp_path / "live.h5"
    P = layout.n_pairs
    with RecordingWriter(path, layout, 30.0) as w:
        for t in rec.trials:  # one frame, then a batch
            w.start_trial(t.name, finger_surface=t.finger_surface)
            per = {f: getattr(t, f) for f in (*GROUND_TRUTH_FIELDS, "force")}
            per = {f: v for f, v in per.items() if v is not None}
            w.append(t.capacitance[0], t.timestamps[0], **{f: v[0] for f, v in per.items()})
            w.append(t.capacitance[1:], t.timestamps[1:], **{f: v[1:] for f, v in per.items()})
        # scalars and single frames; a scalar contact or height holds for every frame
        w.start_trial("scalars", finger_surface="left")
        w.append(np.ones(P), 0.0, contact=True, finger_uv_mm=(1.0, 2.0), finger_height_mm=0.0)
        w.append(
            np.ones((2, P)),
            [0.1, 0.2],
            contact=False,
            finger_uv_mm=[[1, 2], [np.nan, np.nan]],
            finger_height_mm=[5.0, np.nan],
        )
        bad = [
            (
                lambda: w.append(np.ones(P), 0.3),
                r"contact missing here, but the trial's earlier frames had contact",
            ),
            (
                lambda: w.append(
                    np.ones(P), 0.3, contact=2, finger_uv_mm=(1, 2), finger_height_mm=1.0
                ),
                r"append to trial 'scalars': contact must be bool \(or 0/1\), found 2",
            ),
            (
                lambda: w.append(
                    np.ones(P), 0.3, contact=True, finger_uv_mm=(1, 2), finger_height_mm=1.0
                ),
                r"finger_height_mm\[0, 0\] is 1.0 in contact, expected 0",
            ),
            (
                lambda: w.append(
                    np.ones((2, P)),
                    [0.3, 0.4],
                    contact=True,
                    finger_uv_mm=(1, 2),
                    finger_height_mm=0.0,
                ),
                r"finger_uv_mm must have shape \(2, n_fingers, 2\) or, one finger, \(2, 2\); "
                r"got \(1, 2\)",
            ),
            (lambda: w.start_trial("x", finger_surface="top"), r"got 'top'"),
        ]
        for call, message in bad:
            with pytest.raises(EctskinError, match=message):
                call()
    back = read_recording(path)
    assert [t.name for t in back.trials] == ["touch", "hover", "none", "scalars"]
    _assert_same_truth(rec, Recording(layout, back.trials[:3], 30.0))
    s = back.trials[3]
    f = s.finger(0)
    assert s.finger_surface == ("left",) and f.contact.tolist() == [True, False, False]
    assert np.array_equal(f.uv_mm, [[1, 2], [1, 2], [np.nan, np.nan]], equal_nan=True)
    assert np.array_equal(f.height_mm, [0.0, 5.0, np.nan], equal_nan=True)
    # the two writers store the same recording
    other = read_recording(write_recording(back, tmp_path / "batch.h5"))
    _assert_same_truth(back, other)


def load_with_docs_snippet(path):
    """The h5py-only reader of docs/recording-format.md, run on ``path``."""
    docs = Path(__file__).resolve().parents[2] / "docs" / "recording-format.md"
    text = docs.read_text(encoding="utf-8")
    section = text[text.index("## Reading without ectskin") :]
    code = re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)
    namespace: dict = {}
    exec(compile(code, str(docs), "exec"), namespace)  # noqa: S102 (our own docs)
    return namespace["load"](path)


def assert_snippet_agrees(path) -> None:
    """The snippet gives each trial's fingers as read_recording does, bit for bit."""
    trials, _, _ = load_with_docs_snippet(path)
    rec = read_recording(path)
    assert list(trials) == [t.name for t in rec.trials]
    for t in rec.trials:
        got = trials[t.name]
        assert got["n_fingers"] == t.n_fingers, t.name
        assert got["finger_surface"] == list(t.finger_surface), t.name
        for field in ("force", *GROUND_TRUTH_FIELDS):
            want = getattr(t, field)
            assert (got[field] is None) == (want is None), (t.name, field)
            if want is not None:
                assert got[field].dtype == want.dtype and got[field].shape == want.shape
                assert got[field].tobytes() == want.tobytes(), (t.name, field)


def test_docs_snippet_reads_version_1_and_2(tmp_path):
    """The h5py-only reader of docs/recording-format.md reads version 1 and the current one."""
    old, _, _ = load_with_docs_snippet(V1_FILE)
    assert [t["contact"] for t in old.values()] == [None, None]
    assert [t["finger_surface"] for t in old.values()] == [[], [None]]
    assert old["trial_0001"]["force"].tolist() == [[0.0], [0.5], [1.0], [1.5]]
    assert_snippet_agrees(V1_FILE)
    rec = read_recording(V1_FILE)
    path = write_recording(_recording(rec.layout), tmp_path / "v4.h5")
    new, _, _ = load_with_docs_snippet(path)
    assert new["touch"]["finger_surface"] == ["front"] and new["none"]["contact"] is None
    assert new["touch"]["contact"][:, 0].tolist() == truth()["contact"].tolist()
    assert_snippet_agrees(path)
