"""Live frame sources: one interface over replayed files, the digital twin, LSL, serial and TCP.

Every source is an iterator of :class:`Frame` with ``close()`` and a ``counters`` dict:

==================  ==========================================================================
counter             meaning
==================  ==========================================================================
``frames``          valid frames handed out
``malformed``       input that could not be parsed (bad number, unknown field, over-long line,
                    line cut by a disconnect, non-finite value other than ``nan``)
``wrong_channels``  input with the wrong number of channel values (or marker coordinates)
``disconnects``     connections lost (TCP server gone, serial device unplugged, LSL outlet lost)
``reconnects``      connections re-established after a disconnect
``seq_gaps``        frames missing according to the sequence numbers (lost upstream)
==================  ==========================================================================

Bad input is never raised into the consumer: it is counted, logged (rate-limited) and described in
``source.problems`` (the last 50 messages, each naming the source, the line or frame and the
channel). Only configuration errors found when a source is opened (a missing file, an unknown
stream name, a refused connection) raise :class:`~ectskin._check.EctskinError`.

Modules: :mod:`~.base` (:class:`Frame`, :class:`FrameSource`), :mod:`~.protocol` (the serial/TCP
line protocol of ``docs/serial-protocol.md``, :func:`parse_line`), :mod:`~.lines` (the byte-stream
base of serial and TCP), and one module per source: :mod:`~.replay`, :mod:`~.sim`, :mod:`~.lsl`,
:mod:`~.serial`, :mod:`~.tcp`. This package's :func:`open_source` builds a source from a short
spec string: ``replay:FILE``, ``sim``, ``lsl:NAME``, ``serial:PORT[@BAUD]`` or ``tcp:HOST:PORT``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout
from ectskin.live.sources.base import COUNTERS, Frame, FrameSource
from ectskin.live.sources.lines import LineSource
from ectskin.live.sources.lsl import LslSource
from ectskin.live.sources.protocol import (
    MAX_LINE_BYTES,
    MAX_SEQ,
    LineError,
    ParsedLine,
    parse_line,
)
from ectskin.live.sources.replay import ReplaySource
from ectskin.live.sources.serial import SerialSource
from ectskin.live.sources.sim import TwinSource, TwinStep, demo_scenario
from ectskin.live.sources.tcp import TcpSource

SOURCE_SPECS = "replay:FILE, sim, lsl:NAME, serial:PORT[@BAUD], tcp:HOST:PORT"
SOURCE_KINDS = ("replay", "sim", "lsl", "serial", "tcp")

_SPEC = re.compile(r"^(?P<kind>[a-z]+)(?::(?P<rest>.*))?$", re.DOTALL)


def open_source(
    spec: str,
    *,
    layout: SensorLayout | None = None,
    speed: float = 1.0,
    loop: bool = False,
    paced: bool = True,
    seed: int = 0,
    allow_partial: bool = False,
    **kwargs: Any,
) -> FrameSource:
    """Open a source from a spec string.

    ``replay:FILE`` (``speed``, ``loop``, ``allow_partial``: also a recording left incomplete by
    a crash), ``sim`` (the digital twin; ``paced``, ``seed``),
    ``lsl:NAME``, ``serial:PORT[@BAUD]`` (default 115200 baud), ``tcp:HOST:PORT``. ``layout``
    gives the channel count for lsl/serial/tcp (default: the paper's layout); a replay uses the
    recording's own layout. Extra keyword arguments go to the source class.
    """
    if not isinstance(spec, str) or not (m := _SPEC.match(spec.strip())):
        if isinstance(spec, str) and _looks_like_a_file(spec):
            raise EctskinError(
                f"Invalid source {spec!r}: to replay a recording, write replay:{spec}"
            )
        raise EctskinError(f"Invalid source {spec!r}: expected one of {SOURCE_SPECS}")
    kind, rest = m.group("kind"), m.group("rest")
    check_option("source kind", kind, SOURCE_KINDS)
    if kind == "sim":
        if rest:
            raise EctskinError(f"Invalid source {spec!r}: 'sim' takes no argument")
        return TwinSource(layout=layout, paced=paced, seed=seed, **kwargs)
    if not rest:
        raise EctskinError(f"Invalid source {spec!r}: {kind} needs an argument ({SOURCE_SPECS})")
    if kind == "replay":
        path = Path(rest)
        if not path.is_file():
            raise EctskinError(f"source {spec!r}: no such recording file {str(path)!r}")
        return ReplaySource(path, speed=speed, loop=loop, allow_partial=allow_partial, **kwargs)
    if kind == "lsl":
        return LslSource(rest, layout=layout, **kwargs)
    if kind == "serial":
        port, baud = _serial_spec(spec, rest)
        return SerialSource(port, baud, layout=layout, **kwargs)
    host, port = _tcp_spec(spec, rest)
    return TcpSource(host, port, layout=layout, **kwargs)


def _looks_like_a_file(spec: str) -> bool:
    """A spec that is a recording's path rather than a source (``--source s.h5``)."""
    return spec.lower().endswith((".h5", ".hdf5", ".hdf")) or Path(spec).is_file()


def source_files(spec: str) -> list[Path]:
    """The files that the source ``spec`` reads (``replay:FILE``; none for the others)."""
    m = _SPEC.match(spec.strip()) if isinstance(spec, str) else None
    if m and m.group("kind") == "replay" and m.group("rest"):
        return [Path(m.group("rest"))]
    return []


def check_not_input(out: str | os.PathLike, spec: str, option: str) -> None:
    """Refuse to write ``out`` (given as ``option``, e.g. ``--record``) when it is a file that
    source ``spec`` reads: no command writes onto its own input, even when told to overwrite."""
    out_path = Path(out)
    for f in source_files(spec):
        same = (
            os.path.samefile(out_path, f)
            if out_path.exists() and f.exists()
            else out_path.resolve() == f.resolve()
        )
        if same:
            raise EctskinError(
                f"{option} {str(out)!r} is the file the source {spec!r} reads; refusing to write "
                "onto the command's own input (choose another output file)"
            )


def _serial_spec(spec: str, rest: str) -> tuple[str, int]:
    """``PORT[@BAUD]`` → (port, baud); 115200 baud when none is given."""
    port, baud = rest, 115200
    if "@" in rest:
        port, _, b = rest.rpartition("@")
        if not b.isdigit() or int(b) <= 0 or not port:
            raise EctskinError(
                f"Invalid source {spec!r}: expected serial:PORT[@BAUD] with BAUD a positive "
                f"integer, got {b!r}"
            )
        baud = int(b)
    return port, baud


def _tcp_spec(spec: str, rest: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:5000`` for IPv6) → (host, port)."""
    host, _, port_s = rest.rpartition(":")
    host = host.strip("[]")  # [::1]:5000
    if not host or not port_s.isdigit() or not 0 < int(port_s) < 65536:
        raise EctskinError(f"Invalid source {spec!r}: expected tcp:HOST:PORT with PORT in 1..65535")
    return host, int(port_s)


__all__ = [
    "COUNTERS",
    "MAX_LINE_BYTES",
    "MAX_SEQ",
    "SOURCE_KINDS",
    "SOURCE_SPECS",
    "Frame",
    "FrameSource",
    "LineError",
    "LineSource",
    "LslSource",
    "ParsedLine",
    "ReplaySource",
    "SerialSource",
    "TcpSource",
    "TwinSource",
    "TwinStep",
    "check_not_input",
    "demo_scenario",
    "open_source",
    "parse_line",
    "source_files",
]
