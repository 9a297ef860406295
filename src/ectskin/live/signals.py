"""Stopping a recording command cleanly on Ctrl-C, SIGTERM and SIGHUP.

A recording left without its closing write is marked incomplete, and every reader then refuses it
unless told to accept a partial file. ``kill PID`` (SIGTERM), a closed terminal (SIGHUP) and
Ctrl-C (SIGINT) must therefore all take the same path as Ctrl-C: stop reading, write what is
queued, mark the file complete. :func:`stop_on_signals` turns the first of these signals into a
``KeyboardInterrupt`` (the path every live command already takes on Ctrl-C) and ignores the
following ones while the command closes its files, so an impatient second signal cannot cut the
closing write short.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Iterator

logger = logging.getLogger(__name__)

#: The signals that stop a recording command cleanly (those the platform has).
STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


@contextlib.contextmanager
def stop_on_signals(closing: str = "closing") -> Iterator[None]:
    """Within the block, the first SIGINT/SIGTERM/SIGHUP raises ``KeyboardInterrupt``; later
    ones are logged (``closing`` says what is being done) and ignored. The previous handlers
    are restored at the end. Outside the main thread (where Python delivers signals) it does
    nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def handler(signum: int, frame) -> None:
        name = signal.Signals(signum).name
        if received:
            logger.warning("%s received; already %s, please wait", name, closing)
            return
        received.append(signum)
        logger.info("%s received; %s", name, closing)
        raise KeyboardInterrupt(name)

    previous = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
