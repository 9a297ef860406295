"""Live dashboard: a web page fed by the live engine (FastAPI + websocket).

Modules by job: :mod:`~ectskin.dashboard.hub` (the engine → clients hand-over and rate limit),
:mod:`~ectskin.dashboard.messages` (the ``meta`` message, strict JSON encoding),
:mod:`~ectskin.dashboard.security` (Host and Origin checks, public-bind warning),
:mod:`~ectskin.dashboard.app` (the FastAPI routes and the websocket stream),
:mod:`~ectskin.dashboard.server` (socket, engine thread, uvicorn).

Typical use::

    from ectskin.dashboard import serve
    serve(engine)                      # http://127.0.0.1:8765/ until the engine ends
    serve(engine, keep_serving=True)   # ... then the last frame until Ctrl-C

or, from code that keeps running (tests, notebooks)::

    with DashboardServer(engine, port=0) as server:
        print(server.url)

FastAPI and uvicorn come with the ``live`` extra (``pip install 'ectskin[live]'``); they are
imported only when an app is built.
"""

from ectskin.dashboard.app import create_app
from ectskin.dashboard.hub import Hub
from ectskin.dashboard.messages import build_meta
from ectskin.dashboard.server import DashboardServer, serve

__all__ = ["DashboardServer", "Hub", "build_meta", "create_app", "serve"]
