"""Serving the app with uvicorn, stopping in the order the app needs.

uvicorn stops in three steps: it stops accepting, waits for the requests in flight (a
first Ctrl-C; forever, by default), then runs the lifespan's shutdown. A program check in
flight would hold the first step for up to ``programs.check_timeout_s`` (its worker
process ignores SIGINT), and a second Ctrl-C then cancelled its request (a 500). So
:class:`Server` runs the app's :func:`~app.server.app.begin_shutdown` (kill the check
workers: the check in flight answers 503 at once) before uvicorn's own shutdown; a
request a second Ctrl-C still cancels is answered 503 by app/server/errors.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from typing import Any

import uvicorn
from fastapi import FastAPI
from uvicorn.config import STARTUP_FAILURE

from app.server.app import begin_shutdown


class Server(uvicorn.Server):
    """uvicorn's server, with ``begin_shutdown(app)`` as the first step of its shutdown."""

    def __init__(self, config: uvicorn.Config, app: FastAPI) -> None:
        super().__init__(config)
        self.app = app

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        await asyncio.to_thread(begin_shutdown, self.app)
        await super().shutdown(sockets)


def serve(app: FastAPI, **options: Any) -> None:
    """Serve ``app`` until SIGINT or SIGTERM, as ``uvicorn.run(app, **options)`` does: a
    KeyboardInterrupt raised once it has stopped is the stop itself, not an error; a
    server that never started exits with uvicorn's status 3 (SystemExit)."""
    server = Server(uvicorn.Config(app, **options), app)
    with contextlib.suppress(KeyboardInterrupt):
        server.run()
    if not server.started:
        raise SystemExit(STARTUP_FAILURE)
