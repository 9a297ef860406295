"""Live operation: frame sources, crash-safe recording and the inference engine.

* :mod:`ectskin.live.sources` — :class:`Frame` and the sources (replay, twin, LSL, serial, TCP)
  behind one iterator interface, one module each; :func:`open_source` parses ``replay:FILE``,
  ``sim``, ``lsl:NAME``, ``serial:PORT[@BAUD]``, ``tcp:HOST:PORT``.
* :mod:`ectskin.live.recorder` — :class:`Recorder` (every frame to HDF5, flushed ≤ 0.25 s) and
  :func:`record_stream` (``ectskin record``).
* :mod:`ectskin.live.engine` — :class:`LiveEngine`: reference capture
  (:mod:`~ectskin.live.reference`), calibration (paper Eq. 2), the heads
  (:mod:`~ectskin.live.heads`: :class:`TouchHead`, :class:`TrackHead`, :class:`ContactHead`,
  :class:`EctHead`, giving an :class:`EctFrame`; :mod:`~ectskin.live.inversion_head`:
  :class:`InversionHead`, the physical inversion, giving an :class:`InversionFrame`), latency
  and drop accounting
  (:mod:`~ectskin.live.meter`); emits :class:`Output`.
* :mod:`ectskin.live.output` — :class:`Output` and its JSON message, :class:`JsonLinesWriter`
  (every output as a JSON line, ``ectskin live --jsonl``).

Optional dependencies (pyserial, pylsl) are imported only when such a source is opened.
"""

from ectskin.live.engine import POLICIES, LiveEngine
from ectskin.live.heads import ContactHead, EctHead, Head, TouchHead, TrackHead
from ectskin.live.inversion_head import InversionHead, load_fields
from ectskin.live.output import EctFrame, InversionFrame, JsonLinesWriter, Output
from ectskin.live.recorder import Recorder, record_stream
from ectskin.live.sources import (
    Frame,
    FrameSource,
    LslSource,
    ReplaySource,
    SerialSource,
    TcpSource,
    TwinSource,
    TwinStep,
    open_source,
    parse_line,
)

__all__ = [
    "POLICIES",
    "ContactHead",
    "EctFrame",
    "EctHead",
    "Frame",
    "FrameSource",
    "Head",
    "InversionFrame",
    "InversionHead",
    "JsonLinesWriter",
    "LiveEngine",
    "LslSource",
    "Output",
    "Recorder",
    "ReplaySource",
    "SerialSource",
    "TcpSource",
    "TouchHead",
    "TrackHead",
    "TwinSource",
    "TwinStep",
    "load_fields",
    "open_source",
    "parse_line",
    "record_stream",
]
