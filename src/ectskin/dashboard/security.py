"""The dashboard's guards. It has no authentication, so it relies on two checks:

* :func:`same_origin`: a request (the reference re-capture, the websocket) whose ``Origin`` names
  another site is refused, so a web page open in the same browser cannot drive the dashboard;
* :func:`warn_if_public`: :func:`~ectskin.dashboard.server.serve` binds 127.0.0.1 by default,
  and says so loudly when told to listen on another address.
"""

from __future__ import annotations

import logging
from urllib.parse import urlsplit

logger = logging.getLogger(__name__)

#: Hosts that only this machine can reach.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def same_origin(origin: str | None, host: str | None) -> bool:
    """True without an ``Origin`` header (not a browser) or when it names the page's own host."""
    if not origin:
        return True
    if origin == "null":
        return False
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    return bool(host) and parts.netloc.lower() == host.lower()


def warn_if_public(host: str) -> None:
    """Log a warning when ``host`` is reachable from other machines."""
    if host not in LOCAL_HOSTS:
        logger.warning(
            "dashboard listening on %s: anyone who can reach this address can watch the "
            "stream and re-capture the reference (there is no authentication)", host
        )
