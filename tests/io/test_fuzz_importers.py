"""Property-based fuzzing of every importer and the HDF5 reader (Hypothesis).

The property: a file either imports or raises :class:`~ectskin.EctskinError`, never another
exception and never a crash; and what imports can be written and read back (an import must not
make a recording the reader refuses).

Inputs are generated around valid files, so that most examples get past the first checks:
structured tables of chosen columns and cells (generic CSV), archives of fields of varied dtypes
and shapes (generic NPZ), byte-level mutations of the example exports in ``tests/data`` (capacitance
meter, Motive), and structural mutations of valid recordings through h5py (HDF5). Byte-level
mutations of HDF5 files are not fuzzed: HDF5 itself crashes (a segfault in ``H5Aread`` converting
a variable-length string attribute) on some corrupted metadata bytes, below anything ectskin can
check; truncated HDF5 files are fuzzed.

Profiles (``ECTSKIN_FUZZ_PROFILE``): ``ci`` (default: derandomized, a fixed number of examples
per test, about 30 s in all on a 2-core machine) and ``thorough`` (random, 20 times as many).
"""

from __future__ import annotations

import os
import tempfile
from datetime import timedelta
from pathlib import Path

import h5py
import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ectskin import EctskinError
from ectskin.io.capmeter import read_capmeter_csv
from ectskin.io.generic import NPZ_FIELDS, load_generic
from ectskin.io.hdf5 import (
    RecordingWriter,
    list_trials,
    read_layout,
    read_recording,
    write_recording,
)
from ectskin.io.motive import read_motive_csv

DATA = Path(__file__).resolve().parents[1] / "data" / "instruments"

settings.register_profile(
    "ci",
    max_examples=40,
    deadline=timedelta(seconds=5),
    derandomize=True,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "thorough",
    max_examples=800,
    deadline=timedelta(seconds=10),
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
PROFILE = settings.get_profile(os.environ.get("ECTSKIN_FUZZ_PROFILE", "ci"))


def fuzz(scale: float = 1.0):
    """The profile's settings, with ``scale`` times its examples (cheap tests run more)."""
    return settings(PROFILE, max_examples=max(1, int(PROFILE.max_examples * scale)))


def _roundtrip(rec) -> None:
    """What imported can be written and read back, frame for frame."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "r.h5"
        write_recording(rec, path)
        back = read_recording(path)
    assert back.n_trials == rec.n_trials and back.n_frames == rec.n_frames


def _imports_or_refuses(read, *args, **kwargs):
    """``read(...)``, or None when it refuses with an EctskinError (any other exception fails)."""
    try:
        out = read(*args, **kwargs)
    except EctskinError:
        event(f"{read.__name__}: refused")
        return None
    event(f"{read.__name__}: read")
    return out


# ------------------------------------------------------------------------------ generic CSV
SPECIAL_CELLS = [
    "", " ", "0", "1", "-1", "2", "1.5", "1.00239", "1.0", "1.", "nan", "NaN", "inf", "-inf",
    "1e308", "1.7e308", "-1.7e308", "1e-320", "1000", "1001", "-0", "1,5", "a", "#x", '"',
    "\x00", "a\x00b", "é", "g1", "1e", "0x10", "١",
]
GROUP_CELLS = ["1", "2", "g", "h", "", " ", "a\x00b", "-3", "1.5", "99999999999999999999999"]
COLUMNS = [
    "group", "time_s", "label", "c:a", "c:b", "c:c", "ref:a", "ref:b", "m:p.x", "m:p.y",
    "m:p.z", "m:q.x", "c:", "foo", "Group", " c:a",
]
text_cells = st.text(
    alphabet=st.characters(blacklist_categories=("Cs",)), max_size=6
)
number_cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-3, 1200).map(str),
    st.decimals(allow_nan=False, allow_infinity=False, places=5).map(str),
)
cells = st.one_of(st.sampled_from(SPECIAL_CELLS), number_cells, text_cells)


HEADERS = [
    ["group", "time_s", "label", "c:a", "c:b", "m:p.x", "m:p.y", "m:p.z"],
    ["group", "label", "c:a", "c:b", "c:c", "ref:a", "ref:b", "ref:c"],
    ["c:a", "group", "label", "c:b", "time_s"],
    ["group", "time_s", "m:p.x", "m:p.y", "m:p.z", "c:a"],
]


def _good_cell(draw, column: str, row: int, group: str) -> str:
    """A cell a valid file could hold in ``column`` (the row's group id given)."""
    if column == "group":
        return group
    if column == "time_s":
        return repr(row / 30 + draw(st.floats(0, 0.01)))
    if column == "label":
        return draw(st.sampled_from(["0", "1", "2"]))
    if column.startswith("m:"):
        return draw(st.one_of(st.floats(-100, 100).map(repr), st.just("")))
    number = st.floats(0.5, 2.0).map(lambda v: f"{v:.5f}")
    if column.startswith("ref:"):
        return draw(number)
    return draw(st.one_of(number, number, number, st.just("")))


@st.composite
def generic_csv(draw) -> str:
    """A valid generic CSV (a chosen header, rows of plausible cells), then a few faults:
    odd cells, rows of the wrong width, unknown columns, a cut or missing final newline."""
    header = list(draw(st.sampled_from(HEADERS)))
    if draw(st.integers(0, 5)) == 0:
        header = draw(st.lists(st.sampled_from(COLUMNS), min_size=1, max_size=9))
    groups = draw(st.lists(st.sampled_from(["1", "2", "g", "h"]), min_size=1, max_size=3))
    n = draw(st.integers(0, 9))
    rows = [
        [_good_cell(draw, c, k, groups[k * len(groups) // max(n, 1)]) for c in header]
        for k in range(n)
    ]
    for _ in range(draw(st.integers(0, 3))):  # faults
        if not rows:
            break
        r = draw(st.integers(0, len(rows) - 1))
        fault = draw(st.sampled_from(["cell", "cell", "group", "width"]))
        if fault == "width":
            rows[r] = rows[r][:-1] if draw(st.booleans()) else [*rows[r], draw(cells)]
        elif rows[r]:
            j = draw(st.integers(0, len(rows[r]) - 1))
            pool = st.sampled_from(GROUP_CELLS) if fault == "group" else cells
            rows[r][j] = draw(pool)
    head = []
    if draw(st.integers(0, 3)):
        head.append("# frame_rate_hz: " + draw(st.sampled_from(["30", "30", "30", "0", "x"])))
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    text = newline.join([*head, ",".join(header), *(",".join(r) for r in rows)])
    if draw(st.integers(0, 3)):
        text += newline
    if draw(st.integers(0, 5)) == 0:
        text = text[: draw(st.integers(0, len(text)))]  # a copy that stopped
    return text


@fuzz(2.0)
@given(text=generic_csv())
def test_fuzz_generic_csv(text):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.csv"
        path.write_text(text, encoding="utf-8")
        rec = _imports_or_refuses(load_generic, path)
    if rec is not None:
        _roundtrip(rec)


@fuzz(1.0)
@given(raw=st.binary(max_size=400))
def test_fuzz_generic_csv_bytes(raw):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.csv"
        good = "".join(f"g,{k % 2},1.{k}\n" for k in range(5)).encode()
        at = len(raw) // 2
        path.write_bytes(b"group,label,c:a\n" + good[:at] + raw + good[at:])
        rec = _imports_or_refuses(load_generic, path, frame_rate_hz=30.0)
    if rec is not None:
        _roundtrip(rec)


# ------------------------------------------------------------------------------ generic NPZ
NPZ_FIELD_NAMES = list(NPZ_FIELDS)
FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)
SMALL_INTS = st.integers(-2, 1002)


def _array(draw, shape, kind: str):
    dtype = {"f": np.float64, "i": np.int64, "b": np.bool_, "U": "<U4", "S": "S4"}[kind]
    elements = {
        "f": st.one_of(FLOATS, st.sampled_from([0.0, 1.0, 2.0, 1.7e308])),
        "i": SMALL_INTS,
        "b": st.booleans(),
        "U": st.sampled_from(["a", "b", "", " ", "a\x00b", "é"]),
        "S": st.sampled_from([b"a", b"b", b"", b"\xff", b"a\x00b"]),
    }[kind]
    return draw(hnp.arrays(dtype, shape, elements=elements))


@st.composite
def generic_npz(draw) -> dict:
    """Valid fields (readouts, group, labels and some optional ones), then a few faults: a
    field of another dtype or shape, odd values, a missing or unknown field."""
    n = draw(st.integers(1, 6))
    m = draw(st.integers(1, 4))
    n_markers = draw(st.integers(1, 2))
    gkind = draw(st.sampled_from("iU"))
    group = np.sort(draw(hnp.arrays(np.int64, (n,), elements=st.integers(0, 2))))
    fields: dict = {
        "readouts": draw(hnp.arrays(np.float64, (n, m), elements=st.floats(0.5, 2.0))),
        "group": group if gkind == "i" else np.array([f"g{v}" for v in group]),
    }
    if draw(st.integers(0, 3)):
        fields["labels"] = draw(hnp.arrays(np.int64, (n,), elements=st.integers(0, 3)))
    if draw(st.booleans()) or "labels" not in fields:
        fields["markers"] = draw(
            hnp.arrays(np.float64, (n, n_markers, 3), elements=st.floats(-50, 50))
        )
    if draw(st.booleans()):
        fields["timestamps"] = np.arange(n) / 30 + draw(st.floats(0, 100))
    else:
        fields["frame_rate_hz"] = np.float64(draw(st.sampled_from([30.0, 100.0])))
    if draw(st.integers(0, 3)) == 0:
        fields["reference"] = np.ones(draw(st.sampled_from([(m,), (n, m)])))
    if draw(st.integers(0, 3)) == 0:
        fields["channel_names"] = np.array([f"ch{j}" for j in range(m)])
    if "markers" in fields and draw(st.integers(0, 3)) == 0:
        fields["marker_names"] = np.array([f"mk{j}" for j in range(n_markers)])
    odd_shape = hnp.array_shapes(min_dims=0, max_dims=3, max_side=4)
    for _ in range(draw(st.integers(0, 2))):  # faults
        name = draw(st.sampled_from([*NPZ_FIELD_NAMES, "extra"]))
        fault = draw(st.sampled_from(["values", "dtype", "shape", "drop"]))
        if fault == "drop":
            fields.pop(name, None)
            continue
        old = fields.get(name, np.zeros(n))
        shape = draw(odd_shape) if fault == "shape" else old.shape
        kind = draw(st.sampled_from("fibUS")) if fault == "dtype" else old.dtype.kind
        fields[name] = _array(draw, shape, kind if kind in "fibUS" else "f")
    return fields


@fuzz(2.0)
@given(fields=generic_npz())
def test_fuzz_generic_npz(fields):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.npz"
        np.savez(path, **fields)
        rec = _imports_or_refuses(load_generic, path)
    if rec is not None:
        _roundtrip(rec)


@fuzz(0.5)
@given(data=st.data())
def test_fuzz_generic_npz_bytes(data):
    """Damaged archives: bytes of a valid one overwritten or cut."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.npz"
        np.savez(path, readouts=np.ones((3, 2)), group=np.arange(3), labels=np.zeros(3),
                 frame_rate_hz=30.0)
        raw = _mutate(data, path.read_bytes())
        path.write_bytes(raw)
        rec = _imports_or_refuses(load_generic, path)
    if rec is not None:
        _roundtrip(rec)


# -------------------------------------------------------------- byte mutations of example files
def _mutate(data, raw: bytes) -> bytes:
    """A few byte-level edits: overwrite, insert, delete a span, duplicate a line, truncate."""
    b = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 4), label="edits")):
        op = data.draw(st.sampled_from(["set", "insert", "delete", "line", "cut"]), label="op")
        if not b:
            break
        at = data.draw(st.integers(0, len(b) - 1), label="at")
        if op == "set":
            b[at] = data.draw(st.sampled_from(b"0123456789.,;-eE \t\n\"x\x00\xff"), label="byte")
        elif op == "insert":
            b[at:at] = data.draw(
                st.one_of(st.binary(max_size=8), st.sampled_from([b",", b"\n", b"1.7e308",
                                                                   b"OL", b";", b"\r"])),
                label="bytes",
            )
        elif op == "delete":
            del b[at : at + data.draw(st.integers(1, 40), label="length")]
        elif op == "line":
            start = b.rfind(b"\n", 0, at) + 1
            end = b.find(b"\n", at)
            end = len(b) if end < 0 else end + 1
            b[end:end] = b[start:end]
        else:
            del b[at:]
    return bytes(b)


CAPMETER_FILES = sorted(DATA.glob("capmeter_*.csv"))
MOTIVE_FILES = sorted(DATA.glob("motive_*.csv"))


@fuzz(2.0)
@given(data=st.data())
def test_fuzz_capacitance_csv(data):
    src = data.draw(st.sampled_from(CAPMETER_FILES), label="file")
    raw = _mutate(data, src.read_bytes())
    strict = data.draw(st.booleans(), label="strict")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / src.name
        path.write_bytes(raw)
        cap = _imports_or_refuses(read_capmeter_csv, path, strict=strict)
    if cap is not None:
        assert cap.values.shape == (cap.n_frames, len(cap.channels))
        assert np.all(np.diff(cap.timestamps) > 0)
        cap.mask_report.summary()


@fuzz(1.5)
@given(data=st.data())
def test_fuzz_motive_csv(data):
    src = data.draw(st.sampled_from(MOTIVE_FILES), label="file")
    raw = _mutate(data, src.read_bytes())
    strict = data.draw(st.booleans(), label="strict")
    names = data.draw(st.sampled_from([None, ["M1"], ["M2", "M1"], ["Skin:M3"], ["X"]]),
                      label="marker_names")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / src.name
        path.write_bytes(raw)
        mc = _imports_or_refuses(read_motive_csv, path, names, strict=strict)
    if mc is not None:
        assert mc.positions.shape == (mc.n_frames, mc.n_markers, 3)
        assert np.all(np.diff(mc.timestamps) > 0)
        mc.summary()


# ------------------------------------------------------------------------------ HDF5 reader
def _valid_recordings(d: Path, layout) -> list[Path]:
    rng = np.random.default_rng(0)
    from ectskin.io.recording import Recording, Trial

    trials = [
        Trial(
            name=f"t{k}",
            capacitance=rng.uniform(0.5, 1.5, (4, layout.n_pairs)),
            timestamps=np.arange(4) / 30,
            labels=np.array([0, k, k, 0]),
            inflation=(0.0, 10.0, 20.0),
            region=k,
            markers=rng.normal(size=(4, layout.n_markers, 3)) if k else None,
            force=np.zeros(4),
            meta={"k": k},
        )
        for k in range(2)
    ]
    rec = Recording(layout, trials, 30.0, {"events": [{"t_s": 0.1, "trial": "t1", "text": "x"}]})
    full = d / "full.h5"
    write_recording(rec, full)
    partial = d / "partial.h5"
    w = RecordingWriter(partial, layout, 30.0, flush_interval_s=0)
    w.start_trial("live", region=1)
    w.append(np.ones((3, layout.n_pairs)), np.arange(3) / 30, contact=np.zeros(3, bool),
             finger_uv_mm=np.full((3, 2), np.nan), finger_height_mm=np.full(3, np.nan))
    w.add_event(0.0, "start")
    w.close(complete=False)
    return [full, partial]


ATTR_VALUES = st.one_of(
    st.sampled_from(["ectskin.recording", "", "{", "{}", "[]", "null", '{"a": NaN}', "\u00e9"]),
    st.integers(-2, 3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.lists(st.integers(-1, 3), max_size=3).map(np.asarray),
)


def _nodes(f: h5py.File) -> list[str]:
    out = []
    f.visit(out.append)
    return sorted(out)


def _mutate_hdf5(data, path: Path) -> None:
    """Structural edits that keep a valid HDF5 file: attributes, datasets, nodes. An edit that
    h5py itself cannot make (a NUL in a string, a node an earlier edit deleted) is skipped."""
    with h5py.File(path, "r+") as f:
        for _ in range(data.draw(st.integers(1, 3), label="edits")):
            try:
                _edit_hdf5(data, f)
            except (ValueError, KeyError, TypeError, OSError, RuntimeError, OverflowError):
                event("an edit h5py refused")


def _edit_hdf5(data, f: h5py.File) -> None:
    """One edit: an attribute set or deleted, a dataset deleted, replaced, edited or resized."""
    nodes = _nodes(f)
    op = data.draw(
        st.sampled_from(["attr", "del_attr", "delete", "replace", "values", "resize"]),
        label="op",
    )
    if op in ("attr", "del_attr"):
        where = data.draw(st.sampled_from(["/", "layout", "committed"]), label="node")
        obj = f[where]
        keys = sorted(obj.attrs) or ["format"]
        key = data.draw(st.sampled_from([*keys, "json", "complete"]), label="key")
        if op == "del_attr":
            if key in obj.attrs:
                del obj.attrs[key]
        else:
            obj.attrs[key] = data.draw(ATTR_VALUES, label="value")
        return
    datasets = [n for n in nodes if isinstance(f[n], h5py.Dataset)]
    name = data.draw(st.sampled_from(datasets or nodes), label="dataset")
    if op == "delete":
        del f[name]
    elif op == "replace":
        shape = data.draw(hnp.array_shapes(min_dims=0, max_dims=3, max_side=5))
        kind = data.draw(st.sampled_from("fibU"), label="dtype")
        arr = _array(data.draw, shape, kind)
        if kind == "U":
            arr = arr.astype(object)
        del f[name]
        f.create_dataset(
            name, data=arr, dtype=h5py.string_dtype() if kind == "U" else None
        )
    elif op == "values":
        ds = f[name]
        if ds.size and ds.dtype.kind in "iufb":
            flat = np.asarray(ds[()]).copy().reshape(-1)
            k = data.draw(st.integers(0, flat.size - 1), label="index")
            new = [-1, 0, 1, 2, 3, 99, 10**6]
            if ds.dtype.kind == "f":
                new += [np.nan, np.inf, 1.7e308]
            flat[k] = data.draw(st.sampled_from(new), label="new")
            ds[()] = flat.reshape(ds.shape)
        elif ds.size and h5py.check_string_dtype(ds.dtype) is not None and ds.ndim == 1:
            ds[0] = data.draw(st.sampled_from(["", "t1", "{", "[]", "x" * 50]),
                              label="text")
    else:  # resize
        ds = f[name]
        if ds.maxshape and ds.ndim and ds.maxshape[0] is None:
            ds.resize(data.draw(st.integers(0, ds.shape[0] + 3), label="rows"), axis=0)


@fuzz(2.0)
@given(data=st.data())
def test_fuzz_hdf5_reader_structure(data, layout):
    with tempfile.TemporaryDirectory() as d:
        files = _valid_recordings(Path(d), layout)
        path = data.draw(st.sampled_from(files), label="file")
        _mutate_hdf5(data, path)
        partial = data.draw(st.booleans(), label="allow_partial")
        rec = _imports_or_refuses(read_recording, path, allow_partial=partial)
        _imports_or_refuses(list_trials, path, allow_partial=partial)
        _imports_or_refuses(read_layout, path)
        if rec is not None:
            _roundtrip(rec)


@fuzz(1.0)
@given(data=st.data())
def test_fuzz_hdf5_reader_truncated(data, layout):
    with tempfile.TemporaryDirectory() as d:
        files = _valid_recordings(Path(d), layout)
        path = data.draw(st.sampled_from(files), label="file")
        raw = path.read_bytes()
        cut = data.draw(st.integers(0, len(raw) - 1), label="cut")
        path.write_bytes(raw[:cut])
        rec = _imports_or_refuses(read_recording, path, allow_partial=True)
        if rec is not None:
            _roundtrip(rec)

