"""Live dashboard: a web page fed by the live engine (FastAPI + websocket, see ``app.py``).

Typical use::

    from ectskin.dashboard import serve
    serve(engine)                      # http://127.0.0.1:8765/ until Ctrl-C

or, from code that keeps running (tests, notebooks)::

    with DashboardServer(engine, port=0) as server:
        print(server.url)

FastAPI and uvicorn come with the ``live`` extra (``pip install 'ectskin[live]'``); they are
imported only when an app is built.
"""

from ectskin.dashboard.app import DashboardServer, Hub, build_meta, create_app, serve

__all__ = ["DashboardServer", "Hub", "build_meta", "create_app", "serve"]
