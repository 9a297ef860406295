"""The dashboard's guards. It has no authentication, so it relies on three checks:

* :func:`host_allowed` (every request, HTTP and websocket, through :class:`HostCheck`): the
  ``Host`` header must name this machine's loopback (``127.0.0.1`` and the rest of 127/8,
  ``::1``, ``localhost``, ``*.localhost``) or a configured name. This defeats DNS rebinding: a
  page from ``evil.example`` whose name is re-pointed at 127.0.0.1 reaches the port, but its
  requests say ``Host: evil.example`` and are refused, so comparing ``Origin`` with ``Host``
  (which such a page passes, both being ``evil.example``) is not the only guard;
* :func:`same_origin`: a request that changes something (the reference re-capture) or opens the
  stream, and whose ``Origin`` names another site, is refused, so a web page open in the same
  browser cannot drive the dashboard;
* :func:`warn_if_public`: :func:`~ectskin.dashboard.server.serve` binds 127.0.0.1 by default,
  and says so loudly when told to listen on another address.
"""

from __future__ import annotations

import ipaddress
import logging
from collections.abc import Iterable
from urllib.parse import urlsplit

logger = logging.getLogger(__name__)

#: Hosts that only this machine can reach.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def split_host(host: str) -> str:
    """The name or address of a ``Host`` header without its port, lower case, without a
    trailing dot (``"[::1]:8765"`` → ``"::1"``, ``"LocalHost.:80"`` → ``"localhost"``)."""
    host = host.strip().lower()
    if host.startswith("["):  # [v6]:port
        name = host[1:].partition("]")[0]
    else:
        name, colon, port = host.rpartition(":")
        if not colon or not port.isdigit() or ":" in name:
            name = host  # no port (or a bare IPv6 address)
    return name.rstrip(".")


def is_loopback(name: str) -> bool:
    """True for ``localhost``, ``*.localhost`` (RFC 6761) and loopback addresses."""
    if name == "localhost" or name.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def host_allowed(host: str | None, allowed: Iterable[str] = ()) -> bool:
    """True when the ``Host`` header names a loopback host or one of ``allowed`` (names or
    addresses, compared without port and case)."""
    if not host:
        return False
    name = split_host(host)
    return is_loopback(name) or name in {split_host(a) for a in allowed}


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
    if not host:
        return False
    return parts.netloc.lower() == host.lower()


class HostCheck:
    """ASGI middleware: refuses every HTTP request (403) and websocket (closed with 1008, policy
    violation) whose ``Host`` is not allowed by :func:`host_allowed`."""

    def __init__(self, app, allowed: Iterable[str] = ()) -> None:
        self.app = app
        self.allowed = tuple(allowed)

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] in ("http", "websocket"):
            host = None
            for key, value in scope.get("headers", ()):
                if key == b"host":
                    host = value.decode("latin-1")
                    break
            if not host_allowed(host, self.allowed):
                logger.warning("dashboard: refused a request for host %r (not allowed)", host)
                if scope["type"] == "http":
                    await _refuse_http(send)
                else:
                    await send({"type": "websocket.close", "code": 1008, "reason": "host"})
                return
        await self.app(scope, receive, send)


async def _refuse_http(send) -> None:
    body = b'{"ok":false,"error":"host not allowed"}'
    await send(
        {
            "type": "http.response.start",
            "status": 403,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


def warn_if_public(host: str) -> None:
    """Log a warning when ``host`` is reachable from other machines."""
    if host not in LOCAL_HOSTS:
        logger.warning(
            "dashboard listening on %s: anyone who can reach this address can watch the "
            "stream and re-capture the reference (there is no authentication)", host
        )
