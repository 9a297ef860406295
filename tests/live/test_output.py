"""The writers of live outputs (:mod:`ectskin.live.output`): :class:`JsonLinesWriter` as a library
object (what ``ectskin live --jsonl`` uses), and the status line, both checked against values
written out here by hand."""

from __future__ import annotations

import errno
import io
import json
import math

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.layout import default_layout
from ectskin.learn.predict import ContactReading, FingerEstimate
from ectskin.live import JsonLinesWriter, LiveEngine, Output, ReplaySource
from ectskin.live import output as live_output
from ectskin.live.output import status_line

P = default_layout().n_pairs


def _out(seq: int, **kw) -> Output:
    return Output(seq=seq, t=seq / 30, raw=np.full(P, 10.0 + seq), **kw)


def test_every_output_is_one_line_of_its_message(tmp_path):
    path = tmp_path / "out.jsonl"
    outs = [_out(0), _out(1, calibrated=np.full(P, np.nan)), _out(2, touch_cls=3)]
    with JsonLinesWriter(path) as writer:
        for o in outs:
            writer(o)
    assert writer.lines == 3
    lines = path.read_text(encoding="utf-8").splitlines()
    assert [json.loads(x) for x in lines] == [o.to_json_dict() for o in outs]
    assert json.loads(lines[1])["calibrated"] == [None] * P  # strict JSON: NaN is null
    assert json.loads(lines[2])["raw"][0] == 12.0


def test_an_engine_writes_through_it_and_an_existing_file_needs_overwrite(tmp_path, make_recording):
    rec = make_recording(n_frames=5, markers=False)
    path = tmp_path / "out.jsonl"
    path.write_text("earlier\n")
    with pytest.raises(EctskinError, match="out.jsonl exists; refusing to replace it"):
        JsonLinesWriter(path)
    assert path.read_text() == "earlier\n"
    engine = LiveEngine(ReplaySource(rec, speed=math.inf), reference_frames=2, policy="block")
    with JsonLinesWriter(path, overwrite=True) as writer:
        engine.run(on_output=writer)
    seqs = [json.loads(x)["seq"] for x in path.read_text().splitlines()]
    assert seqs == list(range(rec.n_frames))


class _FullDisk(io.StringIO):
    """A text file on a disk that fills up after ``room`` writes."""

    def __init__(self, room: int):
        super().__init__()
        self.room = room

    def write(self, text: str) -> int:
        if self.room <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= 1
        return super().write(text)


def test_a_full_disk_stops_once_removes_the_file_and_says_how_far_it_got(tmp_path, monkeypatch):
    path = tmp_path / "out.jsonl"
    real_open = open

    def open_on_full_disk(p, *args, **kwargs):
        real_open(p, *args, **kwargs).close()  # the file exists, as a real one would
        return _FullDisk(room=2)

    monkeypatch.setattr(live_output, "open", open_on_full_disk, raising=False)
    stops = []
    writer = JsonLinesWriter(path, on_error=lambda: stops.append(1), name="--jsonl X")
    for i in range(5):
        writer(_out(i))
    assert writer.lines == 2 and stops == [1]  # stopped once, not once per later output
    with pytest.raises(
        EctskinError,
        match=r"^--jsonl X: cannot write \(No space left on device\); stopped after 2 lines; "
        r"removed the incomplete file$",
    ):
        writer.close()
    assert not path.exists()


def test_a_stream_is_written_to_never_closed_nor_removed():
    stream = io.StringIO()
    writer = JsonLinesWriter(stream)
    writer(_out(7))
    writer.close()
    assert not stream.closed
    assert json.loads(stream.getvalue())["seq"] == 7

    full = _FullDisk(room=0)
    writer = JsonLinesWriter(full, name="stdout")
    writer(_out(0))
    with pytest.raises(EctskinError, match=r"^stdout: cannot write .*; stopped after 0 lines$"):
        writer.close()


def test_status_line_by_hand():
    stats = {
        "fps_out": 29.96,
        "latency_ms_p50": 1.25,
        "latency_ms_p99": 3.5,
        "dropped": 2,
        "malformed": 1,
        "reconnects": 0,
        "reference": {"touch": {"state": "ready"}},
    }
    ref = np.zeros((2, 3))
    pred = np.array([[3.0, 4.0, 0.0], [0.0, 1.0, 0.0]])  # moved 5 mm and 1 mm
    two = ContactReading(
        2,
        0.99,
        0.01,
        (
            FingerEstimate("front", 3.2, 40.6, 2.0, 0.8),
            FingerEstimate("back", -1, 99.5, 3, 1.25),
        ),
    )
    out = _out(45, touch_cls=7, markers_pred=pred, markers_reference=ref, contact=two, stats=stats)
    assert status_line(out) == (
        "t     1.500 s | touch class  7 | markers moved  5.00 mm | contact 2: front (3, 41) mm "
        "0.80 N, back (-1, 100) mm 1.25 N hover 0.01 | reference ready |  30.0 fps | latency "
        "p50 1.25 ms p99 3.5 ms | dropped 2 malformed 1 reconnects 0"
    )
    out.contact = ContactReading(0, 0.1, 0.7, ())
    assert " | contact 0 hover 0.70 | " in status_line(out)
    out.contact = out.touch_cls = out.markers_pred = None
    stats["reference"] = {}
    assert status_line(out).startswith("t     1.500 s | touch - | markers moved - | reference - |")
